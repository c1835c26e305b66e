#pragma once
// Binary point clouds: little-endian float32 records with no header (nuScenes `.pcd.bin`: x y z intensity
// ring; KITTI `.bin`: x y z reflectance; Argoverse 2 conversions: x y z intensity laser).
#include <filesystem>
#include <string>
#include <vector>

#include "core/pointcloud.h"

namespace sd {

enum class PointFormat { kNuScenes, kKitti, kGeneric };

struct PointLayout {
  int num_features = 5;
  std::vector<std::string> feature_names;
  static PointLayout NuScenes();  // x y z intensity ring
  static PointLayout Kitti();     // x y z reflectance
};

// Reads N x layout.num_features float32. InputError when the file is missing, empty, or its size is not a
// whole number of records ("<file>: size 1003 B is not a whole number of 20-byte records").
PointCloud ReadPointCloudBin(const std::filesystem::path& path, const PointLayout& layout);
// Writes the records atomically.
void WritePointCloudBin(const std::filesystem::path& path, const PointCloud& cloud);

}  // namespace sd
