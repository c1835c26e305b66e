#include "datasets/readers.h"

#include "core/error.h"
#include "datasets/format.h"
#include "io/pointcloud_io.h"

namespace fs = std::filesystem;

namespace sd {

const CameraSensor* Frame::FindCamera(const std::string& channel) const {
  for (const CameraSensor& c : cameras)
    if (c.channel == channel) return &c;
  return nullptr;
}

PointCloud ReadLidar(const LidarSensor& lidar) {
  if (lidar.file == SweepFile::kPandaSetPickle) return ReadPandaSetSweep(lidar);
  if (!fs::exists(lidar.path)) throw InputError(lidar.path, "missing LiDAR sweep file (recorded as " + lidar.relpath + ")");
  return ReadPointCloudBin(lidar.path, lidar.layout);
}

Log OpenLog(const fs::path& path, const OpenLogOptions& options) {
  if (options.format) return FormatInfo(*options.format).read(path, options);
  if (!fs::exists(path)) throw InputError(path, "no such file or directory");
  // First match wins. Probes are cheap (directory layout, file extension); the reader then validates the
  // content and reports what is wrong with it.
  for (const LogFormatInfo& f : LogFormats())
    if (f.probe && f.probe(path)) return f.read(path, options);
  if (fs::is_regular_file(path)) throw InputError(path, "unrecognised dataset file (expected an mmdet3d info .json or .pkl)");
  throw InputError(path, "unrecognised dataset directory: no nuScenes tables (v1.0-*/sample.json), no KITTI "
                         "calib/label_2 (or training/), no Argoverse 2 city_SE3_egovehicle.json + annotations.json, "
                         "no PandaSet lidar/poses.json + camera/; for mmdet3d pass the info .json or .pkl");
}

}  // namespace sd
