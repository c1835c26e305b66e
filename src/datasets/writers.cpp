#include "datasets/writers.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <set>
#include <sstream>

#include "core/error.h"
#include "core/log.h"
#include "datasets/categories.h"
#include "datasets/internal.h"
#include "io/files.h"
#include "io/image_io.h"
#include "io/json.h"
#include "io/pointcloud_io.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace sd {

namespace {

using datasets_internal::RelativePath;

constexpr double kPi = std::numbers::pi;

// The dataset's class name for an added object: canonical categories are translated, unknown names kept.
std::string ClassName(const AddedObject& obj, LogFormat format) {
  const std::optional<CategoryInfo> c = FindCategory(obj.category);
  return c ? DatasetCategoryName(*c, format) : obj.category;
}

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

class SensorFileWriter {
 public:
  SensorFileWriter(const Log& log, const fs::path& out_dir, const WriteOptions& options)
      : log_(log), out_(out_dir), options_(options) {}

  void Image(const CameraSensor& cam, const ImageU8* replacement) {
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
  void Lidar(const LidarSensor& lidar, const PointCloud* replacement) {
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
  void Unchanged(const fs::path& src, const fs::path& dst) {
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
  void Frame(const sd::Frame& frame, const FrameEdit& edit) {
    for (const CameraSensor& cam : frame.cameras) {
      auto it = edit.images.find(cam.channel);
      Image(cam, it == edit.images.end() ? nullptr : &it->second);
    }
    for (const auto& [channel, img] : edit.images)
      if (!frame.FindCamera(channel)) throw InputError(log_.source, "edit replaces an image of unknown camera " + channel);
    if (frame.lidar) Lidar(*frame.lidar, edit.points ? &*edit.points : nullptr);
  }

 private:
  const Log& log_;
  fs::path out_;
  const WriteOptions& options_;
};

void CheckEdits(const Log& log, const std::vector<FrameEdit>& edits) {
  std::set<size_t> seen;
  for (const FrameEdit& e : edits) {
    if (e.frame_index >= log.frames.size())
      throw InputError(log.source, Msg() << "edit names frame " << e.frame_index << " but the log has " << log.frames.size());
    if (!seen.insert(e.frame_index).second) throw InputError(log.source, Msg() << "frame " << e.frame_index << " edited twice");
  }
}

fs::path InfoOutPath(const Log& log, const fs::path& out_dir) {
  return out_dir / RelativePath(fs::absolute(log.annotation_path), fs::absolute(log.data_root));
}

// ---------------------------------------------------------------------------------------------------------
// mmdet3d v1

int CategoryIndex(json& metainfo, std::vector<std::string>& names, const std::string& name) {
  auto it = std::find(names.begin(), names.end(), name);
  if (it != names.end()) return static_cast<int>(it - names.begin());
  names.push_back(name);
  if (metainfo.contains("categories") && metainfo["categories"].is_object())
    metainfo["categories"][name] = static_cast<int>(names.size() - 1);
  else if (metainfo.contains("classes"))
    metainfo["classes"].push_back(name);
  else if (metainfo.contains("CLASSES"))
    metainfo["CLASSES"].push_back(name);
  else
    metainfo["categories"][name] = static_cast<int>(names.size() - 1);
  return static_cast<int>(names.size() - 1);
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

std::vector<fs::path> WriteMmdet3dV1(const Log& log, const std::vector<FrameEdit>& edits, const fs::path& out_dir) {
  json in = datasets_internal::ReadPythonJson(log.annotation_path);
  json out = json::object();
  out["metainfo"] = in.contains("metainfo") ? in["metainfo"] : json::object();
  std::vector<std::string> names = log.categories;
  out["data_list"] = json::array();
  for (const FrameEdit& e : edits) {
    const Frame& frame = log.frames[e.frame_index];
    json d = in["data_list"].at(e.frame_index);
    const Rigid3d T_lidar_ego = frame.lidar ? frame.lidar->T_ego_lidar.Inverse() : Rigid3d();
    if (!d.contains("instances")) d["instances"] = json::array();
    if (!d.contains("cam_instances")) d["cam_instances"] = json::object();
    for (const AddedObject& obj : e.added) {
      const std::string cls = ClassName(obj, LogFormat::kMmdet3dV1);
      const int label = CategoryIndex(out["metainfo"], names, cls);
      const Box3 b = obj.annotation.box.Transformed(T_lidar_ego);
      const Eigen::Vector3d c = b.center(), s = b.size;
      json inst = {{"bbox_label", label},
                   {"bbox_3d", {c.x(), c.y(), c.z(), s.x(), s.y(), s.z(), b.Yaw()}},
                   {"bbox_3d_isvalid", true},
                   {"bbox_label_3d", label},
                   {"num_lidar_pts", std::max(0, obj.annotation.num_lidar_pts)},
                   {"num_radar_pts", 0},
                   {"velocity", {0.0, 0.0}}};
      if (!obj.asset_id.empty()) inst["synthdrive_asset_id"] = obj.asset_id;
      d["instances"].push_back(inst);
      for (const CameraBox& cb : obj.camera_boxes) {
        const CameraSensor* cam = frame.FindCamera(cb.channel);
        if (!cam) throw InputError(log.source, "camera box for unknown camera " + cb.channel);
        const Box3 bc = obj.annotation.box.Transformed(cam->T_ego_cam.Inverse());
        const Eigen::Vector3d p = bc.center();
        const std::optional<Eigen::Vector2d> uv = cam->intrinsics.Project(p);
        if (!uv) continue;  // centre behind the camera: mmdet3d keeps no such cam_instance
        // Camera boxes: [x y z l h w yaw], yaw about camera +y (pinned in readers_test).
        json ci = {{"bbox_label", label},
                   {"bbox_label_3d", label},
                   {"bbox", {cb.box.x1, cb.box.y1, cb.box.x2, cb.box.y2}},
                   {"bbox_3d_isvalid", true},
                   {"bbox_3d", {p.x(), p.y(), p.z(), s.x(), s.z(), s.y(), datasets_internal::CameraYaw(bc.T_frame_box.Rotation())}},
                   {"velocity", {0.0, 0.0}},
                   {"center_2d", {uv->x(), uv->y()}},
                   {"depth", p.z()},
                   {"attr_label", AttrLabel(FindCategory(obj.category) ? FindCategory(obj.category)->name : "")}};
        d["cam_instances"][cb.channel].push_back(ci);
      }
    }
    out["data_list"].push_back(d);
  }
  const fs::path dst = InfoOutPath(log, out_dir);
  WriteJsonFile(dst, out, -1);
  return {dst};
}

// ---------------------------------------------------------------------------------------------------------
// mmdet3d v0

std::vector<fs::path> WriteMmdet3dV0(const Log& log, const std::vector<FrameEdit>& edits, const fs::path& out_dir) {
  json in = datasets_internal::ReadPythonJson(log.annotation_path);
  json out = json::object();
  if (in.contains("metadata")) out["metadata"] = in["metadata"];
  out["infos"] = json::array();
  for (const FrameEdit& e : edits) {
    const Frame& frame = log.frames[e.frame_index];
    json d = in["infos"].at(e.frame_index);
    const Rigid3d T_lidar_ego = frame.lidar ? frame.lidar->T_ego_lidar.Inverse() : Rigid3d();
    for (const char* key : {"gt_boxes", "gt_names", "gt_velocity", "num_lidar_pts", "num_radar_pts", "valid_flag"})
      if (!d.contains(key) || d[key].is_null()) d[key] = json::array();
    for (const AddedObject& obj : e.added) {
      const Box3 b = obj.annotation.box.Transformed(T_lidar_ego);
      const Eigen::Vector3d c = b.center(), s = b.size;
      double yaw_old = -b.Yaw() - kPi / 2;
      yaw_old = std::atan2(std::sin(yaw_old), std::cos(yaw_old));
      d["gt_boxes"].push_back({c.x(), c.y(), c.z(), s.y(), s.x(), s.z(), yaw_old});  // w before l
      d["gt_names"].push_back(ClassName(obj, LogFormat::kMmdet3dV0));
      d["gt_velocity"].push_back({0.0, 0.0});
      d["num_lidar_pts"].push_back(std::max(0, obj.annotation.num_lidar_pts));
      d["num_radar_pts"].push_back(0);
      d["valid_flag"].push_back(obj.annotation.num_lidar_pts != 0);
    }
    out["infos"].push_back(d);
  }
  const fs::path dst = InfoOutPath(log, out_dir);
  WriteJsonFile(dst, out, -1);
  return {dst};
}

// ---------------------------------------------------------------------------------------------------------
// nuScenes tables

json ReadTableOrEmpty(const fs::path& p) { return fs::exists(p) ? ReadJsonFile(p) : json::array(); }

std::vector<fs::path> WriteNuScenesTables(const Log& log, const std::vector<FrameEdit>& edits, const fs::path& out_dir) {
  const fs::path vdir = log.annotation_path;
  const fs::path out_vdir = out_dir / RelativePath(fs::absolute(vdir), fs::absolute(log.data_root));
  json annotations = ReadTableOrEmpty(vdir / "sample_annotation.json");
  json instances = ReadTableOrEmpty(vdir / "instance.json");
  json categories = ReadTableOrEmpty(vdir / "category.json");
  bool categories_changed = false;
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
      if (cat_token.empty()) {
        cat_token = datasets_internal::HexToken("category:" + name);
        categories.push_back({{"token", cat_token}, {"name", name}, {"description", "added by SynthDrive"}});
        categories_changed = true;
      }
      const std::string seed = Msg() << frame.token << "/" << k << "/" << obj.asset_id << "/" << name;
      const std::string ann_token = datasets_internal::HexToken("ann:" + seed), inst_token = datasets_internal::HexToken("inst:" + seed);
      const Box3 b = obj.annotation.box.Transformed(frame.T_world_ego);
      const Eigen::Quaterniond q = b.T_frame_box.rotation;
      json attrs = json::array();
      annotations.push_back({{"token", ann_token},
                             {"sample_token", frame.token},
                             {"instance_token", inst_token},
                             {"visibility_token", VisibilityToken(obj)},
                             {"attribute_tokens", attrs},
                             {"translation", {b.center().x(), b.center().y(), b.center().z()}},
                             {"size", {b.size.y(), b.size.x(), b.size.z()}},  // w, l, h
                             {"rotation", {q.w(), q.x(), q.y(), q.z()}},
                             {"prev", ""},
                             {"next", ""},
                             {"num_lidar_pts", std::max(0, obj.annotation.num_lidar_pts)},
                             {"num_radar_pts", 0}});
      instances.push_back({{"token", inst_token},
                           {"category_token", cat_token},
                           {"nbr_annotations", 1},
                           {"first_annotation_token", ann_token},
                           {"last_annotation_token", ann_token}});
    }
  }
  // Unchanged tables are copied byte for byte; the three we extend are rewritten.
  for (const auto& entry : fs::directory_iterator(vdir)) {
    if (!entry.is_regular_file() || entry.path().extension() != ".json") continue;
    const std::string stem = entry.path().stem().string();
    if (stem == "sample_annotation" || stem == "instance" || (stem == "category" && categories_changed)) continue;
    WriteFileAtomic(out_vdir / entry.path().filename(), ReadFileToString(entry.path()));
  }
  std::vector<fs::path> written;
  WriteJsonFile(out_vdir / "sample_annotation.json", annotations, 0);
  WriteJsonFile(out_vdir / "instance.json", instances, 0);
  written = {out_vdir / "sample_annotation.json", out_vdir / "instance.json"};
  if (categories_changed) {
    WriteJsonFile(out_vdir / "category.json", categories, 0);
    written.push_back(out_vdir / "category.json");
  }
  return written;
}

// ---------------------------------------------------------------------------------------------------------
// KITTI

std::string Fixed(double v, int digits = 2) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f", digits, v);
  return buf;
}

std::vector<fs::path> WriteKitti(const Log& log, const std::vector<FrameEdit>& edits, const fs::path& out_dir) {
  std::vector<fs::path> written;
  for (const FrameEdit& e : edits) {
    const Frame& frame = log.frames[e.frame_index];
    const fs::path calib_src = log.data_root / "calib" / (frame.token + ".txt");
    const datasets_internal::KittiCalib calib = datasets_internal::ReadKittiCalib(calib_src);
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
      line << ClassName(obj, LogFormat::kKitti) << ' ' << Fixed(std::clamp(truncation, 0.0, 1.0)) << ' ' << occluded << ' '
           << Fixed(alpha) << ' ' << Fixed(box2.x1) << ' ' << Fixed(box2.y1) << ' ' << Fixed(box2.x2) << ' ' << Fixed(box2.y2)
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

std::vector<fs::path> WriteDerivative(const Log& log, const std::vector<FrameEdit>& edits, const fs::path& out_dir,
                                      const WriteOptions& options) {
  if (!fs::is_directory(out_dir)) throw InputError(out_dir, "output directory does not exist");
  CheckEdits(log, edits);
  SensorFileWriter files(log, out_dir, options);
  for (const FrameEdit& e : edits) files.Frame(log.frames[e.frame_index], e);
  switch (log.format) {
    case LogFormat::kMmdet3dV1: return WriteMmdet3dV1(log, edits, out_dir);
    case LogFormat::kMmdet3dV0: return WriteMmdet3dV0(log, edits, out_dir);
    case LogFormat::kNuScenesTables: return WriteNuScenesTables(log, edits, out_dir);
    case LogFormat::kKitti: return WriteKitti(log, edits, out_dir);
  }
  return {};
}

}  // namespace sd
