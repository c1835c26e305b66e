#include "datasets/readers.h"

#include <cmath>

#include "core/error.h"
#include "datasets/format.h"
#include "datasets/internal.h"
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

namespace {

// What every format's reader must have produced before synthesis trusts it, whatever the format checked on the
// way (the mmdet3d and nuScenes readers check each matrix where they read it, with its field): finite poses,
// sensors mounted on the vehicle, cameras with positive focal lengths. A zero focal length aborted inside Embree
// and a LiDAR mounted 1e17 m up crashed the road model; here they are one line naming the log, frame and sensor.
void CheckSensorGeometry(const Log& log) {
  using datasets_internal::kMaxSensorOffsetM, datasets_internal::kMaxWorldCoordinateM;
  auto finite = [](const Rigid3d& T) { return T.rotation.coeffs().allFinite() && T.translation.allFinite(); };
  for (const Frame& f : log.frames) {
    auto fail = [&](const std::string& what) {
      throw InputError(log.source, Msg() << "frame " << f.token << ": " << what);
    };
    if (!finite(f.T_world_ego) || f.T_world_ego.translation.norm() > kMaxWorldCoordinateM)
      fail(Msg() << "impossible ego pose (translation " << f.T_world_ego.translation.transpose() << " m)");
    if (f.lidar && (!finite(f.lidar->T_ego_lidar) || f.lidar->T_ego_lidar.translation.norm() > kMaxSensorOffsetM))
      fail(Msg() << "LiDAR " << f.lidar->channel << " mounted at (" << f.lidar->T_ego_lidar.translation.transpose()
                 << ") m from the ego origin (at most " << kMaxSensorOffsetM << " m)");
    for (const CameraSensor& c : f.cameras) {
      const PinholeCamera& k = c.intrinsics;
      if (!(std::isfinite(k.fx) && std::isfinite(k.fy) && k.fx > 0 && k.fy > 0 && std::isfinite(k.cx) && std::isfinite(k.cy)))
        fail(Msg() << "camera " << c.channel << ": impossible intrinsics fx = " << k.fx << ", fy = " << k.fy << ", cx = "
                   << k.cx << ", cy = " << k.cy);
      if (!datasets_internal::PrincipalPointInImage(k.cx, k.cy, k.width, k.height))
        fail(Msg() << "camera " << c.channel << ": the principal point (" << k.cx << ", " << k.cy << ") lies outside its "
                   << k.width << "x" << k.height << " image " << c.image_path.filename().string()
                   << " (resized or cropped after calibration?)");
      if (!finite(c.T_ego_cam) || c.T_ego_cam.translation.norm() > kMaxSensorOffsetM)
        fail(Msg() << "camera " << c.channel << " mounted at (" << c.T_ego_cam.translation.transpose()
                   << ") m from the ego origin (at most " << kMaxSensorOffsetM << " m)");
    }
  }
}

Log ReadAnyFormat(const fs::path& path, const OpenLogOptions& options) {
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

}  // namespace

Log OpenLog(const fs::path& path, const OpenLogOptions& options) {
  Log log = ReadAnyFormat(path, options);
  CheckSensorGeometry(log);
  return log;
}

}  // namespace sd
