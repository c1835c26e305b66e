// mmdetection3d's KITTI infos, as the .pkl its converters write or a .json conversion: the v1.x layout
// (`data_list`, metainfo DATASET / dataset 'KITTI', boxes in rectified camera coordinates) and the v0.x list of
// dicts (`image`, `point_cloud`, `calib`, `annos` columns); their reader and writer (the file handling is
// mmdet3d.cpp's: ReadInfoJson, WriteInfoEdit). ego = the Velodyne frame exactly as ReadKitti (kitti.cpp) makes it,
// so a frame read through its info has the boxes it has read through the KITTI folder. Conventions:
// docs/datasets.md.
#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdio>
#include <numbers>
#include <string>
#include <vector>

#include "core/error.h"
#include "datasets/internal.h"
#include "io/json.h"

namespace fs = std::filesystem;
using nlohmann::json;

namespace sd {

using namespace datasets_internal;

namespace {

constexpr double kPi = std::numbers::pi;

// The camera of KITTI's 2D boxes (image_2), named as v1 infos name it; v0 infos get the same name, so one
// writer finds the camera boxes of either layout.
constexpr const char* kCam2 = "CAM2";

// mmdet3d's KittiDataset.METAINFO['classes']: what bbox_label_3d indexes when the metainfo lists no classes
// (the demo info has only DATASET).
const std::vector<std::string>& KittiClasses() {
  static const std::vector<std::string> kClasses = {"Pedestrian", "Cyclist", "Car", "Van", "Truck", "Person_sitting", "Tram", "Misc"};
  return kClasses;
}

using Mat34d = Eigen::Matrix<double, 3, 4>;

// The top three rows of a 3x3, 3x4 or 4x4 matrix (a missing fourth column reads 0): mmdet3d extends P2, R0_rect
// and Tr_velo_to_cam to 4x4; OpenPCDet-style infos keep the calib file's 3x4 and 3x3.
Mat34d Mat34(const JsonReader& r) {
  const size_t rows = r.Size();
  if (rows < 3 || rows > 4) r.Fail(Msg() << "expected a 3x3, 3x4 or 4x4 matrix, found " << rows << " rows");
  const size_t cols = r[0].Size();
  Mat34d m = Mat34d::Zero();
  for (size_t i = 0; i < 3; ++i) {
    if (r[i].Size() != cols || cols < 3 || cols > 4) r[i].Fail(Msg() << "expected 3 or 4 columns in every row, found " << r[i].Size());
    for (size_t k = 0; k < cols; ++k) m(i, static_cast<int>(k)) = r[i][k].Number();
  }
  return m;
}

// Rectified cam0 <- Velodyne = R0_rect * Tr_velo_to_cam, as ReadKitti builds it (rigid up to R0_rect's rounding).
Rigid3d RectFromVelo(const Mat34d& R0_rect, const Mat34d& Tr_velo_to_cam) {
  const Eigen::Matrix3d R0 = R0_rect.leftCols<3>();
  return Rigid3d(Eigen::Matrix3d(R0 * Tr_velo_to_cam.leftCols<3>()), Eigen::Vector3d(R0 * Tr_velo_to_cam.col(3)));
}

// A record's calibration.
struct KittiRecordCalib {
  Mat34d P2;              // rect cam0 -> image_2 pixels (homogeneous), the info's cam2img / calib.P2
  Rigid3d T_rect0_velo;
  int width = 0, height = 0;  // the image size the record states (0: none)
  // Camera 2 <- rect cam0: P2 = K [I | t], t = K^-1 P2[:,3] (as ReadKitti).
  Rigid3d T_cam2_rect0() const {
    return Rigid3d(Eigen::Quaterniond::Identity(), Eigen::Vector3d(P2.leftCols<3>().inverse() * P2.col(3)));
  }
};

KittiRecordCalib V1Calib(const JsonReader& d) {
  KittiRecordCalib c;
  const JsonReader images = d["images"];
  const JsonReader cam = images[kCam2];
  c.P2 = Mat34(cam["cam2img"]);
  if (const std::string skew = SkewProblem(c.P2.leftCols<3>()); !skew.empty()) cam["cam2img"].Fail(skew);
  if (images.Has("R0_rect") && d.Has("lidar_points") && d["lidar_points"].Has("Tr_velo_to_cam")) {
    c.T_rect0_velo = RectFromVelo(Mat34(images["R0_rect"]), Mat34(d["lidar_points"]["Tr_velo_to_cam"]));
  } else if (cam.Has("lidar2cam")) {
    // mmdet3d's KITTI lidar2cam is R0_rect Tr_velo_to_cam (rect cam0, not camera 2: cam2img carries that offset).
    const Mat34d m = Mat34(cam["lidar2cam"]);
    c.T_rect0_velo = Rigid3d(Eigen::Matrix3d(m.leftCols<3>()), Eigen::Vector3d(m.col(3)));
  } else {
    d.Fail("no calibration: expected images.R0_rect and lidar_points.Tr_velo_to_cam, or images.CAM2.lidar2cam");
  }
  if (cam.Has("width") && cam.Has("height")) {
    c.width = static_cast<int>(cam["width"].IntegerIn(1, kMaxImageSidePx));
    c.height = static_cast<int>(cam["height"].IntegerIn(1, kMaxImageSidePx));
  }
  return c;
}

KittiRecordCalib V0Calib(const JsonReader& d) {
  KittiRecordCalib c;
  const JsonReader calib = d["calib"];
  c.P2 = Mat34(calib["P2"]);
  if (const std::string skew = SkewProblem(c.P2.leftCols<3>()); !skew.empty()) calib["P2"].Fail(skew);
  c.T_rect0_velo = RectFromVelo(Mat34(calib["R0_rect"]), Mat34(calib["Tr_velo_to_cam"]));
  if (d["image"].Has("image_shape")) {
    const JsonReader shape = d["image"]["image_shape"];
    const std::vector<double> hw = Vec(shape, 2);  // rows, columns
    // Checked before the casts (a NaN or 1e300 size would be undefined behaviour, not a wrong number).
    for (double side : hw)
      if (!(side >= 1 && side <= kMaxImageSidePx && side == std::trunc(side)))
        shape.Fail(Msg() << "an image side of " << side << " px (a whole number from 1 to " << kMaxImageSidePx << ")");
    c.height = static_cast<int>(hw[0]);
    c.width = static_cast<int>(hw[1]);
  }
  return c;
}

std::string KittiToken(int64_t index) {
  char buf[32];
  std::snprintf(buf, sizeof buf, "%06lld", static_cast<long long>(index));
  return buf;
}

Log KittiInfoLog(const fs::path& file, const OpenLogOptions& options) {
  Log log;
  log.format = LogFormat::kMmdet3dKitti;
  log.source = file;
  log.annotation_path = file;
  log.data_root = InfoDataRoot(file, options);
  log.version = "kitti-object";
  log.sequential = false;            // object frames: no world pose, no time order
  log.ego_origin_on_ground = false;  // ego = the Velodyne frame, 1.73 m above the road
  log.nominal_road_z = -1.73;
  return log;
}

LidarSensor KittiLidar(const fs::path& path, const std::string& relpath) {
  LidarSensor l;
  l.channel = "velodyne";
  l.relpath = relpath;
  l.path = path;
  l.layout = PointLayout::Kitti();
  // As ReadKitti: KITTI stores scan lines in azimuth order, not firing order: the sensor spins clockwise and
  // the sweep starts behind it; the scans are raw, not de-skewed. (velodyne_reduced keeps that order.)
  l.spin_direction = -1;
  l.start_azimuth = kPi;
  l.motion_compensated = false;
  return l;  // ego = Velodyne frame: T_ego_lidar = identity
}

CameraSensor KittiCamera(const KittiRecordCalib& calib, const fs::path& path, const std::string& relpath) {
  CameraSensor cam;
  cam.channel = kCam2;
  cam.image_relpath = relpath;
  cam.image_path = path;
  std::array<int, 2> wh = ImageSizeFromHeader(path);
  if (wh[0] == 0) wh = {calib.width, calib.height};  // file absent: the size the record states
  cam.intrinsics = PinholeCamera::FromK(calib.P2.leftCols<3>(), wh[0], wh[1]);
  cam.T_ego_cam = (calib.T_cam2_rect0() * calib.T_rect0_velo).Inverse();
  cam.T_egocam_cam = cam.T_ego_cam;
  return cam;
}

// v1 KITTI infos name their files bare ('000008.bin'); mmdet3d's KITTI configs look for them under
// data_root's training/velodyne_reduced (points) and training/image_2. Without a training/ folder they lie
// beside the info (mmdet3d's demo layout).
fs::path V1KittiFile(const fs::path& data_root, const std::string& name, bool points) {
  if (name.find('/') != std::string::npos) return data_root / name;
  const fs::path training = data_root / "training";
  if (!fs::is_directory(training)) return data_root / name;
  if (!points) return training / "image_2" / name;
  if (fs::exists(training / "velodyne_reduced" / name)) return training / "velodyne_reduced" / name;
  return training / "velodyne" / name;
}

Log ReadKittiV1(const json& j, const fs::path& file, const OpenLogOptions& options) {
  Log log = KittiInfoLog(file, options);
  const JsonReader root(j, file);
  if (root.Has("metainfo")) log.categories = InfoClasses(root["metainfo"]);
  if (log.categories.empty()) log.categories = KittiClasses();
  const JsonReader list = root["data_list"];
  for (size_t i = 0; i < list.Size(); ++i) {
    const JsonReader d = list[i];
    Frame f;
    f.token = KittiToken(d.Has("sample_idx") ? d["sample_idx"].Integer() : d.Has("sample_id") ? d["sample_id"].Integer() : int64_t(i));
    const KittiRecordCalib calib = V1Calib(d);
    if (d.Has("lidar_points")) {
      const std::string rel = d["lidar_points"]["lidar_path"].String();
      f.lidar = KittiLidar(V1KittiFile(log.data_root, rel, true), rel);
    }
    const JsonReader cam = d["images"][kCam2];
    if (cam.Has("img_path")) {
      const std::string rel = cam["img_path"].String();
      f.cameras.push_back(KittiCamera(calib, V1KittiFile(log.data_root, rel, false), rel));
    }
    const Rigid3d T_velo_rect0 = calib.T_rect0_velo.Inverse();
    if (d.Has("instances")) {
      f.has_annotations = true;
      const JsonReader inst = d["instances"];
      for (size_t k = 0; k < inst.Size(); ++k) {
        const JsonReader b = inst[k];
        const int64_t label = b["bbox_label_3d"].Integer();
        if (label < 0) continue;  // DontCare (a region, not an object: ReadKitti skips its label lines too)
        const std::vector<double> v = Vec(b["bbox_3d"], 7);  // [x y z l h w ry], bottom centre in rect cam0
        Annotation a;
        a.category = static_cast<size_t>(label) < log.categories.size() ? log.categories[label] : std::to_string(label);
        a.box = BoxFromKittiLabel(Eigen::Vector3d(v[0], v[1], v[2]), v[3], v[4], v[5], v[6], T_velo_rect0);
        if (b.Has("num_lidar_pts")) a.num_lidar_pts = static_cast<int>(b["num_lidar_pts"].Integer());
        if (b.Has("truncated")) a.truncation = b["truncated"].Number();
        if (b.Has("occluded")) a.visibility = static_cast<int>(b["occluded"].Integer());
        if (b.Has("bbox")) {
          const std::vector<double> b2 = Vec(b["bbox"], 4);
          a.box2d_by_camera[kCam2] = Box2{b2[0], b2[1], b2[2], b2[3]};
        }
        f.annotations.push_back(std::move(a));
      }
    }
    log.frames.push_back(std::move(f));
  }
  return log;
}

Log ReadKittiV0(const json& j, const fs::path& file, const OpenLogOptions& options) {
  Log log = KittiInfoLog(file, options);
  log.categories = KittiClasses();
  const JsonReader root(j, file);
  for (size_t i = 0; i < root.Size(); ++i) {
    const JsonReader d = root[i];
    if (!d.raw().is_object()) d.Fail("expected a KITTI info dict (image, point_cloud, calib, annos)");
    Frame f;
    f.token = KittiToken(d["image"]["image_idx"].Integer());
    const KittiRecordCalib calib = V0Calib(d);
    if (d.Has("point_cloud")) {
      const std::string rel = d["point_cloud"]["velodyne_path"].String();
      f.lidar = KittiLidar(log.data_root / rel, rel);
    }
    const std::string image_rel = d["image"]["image_path"].String();
    f.cameras.push_back(KittiCamera(calib, log.data_root / image_rel, image_rel));
    const Rigid3d T_velo_rect0 = calib.T_rect0_velo.Inverse();
    if (d.Has("annos")) {
      f.has_annotations = true;
      const JsonReader an = d["annos"];
      const JsonReader names = an["name"];
      const size_t n = names.Size();
      for (const char* key : {"dimensions", "location", "rotation_y"})
        if (an[key].Size() != n) an[key].Fail(Msg() << an[key].Size() << " rows for " << n << " names");
      for (const char* key : {"truncated", "occluded", "bbox", "num_points_in_gt"})
        if (an.Has(key) && an[key].Size() != n) an[key].Fail(Msg() << an[key].Size() << " rows for " << n << " names");
      for (size_t k = 0; k < n; ++k) {
        const std::string name = names[k].String();
        if (name == "DontCare") continue;
        // dimensions: l h w (mmdet3d's converter reorders the label's h w l); location: the bottom centre.
        const std::vector<double> dims = Vec(an["dimensions"][k], 3);
        Annotation a;
        a.category = name;
        a.box = BoxFromKittiLabel(Vec3(an["location"][k]), dims[0], dims[1], dims[2], an["rotation_y"][k].Number(), T_velo_rect0);
        if (an.Has("truncated")) a.truncation = an["truncated"][k].Number();
        if (an.Has("occluded")) a.visibility = static_cast<int>(an["occluded"][k].Integer());
        if (an.Has("num_points_in_gt")) a.num_lidar_pts = static_cast<int>(an["num_points_in_gt"][k].Integer());
        if (an.Has("bbox")) {
          const std::vector<double> b2 = Vec(an["bbox"][k], 4);
          a.box2d_by_camera[kCam2] = Box2{b2[0], b2[1], b2[2], b2[3]};
        }
        f.annotations.push_back(std::move(a));
      }
    }
    log.frames.push_back(std::move(f));
  }
  return log;
}

// ---------------------------------------------------------------------------------------------------------
// Writer

// An added object in KITTI's terms, which v1 instances and v0 annos rows both record.
struct KittiAdded {
  std::string name;
  KittiLabelBox box;
  Box2 bbox;                  // the image_2 (CAM2) camera box; zeros without one (as the KITTI label writer)
  double truncated = 0;
  int occluded = 3;
  double alpha = 0;
  int difficulty = -1;
  Eigen::Vector2d center_2d;  // mmdet3d's: the gravity centre through cam2img
  double depth = 0;           // the third coordinate of that projection
  int num_lidar_pts = 0;
};

KittiAdded KittiAddedOf(const AddedObject& obj, const KittiRecordCalib& calib) {
  KittiAdded k;
  k.name = ClassName(obj, LogFormat::kMmdet3dKitti);
  k.box = KittiLabelFromBox(obj.annotation.box, calib.T_rect0_velo);
  double visible = -1;
  for (const CameraBox& cb : obj.camera_boxes)
    if (cb.channel == kCam2) {
      k.bbox = cb.box;
      k.truncated = std::clamp(cb.truncation, 0.0, 1.0);
      visible = cb.visible_fraction;
    }
  k.occluded = KittiOccluded(visible);
  // KITTI's observation angle: rotation_y less the azimuth of the object seen from the camera.
  k.alpha = k.box.ry - std::atan2(k.box.bottom.x(), k.box.bottom.z());
  k.alpha = std::atan2(std::sin(k.alpha), std::cos(k.alpha));
  k.difficulty = KittiDifficulty(k.bbox.y2 - k.bbox.y1, k.occluded, k.truncated);
  const Eigen::Vector3d gravity = k.box.bottom - Eigen::Vector3d(0, k.box.h / 2, 0);
  const Eigen::Vector3d p = calib.P2 * gravity.homogeneous();
  k.depth = p.z();
  k.center_2d = p.head<2>() / p.z();
  k.num_lidar_pts = std::max(0, obj.annotation.num_lidar_pts);
  return k;
}

int64_t MaxInt(const JsonReader& list, const char* key, int64_t none) {
  int64_t m = none;
  for (size_t i = 0; i < list.Size(); ++i)
    if (list[i].Has(key)) m = std::max(m, list[i][key].Integer());
  return m;
}

InfoEdit KittiV1Edit(const Log& log, const json& info, const std::vector<FrameEdit>& edits) {
  InfoEdit edit;
  edit.list_key = "data_list";
  const JsonReader root(info, log.annotation_path);
  const JsonReader list = root["data_list"];
  if (list.Size() != log.frames.size())
    throw InputError(log.annotation_path,
                     Msg() << "data_list has " << list.Size() << " records, the log " << log.frames.size() << " frames");
  std::vector<std::string> names = log.categories, new_names;
  auto label_of = [&](const std::string& cls) {
    auto it = std::find(names.begin(), names.end(), cls);
    if (it != names.end()) return static_cast<int>(it - names.begin());
    names.push_back(cls);
    new_names.push_back(cls);
    return static_cast<int>(names.size() - 1);
  };
  for (const FrameEdit& e : edits) {
    const JsonReader d = list[e.frame_index];
    const KittiRecordCalib calib = V1Calib(d);
    // KITTI numbers its objects: index 0..n-1 (DontCare -1) and group_id over all instances.
    int64_t next_index = 0, next_group = 0;
    if (d.Has("instances")) {
      next_index = MaxInt(d["instances"], "index", -1) + 1;
      next_group = MaxInt(d["instances"], "group_id", -1) + 1;
    }
    InfoListEdit instances({"instances"});
    for (const AddedObject& obj : e.added) {
      const KittiAdded k = KittiAddedOf(obj, calib);
      const int label = label_of(k.name);
      ojson inst = {{"bbox", {k.bbox.x1, k.bbox.y1, k.bbox.x2, k.bbox.y2}},
                    {"bbox_label", label},
                    {"bbox_3d", {k.box.bottom.x(), k.box.bottom.y(), k.box.bottom.z(), k.box.l, k.box.h, k.box.w, k.box.ry}},
                    {"bbox_label_3d", label},
                    {"depth", k.depth},
                    {"center_2d", {k.center_2d.x(), k.center_2d.y()}},
                    {"num_lidar_pts", k.num_lidar_pts},
                    {"difficulty", k.difficulty},
                    {"truncated", k.truncated},
                    {"occluded", k.occluded},
                    {"alpha", k.alpha},
                    {"score", 0.0},
                    {"index", next_index++},
                    {"group_id", next_group++}};
      if (!obj.asset_id.empty()) inst["synthdrive_asset_id"] = obj.asset_id;
      instances.items.push_back(inst);
    }
    InfoRecordEdit re;
    re.record = e.frame_index;
    re.lists.push_back(std::move(instances));
    edit.records.push_back(std::move(re));
  }
  // A metainfo without a class list leaves labels to mmdet3d's KITTI defaults; a new class then needs the whole
  // list written, or the reader would know only the new one.
  const bool listed = root.Has("metainfo") && !InfoClasses(root["metainfo"]).empty();
  if (!new_names.empty()) {
    edit.new_classes = listed ? new_names : names;
    edit.first_class_index = listed ? log.categories.size() : 0;
  }
  return edit;
}

// The annos columns of mmdet3d's v0 KITTI infos (kitti_data_utils.get_label_anno + add_difficulty_to_annos +
// the converter's num_points_in_gt), with their dtypes.
struct AnnosColumn {
  const char* key;
  pickle::DType dtype;
};
constexpr AnnosColumn kAnnosColumns[] = {
    {"name", pickle::DType::kUnicode},     {"truncated", pickle::DType::kFloat64}, {"occluded", pickle::DType::kInt64},
    {"alpha", pickle::DType::kFloat64},    {"bbox", pickle::DType::kFloat64},      {"dimensions", pickle::DType::kFloat64},
    {"location", pickle::DType::kFloat64}, {"rotation_y", pickle::DType::kFloat64}, {"score", pickle::DType::kFloat64},
    {"index", pickle::DType::kInt32},      {"group_ids", pickle::DType::kInt32},   {"difficulty", pickle::DType::kInt32},
    {"num_points_in_gt", pickle::DType::kInt32},
};

ojson AnnosRow(const char* key, const KittiAdded& k, int64_t index, int64_t group) {
  const std::string c = key;
  if (c == "name") return k.name;
  if (c == "truncated") return k.truncated;
  if (c == "occluded") return k.occluded;
  if (c == "alpha") return k.alpha;
  if (c == "bbox") return {k.bbox.x1, k.bbox.y1, k.bbox.x2, k.bbox.y2};
  if (c == "dimensions") return {k.box.l, k.box.h, k.box.w};
  if (c == "location") return {k.box.bottom.x(), k.box.bottom.y(), k.box.bottom.z()};
  if (c == "rotation_y") return k.box.ry;
  if (c == "score") return 0.0;
  if (c == "index") return index;
  if (c == "group_ids") return group;
  if (c == "difficulty") return k.difficulty;
  SD_CHECK(c == "num_points_in_gt", << "no row for annos column " << c);
  return k.num_lidar_pts;
}

InfoEdit KittiV0Edit(const Log& log, const json& info, const std::vector<FrameEdit>& edits) {
  InfoEdit edit;
  edit.list_key = "";
  const JsonReader root(info, log.annotation_path);
  if (root.Size() != log.frames.size())
    throw InputError(log.annotation_path,
                     Msg() << "the info has " << root.Size() << " records, the log " << log.frames.size() << " frames");
  for (const FrameEdit& e : edits) {
    const JsonReader d = root[e.frame_index];
    const KittiRecordCalib calib = V0Calib(d);
    // Added rows go before the DontCare rows, which KITTI's converters put last: mmdet3d's and OpenPCDet's
    // tools take the first num_objects rows (index >= 0) as the objects.
    size_t num_objects = 0;
    int64_t next_group = 0;
    std::vector<const AnnosColumn*> columns;
    if (d.Has("annos")) {
      const JsonReader an = d["annos"];
      const JsonReader names = an["name"];
      for (size_t k = 0; k < names.Size(); ++k) num_objects += names[k].String() != "DontCare";
      if (an.Has("group_ids"))
        for (size_t k = 0; k < an["group_ids"].Size(); ++k) next_group = std::max(next_group, an["group_ids"][k].Integer() + 1);
      for (const auto& item : an.raw().items()) {
        const std::string& key = item.key();
        const auto it =
            std::find_if(std::begin(kAnnosColumns), std::end(kAnnosColumns), [&](const AnnosColumn& c) { return key == c.key; });
        if (it == std::end(kAnnosColumns))
          an[key].Fail("a column this writer does not know: cannot add the objects' rows to it");
      }
      for (const AnnosColumn& c : kAnnosColumns)
        if (an.Has(c.key)) columns.push_back(&c);
    } else {
      for (const AnnosColumn& c : kAnnosColumns) columns.push_back(&c);
    }
    InfoRecordEdit re;
    re.record = e.frame_index;
    for (const AnnosColumn* c : columns) re.lists.emplace_back(std::vector<std::string>{"annos", c->key}, num_objects, c->dtype);
    for (size_t j = 0; j < e.added.size(); ++j) {
      const KittiAdded k = KittiAddedOf(e.added[j], calib);
      for (size_t c = 0; c < columns.size(); ++c)
        re.lists[c].items.push_back(
            AnnosRow(columns[c]->key, k, static_cast<int64_t>(num_objects + j), next_group + static_cast<int64_t>(j)));
    }
    edit.records.push_back(std::move(re));
  }
  return edit;
}

std::vector<fs::path> WriteMmdet3dKitti(const Log& log, const std::vector<FrameEdit>& edits, const fs::path& out_dir,
                                        const WriteOptions& options) {
  WriteSensorFiles(log, edits, out_dir, options);
  const json info = ReadInfoJson(log.annotation_path);
  return {WriteInfoEdit(log, info.is_array() ? KittiV0Edit(log, info, edits) : KittiV1Edit(log, info, edits), out_dir)};
}

std::string Lower(std::string s) {
  std::transform(s.begin(), s.end(), s.begin(), [](unsigned char c) { return static_cast<char>(std::tolower(c)); });
  return s;
}

}  // namespace

namespace datasets_internal {

bool IsKittiInfo(const json& info) {
  if (info.is_array()) return true;  // of the mmdet3d layouts, only KITTI's v0.x infos are a bare list of records
  if (!info.is_object() || !info.contains("data_list")) return false;
  if (const auto meta = info.find("metainfo"); meta != info.end() && meta->is_object())
    for (const char* key : {"dataset", "DATASET"})
      if (const auto name = meta->find(key); name != meta->end() && name->is_string() &&
                                             Lower(name->get<std::string>()).find("kitti") != std::string::npos)
        return true;
  const json& list = info["data_list"];
  return list.is_array() && !list.empty() && list[0].is_object() && list[0].contains("images") &&
         list[0]["images"].is_object() && list[0]["images"].contains("R0_rect");
}

Log ReadMmdet3dKittiInfo(const json& info, const fs::path& file, const OpenLogOptions& options) {
  return info.is_array() ? ReadKittiV0(info, file, options) : ReadKittiV1(info, file, options);
}

// Found through the mmdet3d v1 row's probe (one reader for every info layout); KITTI class names for writing.
LogFormatInfo Mmdet3dKittiFormat() {
  return {LogFormat::kMmdet3dKitti, "mmdet3d-kitti", "mmdet3d", nullptr, &ReadMmdet3dInfo, &WriteMmdet3dKitti, nullptr,
          [](const CategoryInfo& c) { return c.kitti_name; }};
}

}  // namespace datasets_internal
}  // namespace sd
