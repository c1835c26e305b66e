#pragma once
// Helpers shared by the dataset formats (one file per format: nuscenes.cpp, mmdet3d.cpp, kitti.cpp,
// argoverse2.cpp); not part of the module's public interface.
#include <array>
#include <filesystem>
#include <initializer_list>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include "core/rigid3.h"
#include "datasets/format.h"
#include "io/json.h"

namespace sd::datasets_internal {

// The rows of the format table, one per format file (format.cpp lists them in probe order).
LogFormatInfo NuScenesTablesFormat();
LogFormatInfo Mmdet3dV1Format();
LogFormatInfo Mmdet3dV0Format();
LogFormatInfo KittiFormat();
LogFormatInfo Argoverse2Format();

// `path` relative to `root` when it lies under it, else its file name.
std::string RelativePath(const std::filesystem::path& path, const std::filesystem::path& root);

// Deterministic 32-hex-digit token from a seed string (FNV-1a based), nuScenes token style.
std::string HexToken(const std::string& seed);

// Parses a JSON file written by Python (NaN / Infinity literals read as null); InputError naming the file.
nlohmann::json ReadPythonJson(const std::filesystem::path& path);

// Image width/height from a PNG IHDR or JPEG SOF header; {0, 0} when the file is missing or unrecognised.
std::array<int, 2> ImageSizeFromHeader(const std::filesystem::path& path);

// Yaw of a box in mmdetection3d camera coordinates: rotation about camera +y (down), measured so that the
// box x axis is (cos yaw, 0, -sin yaw). Pinned in datasets readers_test against the nuScenes cam_instances.
double CameraYaw(const Eigen::Matrix3d& R_cam_box);

// Record fields as the dataset JSON writes them; located InputErrors on the wrong shape.
Eigen::Matrix4d Mat4(const JsonReader& r);
Eigen::Matrix3d Mat3(const JsonReader& r);  // the top-left 3x3 of a 3x3 or larger matrix
std::vector<double> Vec(const JsonReader& r, size_t n);  // null -> NaN
Eigen::Vector3d Vec3(const JsonReader& r);
Rigid3d PoseWxyz(const JsonReader& rotation, const JsonReader& translation);  // quaternion w, x, y, z
// A sensor-frame (vx, vy) velocity rotated into the ego frame; NaN stays NaN.
Eigen::Vector2d RotateVelocity(const Rigid3d& T_ego_sensor, double vx, double vy);

// Nearest ancestor of `start` (inclusive) holding one of `children`; empty when none.
std::filesystem::path AncestorHolding(const std::filesystem::path& start, std::initializer_list<const char*> children);
// Dataset path as written in an info ("./data/nuscenes/samples/CAM_FRONT/x.jpg") -> data_root-relative, by
// its first samples/ or sweeps/ component; unchanged when there is none.
std::string StripToDataComponent(const std::string& p);

// The dataset's class name for an added object: canonical categories are translated through the format's
// table row, unknown names kept.
std::string ClassName(const AddedObject& obj, LogFormat format);

// Writes the sensor files of a derivative at their data_root-relative paths: replaced images (same size as the
// original, InputError otherwise) and sweeps, and every unchanged file the frame references (copied or
// symlinked; a missing one is an InputError or a warning, WriteOptions::require_sensor_files).
class SensorFileWriter {
 public:
  SensorFileWriter(const Log& log, const std::filesystem::path& out_dir, const WriteOptions& options)
      : log_(log), out_(out_dir), options_(options) {}
  void Image(const CameraSensor& cam, const ImageU8* replacement);
  void Lidar(const LidarSensor& lidar, const PointCloud* replacement);
  void Unchanged(const std::filesystem::path& src, const std::filesystem::path& dst);
  // Every camera image of the frame (replaced where the edit has one) and its sweep.
  void Frame(const sd::Frame& frame, const FrameEdit& edit);

 private:
  const Log& log_;
  std::filesystem::path out_;
  const WriteOptions& options_;
};
// SensorFileWriter::Frame for every edited frame.
void WriteSensorFiles(const Log& log, const std::vector<FrameEdit>& edits, const std::filesystem::path& out_dir,
                      const WriteOptions& options);

}  // namespace sd::datasets_internal
