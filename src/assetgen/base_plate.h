#pragma once
// A traffic cone stands on a square plate. A surface of revolution turns that plate into a disc, and the
// plate's corner — which drops below the body as a V when seen corner-on — into a flared skirt, both wrong
// from every side but the photo's (docs/shape_prior.md). This finds the plate from the revolve's profile and
// the photo's silhouette, and builds the body standing on it as one closed mesh.
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "assetgen/views.h"
#include "core/image.h"
#include "core/mesh.h"

namespace sd {

struct BasePlate {
  double half_x = 0, half_y = 0;  // half-sides along the plate's own axes, metres
  double thickness = 0;           // metres: the plate's top face lies at z = thickness, its bottom on z = 0
  double yaw = 0;                 // radians: the plate's x axis against the object frame's x (+ towards +y)
};

// Categories whose objects usually stand on a square plate (traffic cones).
bool HasBasePlate(const std::string& category);

// The rings (z ascending, radius; those at or below the plate's top are dropped) turned about the vertical
// through the origin, standing on `plate`: one closed, outward-facing mesh. `segments` is rounded up to a
// multiple of 4 so that the apex of each of the plate's (rounded) corners is a vertex.
TriangleMesh SurfaceOfRevolutionOnPlate(const std::vector<std::pair<double, double>>& rings, int segments,
                                        const BasePlate& plate);

struct BasePlateFit {
  std::optional<BasePlate> plate;                // nullopt: no plate (see `note`)
  std::vector<std::pair<double, double>> body;   // with a plate: the rings above it, the body's foot continued
                                                 // straight down to the plate (the flare was the plate's outline)
  double ground = 0;                             // with a plate: the plate's bottom in the rings' z (the object
                                                 // stands there; `body` is measured from it)
  double iou_disc = 0, iou_plate = 0;            // the photo's mask against each model redrawn at its camera
                                                 // (0 where the foot does not flare: no plate was tried)
  std::string note;                              // why, in words (for asset.json)
};

// The plate under a revolve's profile `rings` (metres, z ascending from 0; the radius of each row as the photo's
// outline gives it), seen by `photo` (the photo's camera and pose in the object frame, mask 0..1 at its size).
// A plate is looked for where the foot's radius flares above the straight line of the body (the lower third
// against the middle half) and kept where, redrawn at the photo, it covers the mask at least as well as the
// disc the revolve would make. Its heading and thickness come from the photo; its half-sides are `half_sides`
// where a metric box was measured (a cone's box is its plate), else fitted to the photo with the sides' ratio
// `aspect` (half_y / half_x). The plate's corners are rounded, as moulded plates' are.
BasePlateFit FitBasePlate(const std::vector<std::pair<double, double>>& rings, const ViewCamera& photo,
                          const ImageF& mask, double aspect = 1.0,
                          std::optional<Eigen::Vector2d> half_sides = std::nullopt);

}  // namespace sd
