#pragma once
// Helpers shared by the dataset formats (one file per format: nuscenes.cpp, mmdet3d.cpp, kitti.cpp,
// argoverse2.cpp); not part of the module's public interface.
#include <array>
#include <cmath>
#include <filesystem>
#include <initializer_list>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include "core/rigid3.h"
#include "core/box3.h"
#include "datasets/format.h"
#include "io/json.h"
#include "io/pickle.h"
#include "io/raw_json.h"

namespace sd::datasets_internal {

// The rows of the format table, one per format file (format.cpp lists them in probe order).
LogFormatInfo NuScenesTablesFormat();
LogFormatInfo Mmdet3dV1Format();
LogFormatInfo Mmdet3dV0Format();
LogFormatInfo KittiFormat();
LogFormatInfo Argoverse2Format();
LogFormatInfo Mmdet3dKittiFormat();
LogFormatInfo PandaSetFormat();

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
// A calibration or pose matrix, checked before anything trusts it (a non-rigid lidar2cam, a zero bottom row or a
// translation of 1e17 m used to be re-orthonormalised or passed on, and crashed the LiDAR caster or yielded data
// built on nonsense): every entry finite, the bottom row [0 0 0 1], the rotation orthonormal (to 1e-3) with
// determinant +1, the translation within `max_translation_m`. A located InputError (file and field) otherwise.
Rigid3d RigidPose(const JsonReader& r, double max_translation_m);
inline constexpr double kMaxSensorOffsetM = 100;     // a sensor's mounting relative to the ego (a vehicle's size)
inline constexpr double kMaxWorldCoordinateM = 1e7;  // a map frame's coordinates (UTM northings stay below)
inline constexpr int kMaxImageSidePx = 1 << 15;      // a camera image's side: 32768 px, 6x the largest driving cameras'
// A camera matrix (the top-left 3x3 of cam2img / P2) for an image of `width` x `height` (0: unknown): finite, focal
// lengths positive and below 1e6 px, the bottom row [0 0 1], no skew, the principal point near the image's centre.
// A located InputError otherwise.
Eigen::Matrix3d CameraMatrix(const JsonReader& r, int width, int height);
// The rule of CameraMatrix on a matrix already read (KITTI's calib text): the problem, or "" when there is none.
std::string CameraMatrixProblem(const Eigen::Matrix3d& K, int width, int height);
// "" when R is a rotation (orthonormal to 1e-3, determinant +1), else what it is not: RigidPose's rule, shared with
// the readers of rotations that are not JSON (KITTI's R0_rect and Tr_velo_to_cam).
std::string RotationProblem(const Eigen::Matrix3d& R);
// A driving camera's principal point lies near its image's centre: within 0.45-0.55 of the width and height in
// every camera of nuScenes, Lyft, KITTI, Argoverse 2 and PandaSet. Beyond a quarter of the image from the centre
// (outside its middle half), the image is not the one the calibration was made for: resized (a half-size nuScenes
// image puts it outside the image) or cropped (1600x900 cut to 1600x600 puts it at 82 % of the height). True
// where the size is unknown (0).
inline bool PrincipalPointNearCentre(double cx, double cy, int width, int height) {
  if (width <= 0 || height <= 0) return true;
  return std::abs(cx - 0.5 * width) <= 0.25 * width && std::abs(cy - 0.5 * height) <= 0.25 * height;
}
// "the principal point (cx, cy) is not near the centre of the WxH image ..." for the errors of the rule above.
std::string PrincipalPointProblem(double cx, double cy, int width, int height);
// What is wrong with a camera matrix's off-diagonal terms, or "" when nothing is: PinholeCamera has no skew, so
// a skew above 1e-3 fx (real calibrations hold exactly 0) or a non-zero K[1][0] would be dropped silently.
std::string SkewProblem(const Eigen::Matrix3d& K);
// Optional fields a reader defaulted, tallied per kind over a log's frames so each kind becomes one line of
// Log::assumptions ("<what> (in 3 of 81 frames, first: <token>)") instead of one per frame.
class AssumptionTally {
 public:
  void Note(const std::string& what, const std::string& frame_token);
  void AppendTo(std::vector<std::string>& assumptions, size_t frames) const;

 private:
  struct Kind {
    std::string what;
    size_t frames = 0;
    std::string first_token, last_token;
  };
  std::vector<Kind> kinds_;
};
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

// --- KITTI's label convention (rectified cam0: x right, y down, z forward; boxes by their bottom centre)

// A KITTI label box -> a geometric-centre Box3 in the Velodyne frame, size (l, w, h): the length axis is
// (cos ry, 0, -sin ry) in rect0, up is -y, centre = bottom - (0, h/2, 0). T_velo_rect0 = inv(R0_rect Tr_velo_to_cam).
Box3 BoxFromKittiLabel(const Eigen::Vector3d& bottom_rect0, double l, double h, double w, double ry, const Rigid3d& T_velo_rect0);
struct KittiLabelBox {
  Eigen::Vector3d bottom;  // rect0, m
  double l = 0, h = 0, w = 0, ry = 0;
};
// The inverse: only rotation_y (about rect0's y) is kept, any tilt of the box relative to that axis is dropped.
KittiLabelBox KittiLabelFromBox(const Box3& box_velo, const Rigid3d& T_rect0_velo);
// mmdet3d's KITTI difficulty (kitti_data_utils.add_difficulty_to_annos): 0 easy (2D box taller than 40 px,
// occluded 0, truncated <= 0.15), 1 moderate (> 25 px, <= 1, <= 0.3), 2 hard (> 25 px, <= 2, <= 0.5), else -1.
int KittiDifficulty(double box2d_height_px, int occluded, double truncated);
// KITTI occlusion level of a visible fraction: 0 fully visible (> 0.8), 1 partly (> 0.4), 2 largely; 3 unknown (< 0).
int KittiOccluded(double visible_fraction);

// --- mmdetection3d info files (mmdet3d.cpp; the KITTI-flavoured layouts in mmdet3d_kitti.cpp)

// An info file's content: a .json as Python wrote it (ReadPythonJson), a .pkl (gzipped or not) through
// pickle::LoadFile + pickle::ToJson, which is exact for infos (numpy scalars and arrays become numbers and
// nested lists, NaN null, as in the .json conversions). Nothing is ever executed: a pickle naming a global
// outside pickle.h's allow-list is an InputError. InputError naming the file.
nlohmann::json ReadInfoJson(const std::filesystem::path& info);
bool IsPickleInfo(const std::filesystem::path& info);  // by extension: .pkl, .pkl.gz
// OpenLogOptions::data_root, else the nearest ancestor of the info holding samples/ or training/, else its directory.
std::filesystem::path InfoDataRoot(const std::filesystem::path& info, const OpenLogOptions& options);
// A metainfo's class list: `categories` {name: index} (negative indices, KITTI's "DontCare": -1, are not classes),
// else `classes` / `CLASSES`; empty when it has none.
std::vector<std::string> InfoClasses(const JsonReader& metainfo);

// KITTI-flavoured infos (mmdet3d_kitti.cpp): a list of dicts (v0.x: image, point_cloud, calib, annos), or a
// data_list whose metainfo names KITTI or whose records carry images.R0_rect (v1.x: camera-frame boxes).
bool IsKittiInfo(const nlohmann::json& info);
Log ReadMmdet3dKittiInfo(const nlohmann::json& info, const std::filesystem::path& file, const OpenLogOptions& options);

// What a derivative adds to an info, built once per layout from the edits and applied by WriteInfoEdit to the
// input's own kind of file: the JSON text (spliced, io/raw_json.h) or the pickle (its value tree, io/pickle.h).
struct InfoListEdit {
  explicit InfoListEdit(std::vector<std::string> list_path, std::optional<size_t> insert_before = std::nullopt,
                        std::optional<pickle::DType> dtype = std::nullopt)
      : path(std::move(list_path)), insert_at(insert_before), column_dtype(dtype) {}
  // The list from the record: {"instances"}, {"cam_instances", "CAM_FRONT"}, {"gt_boxes"}, {"annos", "name"}.
  std::vector<std::string> path;
  std::vector<ojson> items;           // the added elements (rows, for numpy columns)
  std::optional<size_t> insert_at;    // where the first added element goes; nullopt or past the end: appended
  // Pickles: a numpy column created with this dtype where the record lacks it (else a list).
  std::optional<pickle::DType> column_dtype;
};
struct InfoRecordEdit {
  size_t record = 0;                  // index in the info's record list (= the frame index)
  std::vector<InfoListEdit> lists;    // lists sharing path[0] go under one parent, in order of first use
};
struct InfoEdit {
  const char* list_key = "data_list";  // the root's record list: "data_list", "infos"; "" = the root is the list
  std::vector<InfoRecordEdit> records;  // in output order; only these records are written
  // Appended to metainfo's class list (categories {name: index}, classes or CLASSES; categories created when
  // there is none), indices from first_class_index.
  std::vector<std::string> new_classes;
  size_t first_class_index = 0;
};
// Writes the edited info at its data_root-relative path under out_dir: a .json as the input's text with the
// additions spliced in (every untouched byte kept), a .pkl as the input's value tree with the additions, each
// added element typed like its neighbours (InfoListEdit), in the input's pickle protocol (2 for inputs of 0-2,
// else 4) and gzipped when the input was. Returns the written file. InputError unless the info holds one
// record per frame of the log.
std::filesystem::path WriteInfoEdit(const Log& log, const InfoEdit& edit, const std::filesystem::path& out_dir);

}  // namespace sd::datasets_internal
