// mmdetection3d info files: v1.x (`data_list`) and v0.x (`infos`), their reader and writer. The writer edits
// the info as text (io/raw_json.h), so every record it does not extend keeps its bytes. Conventions:
// docs/datasets.md.
#include <algorithm>
#include <cmath>
#include <map>
#include <numbers>
#include <optional>
#include <string>
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

constexpr double kPi = std::numbers::pi;

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
        const auto wh = ImageSizeFromHeader(cam.image_path);
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
        auto wh = ImageSizeFromHeader(cam.image_path);
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
  const json j = ReadPythonJson(info_json);
  if (!j.is_object()) throw InputError(info_json, "expected a JSON object with data_list (v1.x) or infos (v0.x)");
  if (j.contains("data_list")) return ReadMmdet3dV1(j, info_json, options);
  if (j.contains("infos")) return ReadMmdet3dV0(j, info_json, options);
  throw InputError(info_json, "not an mmdet3d info: neither data_list (v1.x) nor infos (v0.x) present");
}

// ---------------------------------------------------------------------------------------------------------
// Writers

namespace {

fs::path InfoOutPath(const Log& log, const fs::path& out_dir) {
  return out_dir / RelativePath(fs::absolute(log.annotation_path), fs::absolute(log.data_root));
}

// mmdet3d's nuScenes attribute index for an object without motion state ('None' = 8); parked vehicles and
// standing pedestrians otherwise.
int AttrLabel(const std::string& canonical) {
  if (canonical == "car" || canonical == "truck" || canonical == "bus" || canonical == "trailer" || canonical == "construction_vehicle")
    return 6;  // vehicle.parked
  if (canonical == "pedestrian") return 3;  // pedestrian.standing
  if (canonical == "bicycle" || canonical == "motorcycle") return 1;  // cycle.without_rider
  return 8;
}

// The info file's records; InputError unless there is one per frame of the log (the readers keep them 1:1).
std::vector<Span> InfoRecords(const Log& log, const RawJson& raw, const char* key, Span* list) {
  const std::optional<RawMember> m = raw.IsObject(raw.Root()) ? raw.Member(raw.Root(), key) : std::nullopt;
  if (!m || !raw.IsArray(m->value)) throw InputError(log.annotation_path, Msg() << key << " is not an array");
  *list = m->value;
  std::vector<Span> records = raw.Elements(m->value);
  if (records.size() != log.frames.size())
    throw InputError(log.annotation_path,
                     Msg() << key << " has " << records.size() << " records, the log " << log.frames.size() << " frames");
  for (const Span& r : records)
    if (!raw.IsObject(r)) throw InputError(log.annotation_path, Msg() << key << " holds a record that is not an object");
  return records;
}

// New class names go where the metainfo keeps its class list (categories {name: index}, classes, CLASSES).
void AddV1Classes(const RawJson& raw, const std::vector<std::string>& new_names, size_t first_index, const JsonStyle& s,
                  std::vector<Splice>* splices) {
  if (new_names.empty()) return;
  Items by_index, names;
  for (size_t k = 0; k < new_names.size(); ++k) {
    by_index.push_back({new_names[k], static_cast<int>(first_index + k)});
    names.push_back({"", new_names[k]});
  }
  const Span root = raw.Root();
  const std::optional<RawMember> meta = raw.Member(root, "metainfo");
  Items top;
  if (!meta || !raw.IsObject(meta->value)) {
    ExtendMember(raw, root, "metainfo", {{"categories", ObjectOf(by_index)}}, true, s, splices, &top);
    if (!top.empty()) splices->push_back(AppendItems(raw, root, top, s));
    return;
  }
  const std::optional<RawMember> cats = raw.Member(meta->value, "categories");
  Items added;
  if (cats && raw.IsObject(cats->value)) splices->push_back(AppendItems(raw, cats->value, by_index, s));
  else if (raw.Member(meta->value, "classes")) ExtendMember(raw, meta->value, "classes", names, false, s, splices, &added);
  else if (raw.Member(meta->value, "CLASSES")) ExtendMember(raw, meta->value, "CLASSES", names, false, s, splices, &added);
  else ExtendMember(raw, meta->value, "categories", by_index, true, s, splices, &added);
  if (!added.empty()) splices->push_back(AppendItems(raw, meta->value, added, s));
}

std::vector<fs::path> WriteMmdet3dV1(const Log& log, const std::vector<FrameEdit>& edits, const fs::path& out_dir,
                                     const WriteOptions& options) {
  WriteSensorFiles(log, edits, out_dir, options);
  const RawJson raw(ReadFileToString(log.annotation_path), log.annotation_path);
  const JsonStyle style = raw.Style();
  Span list;
  const std::vector<Span> records = InfoRecords(log, raw, "data_list", &list);
  std::vector<std::string> names = log.categories, new_names;
  auto label_of = [&](const std::string& cls) {
    auto it = std::find(names.begin(), names.end(), cls);
    if (it != names.end()) return static_cast<int>(it - names.begin());
    names.push_back(cls);
    new_names.push_back(cls);
    return static_cast<int>(names.size() - 1);
  };
  std::vector<std::string> kept;
  for (const FrameEdit& e : edits) {
    const Frame& frame = log.frames[e.frame_index];
    const Span rec = records[e.frame_index];
    const Rigid3d T_lidar_ego = frame.lidar ? frame.lidar->T_ego_lidar.Inverse() : Rigid3d();
    Items instances;
    std::vector<std::string> channels;  // in order of first use
    std::map<std::string, Items> cam_instances;
    for (const AddedObject& obj : e.added) {
      const int label = label_of(ClassName(obj, LogFormat::kMmdet3dV1));
      const Box3 b = obj.annotation.box.Transformed(T_lidar_ego);
      const Eigen::Vector3d c = b.center(), s = b.size;
      ojson inst = {{"bbox_label", label},
                    {"bbox_3d", {c.x(), c.y(), c.z(), s.x(), s.y(), s.z(), b.Yaw()}},
                    {"bbox_3d_isvalid", true},
                    {"bbox_label_3d", label},
                    {"num_lidar_pts", std::max(0, obj.annotation.num_lidar_pts)},
                    {"num_radar_pts", 0},
                    {"velocity", {0.0, 0.0}}};
      if (!obj.asset_id.empty()) inst["synthdrive_asset_id"] = obj.asset_id;
      instances.push_back({"", inst});
      for (const CameraBox& cb : obj.camera_boxes) {
        const CameraSensor* cam = frame.FindCamera(cb.channel);
        if (!cam) throw InputError(log.source, "camera box for unknown camera " + cb.channel);
        const Box3 bc = obj.annotation.box.Transformed(cam->T_ego_cam.Inverse());
        const Eigen::Vector3d p = bc.center();
        const std::optional<Eigen::Vector2d> uv = cam->intrinsics.Project(p);
        if (!uv) continue;  // centre behind the camera: mmdet3d keeps no such cam_instance
        // Camera boxes: [x y z l h w yaw], yaw about camera +y (pinned in readers_test).
        ojson ci = {{"bbox_label", label},
                    {"bbox_label_3d", label},
                    {"bbox", {cb.box.x1, cb.box.y1, cb.box.x2, cb.box.y2}},
                    {"bbox_3d_isvalid", true},
                    {"bbox_3d", {p.x(), p.y(), p.z(), s.x(), s.z(), s.y(), CameraYaw(bc.T_frame_box.Rotation())}},
                    {"velocity", {0.0, 0.0}},
                    {"center_2d", {uv->x(), uv->y()}},
                    {"depth", p.z()},
                    {"attr_label", AttrLabel(FindCategory(obj.category) ? FindCategory(obj.category)->name : "")}};
        if (!cam_instances.count(cb.channel)) channels.push_back(cb.channel);
        cam_instances[cb.channel].push_back({"", ci});
      }
    }
    std::vector<Splice> splices;
    Items new_members;
    ExtendMember(raw, rec, "instances", instances, false, style, &splices, &new_members);
    if (!channels.empty()) {
      const std::optional<RawMember> m = raw.Member(rec, "cam_instances");
      if (m && raw.IsObject(m->value)) {
        Items new_channels;
        for (const std::string& ch : channels)
          ExtendMember(raw, m->value, ch, cam_instances[ch], false, style, &splices, &new_channels);
        if (!new_channels.empty()) splices.push_back(AppendItems(raw, m->value, new_channels, style));
      } else {
        Items by_channel;
        for (const std::string& ch : channels) by_channel.push_back({ch, ArrayOf(cam_instances[ch])});
        ExtendMember(raw, rec, "cam_instances", by_channel, true, style, &splices, &new_members);
      }
    }
    if (!new_members.empty()) splices.push_back(AppendItems(raw, rec, new_members, style));
    kept.push_back(ApplySplices(raw, rec, splices));
  }
  std::vector<Splice> splices;
  AddV1Classes(raw, new_names, log.categories.size(), style, &splices);
  splices.push_back({list.begin, list.end, ArrayWith(raw, list, records, kept, style)});
  const fs::path dst = InfoOutPath(log, out_dir);
  WriteFileAtomic(dst, ApplySplices(raw, {0, raw.text().size()}, splices));
  return {dst};
}

// ---------------------------------------------------------------------------------------------------------
// mmdet3d v0

std::vector<fs::path> WriteMmdet3dV0(const Log& log, const std::vector<FrameEdit>& edits, const fs::path& out_dir,
                                     const WriteOptions& options) {
  WriteSensorFiles(log, edits, out_dir, options);
  const RawJson raw(ReadFileToString(log.annotation_path), log.annotation_path);
  const JsonStyle style = raw.Style();
  Span list;
  const std::vector<Span> records = InfoRecords(log, raw, "infos", &list);
  std::vector<std::string> kept;
  for (const FrameEdit& e : edits) {
    const Frame& frame = log.frames[e.frame_index];
    const Span rec = records[e.frame_index];
    const Rigid3d T_lidar_ego = frame.lidar ? frame.lidar->T_ego_lidar.Inverse() : Rigid3d();
    Items boxes, names, velocities, lidar_pts, radar_pts, valid;
    for (const AddedObject& obj : e.added) {
      const Box3 b = obj.annotation.box.Transformed(T_lidar_ego);
      const Eigen::Vector3d c = b.center(), s = b.size;
      double yaw_old = -b.Yaw() - kPi / 2;
      yaw_old = std::atan2(std::sin(yaw_old), std::cos(yaw_old));
      boxes.push_back({"", {c.x(), c.y(), c.z(), s.y(), s.x(), s.z(), yaw_old}});  // w before l
      names.push_back({"", ClassName(obj, LogFormat::kMmdet3dV0)});
      velocities.push_back({"", {0.0, 0.0}});
      lidar_pts.push_back({"", std::max(0, obj.annotation.num_lidar_pts)});
      radar_pts.push_back({"", 0});
      valid.push_back({"", obj.annotation.num_lidar_pts != 0});
    }
    std::vector<Splice> splices;
    Items new_members;
    const std::pair<const char*, const Items*> columns[] = {{"gt_boxes", &boxes},         {"gt_names", &names},
                                                            {"gt_velocity", &velocities}, {"num_lidar_pts", &lidar_pts},
                                                            {"num_radar_pts", &radar_pts}, {"valid_flag", &valid}};
    for (const auto& [key, items] : columns) ExtendMember(raw, rec, key, *items, false, style, &splices, &new_members);
    if (!new_members.empty()) splices.push_back(AppendItems(raw, rec, new_members, style));
    kept.push_back(ApplySplices(raw, rec, splices));
  }
  const fs::path dst = InfoOutPath(log, out_dir);
  WriteFileAtomic(dst, ApplySplices(raw, {0, raw.text().size()}, {{list.begin, list.end, ArrayWith(raw, list, records, kept, style)}}));
  return {dst};
}

bool IsInfoFile(const fs::path& p) { return fs::is_regular_file(p) && p.extension() == ".json"; }

std::string CanonicalName(const CategoryInfo& c) { return c.name; }

}  // namespace

namespace datasets_internal {

// Both versions share one reader, which tells them apart by content: the v1 row probes for both.
LogFormatInfo Mmdet3dV1Format() {
  return {LogFormat::kMmdet3dV1, "mmdet3d-v1", "mmdet3d", &IsInfoFile, &ReadMmdet3dInfo, &WriteMmdet3dV1, nullptr, &CanonicalName};
}
LogFormatInfo Mmdet3dV0Format() {
  return {LogFormat::kMmdet3dV0, "mmdet3d-v0", "mmdet3d", nullptr, &ReadMmdet3dInfo, &WriteMmdet3dV0, nullptr, &CanonicalName};
}

}  // namespace datasets_internal
}  // namespace sd
