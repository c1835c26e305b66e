#include "datasets/internal.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>

#include "core/error.h"
#include "core/log.h"
#include "io/files.h"
#include "io/image_io.h"
#include "io/pointcloud_io.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace sd::datasets_internal {

std::string RelativePath(const fs::path& path, const fs::path& root) {
  if (!root.empty()) {
    const fs::path rel = path.lexically_normal().lexically_relative(root.lexically_normal());
    if (!rel.empty() && *rel.begin() != "..") return rel.generic_string();
  }
  return path.filename().string();
}

std::string HexToken(const std::string& seed) {
  // Two FNV-1a 64-bit hashes with different offsets give 128 bits: deterministic, no RNG state.
  auto fnv = [&](uint64_t h) {
    for (unsigned char c : seed) h = (h ^ c) * 1099511628211ull;
    return h;
  };
  char buf[33];
  std::snprintf(buf, sizeof buf, "%016llx%016llx", static_cast<unsigned long long>(fnv(14695981039346656037ull)),
                static_cast<unsigned long long>(fnv(0x84222325cbf29ce4ull)));
  return buf;
}

std::array<int, 2> ImageSizeFromHeader(const fs::path& path) {
  std::error_code ec;
  if (!fs::is_regular_file(path, ec)) return {0, 0};  // a FIFO would block here; ReadImage says what it is
  std::ifstream in(path, std::ios::binary);
  if (!in) return {0, 0};
  std::string head(64 * 1024, '\0');
  in.read(head.data(), static_cast<std::streamsize>(head.size()));
  head.resize(static_cast<size_t>(in.gcount()));
  auto u8 = [&](size_t i) { return static_cast<unsigned>(static_cast<unsigned char>(head[i])); };
  auto be16 = [&](size_t i) { return static_cast<int>((u8(i) << 8) | u8(i + 1)); };
  auto be32 = [&](size_t i) { return static_cast<int>((u8(i) << 24) | (u8(i + 1) << 16) | (u8(i + 2) << 8) | u8(i + 3)); };
  if (head.size() >= 24 && head.compare(0, 8, "\x89PNG\r\n\x1a\n") == 0 && head.compare(12, 4, "IHDR") == 0)
    return {be32(16), be32(20)};
  if (head.size() >= 4 && u8(0) == 0xFF && u8(1) == 0xD8) {
    size_t i = 2;
    while (i + 9 < head.size()) {
      if (u8(i) != 0xFF) return {0, 0};
      const unsigned marker = u8(i + 1);
      if (marker == 0xFF) { ++i; continue; }
      // SOF0..SOF15 except DHT (C4), JPG (C8), DAC (CC) carry height, width.
      if (marker >= 0xC0 && marker <= 0xCF && marker != 0xC4 && marker != 0xC8 && marker != 0xCC)
        return {be16(i + 7), be16(i + 5)};
      i += 2 + static_cast<size_t>(be16(i + 2));
    }
  }
  return {0, 0};
}

// Python's json module writes NaN / Infinity / -Infinity, which strict JSON (and nlohmann) rejects: pickle
// conversions of mmdet3d infos contain them (e.g. gt_velocity of boxes without a track). Read them as null.
json ReadPythonJson(const fs::path& path) {
  const std::string text = ReadFileToString(path);
  std::string clean;
  clean.reserve(text.size());
  bool in_string = false;
  for (size_t i = 0; i < text.size(); ++i) {
    const char c = text[i];
    if (in_string) {
      clean += c;
      if (c == '\\' && i + 1 < text.size()) clean += text[++i];
      else if (c == '"') in_string = false;
      continue;
    }
    if (c == '"') in_string = true;
    if (text.compare(i, 3, "NaN") == 0) { clean += "null"; i += 2; continue; }
    if (text.compare(i, 8, "Infinity") == 0) { clean += "null"; i += 7; continue; }
    if (text.compare(i, 9, "-Infinity") == 0) { clean += "null"; i += 8; continue; }
    clean += c;
  }
  return ParseJsonText(clean, path);
}

double CameraYaw(const Eigen::Matrix3d& R_cam_box) {
  const Eigen::Vector3d x = R_cam_box.col(0);
  return std::atan2(-x.z(), x.x());
}

Eigen::Matrix4d Mat4(const JsonReader& r) {
  if (r.Size() != 4) r.Fail(Msg() << "expected a 4x4 matrix, found " << r.Size() << " rows");
  Eigen::Matrix4d m;
  for (size_t i = 0; i < 4; ++i) {
    if (r[i].Size() != 4) r[i].Fail(Msg() << "expected 4 columns, found " << r[i].Size());
    for (size_t j = 0; j < 4; ++j) m(i, j) = r[i][j].Number();
  }
  return m;
}

Eigen::Matrix3d Mat3(const JsonReader& r) {
  if (r.Size() < 3) r.Fail(Msg() << "expected a 3x3 matrix, found " << r.Size() << " rows");
  Eigen::Matrix3d m;
  for (size_t i = 0; i < 3; ++i) {
    if (r[i].Size() < 3) r[i].Fail(Msg() << "expected 3 columns, found " << r[i].Size());
    for (size_t j = 0; j < 3; ++j) m(i, j) = r[i][j].Number();
  }
  return m;
}

Rigid3d RigidPose(const JsonReader& r, double max_translation_m) {
  const Eigen::Matrix4d m = Mat4(r);
  if (!m.allFinite()) r.Fail("a matrix entry is not finite");
  if ((m.row(3) - Eigen::RowVector4d(0, 0, 0, 1)).cwiseAbs().maxCoeff() > 1e-6)
    r.Fail(Msg() << "not a rigid transform: the bottom row is [" << m.row(3) << "], not [0 0 0 1]");
  if (const std::string rotation = RotationProblem(m.topLeftCorner<3, 3>()); !rotation.empty())
    r.Fail("not a rigid transform: " + rotation);
  const double t = m.topRightCorner<3, 1>().norm();
  if (t > max_translation_m)
    r.Fail(Msg() << "the translation is " << t << " m from the origin, beyond the " << max_translation_m << " m a "
                 << (max_translation_m <= kMaxSensorOffsetM ? "sensor's mounting" : "pose") << " can be");
  return Rigid3d::FromMatrix(m);
}

std::string RotationProblem(const Eigen::Matrix3d& R) {
  const double off = (R.transpose() * R - Eigen::Matrix3d::Identity()).cwiseAbs().maxCoeff();
  if (off > 1e-3) return Msg() << "the rotation is not orthonormal (R^T R differs from I by " << off << ")";
  if (R.determinant() < 0) return "the rotation is a reflection (determinant -1)";
  return "";
}

std::string CameraMatrixProblem(const Eigen::Matrix3d& K, int width, int height) {
  if (!K.allFinite()) return "a camera matrix entry is not finite";
  if (!(K(0, 0) > 0 && K(1, 1) > 0 && K(0, 0) < 1e6 && K(1, 1) < 1e6))
    return Msg() << "impossible focal lengths fx = " << K(0, 0) << ", fy = " << K(1, 1) << " px (must be > 0 and < 1e6)";
  if ((K.row(2) - Eigen::RowVector3d(0, 0, 1)).cwiseAbs().maxCoeff() > 1e-6)
    return Msg() << "not a camera matrix: the bottom row is [" << K.row(2) << "], not [0 0 1]";
  if (std::string skew = SkewProblem(K); !skew.empty()) return skew;
  if (!PrincipalPointNearCentre(K(0, 2), K(1, 2), width, height)) return PrincipalPointProblem(K(0, 2), K(1, 2), width, height);
  return "";
}

Eigen::Matrix3d CameraMatrix(const JsonReader& r, int width, int height) {
  const Eigen::Matrix3d K = Mat3(r);
  if (const std::string problem = CameraMatrixProblem(K, width, height); !problem.empty()) r.Fail(problem);
  return K;
}

std::string SkewProblem(const Eigen::Matrix3d& K) {
  if (std::abs(K(0, 1)) > 1e-3 * std::abs(K(0, 0)) || std::abs(K(1, 0)) > 1e-6)
    return Msg() << "a skewed camera matrix (K[0][1] = " << K(0, 1) << ", K[1][0] = " << K(1, 0)
                 << "): the pinhole model here has no skew, and dropping it would move the projections";
  return "";
}

std::string PrincipalPointProblem(double cx, double cy, int width, int height) {
  const bool inside = cx >= 0 && cx <= width && cy >= 0 && cy <= height;
  return Msg() << "the principal point (" << cx << ", " << cy << ") lies " << (inside ? "far from the centre of" : "outside")
               << " the " << width << "x" << height << " image (a driving camera's lies in its middle half): the image "
               << "is not the size this calibration was made for (resized or cropped?)";
}

void AssumptionTally::Note(const std::string& what, const std::string& frame_token) {
  for (Kind& k : kinds_) {
    if (k.what != what) continue;
    // A frame counts once however many of its sensors lack the field; readers note frame by frame.
    if (k.last_token != frame_token) ++k.frames, k.last_token = frame_token;
    return;
  }
  kinds_.push_back({what, 1, frame_token, frame_token});
}

void AssumptionTally::AppendTo(std::vector<std::string>& assumptions, size_t frames) const {
  for (const Kind& k : kinds_)
    assumptions.push_back(Msg() << k.what << " (in " << k.frames << " of " << frames << " frames, first: " << k.first_token << ")");
}

std::vector<double> Vec(const JsonReader& r, size_t n) {
  if (r.Size() != n) r.Fail(Msg() << "expected " << n << " numbers, found " << r.Size());
  std::vector<double> v(n);
  for (size_t i = 0; i < n; ++i) v[i] = r[i].raw().is_null() ? std::nan("") : r[i].Number();
  return v;
}

Eigen::Vector3d Vec3(const JsonReader& r) {
  const std::vector<double> v = Vec(r, 3);
  return {v[0], v[1], v[2]};
}

Rigid3d PoseWxyz(const JsonReader& rotation, const JsonReader& translation) {
  const std::vector<double> q = Vec(rotation, 4);
  const double norm = std::sqrt(q[0] * q[0] + q[1] * q[1] + q[2] * q[2] + q[3] * q[3]);
  // Normalising a zero or scaled quaternion would hide it (a zero one becomes NaN everywhere downstream).
  if (!std::isfinite(norm) || std::abs(norm - 1) > 1e-3)
    rotation.Fail(Msg() << "not a rotation: the quaternion's norm is " << norm << ", not 1");
  const Eigen::Vector3d t = Vec3(translation);
  if (!t.allFinite() || t.norm() > kMaxWorldCoordinateM)
    translation.Fail(Msg() << "impossible translation (" << t.transpose() << ") m");
  return Rigid3d::FromWxyz(q[0], q[1], q[2], q[3], t);
}

Eigen::Vector2d RotateVelocity(const Rigid3d& T_ego_sensor, double vx, double vy) {
  if (!std::isfinite(vx) || !std::isfinite(vy)) return Eigen::Vector2d::Constant(std::nan(""));
  return (T_ego_sensor.rotation * Eigen::Vector3d(vx, vy, 0)).head<2>();
}

fs::path AncestorHolding(const fs::path& start, std::initializer_list<const char*> children) {
  for (fs::path p = fs::absolute(start).lexically_normal(); !p.empty(); p = p.parent_path()) {
    for (const char* c : children)
      if (fs::is_directory(p / c)) return p;
    if (p == p.parent_path()) break;
  }
  return {};
}

std::string StripToDataComponent(const std::string& p) {
  const fs::path path(p);
  std::vector<std::string> parts;
  for (const auto& c : path) parts.push_back(c.string());
  for (size_t i = 0; i < parts.size(); ++i) {
    if (parts[i] == "samples" || parts[i] == "sweeps") {
      fs::path rel;
      for (size_t k = i; k < parts.size(); ++k) rel /= parts[k];
      return rel.generic_string();
    }
  }
  return path.lexically_normal().generic_string();
}

std::string ClassName(const AddedObject& obj, LogFormat format) {
  const std::optional<CategoryInfo> c = FindCategory(obj.category);
  return c ? DatasetCategoryName(*c, format) : obj.category;
}

Box3 BoxFromKittiLabel(const Eigen::Vector3d& bottom_rect0, double l, double h, double w, double ry, const Rigid3d& T_velo_rect0) {
  const double c = std::cos(ry), s = std::sin(ry);
  Eigen::Matrix3d R_rect0_box;
  // Box axes in rectified cam0 (y down): length along (cos ry, 0, -sin ry), up = -y.
  R_rect0_box.col(0) = Eigen::Vector3d(c, 0, -s);
  R_rect0_box.col(1) = Eigen::Vector3d(s, 0, c);
  R_rect0_box.col(2) = Eigen::Vector3d(0, -1, 0);
  Box3 box;
  box.T_frame_box = T_velo_rect0 * Rigid3d(R_rect0_box, Eigen::Vector3d(bottom_rect0 - Eigen::Vector3d(0, h / 2, 0)));
  box.size = Eigen::Vector3d(l, w, h);
  return box;
}

KittiLabelBox KittiLabelFromBox(const Box3& box_velo, const Rigid3d& T_rect0_velo) {
  const Box3 b = box_velo.Transformed(T_rect0_velo);
  const Eigen::Vector3d x_axis = b.T_frame_box.Rotation().col(0);
  KittiLabelBox k;
  k.ry = std::atan2(-x_axis.z(), x_axis.x());
  k.l = b.size.x();
  k.w = b.size.y();
  k.h = b.size.z();
  k.bottom = b.center() + Eigen::Vector3d(0, k.h / 2, 0);  // rect cam0: y down
  return k;
}

int KittiDifficulty(double box2d_height_px, int occluded, double truncated) {
  constexpr double kMinHeight[] = {40, 25, 25}, kMaxTruncation[] = {0.15, 0.3, 0.5};
  constexpr int kMaxOcclusion[] = {0, 1, 2};
  for (int level = 0; level < 3; ++level)
    if (box2d_height_px > kMinHeight[level] && occluded <= kMaxOcclusion[level] && truncated <= kMaxTruncation[level])
      return level;
  return -1;
}

int KittiOccluded(double visible_fraction) {
  return visible_fraction < 0 ? 3 : visible_fraction > 0.8 ? 0 : visible_fraction > 0.4 ? 1 : 2;
}

void SensorFileWriter::Image(const CameraSensor& cam, const ImageU8* replacement) {
  const fs::path dst = out_ / RelativePath(cam.image_path, log_.data_root);
  if (replacement) {
    if (cam.intrinsics.width > 0 && (replacement->width() != cam.intrinsics.width || replacement->height() != cam.intrinsics.height))
      throw InputError(cam.image_path, Msg() << "replacement image is " << replacement->width() << "x" << replacement->height()
                                             << ", the original is " << cam.intrinsics.width << "x" << cam.intrinsics.height);
    WriteImage(dst, *replacement, options_.jpeg_quality);
  } else {
    Unchanged(cam.image_path, dst);
  }
}

void SensorFileWriter::Lidar(const LidarSensor& lidar, const PointCloud* replacement) {
  const fs::path dst = out_ / RelativePath(lidar.path, log_.data_root);
  if (replacement) {
    if (replacement->num_features != lidar.layout.num_features)
      throw InputError(lidar.path, Msg() << "replacement sweep has " << replacement->num_features << " features per point, the original "
                                         << lidar.layout.num_features);
    WritePointCloudBin(dst, *replacement);
  } else {
    Unchanged(lidar.path, dst);
  }
}

void SensorFileWriter::Unchanged(const fs::path& src, const fs::path& dst) {
  if (!fs::exists(src)) {
    if (options_.require_sensor_files) throw InputError(src, "sensor file referenced by the log is missing");
    SD_LOG(Warn, src.string() << ": missing, not written to the derivative");
    return;
  }
  if (fs::exists(dst)) return;
  fs::create_directories(dst.parent_path());
  if (options_.unchanged == UnchangedFiles::kSymlink) {
    fs::create_symlink(fs::absolute(src), dst);
  } else {
    WriteFileAtomic(dst, ReadFileToString(src));
  }
}

void SensorFileWriter::Frame(const sd::Frame& frame, const FrameEdit& edit) {
  for (const CameraSensor& cam : frame.cameras) {
    auto it = edit.images.find(cam.channel);
    Image(cam, it == edit.images.end() ? nullptr : &it->second);
  }
  for (const auto& [channel, img] : edit.images)
    if (!frame.FindCamera(channel)) throw InputError(log_.source, "edit replaces an image of unknown camera " + channel);
  if (frame.lidar) Lidar(*frame.lidar, edit.points ? &*edit.points : nullptr);
}

void WriteSensorFiles(const Log& log, const std::vector<FrameEdit>& edits, const fs::path& out_dir, const WriteOptions& options) {
  SensorFileWriter files(log, out_dir, options);
  for (const FrameEdit& e : edits) files.Frame(log.frames[e.frame_index], e);
}

}  // namespace sd::datasets_internal
