#include "core/pointcloud.h"

namespace sd {

int PointCloud::FeatureIndex(const std::string& name) const {
  for (size_t i = 0; i < feature_names.size(); ++i)
    if (feature_names[i] == name) return static_cast<int>(i);
  return -1;
}

}  // namespace sd
