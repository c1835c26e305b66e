#pragma once
// Inserting objects into a real LiDAR sweep by casting the sweep's own beams.
//
//  - Every real return whose beam now meets an inserted object before its recorded range moves onto the
//    object's surface (the object blocks it); its other features (ring, ...) are kept, intensity is
//    re-simulated.
//  - Beams that returned nothing in the real sweep (sky, far range) are recovered from the scan pattern:
//    per ring, the elevation angle and azimuth step are measured from the sweep, and empty azimuth slots
//    across each object are cast too; hits are added as new points. Needs a ring feature (nuScenes); for
//    formats without one (KITTI) only the real returns are cast.
//  - Intensity = reference x |cos(incidence)| / 0.7, where the reference is the median intensity of real
//    points on annotated objects of the same category in this sweep, or the category's relative
//    reflectivity x the median intensity of the sweep's ground points. Clamped to the sweep's range.
// Points of the sweep that no object touches are returned bit-identical.
#include <string>
#include <vector>

#include "core/pointcloud.h"
#include "core/rigid3.h"
#include "synth/placement.h"

namespace sd {

struct LidarSimInput {
  const PointCloud* sweep = nullptr;  // sensor frame, dataset layout
  Rigid3d T_ego_lidar;
  std::vector<const PlacedObject*> objects;
  // Per-object reference intensity (see file comment); computed by the caller from the sweep.
  std::vector<float> reference_intensity;
  float max_range = 120.0f;
};

struct LidarSimResult {
  PointCloud cloud;
  int moved = 0, added = 0;
  std::vector<int> points_on_object;  // per object
  // For verification: indices (into cloud) of every point that now lies on an object, and which object.
  std::vector<std::pair<int, int>> object_points;
};

LidarSimResult SimulateLidar(const LidarSimInput& input);

// Reference intensity per object (see file comment). `points_ego` is the sweep in the ego frame.
std::vector<float> ReferenceIntensities(const PointCloud& sweep, const std::vector<Eigen::Vector3d>& points_ego,
                                        const std::vector<int>& ground_indices,
                                        const std::vector<std::pair<std::string, Box3>>& annotated,  // category, box
                                        const std::vector<const PlacedObject*>& objects);

}  // namespace sd
