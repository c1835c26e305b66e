// nuScenes devkit tables (also Lyft Level 5, which uses the nuScenes schema): the reader, table by table, and
// the writer, which appends the added boxes to the tables as text. Conventions: docs/datasets.md.
#include <algorithm>
#include <map>
#include <string>
#include <unordered_map>
#include <vector>

#include "core/error.h"
#include "datasets/internal.h"
#include "io/files.h"
#include "io/json.h"
#include "io/raw_json.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace sd {

using namespace datasets_internal;

namespace {

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

using TokenIndex = std::unordered_map<std::string, const json*>;

// The version directory's tables, and the ones looked up by token indexed by it. Optional tables that are
// missing read as empty.
struct Tables {
  fs::path dir;
  json sample, sample_data, ego_pose, calibrated_sensor, sensor, category, instance, sample_annotation, scene, log;
  bool has_annotations = false;
  TokenIndex ego_pose_by, calibrated_sensor_by, sensor_by, category_by, instance_by, log_by;
  fs::path File(const char* table) const { return dir / (std::string(table) + ".json"); }
};

TokenIndex IndexByToken(const json& table, const fs::path& file) {
  TokenIndex m;
  for (const json& rec : table) {
    if (!rec.is_object() || !rec.contains("token") || !rec["token"].is_string())
      throw InputError(file, "record without a string 'token'");
    m[rec["token"].get<std::string>()] = &rec;
  }
  return m;
}

Tables LoadTables(const fs::path& vdir) {
  Tables t;
  t.dir = vdir;
  t.sample = LoadTable(vdir, "sample", true);
  t.sample_data = LoadTable(vdir, "sample_data", true);
  t.ego_pose = LoadTable(vdir, "ego_pose", true);
  t.calibrated_sensor = LoadTable(vdir, "calibrated_sensor", true);
  t.sensor = LoadTable(vdir, "sensor", true);
  t.category = LoadTable(vdir, "category", false);
  t.instance = LoadTable(vdir, "instance", false);
  t.sample_annotation = LoadTable(vdir, "sample_annotation", false);
  t.scene = LoadTable(vdir, "scene", false);
  t.log = LoadTable(vdir, "log", false);
  t.has_annotations = fs::exists(t.File("sample_annotation"));
  t.ego_pose_by = IndexByToken(t.ego_pose, t.File("ego_pose"));
  t.calibrated_sensor_by = IndexByToken(t.calibrated_sensor, t.File("calibrated_sensor"));
  t.sensor_by = IndexByToken(t.sensor, t.File("sensor"));
  t.category_by = IndexByToken(t.category, t.File("category"));
  t.instance_by = IndexByToken(t.instance, t.File("instance"));
  t.log_by = IndexByToken(t.log, t.File("log"));
  return t;
}

const json& Lookup(const TokenIndex& by, const std::string& token, const fs::path& file, const std::string& what) {
  auto it = by.find(token);
  if (it == by.end()) throw InputError(file, what + " token " + token + " not found");
  return *it->second;
}

// scene + log: the log's name and, for the four nuScenes maps, its location.
void ReadScene(const Tables& t, Log* log) {
  if (t.scene.empty()) return;
  JsonReader s(t.scene[0], t.File("scene"), "[0]");
  log->name = s.StringOr("name", "");
  if (s.Has("log_token")) {
    auto it = t.log_by.find(s["log_token"].String());
    if (it != t.log_by.end() && it->second->contains("location"))
      log->location = NuScenesLocation((*it->second)["location"].get<std::string>());
  }
}

// sample: one frame per keyframe, in timestamp order. Returns the frame index of each sample token.
std::map<std::string, size_t> ReadSamples(const Tables& t, Log* log) {
  std::vector<std::pair<double, std::string>> order;
  for (size_t i = 0; i < t.sample.size(); ++i) {
    JsonReader s(t.sample[i], t.File("sample"), Msg() << "[" << i << "]");
    order.emplace_back(s["timestamp"].Number(), s["token"].String());
  }
  std::sort(order.begin(), order.end());
  std::map<std::string, size_t> frame_of_sample;
  log->frames.resize(order.size());
  for (size_t i = 0; i < order.size(); ++i) {
    log->frames[i].token = order[i].second;
    log->frames[i].timestamp = order[i].first * 1e-6;
    log->frames[i].has_annotations = t.has_annotations;
    frame_of_sample[order[i].second] = i;
  }
  return frame_of_sample;
}

// sample_data -> calibrated_sensor -> sensor, and ego_pose: the keyframes' cameras and LiDAR. Each camera's pose
// at its own timestamp is kept until the LiDAR pose (the frame's ego pose) is known.
void ReadSampleData(const Tables& t, const std::map<std::string, size_t>& frame_of_sample, Log* log) {
  const fs::path sd_file = t.File("sample_data");
  for (size_t i = 0; i < t.sample_data.size(); ++i) {
    JsonReader r(t.sample_data[i], sd_file, Msg() << "[" << i << "]");
    auto fit = frame_of_sample.find(r["sample_token"].String());
    if (fit == frame_of_sample.end()) continue;
    if (r.raw().contains("is_key_frame") && !r["is_key_frame"].Bool()) continue;
    Frame& frame = log->frames[fit->second];
    const json& cs = Lookup(t.calibrated_sensor_by, r["calibrated_sensor_token"].String(), sd_file, "calibrated_sensor");
    JsonReader c(cs, t.File("calibrated_sensor"), r["calibrated_sensor_token"].String());
    const json& sn = Lookup(t.sensor_by, c["sensor_token"].String(), t.File("calibrated_sensor"), "sensor");
    JsonReader sr(sn, t.File("sensor"), c["sensor_token"].String());
    const json& ep = Lookup(t.ego_pose_by, r["ego_pose_token"].String(), sd_file, "ego_pose");
    JsonReader e(ep, t.File("ego_pose"), r["ego_pose_token"].String());
    const Rigid3d T_world_egot = PoseWxyz(e["rotation"], e["translation"]);
    const Rigid3d T_ego_sensor = PoseWxyz(c["rotation"], c["translation"]);
    const std::string channel = sr["channel"].String(), modality = sr.StringOr("modality", "");
    const std::string filename = r["filename"].String();
    const double time = r["timestamp"].Number() * 1e-6;
    if (modality == "camera") {
      CameraSensor cam;
      cam.channel = channel;
      cam.token = r["token"].String();
      cam.image_relpath = filename;
      cam.image_path = log->data_root / filename;
      cam.timestamp = time;
      const JsonReader K = c["camera_intrinsic"];
      if (K.Size() != 3) K.Fail("expected a 3x3 camera_intrinsic for a camera");
      // The record's size, where it gives one, is what the calibration is checked against: bounded here so
      // that a broken number is blamed on sample_data, not on the camera matrix.
      auto dimension = [&](const char* key) -> int {
        if (!r.Has(key)) return 0;
        const int64_t v = r[key].Integer();
        if (v < 0 || v > kMaxImageSidePx) r[key].Fail(Msg() << "an image " << key << " of " << v << " px (at most " << kMaxImageSidePx << ")");
        return static_cast<int>(v);
      };
      int w = dimension("width");
      int h = dimension("height");
      if (w <= 0 || h <= 0) {
        const auto wh = ImageSizeFromHeader(cam.image_path);
        w = wh[0];
        h = wh[1];
      }
      cam.intrinsics = PinholeCamera::FromK(CameraMatrix(K, w, h), w, h);
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
      l.path = log->data_root / filename;
      l.layout = PointLayout::NuScenes();
      l.timestamp = time;
      l.T_ego_lidar = T_ego_sensor;
      frame.lidar = l;
      frame.T_world_ego = T_world_egot;
      frame.timestamp = time;
    }
  }
  for (Frame& f : log->frames) {
    std::sort(f.cameras.begin(), f.cameras.end(), [](const CameraSensor& a, const CameraSensor& b) { return a.channel < b.channel; });
    for (CameraSensor& c : f.cameras) c.T_ego_cam = f.T_world_ego.Inverse() * c.T_world_egocam * c.T_egocam_cam;
  }
}

// sample_annotation -> instance -> category: boxes, global frame -> ego at the LiDAR timestamp.
void ReadSampleAnnotations(const Tables& t, const std::map<std::string, size_t>& frame_of_sample, Log* log) {
  const fs::path sa_file = t.File("sample_annotation");
  for (size_t i = 0; i < t.sample_annotation.size(); ++i) {
    JsonReader r(t.sample_annotation[i], sa_file, Msg() << "[" << i << "]");
    auto fit = frame_of_sample.find(r["sample_token"].String());
    if (fit == frame_of_sample.end()) continue;
    Frame& frame = log->frames[fit->second];
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
    auto iit = t.instance_by.find(a.instance_token);
    if (iit != t.instance_by.end()) {
      auto cit = t.category_by.find(JsonReader(*iit->second, t.File("instance"), a.instance_token)["category_token"].String());
      if (cit != t.category_by.end()) a.category = (*cit->second)["name"].get<std::string>();
    }
    if (a.category.empty() && r.Has("category_name")) a.category = r["category_name"].String();
    frame.annotations.push_back(std::move(a));
  }
}

}  // namespace

Log ReadNuScenesTables(const fs::path& path, const OpenLogOptions& options) {
  if (!fs::exists(path)) throw InputError(path, "no such directory");
  const fs::path vdir = FindVersionDir(path);
  if (vdir.empty()) throw InputError(path, "no nuScenes tables found (expected sample.json here or in a version directory)");
  const Tables tables = LoadTables(vdir);
  Log log;
  log.format = LogFormat::kNuScenesTables;
  log.source = path;
  log.annotation_path = vdir;
  log.data_root = options.data_root.empty() ? vdir.parent_path() : options.data_root;
  log.version = vdir.filename().string();
  ReadScene(tables, &log);
  const std::map<std::string, size_t> frame_of_sample = ReadSamples(tables, &log);
  ReadSampleData(tables, frame_of_sample, &log);
  ReadSampleAnnotations(tables, frame_of_sample, &log);
  return log;
}

// ---------------------------------------------------------------------------------------------------------
// Writer

namespace {

double MaxVisibleFraction(const AddedObject& obj) {
  double v = -1;
  for (const CameraBox& b : obj.camera_boxes) v = std::max(v, b.visible_fraction);
  return v;
}

// nuScenes visibility token: bins of visible fraction 0-40, 40-60, 60-80, 80-100 % -> "1".."4".
std::string VisibilityToken(const AddedObject& obj) {
  double v = MaxVisibleFraction(obj);
  if (v < 0) {
    if (obj.annotation.visibility >= 1 && obj.annotation.visibility <= 4) return std::to_string(obj.annotation.visibility);
    return "";
  }
  return v <= 0.4 ? "1" : v <= 0.6 ? "2" : v <= 0.8 ? "3" : "4";
}

json ReadTableOrEmpty(const fs::path& p) { return fs::exists(p) ? ReadJsonFile(p) : json::array(); }

// Writes table `src` with `records` appended at `dst`; a missing table is created in `style`.
void AppendToTable(const fs::path& src, const fs::path& dst, const Items& records, const JsonStyle& style, const std::string& eof) {
  if (!fs::exists(src)) {
    WriteFileAtomic(dst, Serialize(ArrayOf(records), style, "") + eof);
    return;
  }
  const RawJson raw(ReadFileToString(src), src);
  const Span root = raw.Root();
  if (!raw.IsArray(root)) throw InputError(src, "expected a JSON array of records");
  const JsonStyle own = raw.Elements(root).empty() ? style : raw.Style();
  WriteFileAtomic(dst, ApplySplices(raw, {0, raw.text().size()}, {AppendItems(raw, root, records, own)}));
}

std::vector<fs::path> WriteNuScenesTables(const Log& log, const std::vector<FrameEdit>& edits, const fs::path& out_dir,
                                          const WriteOptions& options) {
  WriteSensorFiles(log, edits, out_dir, options);
  const fs::path vdir = log.annotation_path;
  const fs::path out_vdir = out_dir / RelativePath(fs::absolute(vdir), fs::absolute(log.data_root));
  const json categories = ReadTableOrEmpty(vdir / "category.json");
  Items annotations, instances, new_categories;
  std::map<std::string, std::string> new_category_tokens;
  for (const FrameEdit& e : edits) {
    const Frame& frame = log.frames[e.frame_index];
    for (size_t k = 0; k < e.added.size(); ++k) {
      const AddedObject& obj = e.added[k];
      const std::string name = ClassName(obj, LogFormat::kNuScenesTables);
      // The dataset's own record for this class: its exact nuScenes name, else any name that means the same
      // canonical class (Lyft calls vehicle.car "car").
      std::string cat_token;
      for (const json& c : categories)
        if (c.value("name", "") == name) cat_token = c.value("token", "");
      const std::optional<CategoryInfo> canonical = FindCategory(obj.category);
      for (const json& c : categories) {
        if (!cat_token.empty() || !canonical) break;
        const std::optional<CategoryInfo> other = FindCategory(c.value("name", ""));
        if (other && other->name == canonical->name) cat_token = c.value("token", "");
      }
      if (cat_token.empty() && new_category_tokens.count(name)) cat_token = new_category_tokens[name];
      if (cat_token.empty()) {
        cat_token = new_category_tokens[name] = HexToken("category:" + name);
        new_categories.push_back({"", {{"token", cat_token}, {"name", name}, {"description", "added by SynthDrive"}}});
      }
      const std::string seed = Msg() << frame.token << "/" << k << "/" << obj.asset_id << "/" << name;
      const std::string ann_token = HexToken("ann:" + seed), inst_token = HexToken("inst:" + seed);
      const Box3 b = obj.annotation.box.Transformed(frame.T_world_ego);
      const Eigen::Quaterniond q = b.T_frame_box.rotation;
      annotations.push_back({"",
                             {{"token", ann_token},
                              {"sample_token", frame.token},
                              {"instance_token", inst_token},
                              {"visibility_token", VisibilityToken(obj)},
                              {"attribute_tokens", ojson::array()},
                              {"translation", {b.center().x(), b.center().y(), b.center().z()}},
                              {"size", {b.size.y(), b.size.x(), b.size.z()}},  // w, l, h
                              {"rotation", {q.w(), q.x(), q.y(), q.z()}},
                              {"prev", ""},
                              {"next", ""},
                              {"num_lidar_pts", std::max(0, obj.annotation.num_lidar_pts)},
                              {"num_radar_pts", 0}}});
      instances.push_back({"",
                           {{"token", inst_token},
                            {"category_token", cat_token},
                            {"nbr_annotations", 1},
                            {"first_annotation_token", ann_token},
                            {"last_annotation_token", ann_token}}});
    }
  }
  // Tables we do not extend are copied byte for byte; the ones we extend get records appended as text, so
  // every existing record keeps its bytes too. A table the input lacks is created in sample.json's layout.
  const std::map<std::string, const Items*> extended = {
      {"sample_annotation.json", &annotations}, {"instance.json", &instances}, {"category.json", &new_categories}};
  for (const auto& entry : fs::directory_iterator(vdir)) {
    if (!entry.is_regular_file() || entry.path().extension() != ".json") continue;
    auto it = extended.find(entry.path().filename().string());
    if (it == extended.end() || it->second->empty()) WriteFileAtomic(out_vdir / entry.path().filename(), ReadFileToString(entry.path()));
  }
  JsonStyle style;
  std::string eof;
  if (fs::exists(vdir / "sample.json")) {
    const RawJson sample(ReadFileToString(vdir / "sample.json"), vdir / "sample.json");
    style = sample.Style();
    eof = sample.text().substr(sample.Root().end);
  }
  std::vector<fs::path> written;
  for (const auto& [file, records] : {std::pair<std::string, const Items*>{"sample_annotation.json", &annotations},
                                      {"instance.json", &instances}, {"category.json", &new_categories}}) {
    if (!records->empty()) AppendToTable(vdir / file, out_vdir / file, *records, style, eof);
    if (!records->empty() || (file != "category.json" && fs::exists(vdir / file))) written.push_back(out_vdir / file);
  }
  return written;
}

}  // namespace

namespace datasets_internal {

LogFormatInfo NuScenesTablesFormat() {
  return {LogFormat::kNuScenesTables, "nuscenes-tables", "nuscenes",
          [](const fs::path& p) { return fs::is_directory(p) && !FindVersionDir(p).empty(); },
          &ReadNuScenesTables, &WriteNuScenesTables, nullptr,
          [](const CategoryInfo& c) { return c.nuscenes_name; }};
}

}  // namespace datasets_internal
}  // namespace sd
