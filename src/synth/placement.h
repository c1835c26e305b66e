#pragma once
// Collision-free placement of requested objects on the estimated road surface.
//
// A candidate (position, yaw) drawn by the seeded generator from the request's ranges is accepted when:
//  - its footprint lies on the drivable area (>= 90% of footprint samples, GroundModel::DrivableFraction);
//  - no LiDAR point stands 0.25..3 m above the ground inside the footprint grown by the margin (unlabelled
//    obstacles: poles, walls, vegetation, parked bikes);
//  - its box does not overlap any annotated box or any object placed before it (grown by the margin);
//  - its centre is seen by at least one camera (projects into the image, in front of the camera).
// The object stands on the local surface: its up axis follows the local ground normal, its lowest point
// touches the local plane.
#include <string>
#include <vector>

#include <Eigen/Core>

#include "assetgen/asset.h"
#include "core/box3.h"
#include "datasets/log.h"
#include "synth/ground.h"
#include "synth/scenario.h"

namespace sd {

struct PlacedObject {
  const Asset* asset = nullptr;
  int request = -1;         // index into Scenario::objects
  Rigid3d T_ego_asset;      // canonical asset frame (ground-contact origin) -> ego
  Box3 box;                 // ego frame, geometric centre, size = asset extent
  double ground_height = 0; // local ground height under the object (ego z)
};

struct PlacementStats {
  int candidates = 0, off_road = 0, blocked_by_points = 0, overlaps_real = 0, overlaps_placed = 0, not_visible = 0;
  std::string Summary() const;
};

struct PlacementInput {
  const GroundModel* ground = nullptr;
  std::vector<Eigen::Vector3d> points_ego;  // whole sweep, ego frame
  std::vector<Box3> real_boxes;             // annotated objects, ego frame
  std::vector<const CameraSensor*> cameras;
  int max_candidates_per_object = 2000;
};

// Places every requested object, in request order. Assets are chosen from `assets` by id or category.
// InputError when a request names an unknown asset/category, or when an object finds no free space
// (the message says which object and why candidates were rejected).
std::vector<PlacedObject> PlaceObjects(const Scenario& scenario, const std::vector<Asset>& assets,
                                       const PlacementInput& input, PlacementStats* stats = nullptr);

}  // namespace sd
