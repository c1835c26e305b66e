#include "datasets/readers.h"

#include <cmath>
#include <map>
#include <string>

#include "core/error.h"
#include "core/log.h"
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

std::string Listed(const Eigen::Vector3d& v) { return Msg() << v.x() << ", " << v.y() << ", " << v.z(); }

// What every format's reader must have produced before synthesis trusts it, whatever the format checked on the
// way (the mmdet3d and nuScenes readers check each matrix where they read it, with its field): finite poses,
// sensors mounted on the vehicle, cameras with positive focal lengths. A zero focal length aborted inside Embree
// and a LiDAR mounted 1e17 m up crashed the road model; here they are one line naming the log, frame and sensor.
void CheckSensorGeometry(const Log& log) {
  using datasets_internal::kMaxSensorOffsetM, datasets_internal::kMaxWorldCoordinateM;
  constexpr double kMaxBoxDistanceM = 1e5;  // far beyond any sensor's range; an annotation beyond is a broken number
  constexpr double kMaxBoxSizeM = 100;      // longer than any road vehicle or structure a dataset boxes
  constexpr double kMaxTimestampS = 1e10;
  auto finite = [](const Rigid3d& T) { return T.rotation.coeffs().allFinite() && T.translation.allFinite(); };
  for (const Frame& f : log.frames) {
    auto fail = [&](const std::string& what) {
      throw InputError(log.source, Msg() << "frame " << f.token << ": " << what);
    };
    // Seconds: Unix time or from the log's start. Ego motion, sequences and the sun's position are derived from it.
    auto check_time = [&](double t, const std::string& what) {
      if (!std::isfinite(t) || std::abs(t) > kMaxTimestampS)
        fail(Msg() << "impossible " << what << "timestamp " << t << " s (at most " << kMaxTimestampS << " s, the year 2286)");
    };
    check_time(f.timestamp, "");
    if (f.lidar) check_time(f.lidar->timestamp, f.lidar->channel + " ");
    for (const CameraSensor& c : f.cameras) check_time(c.timestamp, c.channel + " ");
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
      if (!datasets_internal::PrincipalPointNearCentre(k.cx, k.cy, k.width, k.height))
        fail(Msg() << "camera " << c.channel << " (" << c.image_path.filename().string()
                   << "): " << datasets_internal::PrincipalPointProblem(k.cx, k.cy, k.width, k.height));
      if (!finite(c.T_ego_cam) || c.T_ego_cam.translation.norm() > kMaxSensorOffsetM)
        fail(Msg() << "camera " << c.channel << " mounted at (" << c.T_ego_cam.translation.transpose()
                   << ") m from the ego origin (at most " << kMaxSensorOffsetM << " m)");
    }
    // An annotated box is what placement keeps clear of and what the labels are compared with: a null or 1e308
    // entry used to surface as an "impossible scenario", far from its cause.
    for (size_t k = 0; k < f.annotations.size(); ++k) {
      const Box3& b = f.annotations[k].box;
      const Eigen::Vector3d c = b.center();
      if (!finite(b.T_frame_box) || !c.allFinite() || c.norm() > kMaxBoxDistanceM)
        fail(Msg() << "annotation " << k << " (" << f.annotations[k].category << "): impossible box centre (" << Listed(c)
                   << ") m in the ego frame (at most " << kMaxBoxDistanceM << " m away)");
      if (!b.size.allFinite() || b.size.minCoeff() <= 0 || b.size.maxCoeff() >= kMaxBoxSizeM)
        fail(Msg() << "annotation " << k << " (" << f.annotations[k].category << "): impossible box size ("
                   << Listed(b.size) << ") m (each must be > 0 and < " << kMaxBoxSizeM << " m)");
    }
  }
}

// Each frame once, each sensor file in one place only. A sample listed twice used to be synthesised twice into one
// image: labels for objects that are not in its pixels.
void CheckFramesDistinct(const Log& log) {
  std::map<std::string, size_t> frame_of_token, frame_of_file;
  for (size_t i = 0; i < log.frames.size(); ++i) {
    const Frame& f = log.frames[i];
    if (auto [it, fresh] = frame_of_token.emplace(f.token, i); !fresh)
      throw InputError(log.source, Msg() << "frame " << i << ": the sample " << f.token << " is listed twice (also frame "
                                         << it->second << "): each sample must appear once");
    auto once = [&](const fs::path& file, const std::string& sensor) {
      if (auto [it, fresh] = frame_of_file.emplace(file.lexically_normal().string(), i); !fresh)
        throw InputError(log.source, Msg() << "frame " << f.token << ": " << sensor << "'s file " << file.string()
                                           << " is also frame " << log.frames[it->second].token
                                           << "'s: one recording cannot be two samples");
    };
    if (f.lidar) once(f.lidar->path, f.lidar->channel);
    for (const CameraSensor& c : f.cameras) once(c.image_path, c.channel);
  }
}

// Sensor paths come from the info file, and an info file can name anything ("/etc/passwd", "../../.."). Only what
// lies under the data root is read; a layout that keeps its files elsewhere names a root that holds them
// (--data-root). Lexical, so a data root whose samples/ is a symlink to another disk still works.
void CheckPathsInsideDataRoot(const Log& log) {
  if (log.data_root.empty()) return;
  const fs::path root = fs::absolute(log.data_root).lexically_normal();
  auto inside = [&](const fs::path& p) {
    const fs::path rel = fs::absolute(p).lexically_normal().lexically_relative(root);
    return !rel.empty() && *rel.begin() != "..";
  };
  for (const Frame& f : log.frames) {
    auto check = [&](const fs::path& p, const std::string& sensor, const std::string& recorded) {
      // The system calls stop at a NUL: "a.jpg\u0000../../x" would open a.jpg while every check saw the rest.
      if (p.native().find('\0') != std::string::npos)
        throw InputError(log.source, Msg() << "frame " << f.token << ": " << sensor << "'s path holds a NUL character");
      if (!inside(p))
        throw InputError(log.source, Msg() << "frame " << f.token << ": " << sensor << "'s path '" << recorded
                                           << "' leads outside the data root " << root.string()
                                           << " (pass --data-root with a folder that holds it)");
    };
    if (f.lidar) check(f.lidar->path, f.lidar->channel, f.lidar->relpath.empty() ? f.lidar->path.string() : f.lidar->relpath);
    for (const CameraSensor& c : f.cameras)
      check(c.image_path, c.channel, c.image_relpath.empty() ? c.image_path.string() : c.image_relpath);
  }
}

// Every nuScenes camera records 1600x900 (devkit, all v1.0-* releases) and is calibrated for it: a camera matrix
// whose principal point lies within 10 % of that image's centre, used with an image of another size, is the
// original calibration on a resized or cropped image (1920x1080 or 1600x800 keep the principal point in their
// middle half, so the general check passes them). A resized copy with its calibration scaled along passes.
void CheckNuScenesImageSizes(const Log& log) {
  if (log.version.rfind("v1.0-", 0) != 0) return;
  for (const Frame& f : log.frames)
    for (const CameraSensor& c : f.cameras) {
      const PinholeCamera& k = c.intrinsics;
      const bool calibrated_for_1600x900 = std::abs(k.cx - 800) < 80 && std::abs(k.cy - 450) < 45;
      if (k.width > 0 && (k.width != 1600 || k.height != 900) && calibrated_for_1600x900)
        throw InputError(log.source, Msg() << "frame " << f.token << ": camera " << c.channel << "'s image "
                                           << c.image_path.filename().string() << " is " << k.width << "x" << k.height
                                           << ", but its calibration (principal point " << k.cx << ", " << k.cy
                                           << ") is nuScenes' for 1600x900 images (resized or cropped?)");
    }
}

// A camera's images all have one size: one image of another size than the others its calibration was used with
// was resized or cropped afterwards, even where its principal point still lies near the centre. Compared per
// channel and camera matrix: KITTI's frames come from drives calibrated apart, at 1224x370 and 1242x375.
void CheckImageSizesPerCalibration(const Log& log) {
  struct FirstSeen {
    int width, height;
    std::string token;
  };
  std::map<std::string, FirstSeen> size_of_camera;
  for (const Frame& f : log.frames) {
    for (const CameraSensor& c : f.cameras) {
      const PinholeCamera& k = c.intrinsics;
      if (k.width <= 0 || k.height <= 0) continue;  // no image file to measure
      const std::string camera = Msg() << c.channel << ' ' << k.fx << ' ' << k.fy << ' ' << k.cx << ' ' << k.cy;
      auto [it, fresh] = size_of_camera.emplace(camera, FirstSeen{k.width, k.height, f.token});
      if (!fresh && (it->second.width != k.width || it->second.height != k.height))
        throw InputError(log.source, Msg() << "frame " << f.token << ": camera " << c.channel << "'s image "
                                           << c.image_path.filename().string() << " is " << k.width << "x" << k.height
                                           << " where frame " << it->second.token << "'s, of the same calibration, is "
                                           << it->second.width << "x" << it->second.height
                                           << " (resized or cropped after calibration?)");
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
  CheckFramesDistinct(log);
  CheckPathsInsideDataRoot(log);
  CheckImageSizesPerCalibration(log);
  CheckNuScenesImageSizes(log);
  for (const std::string& a : log.assumptions) SD_LOG(Warn, log.source.string() << ": " << a);
  return log;
}

}  // namespace sd
