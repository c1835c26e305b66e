#include "io/pointcloud_io.h"

#include <cmath>
#include <cstring>

#include "core/error.h"
#include "io/files.h"

namespace sd {

PointLayout PointLayout::NuScenes() { return {5, {"x", "y", "z", "intensity", "ring"}}; }
PointLayout PointLayout::Kitti() { return {4, {"x", "y", "z", "reflectance"}}; }

PointCloud ReadPointCloudBin(const std::filesystem::path& path, const PointLayout& layout) {
  SD_CHECK(layout.num_features >= 3);
  const std::string bytes = ReadFileToString(path);
  const size_t record = sizeof(float) * static_cast<size_t>(layout.num_features);
  if (bytes.empty()) throw InputError(path, "point cloud file is empty");
  if (bytes.size() % record != 0)
    throw InputError(path, Msg() << "size " << bytes.size() << " B is not a whole number of " << record
                                 << "-byte records (" << layout.num_features << " x float32 per point)");
  PointCloud cloud;
  cloud.num_features = layout.num_features;
  cloud.feature_names = layout.feature_names;
  cloud.feature_names.resize(layout.num_features);
  cloud.data.resize(bytes.size() / sizeof(float));
  std::memcpy(cloud.data.data(), bytes.data(), bytes.size());  // little-endian host assumed (x86-64, arm64)
  for (size_t i = 0; i < cloud.size(); ++i)
    if (!cloud.xyz(i).allFinite()) throw InputError(path, Msg() << "point " << i << " has a non-finite coordinate");
  return cloud;
}

void WritePointCloudBin(const std::filesystem::path& path, const PointCloud& cloud) {
  WriteFileAtomic(path, std::string_view(reinterpret_cast<const char*>(cloud.data.data()),
                                         cloud.data.size() * sizeof(float)));
}

}  // namespace sd
