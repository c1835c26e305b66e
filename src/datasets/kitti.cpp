// KITTI 3D object layout (<root>/{image_2,velodyne,calib,label_2}/NNNNNN.*, or <root>/training/...): the reader
// and the writer, which appends label lines. Conventions: docs/datasets.md.
#include <algorithm>
#include <cmath>
#include <map>
#include <numbers>
#include <sstream>
#include <string>
#include <vector>

#include "core/error.h"
#include "datasets/internal.h"
#include "io/files.h"

namespace fs = std::filesystem;

namespace sd {

using namespace datasets_internal;

namespace {

constexpr double kPi = std::numbers::pi;

// KITTI object calib file (P0..P3 3x4, R0_rect 3x3, Tr_velo_to_cam 3x4).
struct KittiCalib {
  Eigen::Matrix<double, 3, 4> P2;
  Eigen::Matrix3d R0_rect;
  Eigen::Matrix<double, 3, 4> Tr_velo_to_cam;
  // Rectified cam0 <- Velodyne: R0_rect * Tr_velo_to_cam (rigid up to R0_rect's rounding).
  Rigid3d T_rect0_velo() const;
  // Camera 2 <- rectified cam0: P2 = K [I | t], t = K^-1 P2[:,3].
  Rigid3d T_cam2_rect0() const;
  Eigen::Matrix3d K2() const { return P2.leftCols<3>(); }
};

std::vector<double> ParseNumbers(const std::string& text) {
  std::vector<double> v;
  std::istringstream is(text);
  std::string tok;
  while (is >> tok) {
    char* end = nullptr;
    const double d = std::strtod(tok.c_str(), &end);
    if (end == tok.c_str() || *end != '\0') return {};  // signals "unparseable"
    v.push_back(d);
  }
  return v;
}

// What the reader trusts of a calib file, by the rules an info file's matrices follow (CameraMatrix, RigidPose):
// finite entries, P2 a camera matrix (its principal point is checked against the image at OpenLog), R0_rect and
// Tr_velo_to_cam's rotations, the Velodyne within 100 m of the camera.
void CheckKittiCalib(const KittiCalib& c, const fs::path& path) {
  if (!c.P2.allFinite() || !c.R0_rect.allFinite() || !c.Tr_velo_to_cam.allFinite())
    throw InputError(path, "a calib entry is not a finite number");
  if (const std::string problem = CameraMatrixProblem(c.K2(), 0, 0); !problem.empty())
    throw InputError(path, "P2: " + problem);
  for (const auto& [key, R] : {std::pair<const char*, Eigen::Matrix3d>{"R0_rect", c.R0_rect},
                               {"Tr_velo_to_cam", c.Tr_velo_to_cam.leftCols<3>()}})
    if (const std::string problem = RotationProblem(R); !problem.empty()) throw InputError(path, Msg() << key << ": " << problem);
  if (c.Tr_velo_to_cam.col(3).norm() > kMaxSensorOffsetM)
    throw InputError(path, Msg() << "Tr_velo_to_cam: the translation is " << c.Tr_velo_to_cam.col(3).norm()
                                 << " m, beyond the " << kMaxSensorOffsetM << " m a sensor's mounting can be");
}

// InputError naming the file and line when a required key is missing or has the wrong number of values.
KittiCalib ReadKittiCalib(const fs::path& path) {
  if (!fs::exists(path)) throw InputError(path, "missing KITTI calib file");
  std::istringstream in(ReadFileToString(path));
  std::map<std::string, std::vector<double>> values;
  std::string line;
  int line_no = 0;
  while (std::getline(in, line)) {
    ++line_no;
    if (line.find_first_not_of(" \t\r") == std::string::npos) continue;
    const size_t colon = line.find(':');
    if (colon == std::string::npos)
      throw InputError(path, Msg() << "line " << line_no << ": expected 'KEY: values', got '" << line << "'");
    const std::string key = line.substr(0, colon);
    std::vector<double> v = ParseNumbers(line.substr(colon + 1));
    if (v.empty()) throw InputError(path, Msg() << "line " << line_no << " (" << key << "): unparseable numbers");
    values[key] = std::move(v);
  }
  auto get = [&](const std::string& key, size_t n) {
    auto it = values.find(key);
    if (it == values.end()) throw InputError(path, "missing calib entry " + key);
    if (it->second.size() != n)
      throw InputError(path, Msg() << key << " has " << it->second.size() << " values, expected " << n);
    return it->second;
  };
  KittiCalib c;
  const std::vector<double> p2 = get("P2", 12);
  for (int r = 0; r < 3; ++r)
    for (int k = 0; k < 4; ++k) c.P2(r, k) = p2[r * 4 + k];
  const std::vector<double> r0 = get("R0_rect", 9);
  for (int r = 0; r < 3; ++r)
    for (int k = 0; k < 3; ++k) c.R0_rect(r, k) = r0[r * 3 + k];
  const std::vector<double> tr = get("Tr_velo_to_cam", 12);
  for (int r = 0; r < 3; ++r)
    for (int k = 0; k < 4; ++k) c.Tr_velo_to_cam(r, k) = tr[r * 4 + k];
  CheckKittiCalib(c, path);
  return c;
}

Rigid3d KittiCalib::T_rect0_velo() const {
  const Eigen::Matrix3d R = R0_rect * Tr_velo_to_cam.leftCols<3>();
  return Rigid3d(R, Eigen::Vector3d(R0_rect * Tr_velo_to_cam.col(3)));
}

Rigid3d KittiCalib::T_cam2_rect0() const {
  return Rigid3d(Eigen::Quaterniond::Identity(), Eigen::Vector3d(K2().inverse() * P2.col(3)));
}

fs::path KittiSplitDir(const fs::path& root) {
  if (fs::is_directory(root / "calib") && (fs::is_directory(root / "label_2") || fs::is_directory(root / "velodyne")))
    return root;
  if (fs::is_directory(root / "training" / "calib")) return root / "training";
  return {};
}

}  // namespace

Log ReadKitti(const fs::path& root, const OpenLogOptions& options) {
  const fs::path split = KittiSplitDir(root);
  if (split.empty()) throw InputError(root, "not a KITTI object directory (expected calib/ and label_2/, or training/)");
  Log log;
  log.format = LogFormat::kKitti;
  log.source = root;
  log.data_root = options.data_root.empty() ? split : options.data_root;
  log.annotation_path = split / "label_2";
  log.version = "kitti-object";
  log.sequential = false;            // object frames: no world pose, no time order
  log.ego_origin_on_ground = false;  // ego = the Velodyne frame, 1.73 m above the road
  log.nominal_road_z = -1.73;
  log.categories = {"Car", "Van", "Truck", "Pedestrian", "Person_sitting", "Cyclist", "Tram", "Misc"};
  std::vector<std::string> ids;
  for (const auto& e : fs::directory_iterator(split / "calib"))
    if (e.path().extension() == ".txt") ids.push_back(e.path().stem().string());
  std::sort(ids.begin(), ids.end());
  AssumptionTally assumed;
  for (const std::string& id : ids) {
    const KittiCalib calib = ReadKittiCalib(split / "calib" / (id + ".txt"));
    const Rigid3d T_rect0_velo = calib.T_rect0_velo();
    Frame f;
    f.token = id;
    LidarSensor l;
    l.channel = "velodyne";
    l.relpath = "velodyne/" + id + ".bin";
    l.path = split / l.relpath;
    l.layout = PointLayout::Kitti();
    // KITTI stores scan lines in azimuth order, not firing order: the sensor spins clockwise and the sweep
    // starts behind it; the scans are raw, not de-skewed.
    l.spin_direction = -1;
    l.start_azimuth = kPi;
    l.motion_compensated = false;
    f.lidar = l;  // ego = Velodyne frame: T_ego_lidar = identity
    CameraSensor cam;
    cam.channel = "image_2";
    cam.image_relpath = "image_2/" + id + ".png";
    cam.image_path = split / cam.image_relpath;
    // A layout without image_2/ is LiDAR only; one frame's image missing from it is a broken copy, and without
    // it the frame's objects would be placed where no camera looks.
    if (!fs::exists(cam.image_path) && fs::is_directory(split / "image_2"))
      throw InputError(cam.image_path, "missing KITTI image (its calib and velodyne files are there)");
    if (fs::exists(cam.image_path)) {
      const auto wh = ImageSizeFromHeader(cam.image_path);
      cam.intrinsics = PinholeCamera::FromK(calib.K2(), wh[0], wh[1]);
      cam.T_ego_cam = (calib.T_cam2_rect0() * T_rect0_velo).Inverse();
      cam.T_egocam_cam = cam.T_ego_cam;
      f.cameras.push_back(cam);
    } else {
      assumed.Note("image_2/ missing: no camera (LiDAR only)", id);
    }

    const fs::path label_file = split / "label_2" / (id + ".txt");
    if (fs::exists(label_file)) {
      f.has_annotations = true;
      std::istringstream in(ReadFileToString(label_file));
      std::string line;
      int line_no = 0;
      const Rigid3d T_velo_rect0 = T_rect0_velo.Inverse();
      while (std::getline(in, line)) {
        ++line_no;
        std::istringstream ls(line);
        std::string type;
        if (!(ls >> type)) continue;
        if (type == "DontCare") continue;
        std::string rest;
        std::getline(ls, rest);
        const std::vector<double> v = ParseNumbers(rest);
        if (v.size() < 14)
          throw InputError(label_file, Msg() << "line " << line_no << ": expected 15 fields (type + 14 numbers), got '" << line << "'");
        // v: truncated occluded alpha x1 y1 x2 y2 h w l x y z ry
        const double h = v[7], w = v[8], len = v[9], ry = v[13];
        for (size_t k = 0; k < 14; ++k)
          if (!std::isfinite(v[k])) throw InputError(label_file, Msg() << "line " << line_no << ": field " << k + 2 << " is not a finite number");
        if (!(h > 0 && w > 0 && len > 0 && h < 100 && w < 100 && len < 100))
          throw InputError(label_file, Msg() << "line " << line_no << ": impossible dimensions h w l = " << h << " " << w << " " << len
                                             << " m (each must be > 0 and < 100)");
        const Eigen::Vector3d bottom(v[10], v[11], v[12]);
        const double c = std::cos(ry), s = std::sin(ry);
        Eigen::Matrix3d R_rect0_box;
        // Box axes in rectified cam0 (y down): length along (cos ry, 0, -sin ry), up = -y.
        R_rect0_box.col(0) = Eigen::Vector3d(c, 0, -s);
        R_rect0_box.col(1) = Eigen::Vector3d(s, 0, c);
        R_rect0_box.col(2) = Eigen::Vector3d(0, -1, 0);
        Annotation a;
        a.category = type;
        a.box.T_frame_box = T_velo_rect0 * Rigid3d(R_rect0_box, Eigen::Vector3d(bottom - Eigen::Vector3d(0, h / 2, 0)));
        a.box.size = Eigen::Vector3d(len, w, h);
        a.truncation = v[0];
        a.visibility = static_cast<int>(v[1]);
        a.box2d_by_camera[cam.channel] = Box2{v[3], v[4], v[5], v[6]};
        f.annotations.push_back(std::move(a));
      }
    }
    log.frames.push_back(std::move(f));
  }
  assumed.AppendTo(log.assumptions, log.frames.size());
  return log;
}

namespace {

std::vector<fs::path> WriteKitti(const Log& log, const std::vector<FrameEdit>& edits, const fs::path& out_dir,
                                 const WriteOptions& options) {
  WriteSensorFiles(log, edits, out_dir, options);
  std::vector<fs::path> written;
  for (const FrameEdit& e : edits) {
    const Frame& frame = log.frames[e.frame_index];
    const fs::path calib_src = log.data_root / "calib" / (frame.token + ".txt");
    const KittiCalib calib = ReadKittiCalib(calib_src);
    const Rigid3d T_rect0_velo = calib.T_rect0_velo();
    WriteFileAtomic(out_dir / "calib" / (frame.token + ".txt"), ReadFileToString(calib_src));
    const fs::path label_src = log.annotation_path / (frame.token + ".txt");
    std::string text = fs::exists(label_src) ? ReadFileToString(label_src) : std::string();
    if (!text.empty() && text.back() != '\n') text += '\n';
    for (const AddedObject& obj : e.added) {
      const Box3 b = obj.annotation.box.Transformed(T_rect0_velo);
      const Eigen::Vector3d x_axis = b.T_frame_box.Rotation().col(0);
      const double ry = std::atan2(-x_axis.z(), x_axis.x());
      const double l = b.size.x(), w = b.size.y(), h = b.size.z();
      const Eigen::Vector3d bottom = b.center() + Eigen::Vector3d(0, h / 2, 0);  // rect cam0: y down
      double alpha = ry - std::atan2(bottom.x(), bottom.z());
      alpha = std::atan2(std::sin(alpha), std::cos(alpha));
      Box2 box2;
      double truncation = 0, visible = -1;
      for (const CameraBox& cb : obj.camera_boxes)
        if (cb.channel == "image_2") {
          box2 = cb.box;
          truncation = cb.truncation;
          visible = cb.visible_fraction;
        }
      // KITTI occlusion: 0 fully visible, 1 partly, 2 largely occluded, 3 unknown.
      const int occluded = visible < 0 ? 3 : visible > 0.8 ? 0 : visible > 0.4 ? 1 : 2;
      std::ostringstream line;
      line << ClassName(obj, LogFormat::kKitti) << ' ' << Fixed(std::clamp(truncation, 0.0, 1.0), 2) << ' ' << occluded
           << ' ' << Fixed(alpha, 2) << ' ' << Fixed(box2.x1, 2) << ' ' << Fixed(box2.y1, 2) << ' ' << Fixed(box2.x2, 2)
           << ' ' << Fixed(box2.y2, 2)
           // Sub-millimetre digits (official labels carry 2) so the box survives a round trip to 1e-4 m.
           << ' ' << Fixed(h, 6) << ' ' << Fixed(w, 6) << ' ' << Fixed(l, 6) << ' ' << Fixed(bottom.x(), 6) << ' '
           << Fixed(bottom.y(), 6) << ' ' << Fixed(bottom.z(), 6) << ' ' << Fixed(ry, 6) << '\n';
      text += line.str();
    }
    const fs::path label_dst = out_dir / "label_2" / (frame.token + ".txt");
    WriteFileAtomic(label_dst, text);
    written.push_back(label_dst);
  }
  return written;
}

}  // namespace

namespace datasets_internal {

LogFormatInfo KittiFormat() {
  return {LogFormat::kKitti, "kitti", "kitti", [](const fs::path& p) { return fs::is_directory(p) && !KittiSplitDir(p).empty(); },
          &ReadKitti, &WriteKitti, nullptr, [](const CategoryInfo& c) { return c.kitti_name; }};
}

}  // namespace datasets_internal
}  // namespace sd
