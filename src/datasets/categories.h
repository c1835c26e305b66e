#pragma once
// Canonical object categories and their names in each dataset format.
// Canonical names are nuScenes' detection classes plus the rare road objects SynthDrive is built for.
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "datasets/log.h"

namespace sd {

struct CategoryInfo {
  std::string name;              // canonical: "traffic_cone", "barrier", "car", "warning_tripod", ...
  Eigen::Vector3d default_size;  // length, width, height in metres (typical real object)
  std::string nuscenes_name;     // "movable_object.trafficcone"
  std::string kitti_name;        // "Car", or a CamelCase name for classes KITTI lacks ("TrafficCone")
  std::string pandaset_name;     // PandaSet's cuboid label ("Cones"), or a name in its style for classes it lacks
  double lidar_reflectivity;     // typical return intensity relative to asphalt (~1), for LiDAR simulation
};

const std::vector<CategoryInfo>& Categories();
// By canonical name or any dataset name (case-insensitive); empty when unknown.
std::optional<CategoryInfo> FindCategory(const std::string& name);
// The canonical name of `name` (FindCategory's), or `name` itself when no category knows it.
std::string CanonicalCategory(const std::string& name);
// The dataset's own class name for a canonical category.
std::string DatasetCategoryName(const CategoryInfo& category, LogFormat format);

}  // namespace sd
