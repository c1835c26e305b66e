#pragma once
// A LiDAR sweep as the dataset stores it: N records of `num_features` float32 values, the first three being
// x, y, z in metres in the sensor frame. The remaining features keep their dataset meaning, named in
// `feature_names` (nuScenes: intensity 0..255, ring 0..31; KITTI: reflectance 0..1). Keeping the raw record
// layout lets a writer emit the same format byte for byte for the points we do not touch.
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/error.h"

namespace sd {

struct PointCloud {
  int num_features = 3;
  std::vector<std::string> feature_names = {"x", "y", "z"};
  std::vector<float> data;  // size() * num_features

  size_t size() const { return num_features > 0 ? data.size() / num_features : 0; }
  Eigen::Map<Eigen::Vector3f> xyz(size_t i) { return Eigen::Map<Eigen::Vector3f>(&data[i * num_features]); }
  Eigen::Map<const Eigen::Vector3f> xyz(size_t i) const {
    return Eigen::Map<const Eigen::Vector3f>(&data[i * num_features]);
  }
  float feature(size_t i, int f) const { return data[i * num_features + f]; }
  float& feature(size_t i, int f) { return data[i * num_features + f]; }
  // Index of a named feature, or -1.
  int FeatureIndex(const std::string& name) const;
  // Appends one record; `features` holds num_features values (x, y, z first).
  void Append(const float* features) { data.insert(data.end(), features, features + num_features); }
};

}  // namespace sd
