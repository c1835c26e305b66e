#pragma once
// One photo → the views and coarse mesh of an asset, with no learned model: a shape prior makes the views the
// photo does not have (docs/shape_prior.md).
//
//   revolve  surfaces of revolution (cones, drums, bollards, posts): the axis from the silhouette's mirror
//            symmetry, the radius of each row from the rays through its outline (exact for a cylinder at any
//            elevation, so perspective needs no separate correction), the rim and base ellipses cut off at the
//            camera's elevation; the photo rotated about the axis gives the views of the other sides.
//   mirror   bilateral symmetry (vehicles, barriers, A-frame signs, tripods): the photo mirrored in the object's
//            symmetry plane is a second real silhouette, seen from the mirrored camera; the hull of the two is
//            carved inside the metric box.
//   extrude  thin flat objects facing the camera (signs, boards): the silhouette through the box's thickness.
//   hull     anything else: the single-view hull inside the metric box.
//
// Frame: the asset's canonical one — x front, y left, z up, metres, origin at the centre of the ground contact.
// The camera is placed so that its ray through the silhouette's centre meets the object's centre at the
// elevation given or estimated, at the distance where the object's metric size fills the silhouette; its roll is
// zero (the object stands upright in the photo). Everything assumed is recorded in PhotoShape, for asset.json.
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "assetgen/base_plate.h"
#include "assetgen/views.h"
#include "core/camera.h"
#include "core/image.h"
#include "core/mesh.h"

namespace sd {

enum class ShapePrior { kRevolve, kMirror, kExtrude, kHull };
const char* ToString(ShapePrior prior);
// "revolve", "mirror", "extrude", "hull"; nullopt for anything else.
std::optional<ShapePrior> ParseShapePrior(const std::string& name);
// The prior a category's objects have (traffic cones revolve, vehicles mirror, signs extrude, the rest hull).
ShapePrior DefaultShapePrior(const std::string& category);
// Vehicles whose body is solid across its width (cars, trucks, buses, trailers; not bicycles or barriers): the
// mirror prior empties what its views leave as a thin ridge across the width.
bool HasClosedBody(const std::string& category);

struct PhotoObservation {
  ImageU8 image;                         // sRGB, 3 or 4 channels
  ImageF mask;                           // 1 channel, image size, 0..1 (> 0.5 object)
  std::optional<PinholeCamera> camera;   // known intrinsics (a log's camera); else a field of view is assumed
  std::optional<double> elevation_deg;   // of the camera above the object's centre, when known
};

struct ShapePriorOptions {
  std::optional<ShapePrior> prior;       // forced; else DefaultShapePrior, demoted to hull when it cannot fit
  std::string category;
  Eigen::Vector3d size{1, 1, 1};         // length (x), width (y), height (z), metres
  bool size_measured = false;            // the size is the object's own (--size, a log's box), not its category's
  std::optional<double> yaw_deg;         // camera azimuth about the object, 0 = in front of it (+x), + to its left
  double assumed_vertical_fov_deg = 50;  // when the intrinsics are unknown
  double assumed_elevation_deg = 8;      // when neither given nor measurable (a road camera, objects 5-30 m away)
  // Revolve is refused (forced) or demoted (chosen) below this IoU of the silhouette with its mirror image.
  double min_revolve_symmetry = 0.85;
  int rotated_views = 8;                 // revolve: views about the axis, the photo's included
  int hull_resolution = 96;
  int view_size = 0;                     // square side of the views' images; 0 = the photo's crop at its size
};

struct PhotoShape {
  ShapePrior prior = ShapePrior::kHull;
  std::string prior_reason;              // "category traffic_cone", "forced", "silhouette symmetry 0.62 < 0.85"
  double symmetry_iou = 0;               // silhouette vs its mirror image about the fitted vertical axis
  double axis_tilt_deg = 0;              // that axis against the image's vertical
  PinholeCamera camera;                  // the photo's (possibly assumed) intrinsics
  bool intrinsics_assumed = false;
  double elevation_deg = 0;
  std::string elevation_method;          // "given", "base ellipse", "assumed"
  double yaw_deg = 0;
  std::string yaw_method;                // "given", "silhouette vs box outline ...", "facing the camera"
  double distance_m = 0;                 // camera to the object's centre
  // Revolve of a category that stands on a plate (HasBasePlate): the plate found under the body, and why or why not.
  std::optional<BasePlate> base_plate;
  std::string base_plate_note;
  TriangleMesh coarse;                   // canonical frame, metres; watertight
  // The photo's view first (colour, mask), then the views the prior made (rotated or mirrored photo, same
  // intrinsics); normals are zero (no estimator ran: refinement uses the mask terms only).
  MultiViewSet views;
  int real_views = 1;
};

// InputError (no file: the caller names the photo) for: an empty image, a mask of another size, a mask that is
// empty or covers (nearly) the whole image, a silhouette touching the image border on three or more sides (the
// object is not whole in the photo), a size that is not positive, a forced revolve on a clearly asymmetric
// silhouette (symmetry_iou below min_revolve_symmetry).
PhotoShape ShapeFromPhoto(const PhotoObservation& photo, const ShapePriorOptions& options);

// A closed surface through horizontal rings (each the same number of points, in the same counter-clockwise angular
// order about `centre`, seen from above) at heights z (ascending), capped by a fan about `centre` at each end;
// watertight, outward-facing.
TriangleMesh LoftRings(const std::vector<std::vector<Eigen::Vector2d>>& rings, const std::vector<double>& z,
                       const Eigen::Vector2d& centre = Eigen::Vector2d::Zero());

// A closed surface of revolution about the vertical through `axis`: rings (z ascending, radius), `segments` around,
// capped at both ends; watertight, outward-facing.
TriangleMesh SurfaceOfRevolution(const std::vector<std::pair<double, double>>& rings, int segments,
                                 const Eigen::Vector2d& axis = Eigen::Vector2d::Zero());

// The silhouette's IoU with its mirror image about the best vertical-ish axis (u = a + b v), and that axis.
struct SilhouetteAxis {
  double a = 0, b = 0;  // u = a + b * v, pixels
  double symmetry_iou = 0;
};
SilhouetteAxis FitSymmetryAxis(const ImageF& mask);

}  // namespace sd
