#include "datasets/readers.h"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <map>
#include <numbers>
#include <sstream>
#include <unordered_map>

#include "core/error.h"
#include "datasets/internal.h"
#include "io/files.h"
#include "io/json.h"
#include "io/pointcloud_io.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace sd {

const char* ToString(LogFormat f) {
  switch (f) {
    case LogFormat::kNuScenesTables: return "nuscenes-tables";
    case LogFormat::kMmdet3dV1: return "mmdet3d-v1";
    case LogFormat::kMmdet3dV0: return "mmdet3d-v0";
    case LogFormat::kKitti: return "kitti";
    case LogFormat::kArgoverse2: return "argoverse2";
  }
  return "unknown";
}

const CameraSensor* Frame::FindCamera(const std::string& channel) const {
  for (const CameraSensor& c : cameras)
    if (c.channel == channel) return &c;
  return nullptr;
}

namespace datasets_internal {

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
  try {
    return json::parse(clean);
  } catch (const json::parse_error& e) {
    const std::string what = e.what();
    const size_t pos = what.find("] ");
    throw InputError(path, "malformed JSON: " + (pos == std::string::npos ? what : what.substr(pos + 2)));
  }
}

double CameraYaw(const Eigen::Matrix3d& R_cam_box) {
  const Eigen::Vector3d x = R_cam_box.col(0);
  return std::atan2(-x.z(), x.x());
}

namespace {
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
}  // namespace

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
  return c;
}

Rigid3d KittiCalib::T_rect0_velo() const {
  const Eigen::Matrix3d R = R0_rect * Tr_velo_to_cam.leftCols<3>();
  return Rigid3d(R, Eigen::Vector3d(R0_rect * Tr_velo_to_cam.col(3)));
}

Rigid3d KittiCalib::T_cam2_rect0() const {
  return Rigid3d(Eigen::Quaterniond::Identity(), Eigen::Vector3d(K2().inverse() * P2.col(3)));
}

}  // namespace datasets_internal

namespace {

using datasets_internal::RelativePath;

constexpr double kPi = std::numbers::pi;

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
  return Rigid3d::FromWxyz(q[0], q[1], q[2], q[3], Vec3(translation));
}

Eigen::Vector2d RotateVelocity(const Rigid3d& T_ego_sensor, double vx, double vy) {
  if (!std::isfinite(vx) || !std::isfinite(vy)) return Eigen::Vector2d::Constant(std::nan(""));
  return (T_ego_sensor.rotation * Eigen::Vector3d(vx, vy, 0)).head<2>();
}

// Nearest ancestor of `start` (inclusive) holding one of `children`; empty when none.
fs::path AncestorHolding(const fs::path& start, std::initializer_list<const char*> children) {
  for (fs::path p = fs::absolute(start).lexically_normal(); !p.empty(); p = p.parent_path()) {
    for (const char* c : children)
      if (fs::is_directory(p / c)) return p;
    if (p == p.parent_path()) break;
  }
  return {};
}

// Dataset path as written in a v0 info ("./data/nuscenes/samples/CAM_FRONT/x.jpg") -> data_root-relative,
// by the first samples/ or sweeps/ component; unchanged when there is none.
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

// ---------------------------------------------------------------------------------------------------------
// nuScenes tables

json LoadTable(const fs::path& dir, const std::string& name, bool required) {
  const fs::path p = dir / (name + ".json");
  if (!fs::exists(p)) {
    if (required) throw InputError(p, "missing required nuScenes table " + name + ".json");
    return json::array();
  }
  json j = ReadJsonFile(p);
  if (!j.is_array()) throw InputError(p, "expected a JSON array of records");
  return j;
}

// The version directory (holding sample.json) for a dataset root or the version directory itself.
fs::path FindVersionDir(const fs::path& path) {
  if (fs::exists(path / "sample.json")) return path;
  std::vector<fs::path> found;
  if (fs::is_directory(path)) {
    for (const auto& e : fs::directory_iterator(path)) {
      if (!e.is_directory()) continue;
      if (fs::exists(e.path() / "sample.json")) found.push_back(e.path());
      // Lyft nests the tables one level deeper: v1.01-train/v1.01-train/*.json.
      else if (fs::exists(e.path() / e.path().filename() / "sample.json"))
        found.push_back(e.path() / e.path().filename());
    }
  }
  std::sort(found.begin(), found.end());
  if (found.size() > 1)
    throw InputError(path, Msg() << "several nuScenes table versions found (" << found[0].filename().string() << ", "
                                 << found[1].filename().string() << ", ...); pass the version directory");
  return found.empty() ? fs::path() : found[0];
}

std::optional<GeoLocation> NuScenesLocation(const std::string& name) {
  // Map-origin reference coordinates of the four nuScenes maps (as in the devkit's pose export script);
  // approximate: good to a few hundred metres, enough for sun position and climate lookups.
  static const std::map<std::string, std::pair<double, double>> kOrigins = {
      {"boston-seaport", {42.336849169438615, -71.05785369873047}},
      {"singapore-onenorth", {1.2882100868743724, 103.78475189208984}},
      {"singapore-hollandvillage", {1.2993652317780957, 103.78217697143555}},
      {"singapore-queenstown", {1.2782562240223188, 103.76741409301758}},
  };
  auto it = kOrigins.find(name);
  if (it == kOrigins.end()) return std::nullopt;
  return GeoLocation{it->second.first, it->second.second, name};
}

}  // namespace

Log ReadNuScenesTables(const fs::path& path, const OpenLogOptions& options) {
  if (!fs::exists(path)) throw InputError(path, "no such directory");
  const fs::path vdir = FindVersionDir(path);
  if (vdir.empty()) throw InputError(path, "no nuScenes tables found (expected sample.json here or in a version directory)");

  auto index = [](const json& table, const fs::path& file) {
    std::unordered_map<std::string, const json*> m;
    for (const json& rec : table) {
      if (!rec.is_object() || !rec.contains("token") || !rec["token"].is_string())
        throw InputError(file, "record without a string 'token'");
      m[rec["token"].get<std::string>()] = &rec;
    }
    return m;
  };
  const json sample = LoadTable(vdir, "sample", true), sample_data = LoadTable(vdir, "sample_data", true),
             ego_pose = LoadTable(vdir, "ego_pose", true), calibrated = LoadTable(vdir, "calibrated_sensor", true),
             sensor = LoadTable(vdir, "sensor", true), category = LoadTable(vdir, "category", false),
             instance = LoadTable(vdir, "instance", false), annotations = LoadTable(vdir, "sample_annotation", false),
             scene = LoadTable(vdir, "scene", false), log_table = LoadTable(vdir, "log", false);
  const bool have_annotations = fs::exists(vdir / "sample_annotation.json");
  const auto ego_by = index(ego_pose, vdir / "ego_pose.json"), calib_by = index(calibrated, vdir / "calibrated_sensor.json"),
             sensor_by = index(sensor, vdir / "sensor.json"), cat_by = index(category, vdir / "category.json"),
             inst_by = index(instance, vdir / "instance.json"), log_by = index(log_table, vdir / "log.json");

  Log log;
  log.format = LogFormat::kNuScenesTables;
  log.source = path;
  log.annotation_path = vdir;
  log.data_root = options.data_root.empty() ? vdir.parent_path() : options.data_root;
  log.version = vdir.filename().string();
  if (!scene.empty()) {
    const fs::path f = vdir / "scene.json";
    JsonReader s(scene[0], f, "[0]");
    log.name = s.StringOr("name", "");
    if (s.Has("log_token")) {
      auto it = log_by.find(s["log_token"].String());
      if (it != log_by.end() && it->second->contains("location"))
        log.location = NuScenesLocation((*it->second)["location"].get<std::string>());
    }
  }

  auto pose = [&](const std::unordered_map<std::string, const json*>& by, const std::string& token, const fs::path& file,
                  const std::string& what) -> const json& {
    auto it = by.find(token);
    if (it == by.end()) throw InputError(file, what + " token " + token + " not found");
    return *it->second;
  };

  std::map<std::string, size_t> frame_of_sample;
  std::vector<std::pair<double, std::string>> order;
  for (size_t i = 0; i < sample.size(); ++i) {
    JsonReader s(sample[i], vdir / "sample.json", Msg() << "[" << i << "]");
    order.emplace_back(s["timestamp"].Number(), s["token"].String());
  }
  std::sort(order.begin(), order.end());
  log.frames.resize(order.size());
  for (size_t i = 0; i < order.size(); ++i) {
    log.frames[i].token = order[i].second;
    log.frames[i].timestamp = order[i].first * 1e-6;
    log.frames[i].has_annotations = have_annotations;
    frame_of_sample[order[i].second] = i;
  }

  // Pass 1: sensors. Remember each camera's pose at its own timestamp until the LiDAR pose is known.
  const fs::path sd_file = vdir / "sample_data.json";
  for (size_t i = 0; i < sample_data.size(); ++i) {
    JsonReader r(sample_data[i], sd_file, Msg() << "[" << i << "]");
    auto fit = frame_of_sample.find(r["sample_token"].String());
    if (fit == frame_of_sample.end()) continue;
    if (r.raw().contains("is_key_frame") && !r["is_key_frame"].Bool()) continue;
    Frame& frame = log.frames[fit->second];
    const json& cs = pose(calib_by, r["calibrated_sensor_token"].String(), sd_file, "calibrated_sensor");
    JsonReader c(cs, vdir / "calibrated_sensor.json", r["calibrated_sensor_token"].String());
    const json& sn = pose(sensor_by, c["sensor_token"].String(), vdir / "calibrated_sensor.json", "sensor");
    JsonReader sr(sn, vdir / "sensor.json", c["sensor_token"].String());
    const json& ep = pose(ego_by, r["ego_pose_token"].String(), sd_file, "ego_pose");
    JsonReader e(ep, vdir / "ego_pose.json", r["ego_pose_token"].String());
    const Rigid3d T_world_egot = PoseWxyz(e["rotation"], e["translation"]);
    const Rigid3d T_ego_sensor = PoseWxyz(c["rotation"], c["translation"]);
    const std::string channel = sr["channel"].String(), modality = sr.StringOr("modality", "");
    const std::string filename = r["filename"].String();
    const double t = r["timestamp"].Number() * 1e-6;
    if (modality == "camera") {
      CameraSensor cam;
      cam.channel = channel;
      cam.token = r["token"].String();
      cam.image_relpath = filename;
      cam.image_path = log.data_root / filename;
      cam.timestamp = t;
      const JsonReader K = c["camera_intrinsic"];
      if (K.Size() != 3) K.Fail("expected a 3x3 camera_intrinsic for a camera");
      int w = r.Has("width") ? static_cast<int>(r["width"].Integer()) : 0;
      int h = r.Has("height") ? static_cast<int>(r["height"].Integer()) : 0;
      if (w <= 0 || h <= 0) {
        const auto wh = datasets_internal::ImageSizeFromHeader(cam.image_path);
        w = wh[0];
        h = wh[1];
      }
      cam.intrinsics = PinholeCamera::FromK(Mat3(K), w, h);
      cam.T_egocam_cam = T_ego_sensor;
      cam.T_world_egocam = T_world_egot;
      frame.cameras.push_back(std::move(cam));
    } else if (modality == "lidar") {
      // Prefer LIDAR_TOP where a vehicle has several (Lyft: LIDAR_TOP + two front lidars).
      if (frame.lidar && frame.lidar->channel == "LIDAR_TOP") continue;
      LidarSensor l;
      l.channel = channel;
      l.token = r["token"].String();
      l.relpath = filename;
      l.path = log.data_root / filename;
      l.layout = PointLayout::NuScenes();
      l.timestamp = t;
      l.T_ego_lidar = T_ego_sensor;
      frame.lidar = l;
      frame.T_world_ego = T_world_egot;
      frame.timestamp = t;
    }
  }
  for (Frame& f : log.frames) {
    std::sort(f.cameras.begin(), f.cameras.end(), [](const CameraSensor& a, const CameraSensor& b) { return a.channel < b.channel; });
    for (CameraSensor& c : f.cameras) c.T_ego_cam = f.T_world_ego.Inverse() * c.T_world_egocam * c.T_egocam_cam;
  }

  // Pass 2: annotations, global frame -> ego at the LiDAR timestamp.
  const fs::path sa_file = vdir / "sample_annotation.json";
  for (size_t i = 0; i < annotations.size(); ++i) {
    JsonReader r(annotations[i], sa_file, Msg() << "[" << i << "]");
    auto fit = frame_of_sample.find(r["sample_token"].String());
    if (fit == frame_of_sample.end()) continue;
    Frame& frame = log.frames[fit->second];
    Annotation a;
    a.token = r["token"].String();
    a.instance_token = r.StringOr("instance_token", "");
    const Rigid3d T_world_box = PoseWxyz(r["rotation"], r["translation"]);
    const Eigen::Vector3d wlh = Vec3(r["size"]);
    a.box.T_frame_box = frame.T_world_ego.Inverse() * T_world_box;
    a.box.size = Eigen::Vector3d(wlh[1], wlh[0], wlh[2]);  // nuScenes size is w, l, h
    if (r.Has("num_lidar_pts")) a.num_lidar_pts = static_cast<int>(r["num_lidar_pts"].Integer());
    const std::string vis = r.StringOr("visibility_token", "");
    a.visibility = (vis.size() == 1 && vis[0] >= '1' && vis[0] <= '4') ? vis[0] - '0' : -1;
    auto iit = inst_by.find(a.instance_token);
    if (iit != inst_by.end()) {
      auto cit = cat_by.find(JsonReader(*iit->second, vdir / "instance.json", a.instance_token)["category_token"].String());
      if (cit != cat_by.end()) a.category = (*cit->second)["name"].get<std::string>();
    }
    if (a.category.empty() && r.Has("category_name")) a.category = r["category_name"].String();
    frame.annotations.push_back(std::move(a));
  }
  return log;
}

// ---------------------------------------------------------------------------------------------------------
// mmdetection3d infos

namespace {

fs::path ProbeInfoDataRoot(const fs::path& info_json, const OpenLogOptions& options) {
  if (!options.data_root.empty()) return options.data_root;
  fs::path root = AncestorHolding(info_json.parent_path(), {"samples", "training"});
  return root.empty() ? fs::absolute(info_json).parent_path() : root;
}

// v1 paths: a bare file name lives in samples/<CHANNEL>/; otherwise strip to samples/ or sweeps/.
std::string V1RelPath(const std::string& p, const std::string& channel) {
  if (p.find('/') == std::string::npos) return "samples/" + channel + "/" + p;
  return StripToDataComponent(p);
}

Log ReadMmdet3dV1(const json& j, const fs::path& file, const OpenLogOptions& options) {
  Log log;
  log.format = LogFormat::kMmdet3dV1;
  log.source = file;
  log.annotation_path = file;
  log.data_root = ProbeInfoDataRoot(file, options);
  JsonReader root(j, file);
  if (root.Has("metainfo")) {
    const JsonReader meta = root["metainfo"];
    const std::string dataset = meta.StringOr("dataset", meta.StringOr("DATASET", ""));
    std::string lower = dataset;
    std::transform(lower.begin(), lower.end(), lower.begin(), [](unsigned char c) { return std::tolower(c); });
    if (lower.find("kitti") != std::string::npos)
      throw InputError(file, "mmdet3d KITTI infos (camera-frame boxes) are not supported; open the KITTI directory instead");
    log.version = meta.StringOr("version", "");
    if (meta.Has("categories") && meta["categories"].raw().is_object()) {
      for (const auto& [name, idx] : meta["categories"].raw().items()) {
        if (!idx.is_number_integer() || idx.get<int64_t>() < 0) meta["categories"][name].Fail("expected a class index");
        const size_t k = static_cast<size_t>(idx.get<int64_t>());
        if (log.categories.size() <= k) log.categories.resize(k + 1);
        log.categories[k] = name;
      }
    } else {
      for (const char* key : {"classes", "CLASSES"})
        if (meta.Has(key))
          for (size_t i = 0; i < meta[key].Size(); ++i) log.categories.push_back(meta[key][i].String());
    }
  }
  const JsonReader list = root["data_list"];
  for (size_t i = 0; i < list.Size(); ++i) {
    const JsonReader d = list[i];
    Frame f;
    f.token = d.Has("token") ? d["token"].String() : std::to_string(d.Has("sample_idx") ? d["sample_idx"].Integer() : int64_t(i));
    f.timestamp = d.NumberOr("timestamp", 0);
    f.T_world_ego = d.Has("ego2global") ? Rigid3d::FromMatrix(Mat4(d["ego2global"])) : Rigid3d();
    Rigid3d T_ego_lidar;
    if (d.Has("lidar_points")) {
      const JsonReader lp = d["lidar_points"];
      LidarSensor l;
      l.channel = "LIDAR_TOP";
      l.relpath = lp["lidar_path"].String();
      l.path = log.data_root / V1RelPath(l.relpath, l.channel);
      // nuScenes and Lyft sweeps hold 5 float32 per point even where num_pts_feats says how many are used.
      l.layout = PointLayout::NuScenes();
      l.timestamp = f.timestamp;
      l.T_ego_lidar = Rigid3d::FromMatrix(Mat4(lp["lidar2ego"]));
      T_ego_lidar = l.T_ego_lidar;
      f.lidar = l;
    }
    if (d.Has("images")) {
      for (const auto& [channel, rec] : d["images"].raw().items()) {
        const JsonReader c = d["images"][channel];
        if (!c.Has("img_path")) continue;
        CameraSensor cam;
        cam.channel = channel;
        cam.token = c.StringOr("sample_data_token", "");
        cam.image_relpath = c["img_path"].String();
        cam.image_path = log.data_root / V1RelPath(cam.image_relpath, channel);
        cam.timestamp = c.NumberOr("timestamp", f.timestamp);
        const auto wh = datasets_internal::ImageSizeFromHeader(cam.image_path);
        cam.intrinsics = PinholeCamera::FromK(Mat3(c["cam2img"]), wh[0], wh[1]);
        cam.T_egocam_cam = Rigid3d::FromMatrix(Mat4(c["cam2ego"]));
        // lidar2cam = inv(cam2ego) inv(E(t_cam)) E(t_lidar) lidar2ego, so lidar2ego inv(lidar2cam) is the
        // camera seen from the LiDAR-time ego pose (log.h's T_ego_cam), ego motion included.
        const Rigid3d T_cam_lidar = c.Has("lidar2cam") ? Rigid3d::FromMatrix(Mat4(c["lidar2cam"]))
                                                       : cam.T_egocam_cam.Inverse() * T_ego_lidar;
        cam.T_ego_cam = T_ego_lidar * T_cam_lidar.Inverse();
        cam.T_world_egocam = f.T_world_ego * cam.T_ego_cam * cam.T_egocam_cam.Inverse();
        f.cameras.push_back(std::move(cam));
      }
    }
    if (d.Has("instances")) {
      f.has_annotations = true;
      const JsonReader inst = d["instances"];
      for (size_t k = 0; k < inst.Size(); ++k) {
        const JsonReader b = inst[k];
        const std::vector<double> v = Vec(b["bbox_3d"], 7);
        const int64_t label = b["bbox_label_3d"].Integer();
        Annotation a;
        // Label -1: a real object outside the class list (mmdet3d ignores it in training); category stays empty.
        if (label >= 0)
          a.category = static_cast<size_t>(label) < log.categories.size() ? log.categories[label] : std::to_string(label);
        a.box.T_frame_box = T_ego_lidar * Rigid3d::FromYaw(v[6], Eigen::Vector3d(v[0], v[1], v[2]));
        a.box.size = Eigen::Vector3d(v[3], v[4], v[5]);
        if (b.Has("num_lidar_pts")) a.num_lidar_pts = static_cast<int>(b["num_lidar_pts"].Integer());
        if (b.Has("velocity")) {
          const std::vector<double> vel = Vec(b["velocity"], 2);
          a.velocity = RotateVelocity(T_ego_lidar, vel[0], vel[1]);
        }
        f.annotations.push_back(std::move(a));
      }
    }
    if (d.Has("cam_instances") && d["cam_instances"].raw().is_object()) {
      // cam_instances carry no index into `instances`: each is matched to the annotation whose centre, seen from
      // that camera, is nearest to its camera-frame bbox_3d centre (the same box gives ~1e-6 m; neighbours are
      // metres apart), and skipped when none lies within 1 m.
      for (const auto& [channel, rec] : d["cam_instances"].raw().items()) {
        const CameraSensor* cam = f.FindCamera(channel);
        if (!cam) continue;
        const Rigid3d T_cam_ego = cam->T_ego_cam.Inverse();
        const JsonReader list = d["cam_instances"][channel];
        std::map<size_t, double> matched_distance;
        for (size_t k = 0; k < list.Size(); ++k) {
          const JsonReader ci = list[k];
          if (!ci.Has("bbox") || !ci.Has("bbox_3d")) continue;
          const std::vector<double> b2 = Vec(ci["bbox"], 4);
          const std::vector<double> b3 = Vec(ci["bbox_3d"], ci["bbox_3d"].Size());
          if (b3.size() < 3) ci["bbox_3d"].Fail("expected at least 3 numbers");
          const Eigen::Vector3d c(b3[0], b3[1], b3[2]);
          size_t best = f.annotations.size();
          double best_d = 1.0;
          for (size_t a = 0; a < f.annotations.size(); ++a) {
            const double dist = (T_cam_ego * f.annotations[a].box.center() - c).norm();
            if (dist < best_d) best_d = dist, best = a;
          }
          if (best == f.annotations.size()) continue;
          auto it = matched_distance.find(best);
          if (it != matched_distance.end() && it->second <= best_d) continue;
          matched_distance[best] = best_d;
          f.annotations[best].box2d_by_camera[channel] = Box2{b2[0], b2[1], b2[2], b2[3]};
        }
      }
    }
    log.frames.push_back(std::move(f));
  }
  return log;
}

Log ReadMmdet3dV0(const json& j, const fs::path& file, const OpenLogOptions& options) {
  Log log;
  log.format = LogFormat::kMmdet3dV0;
  log.source = file;
  log.annotation_path = file;
  log.data_root = ProbeInfoDataRoot(file, options);
  JsonReader root(j, file);
  if (root.Has("metadata")) log.version = root["metadata"].StringOr("version", "");
  const JsonReader infos = root["infos"];
  for (size_t i = 0; i < infos.Size(); ++i) {
    const JsonReader d = infos[i];
    Frame f;
    f.token = d["token"].String();
    f.timestamp = d["timestamp"].Number() * 1e-6;
    f.T_world_ego = PoseWxyz(d["ego2global_rotation"], d["ego2global_translation"]);
    LidarSensor l;
    l.channel = "LIDAR_TOP";
    l.relpath = d["lidar_path"].String();
    l.path = log.data_root / StripToDataComponent(l.relpath);
    l.layout = PointLayout::NuScenes();
    l.timestamp = f.timestamp;
    l.T_ego_lidar = PoseWxyz(d["lidar2ego_rotation"], d["lidar2ego_translation"]);
    f.lidar = l;
    if (d.Has("cams")) {
      for (const auto& [channel, rec] : d["cams"].raw().items()) {
        const JsonReader c = d["cams"][channel];
        CameraSensor cam;
        cam.channel = channel;
        cam.token = c.StringOr("sample_data_token", "");
        cam.image_relpath = c["data_path"].String();
        cam.image_path = log.data_root / StripToDataComponent(cam.image_relpath);
        cam.timestamp = c["timestamp"].Number() * 1e-6;
        auto wh = datasets_internal::ImageSizeFromHeader(cam.image_path);
        // Files absent: every nuScenes camera image is 1600x900.
        if (wh[0] == 0) wh = {1600, 900};
        cam.intrinsics = PinholeCamera::FromK(Mat3(c["cam_intrinsic"]), wh[0], wh[1]);
        cam.T_egocam_cam = PoseWxyz(c["sensor2ego_rotation"], c["sensor2ego_translation"]);
        cam.T_world_egocam = PoseWxyz(c["ego2global_rotation"], c["ego2global_translation"]);
        cam.T_ego_cam = f.T_world_ego.Inverse() * cam.T_world_egocam * cam.T_egocam_cam;
        f.cameras.push_back(std::move(cam));
      }
    }
    if (d.Has("gt_boxes")) {
      f.has_annotations = true;
      const JsonReader boxes = d["gt_boxes"], names = d["gt_names"];
      if (names.Size() != boxes.Size())
        names.Fail(Msg() << names.Size() << " names for " << boxes.Size() << " gt_boxes");
      for (size_t k = 0; k < boxes.Size(); ++k) {
        const std::vector<double> v = Vec(boxes[k], 7);
        Annotation a;
        a.category = names[k].String();
        // Old mmdet3d (< 1.0): [x y z w l h yaw_old] with yaw_old = -yaw - pi/2.
        a.box.T_frame_box = l.T_ego_lidar * Rigid3d::FromYaw(-v[6] - kPi / 2, Eigen::Vector3d(v[0], v[1], v[2]));
        a.box.size = Eigen::Vector3d(v[4], v[3], v[5]);
        if (d.Has("num_lidar_pts") && k < d["num_lidar_pts"].Size())
          a.num_lidar_pts = static_cast<int>(d["num_lidar_pts"][k].Integer());
        if (d.Has("gt_velocity") && k < d["gt_velocity"].Size()) {
          const std::vector<double> vel = Vec(d["gt_velocity"][k], 2);
          a.velocity = RotateVelocity(l.T_ego_lidar, vel[0], vel[1]);
        }
        f.annotations.push_back(std::move(a));
      }
    }
    log.frames.push_back(std::move(f));
  }
  return log;
}

}  // namespace

Log ReadMmdet3dInfo(const fs::path& info_json, const OpenLogOptions& options) {
  if (!fs::exists(info_json)) throw InputError(info_json, "missing mmdet3d info file");
  const json j = datasets_internal::ReadPythonJson(info_json);
  if (!j.is_object()) throw InputError(info_json, "expected a JSON object with data_list (v1.x) or infos (v0.x)");
  if (j.contains("data_list")) return ReadMmdet3dV1(j, info_json, options);
  if (j.contains("infos")) return ReadMmdet3dV0(j, info_json, options);
  throw InputError(info_json, "not an mmdet3d info: neither data_list (v1.x) nor infos (v0.x) present");
}

// ---------------------------------------------------------------------------------------------------------
// KITTI

namespace {

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
  log.categories = {"Car", "Van", "Truck", "Pedestrian", "Person_sitting", "Cyclist", "Tram", "Misc"};
  std::vector<std::string> ids;
  for (const auto& e : fs::directory_iterator(split / "calib"))
    if (e.path().extension() == ".txt") ids.push_back(e.path().stem().string());
  std::sort(ids.begin(), ids.end());
  for (const std::string& id : ids) {
    const datasets_internal::KittiCalib calib = datasets_internal::ReadKittiCalib(split / "calib" / (id + ".txt"));
    const Rigid3d T_rect0_velo = calib.T_rect0_velo();
    Frame f;
    f.token = id;
    LidarSensor l;
    l.channel = "velodyne";
    l.relpath = "velodyne/" + id + ".bin";
    l.path = split / l.relpath;
    l.layout = PointLayout::Kitti();
    f.lidar = l;  // ego = Velodyne frame: T_ego_lidar = identity
    CameraSensor cam;
    cam.channel = "image_2";
    cam.image_relpath = "image_2/" + id + ".png";
    cam.image_path = split / cam.image_relpath;
    const auto wh = datasets_internal::ImageSizeFromHeader(cam.image_path);
    cam.intrinsics = PinholeCamera::FromK(calib.K2(), wh[0], wh[1]);
    cam.T_ego_cam = (calib.T_cam2_rect0() * T_rect0_velo).Inverse();
    cam.T_egocam_cam = cam.T_ego_cam;
    f.cameras.push_back(cam);

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
        const std::vector<double> v = datasets_internal::ParseNumbers(rest);
        if (v.size() < 14)
          throw InputError(label_file, Msg() << "line " << line_no << ": expected 15 fields (type + 14 numbers), got '" << line << "'");
        // v: truncated occluded alpha x1 y1 x2 y2 h w l x y z ry
        const double h = v[7], w = v[8], len = v[9], ry = v[13];
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
  return log;
}

PointCloud ReadLidar(const LidarSensor& lidar) {
  if (!fs::exists(lidar.path)) throw InputError(lidar.path, "missing LiDAR sweep file (recorded as " + lidar.relpath + ")");
  PointCloud pc = ReadPointCloudBin(lidar.path, lidar.layout);
  return pc;
}

// ---------------------------------------------------------------------------------------------------------
// Probing

Log OpenLog(const fs::path& path, const OpenLogOptions& options) {
  if (options.format) {
    switch (*options.format) {
      case LogFormat::kNuScenesTables: return ReadNuScenesTables(path, options);
      case LogFormat::kMmdet3dV1:
      case LogFormat::kMmdet3dV0: return ReadMmdet3dInfo(path, options);
      case LogFormat::kKitti: return ReadKitti(path, options);
      case LogFormat::kArgoverse2: return ReadArgoverse2(path, options);
    }
  }
  if (!fs::exists(path)) throw InputError(path, "no such file or directory");
  // The probe table: first match wins. Probes are cheap (directory layout, file extension); the reader
  // then validates the content and reports what is wrong with it.
  struct Probe {
    bool (*matches)(const fs::path&);
    Log (*read)(const fs::path&, const OpenLogOptions&);
  };
  static const Probe kProbes[] = {
      {[](const fs::path& p) { return fs::is_regular_file(p) && p.extension() == ".json"; }, &ReadMmdet3dInfo},
      {[](const fs::path& p) { return fs::is_directory(p) && !FindVersionDir(p).empty(); }, &ReadNuScenesTables},
      {[](const fs::path& p) { return fs::is_directory(p) && !KittiSplitDir(p).empty(); }, &ReadKitti},
      {[](const fs::path& p) {
         return fs::is_regular_file(p / "city_SE3_egovehicle.json") && fs::is_regular_file(p / "annotations.json");
       },
       &ReadArgoverse2},
  };
  for (const Probe& probe : kProbes)
    if (probe.matches(path)) return probe.read(path, options);
  if (fs::is_regular_file(path)) throw InputError(path, "unrecognised dataset file (expected an mmdet3d info .json)");
  throw InputError(path, "unrecognised dataset directory: no nuScenes tables (v1.0-*/sample.json), no KITTI "
                         "calib/label_2 (or training/), no Argoverse 2 "
                         "city_SE3_egovehicle.json + annotations.json; for mmdet3d pass the info .json");
}

}  // namespace sd
