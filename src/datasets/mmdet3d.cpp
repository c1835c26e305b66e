// mmdetection3d info files of nuScenes-like datasets (LiDAR-frame boxes): v1.x (`data_list`) and v0.x (`infos`),
// as the .pkl mmdet3d writes or its .json conversion; their reader and the edits their writer hands to
// WriteInfoEdit (info_edit.cpp). Also the reading every info layout shares (the KITTI-flavoured ones live in
// mmdet3d_kitti.cpp): ReadInfoJson (a pickle is read as data and becomes its JSON twin), the data root and the
// class list. Conventions: docs/datasets.md.
#include <algorithm>
#include <cmath>
#include <cstring>
#include <map>
#include <numbers>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "core/error.h"
#include "datasets/internal.h"
#include "io/files.h"
#include "io/gzip.h"
#include "io/json.h"
#include "io/pickle.h"
#include "io/raw_json.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace sd {

using namespace datasets_internal;

namespace {

constexpr double kPi = std::numbers::pi;

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
  log.data_root = InfoDataRoot(file, options);
  JsonReader root(j, file);
  if (root.Has("metainfo")) {
    const JsonReader meta = root["metainfo"];
    log.version = meta.StringOr("version", "");
    log.categories = InfoClasses(meta);
  }
  const JsonReader list = root["data_list"];
  AssumptionTally assumed;
  for (size_t i = 0; i < list.Size(); ++i) {
    const JsonReader d = list[i];
    Frame f;
    f.token = d.Has("token") ? d["token"].String() : std::to_string(d.Has("sample_idx") ? d["sample_idx"].Integer() : int64_t(i));
    // Python writes a NaN time as NaN, read as null: a broken value, not a missing one to default.
    if (d.raw().contains("timestamp") && d.raw()["timestamp"].is_null()) d["timestamp"].Fail("NaN or null: not a time");
    if (d.Has("timestamp")) f.timestamp = d["timestamp"].Number();
    else assumed.Note("timestamp missing: 0 s assumed (no ego motion can be derived from time)", f.token);
    if (d.Has("ego2global")) {
      f.T_world_ego = RigidPose(d["ego2global"], kMaxWorldCoordinateM);
    } else {
      // Without its pose a frame cannot be placed in a sequence: every frame is synthesised on its own.
      assumed.Note("ego2global missing: the ego pose taken as the world origin, frames synthesised one by one", f.token);
      log.sequential = false;
    }
    Rigid3d T_ego_lidar;
    if (d.Has("lidar_points")) {
      const JsonReader lp = d["lidar_points"];
      LidarSensor l;
      l.channel = "LIDAR_TOP";
      l.relpath = lp["lidar_path"].String();
      l.path = log.data_root / V1RelPath(l.relpath, l.channel);
      // nuScenes and Lyft sweeps hold 5 float32 per point; num_pts_feats says how many of them a model uses
      // (Lyft's infos say 4 of the 5), so it bounds the layout rather than setting it. Anything else (Waymo's 6,
      // a string) is a file this reader would read with the wrong stride: refused, not guessed.
      l.layout = PointLayout::NuScenes();
      if (lp.Has("num_pts_feats")) {
        const int64_t used = lp["num_pts_feats"].Integer();
        if (used < 3 || used > l.layout.num_features)
          lp["num_pts_feats"].Fail(Msg() << used << " features per point: this reader takes sweeps of "
                                         << l.layout.num_features << " float32 per point (x y z intensity ring), of which 3 to "
                                         << l.layout.num_features << " are used");
      }
      l.timestamp = f.timestamp;
      l.T_ego_lidar = RigidPose(lp["lidar2ego"], kMaxSensorOffsetM);
      T_ego_lidar = l.T_ego_lidar;
      f.lidar = l;
    } else {
      assumed.Note("lidar_points missing: no LiDAR sweep (cameras only); boxes taken in the ego frame and cameras "
                   "placed by cam2ego (a lidar2cam names a LiDAR frame the info does not place)", f.token);
    }
    if (!d.Has("images")) assumed.Note("images missing: no cameras (LiDAR only)", f.token);
    if (d.Has("images")) {
      for (const auto& [channel, rec] : d["images"].raw().items()) {
        const JsonReader c = d["images"][channel];
        // mmdet3d's KITTI-style infos keep R0_rect, a matrix, among the cameras; a camera without its image is
        // another matter: dropping it silently moved its objects to other cameras.
        if (!rec.is_object()) continue;
        if (!c.Has("img_path")) c.Fail("a camera without img_path: its image cannot be read");
        CameraSensor cam;
        cam.channel = channel;
        cam.token = c.StringOr("sample_data_token", "");
        cam.image_relpath = c["img_path"].String();
        cam.image_path = log.data_root / V1RelPath(cam.image_relpath, channel);
        cam.timestamp = c.NumberOr("timestamp", f.timestamp);
        const auto wh = ImageSizeFromHeader(cam.image_path);
        cam.intrinsics = PinholeCamera::FromK(CameraMatrix(c["cam2img"], wh[0], wh[1]), wh[0], wh[1]);
        cam.T_egocam_cam = RigidPose(c["cam2ego"], kMaxSensorOffsetM);
        // lidar2cam = inv(cam2ego) inv(E(t_cam)) E(t_lidar) lidar2ego, so lidar2ego inv(lidar2cam) is the
        // camera seen from the LiDAR-time ego pose (log.h's T_ego_cam), ego motion included.
        if (!c.Has("lidar2cam") && f.lidar)
          assumed.Note("lidar2cam missing: derived from cam2ego and lidar2ego (the ego's motion between the LiDAR "
                       "and camera times ignored)", f.token);
        const bool through_lidar = c.Has("lidar2cam") && f.lidar;
        const Rigid3d T_cam_lidar = through_lidar ? RigidPose(c["lidar2cam"], kMaxSensorOffsetM)
                                                  : cam.T_egocam_cam.Inverse() * T_ego_lidar;
        cam.T_ego_cam = T_ego_lidar * T_cam_lidar.Inverse();
        cam.T_world_egocam = f.T_world_ego * cam.T_ego_cam * cam.T_egocam_cam.Inverse();
        f.cameras.push_back(std::move(cam));
      }
    }
    if (!d.Has("instances")) assumed.Note("instances missing: an unannotated frame (objects kept clear of LiDAR obstacles only)", f.token);
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
  assumed.AppendTo(log.assumptions, log.frames.size());
  return log;
}

Log ReadMmdet3dV0(const json& j, const fs::path& file, const OpenLogOptions& options) {
  Log log;
  log.format = LogFormat::kMmdet3dV0;
  log.source = file;
  log.annotation_path = file;
  log.data_root = InfoDataRoot(file, options);
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
        cam.intrinsics = PinholeCamera::FromK(CameraMatrix(c["cam_intrinsic"], wh[0], wh[1]), wh[0], wh[1]);
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

Log ReadMmdet3dInfo(const fs::path& info, const OpenLogOptions& options) {
  if (!fs::exists(info)) throw InputError(info, "missing mmdet3d info file");
  const json j = ReadInfoJson(info);
  if (IsKittiInfo(j)) return ReadMmdet3dKittiInfo(j, info, options);
  if (!j.is_object())
    throw InputError(info, "expected an object with data_list (v1.x) or infos (v0.x), or a list of KITTI info dicts");
  if (j.contains("data_list")) return ReadMmdet3dV1(j, info, options);
  if (j.contains("infos")) return ReadMmdet3dV0(j, info, options);
  throw InputError(info, "not an mmdet3d info: neither data_list (v1.x) nor infos (v0.x) present");
}

namespace datasets_internal {

bool IsPickleInfo(const fs::path& info) {
  const std::string name = info.filename().string();
  return info.extension() == ".pkl" || (name.size() > 7 && name.ends_with(".pkl.gz"));
}

json ReadInfoJson(const fs::path& info) {
  if (!IsPickleInfo(info)) return ReadPythonJson(info);
  const pickle::Value v = pickle::LoadFile(info);
  try {
    return pickle::ToJson(v);
  } catch (const InputError& e) {
    throw InputError(info, e.what());  // ToJson names the value's JSON pointer, not the file
  }
}

fs::path InfoDataRoot(const fs::path& info, const OpenLogOptions& options) {
  if (!options.data_root.empty()) return options.data_root;
  fs::path root = AncestorHolding(info.parent_path(), {"samples", "training"});
  return root.empty() ? fs::absolute(info).parent_path() : root;
}

std::vector<std::string> InfoClasses(const JsonReader& meta) {
  std::vector<std::string> names;
  if (meta.Has("categories") && meta["categories"].raw().is_object()) {
    for (const auto& [name, idx] : meta["categories"].raw().items()) {
      if (!idx.is_number_integer()) meta["categories"][name].Fail("expected a class index");
      if (idx.get<int64_t>() < 0) continue;  // KITTI's "DontCare": -1, the label of ignored regions
      const size_t k = static_cast<size_t>(idx.get<int64_t>());
      if (names.size() <= k) names.resize(k + 1);
      names[k] = name;
    }
    return names;
  }
  for (const char* key : {"classes", "CLASSES"})
    if (meta.Has(key))
      for (size_t i = 0; i < meta[key].Size(); ++i) names.push_back(meta[key][i].String());
  return names;
}

}  // namespace datasets_internal

// ---------------------------------------------------------------------------------------------------------
// Writers of the nuScenes-like layouts

namespace {

using pickle::DType;

// mmdet3d's nuScenes attribute index for an object without motion state ('None' = 8); parked vehicles and
// standing pedestrians otherwise.
int AttrLabel(const std::string& canonical) {
  if (canonical == "car" || canonical == "truck" || canonical == "bus" || canonical == "trailer" || canonical == "construction_vehicle")
    return 6;  // vehicle.parked
  if (canonical == "pedestrian") return 3;  // pedestrian.standing
  if (canonical == "bicycle" || canonical == "motorcycle") return 1;  // cycle.without_rider
  return 8;
}

// v1 `instances` (LiDAR-frame boxes) and `cam_instances.<CAM>` of the added objects.
InfoEdit V1Edit(const Log& log, const std::vector<FrameEdit>& edits) {
  InfoEdit edit;
  edit.list_key = "data_list";
  std::vector<std::string> names = log.categories;
  auto label_of = [&](const std::string& cls) {
    auto it = std::find(names.begin(), names.end(), cls);
    if (it != names.end()) return static_cast<int>(it - names.begin());
    names.push_back(cls);
    edit.new_classes.push_back(cls);
    return static_cast<int>(names.size() - 1);
  };
  edit.first_class_index = log.categories.size();
  for (const FrameEdit& e : edits) {
    const Frame& frame = log.frames[e.frame_index];
    const Rigid3d T_lidar_ego = frame.lidar ? frame.lidar->T_ego_lidar.Inverse() : Rigid3d();
    InfoListEdit instances({"instances"});
    std::vector<std::string> channels;  // in order of first use
    std::map<std::string, std::vector<ojson>> cam_instances;
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
      instances.items.push_back(inst);
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
        cam_instances[cb.channel].push_back(ci);
      }
    }
    InfoRecordEdit re;
    re.record = e.frame_index;
    re.lists.push_back(std::move(instances));
    for (const std::string& ch : channels) {
      re.lists.emplace_back(std::vector<std::string>{"cam_instances", ch});
      re.lists.back().items = cam_instances[ch];
    }
    edit.records.push_back(std::move(re));
  }
  return edit;
}

// v0 columns: gt_boxes [x y z w l h yaw_old] and the per-box columns beside it.
InfoEdit V0Edit(const Log& log, const std::vector<FrameEdit>& edits) {
  InfoEdit edit;
  edit.list_key = "infos";
  for (const FrameEdit& e : edits) {
    const Frame& frame = log.frames[e.frame_index];
    const Rigid3d T_lidar_ego = frame.lidar ? frame.lidar->T_ego_lidar.Inverse() : Rigid3d();
    // Where a pickle lacks a column, it gets the dtype mmdet3d's converter gives it.
    InfoRecordEdit re;
    re.record = e.frame_index;
    const std::pair<const char*, DType> columns[] = {{"gt_boxes", DType::kFloat64},    {"gt_names", DType::kUnicode},
                                                     {"gt_velocity", DType::kFloat64}, {"num_lidar_pts", DType::kInt64},
                                                     {"num_radar_pts", DType::kInt64}, {"valid_flag", DType::kBool}};
    for (const auto& [key, dtype] : columns) re.lists.emplace_back(std::vector<std::string>{key}, std::nullopt, dtype);
    for (const AddedObject& obj : e.added) {
      const Box3 b = obj.annotation.box.Transformed(T_lidar_ego);
      const Eigen::Vector3d c = b.center(), s = b.size;
      double yaw_old = -b.Yaw() - kPi / 2;
      yaw_old = std::atan2(std::sin(yaw_old), std::cos(yaw_old));
      re.lists[0].items.push_back({c.x(), c.y(), c.z(), s.y(), s.x(), s.z(), yaw_old});  // w before l
      re.lists[1].items.push_back(ClassName(obj, LogFormat::kMmdet3dV0));
      re.lists[2].items.push_back({0.0, 0.0});
      re.lists[3].items.push_back(std::max(0, obj.annotation.num_lidar_pts));
      re.lists[4].items.push_back(0);
      re.lists[5].items.push_back(obj.annotation.num_lidar_pts != 0);
    }
    edit.records.push_back(std::move(re));
  }
  return edit;
}

std::vector<fs::path> WriteMmdet3dV1(const Log& log, const std::vector<FrameEdit>& edits, const fs::path& out_dir,
                                     const WriteOptions& options) {
  WriteSensorFiles(log, edits, out_dir, options);
  return {WriteInfoEdit(log, V1Edit(log, edits), out_dir)};
}

std::vector<fs::path> WriteMmdet3dV0(const Log& log, const std::vector<FrameEdit>& edits, const fs::path& out_dir,
                                     const WriteOptions& options) {
  WriteSensorFiles(log, edits, out_dir, options);
  return {WriteInfoEdit(log, V0Edit(log, edits), out_dir)};
}

// mmdet3d's converters write .pkl (some pipelines gzip them); the .json conversions of them read the same.
bool IsInfoFile(const fs::path& p) {
  return fs::is_regular_file(p) && (p.extension() == ".json" || datasets_internal::IsPickleInfo(p));
}

std::string CanonicalName(const CategoryInfo& c) { return c.name; }

}  // namespace

namespace datasets_internal {

// All mmdet3d layouts share one reader, which tells them apart by content: the v1 row probes for every one.
LogFormatInfo Mmdet3dV1Format() {
  return {LogFormat::kMmdet3dV1, "mmdet3d-v1", "mmdet3d", &IsInfoFile, &ReadMmdet3dInfo, &WriteMmdet3dV1, nullptr, &CanonicalName};
}
LogFormatInfo Mmdet3dV0Format() {
  return {LogFormat::kMmdet3dV0, "mmdet3d-v0", "mmdet3d", nullptr, &ReadMmdet3dInfo, &WriteMmdet3dV0, nullptr, &CanonicalName};
}

}  // namespace datasets_internal
}  // namespace sd
