// mmdet3d info pickles, in and out (datasets/mmdet3d.cpp, mmdet3d_kitti.cpp): the .pkl reads as its .json twin;
// KITTI-flavoured infos follow KITTI's label convention with ego = the Velodyne frame (pinned on the real frame
// 000008 and against the KITTI folder reader); derivatives of .pkl infos are .pkl files that CPython's pickle and
// numpy load to the input plus the added objects, typed like their neighbours (tools/testing/mmdet3d_pickle_check.py).
#include <gtest/gtest.h>
#include <sys/wait.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <numbers>

#include "core/error.h"
#include "datasets/categories.h"
#include "datasets/internal.h"
#include "datasets/readers.h"
#include "datasets/writers.h"
#include "io/files.h"
#include "io/gzip.h"
#include "io/json.h"
#include "io/pickle.h"
#include "testing/testing.h"

namespace sd {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;
using sd::testing::RepoData;
using sd::testing::SharedData;
using sd::testing::TempDir;

const char* kKf0Pkl = "driving/nuscenes-scene0061-kf0/mmdet3d_info/n015-2018-07-24-11-22-45+0800.pkl";
const char* kKf0Json = "driving/nuscenes-scene0061-kf0/mmdet3d_info/n015-2018-07-24-11-22-45+0800.json";
const char* kBevfusionPkl = "driving/nuscenes-scene0061-kf0/bevfusion_demo_info/nuscenes_infos_test.pkl";
const char* kBevfusionJson = "driving/nuscenes-scene0061-kf0/bevfusion_demo_info/nuscenes_infos_test.json";
const char* kKittiV1 = "driving/kitti-mmdet3d-pkl-000008/v1x_format/000008.pkl";
const char* kKittiV0 = "driving/kitti-mmdet3d-pkl-000008/v0x_format/kitti_000008_infos.pkl";
const char* kMiniValPkl = "driving/nuscenes-mini-val-infos/nuscenes_infos_val.pkl";
const char* kMiniValJson = "driving/nuscenes-mini-val-infos/nuscenes_infos_val.json";

// --- the Python check (tools/testing/mmdet3d_pickle_check.py under /usr/bin/python3 with numpy)

// Runs the check script with `args`; its exit status, with stdout and stderr in *output.
int RunCheck(const std::vector<std::string>& args, std::string* output) {
  return testing::RunPython("tools/testing/mmdet3d_pickle_check.py", args, output);
}

// Writes `spec` beside the output and runs `check` on it.
void ExpectPythonAgrees(const json& spec, const fs::path& dir) {
  const fs::path file = dir / "spec.json";
  WriteJsonFile(file, spec);
  std::string output;
  EXPECT_EQ(RunCheck({"check", file.string()}, &output), 0) << output;
}

// --- comparisons

void ExpectSameBox(const Box3& a, const Box3& b, double tol, const std::string& what = "") {
  const auto ca = a.Corners(), cb = b.Corners();
  double worst = 0;
  for (int k = 0; k < 8; ++k) worst = std::max(worst, (ca[k] - cb[k]).norm());
  EXPECT_LT(worst, tol) << what;
  EXPECT_LT((a.size - b.size).cwiseAbs().maxCoeff(), tol) << what;
}

double MaxDiff(const Rigid3d& a, const Rigid3d& b) { return (a.Matrix() - b.Matrix()).cwiseAbs().maxCoeff(); }

bool SameNumber(double a, double b) { return a == b || (std::isnan(a) && std::isnan(b)); }

// Two reads of one info (its .pkl and its .json twin): the same log, to the last bit.
void ExpectSameLog(const Log& a, const Log& b) {
  EXPECT_EQ(a.format, b.format);
  EXPECT_EQ(a.version, b.version);
  EXPECT_EQ(a.categories, b.categories);
  EXPECT_EQ(a.data_root, b.data_root);
  EXPECT_EQ(a.sequential, b.sequential);
  ASSERT_EQ(a.frames.size(), b.frames.size());
  for (size_t i = 0; i < a.frames.size(); ++i) {
    const Frame &fa = a.frames[i], &fb = b.frames[i];
    SCOPED_TRACE("frame " + fa.token);
    EXPECT_EQ(fa.token, fb.token);
    EXPECT_EQ(fa.timestamp, fb.timestamp);
    EXPECT_EQ(MaxDiff(fa.T_world_ego, fb.T_world_ego), 0);
    ASSERT_EQ(fa.lidar.has_value(), fb.lidar.has_value());
    if (fa.lidar) {
      EXPECT_EQ(fa.lidar->path, fb.lidar->path);
      EXPECT_EQ(MaxDiff(fa.lidar->T_ego_lidar, fb.lidar->T_ego_lidar), 0);
      EXPECT_EQ(fa.lidar->spin_direction, fb.lidar->spin_direction);
    }
    ASSERT_EQ(fa.cameras.size(), fb.cameras.size());
    for (size_t c = 0; c < fa.cameras.size(); ++c) {
      EXPECT_EQ(fa.cameras[c].channel, fb.cameras[c].channel);
      EXPECT_EQ(fa.cameras[c].image_path, fb.cameras[c].image_path);
      EXPECT_EQ(fa.cameras[c].intrinsics.fx, fb.cameras[c].intrinsics.fx);
      EXPECT_EQ(fa.cameras[c].intrinsics.width, fb.cameras[c].intrinsics.width);
      EXPECT_EQ(MaxDiff(fa.cameras[c].T_ego_cam, fb.cameras[c].T_ego_cam), 0);
    }
    ASSERT_EQ(fa.annotations.size(), fb.annotations.size());
    for (size_t k = 0; k < fa.annotations.size(); ++k) {
      const Annotation &x = fa.annotations[k], &y = fb.annotations[k];
      EXPECT_EQ(x.category, y.category);
      EXPECT_EQ(MaxDiff(x.box.T_frame_box, y.box.T_frame_box), 0);
      EXPECT_EQ(x.box.size, y.box.size);
      EXPECT_EQ(x.num_lidar_pts, y.num_lidar_pts);
      EXPECT_TRUE(SameNumber(x.velocity.x(), y.velocity.x()) && SameNumber(x.velocity.y(), y.velocity.y()));
      EXPECT_EQ(x.box2d_by_camera.size(), y.box2d_by_camera.size());
    }
  }
}

std::vector<int> CountPointsInBoxes(const Frame& frame) {
  const PointCloud pc = ReadLidar(*frame.lidar);
  std::vector<int> counts;
  for (const Annotation& a : frame.annotations) {
    int n = 0;
    for (size_t i = 0; i < pc.size(); ++i) n += a.box.Contains(frame.lidar->T_ego_lidar * pc.xyz(i).cast<double>());
    counts.push_back(n);
  }
  return counts;
}

// --- KITTI's label convention, written out here independently of the reader (KITTI devkit readme): location
// is the bottom centre in rectified cam0 (x right, y down, z forward), rotation_y turns about its y axis with the
// length along (cos ry, 0, -sin ry); Velodyne <- rect cam0 = inv(R0_rect * Tr_velo_to_cam) as general 4x4s.

Eigen::Matrix4d Mat4Of(const json& m) {
  Eigen::Matrix4d out = Eigen::Matrix4d::Identity();
  for (size_t r = 0; r < m.size(); ++r)
    for (size_t c = 0; c < m[r].size(); ++c) out(static_cast<int>(r), static_cast<int>(c)) = m[r][c].get<double>();
  return out;
}

Box3 VeloBoxOfLabel(const Eigen::Vector3d& bottom, double l, double h, double w, double ry, const Eigen::Matrix4d& rect_from_velo) {
  const Eigen::Matrix4d velo_from_rect = rect_from_velo.inverse();
  const Eigen::Matrix3d M = velo_from_rect.topLeftCorner<3, 3>();
  const Eigen::Vector3d centre = (velo_from_rect * (bottom - Eigen::Vector3d(0, h / 2, 0)).homogeneous()).head<3>();
  const Eigen::Vector3d x = (M * Eigen::Vector3d(std::cos(ry), 0, -std::sin(ry))).normalized();
  const Eigen::Vector3d z = (M * Eigen::Vector3d(0, -1, 0)).normalized();
  Eigen::Matrix3d R;
  R << x, z.cross(x).normalized(), z;
  Box3 b;
  b.T_frame_box = Rigid3d(R, centre);
  b.size = Eigen::Vector3d(l, w, h);
  return b;
}

// rect cam0 <- Velodyne of a KITTI info record (v1: images.R0_rect, lidar_points.Tr_velo_to_cam; v0: calib.*).
Eigen::Matrix4d RectFromVelo(const json& record) {
  if (record.contains("calib")) return Mat4Of(record["calib"]["R0_rect"]) * Mat4Of(record["calib"]["Tr_velo_to_cam"]);
  return Mat4Of(record["images"]["R0_rect"]) * Mat4Of(record["lidar_points"]["Tr_velo_to_cam"]);
}

// --- added objects

AddedObject Added(const std::string& category, const Box3& box, const std::string& channel) {
  AddedObject obj;
  obj.category = category;
  obj.asset_id = category + "-001";
  obj.annotation.box = box;
  obj.annotation.num_lidar_pts = 42;
  CameraBox cb;
  cb.channel = channel;
  cb.box = {500, 300, 560, 350};
  cb.visible_fraction = 0.9;
  cb.truncation = 0.0;
  obj.camera_boxes.push_back(cb);
  return obj;
}

// A nuScenes-like object: yaw about the LiDAR's z only (what mmdet3d boxes hold), ahead of the ego vehicle.
AddedObject AddedLidarYaw(const std::string& category, const Frame& f, double yaw, const Eigen::Vector3d& p_ego) {
  const Rigid3d& T = f.lidar->T_ego_lidar;
  Box3 box;
  box.size = FindCategory(category)->default_size;
  box.T_frame_box = T * Rigid3d::FromYaw(yaw, T.Inverse() * p_ego);
  return Added(category, box, "CAM_FRONT");
}

json Row(const Eigen::Vector3d& v) { return {v.x(), v.y(), v.z()}; }

// What the writer must add for an object in mmdet3d v1 nuScenes terms (LiDAR frame, [x y z l w h yaw]).
json V1Expected(const AddedObject& obj, const Frame& f, int label) {
  const Box3 b = obj.annotation.box.Transformed(f.lidar->T_ego_lidar.Inverse());
  return {{"bbox_3d", {b.center().x(), b.center().y(), b.center().z(), b.size.x(), b.size.y(), b.size.z(), b.Yaw()}},
          {"bbox_label_3d", label},
          {"num_lidar_pts", obj.annotation.num_lidar_pts},
          {"bbox_3d_isvalid", true},
          {"velocity", {0.0, 0.0}},
          {"synthdrive_asset_id", obj.asset_id}};
}

// The added objects read back: after the frame's own annotations (unchanged), in order, to 1e-6 m.
void ExpectReadBack(const Frame& got, const Frame& in, const FrameEdit& edit, const std::vector<std::string>& categories) {
  ASSERT_EQ(got.annotations.size(), in.annotations.size() + edit.added.size());
  for (size_t k = 0; k < in.annotations.size(); ++k) {
    EXPECT_EQ(got.annotations[k].category, in.annotations[k].category);
    EXPECT_EQ(got.annotations[k].num_lidar_pts, in.annotations[k].num_lidar_pts);
    ExpectSameBox(got.annotations[k].box, in.annotations[k].box, 1e-9);
  }
  for (size_t k = 0; k < edit.added.size(); ++k) {
    const Annotation& a = got.annotations[in.annotations.size() + k];
    EXPECT_EQ(a.category, categories[k]);
    EXPECT_EQ(a.num_lidar_pts, 42);
    ExpectSameBox(a.box, edit.added[k].annotation.box, 1e-6, "added " + categories[k]);
  }
}

int ProtocolOfFile(const fs::path& file) {
  const std::string bytes = ReadFileToString(file);
  return pickle::ProtocolOf(IsGzip(bytes) ? Gunzip(bytes, file, size_t(1) << 30) : bytes);
}

// ---------------------------------------------------------------------------------------------------------
// Reading

TEST(Mmdet3dPickle, ReadsLikeItsJsonTwin) {
  for (const auto& [pkl, twin] : {std::pair{kKf0Pkl, kKf0Json}, std::pair{kBevfusionPkl, kBevfusionJson}}) {
    SCOPED_TRACE(pkl);
    const Log a = OpenLog(RepoData(pkl)), b = OpenLog(RepoData(twin));
    ExpectSameLog(a, b);
  }
  const Log kf0 = OpenLog(RepoData(kKf0Pkl));
  EXPECT_EQ(kf0.format, LogFormat::kMmdet3dV1);
  EXPECT_EQ(kf0.frames[0].annotations.size(), 69u);
  EXPECT_EQ(OpenLog(RepoData(kBevfusionPkl)).format, LogFormat::kMmdet3dV0);
}

TEST(Mmdet3dPickle, SharedInfosReadLikeTheirJsonTwins) {
  SD_REQUIRE_SHARED(v0, kMiniValPkl);
  ExpectSameLog(OpenLog(v0), OpenLog(SharedData(kMiniValJson)));  // NaN velocities: null in the JSON, NaN in the pickle
  SD_REQUIRE_SHARED(lyft, "driving/lyft-mmdet3d-tests/lyft_infos.pkl");
  ExpectSameLog(OpenLog(lyft), OpenLog(SharedData("driving/lyft-mmdet3d-tests/lyft_infos.json")));
  SD_REQUIRE_SHARED(kitti, "driving/kitti-mmdet3d/demo/000008.pkl");
  ExpectSameLog(OpenLog(kitti), OpenLog(SharedData("driving/kitti-mmdet3d/demo/000008.json")));
  SD_REQUIRE_SHARED(kitti_train, "driving/kitti-mmdet3d/tests/kitti_infos_train.pkl");
  ExpectSameLog(OpenLog(kitti_train), OpenLog(SharedData("driving/kitti-mmdet3d/tests/kitti_infos_train.json")));
}

// The real v1.x KITTI info of frame 000008 with its point cloud and image: the conventions of docs/datasets.md.
TEST(KittiInfo, V1Frame000008BoxesHoldTheirPointsAndProjectOntoTheirBoxes) {
  const fs::path info = RepoData(kKittiV1);
  const Log log = OpenLog(info);
  EXPECT_EQ(log.format, LogFormat::kMmdet3dKitti);
  EXPECT_STREQ(ToString(log.format), "mmdet3d-kitti");
  EXPECT_FALSE(log.sequential);
  EXPECT_FALSE(log.ego_origin_on_ground);
  ASSERT_EQ(log.categories.size(), 8u);  // mmdet3d's KITTI classes: the metainfo lists none
  EXPECT_EQ(log.categories[2], "Car");
  ASSERT_EQ(log.frames.size(), 1u);
  const Frame& f = log.frames[0];
  EXPECT_EQ(f.token, "000008");
  ASSERT_TRUE(f.lidar);
  EXPECT_EQ(f.lidar->path, info.parent_path() / "000008.bin");  // the demo layout: beside the info
  EXPECT_EQ(f.lidar->spin_direction, -1);
  EXPECT_DOUBLE_EQ(f.lidar->start_azimuth, std::numbers::pi);
  EXPECT_FALSE(f.lidar->motion_compensated);
  EXPECT_EQ(MaxDiff(f.lidar->T_ego_lidar, Rigid3d()), 0);  // ego = Velodyne
  ASSERT_EQ(f.cameras.size(), 1u);
  const CameraSensor& cam = f.cameras[0];
  EXPECT_EQ(cam.channel, "CAM2");
  EXPECT_EQ(cam.intrinsics.width, 1242);
  EXPECT_EQ(cam.intrinsics.height, 375);
  EXPECT_GT((cam.T_ego_cam.rotation * Eigen::Vector3d::UnitZ()).x(), 0.99);  // looks forward

  const json j = datasets_internal::ReadInfoJson(info);
  const json& rec = j["data_list"][0];
  const json& inst = rec["instances"];
  ASSERT_EQ(inst.size(), 10u);
  ASSERT_EQ(f.annotations.size(), 6u);  // the 4 DontCare (label -1) are regions, not objects
  const Eigen::Matrix4d rect_from_velo = RectFromVelo(rec);
  const std::vector<int> counts = CountPointsInBoxes(f);
  int worst_points = 0;
  double worst_box = 0, worst_centre_px = 0, worst_depth = 0, worst_iou = 1;
  for (size_t k = 0; k < f.annotations.size(); ++k) {
    const Annotation& a = f.annotations[k];
    const json& b = inst[k];
    EXPECT_EQ(a.category, "Car");
    EXPECT_EQ(b["bbox_label_3d"].get<int>(), 2);
    // The box is KITTI's label box: [x y z l h w ry], bottom centre in rect cam0.
    const json& v = b["bbox_3d"];
    const Box3 want = VeloBoxOfLabel(Eigen::Vector3d(v[0].get<double>(), v[1].get<double>(), v[2].get<double>()), v[3].get<double>(),
                                     v[4].get<double>(), v[5].get<double>(), v[6].get<double>(), rect_from_velo);
    const auto ca = a.box.Corners(), cw = want.Corners();
    for (int c = 0; c < 8; ++c) worst_box = std::max(worst_box, (ca[c] - cw[c]).norm());
    EXPECT_NEAR(a.box.size.x(), v[3].get<double>(), 1e-12);  // l
    EXPECT_NEAR(a.box.size.z(), v[4].get<double>(), 1e-12);  // h
    EXPECT_NEAR(a.box.size.y(), v[5].get<double>(), 1e-12);  // w
    // num_lidar_pts was not counted on this file's points: a plain numpy count in rect cam0 (|d.a| <= l/2,
    // |d.b| <= w/2, 0 <= -d.y <= h around the bottom centre) finds exactly kCounts, which the boxes must hold;
    // num_lidar_pts is within 8 % of them (worst: the car cut by the image's left edge, 1424 vs 1325). Swapping
    // l and w (725 for the second car) or the sign of ry (1354) misses by far more.
    constexpr int kCounts[] = {1424, 1940, 878, 668, 53, 164};
    EXPECT_EQ(counts[k], kCounts[k]) << "car " << k;
    const int num = b["num_lidar_pts"].get<int>();
    worst_points = std::max(worst_points, std::abs(counts[k] - num));
    EXPECT_LE(std::abs(counts[k] - num), std::max(3.0, 0.08 * num)) << "car " << k;
    EXPECT_EQ(a.num_lidar_pts, b["num_lidar_pts"].get<int>());
    // center_2d and depth are the gravity centre through cam2img: our camera must see it there.
    const Eigen::Vector3d p_cam = cam.T_ego_cam.Inverse() * a.box.center();
    const auto uv = cam.intrinsics.Project(p_cam);
    ASSERT_TRUE(uv);
    const Eigen::Vector2d centre_2d(b["center_2d"][0].get<double>(), b["center_2d"][1].get<double>());
    worst_centre_px = std::max(worst_centre_px, (*uv - centre_2d).norm());
    // (camera 2 sits at K^-1 P2[:,3] in rect cam0, so its z is the third row of P2 [c; 1]: mmdet3d's depth)
    worst_depth = std::max(worst_depth, std::abs(p_cam.z() - b["depth"].get<double>()));
    // The projected 3D box covers its 2D label box (KITTI's hand-drawn boxes, clipped to the image).
    double x1 = 1e9, y1 = 1e9, x2 = -1e9, y2 = -1e9;
    for (const Eigen::Vector3d& c : a.box.Corners()) {
      const auto q = cam.intrinsics.Project(cam.T_ego_cam.Inverse() * c);
      ASSERT_TRUE(q);
      x1 = std::min(x1, q->x()), y1 = std::min(y1, q->y()), x2 = std::max(x2, q->x()), y2 = std::max(y2, q->y());
    }
    const Box2 projected{std::max(x1, 0.0), std::max(y1, 0.0), std::min(x2, 1241.0), std::min(y2, 374.0)};
    ASSERT_EQ(a.box2d_by_camera.count("CAM2"), 1u);
    const Box2 label = a.box2d_by_camera.at("CAM2");
    EXPECT_EQ(label.x1, b["bbox"][0].get<double>());
    EXPECT_EQ(label.y2, b["bbox"][3].get<double>());
    worst_iou = std::min(worst_iou, IoU(projected, label));
    // KITTI labels: truncated, occluded; mmdet3d's difficulty follows from them and the 2D box height.
    EXPECT_EQ(a.truncation, b["truncated"].get<double>());
    EXPECT_EQ(a.visibility, b["occluded"].get<int>());
    EXPECT_EQ(datasets_internal::KittiDifficulty(label.y2 - label.y1, a.visibility, a.truncation), b["difficulty"].get<int>());
  }
  std::cout << "KITTI info 000008: boxes vs the label convention " << worst_box << " m; points in box vs num_lidar_pts worst "
            << worst_points << "; centre_2d " << worst_centre_px << " px; depth " << worst_depth << " m; worst IoU of projected box "
            << worst_iou << "\n";
  EXPECT_LT(worst_box, 1e-5);         // R0_rect * Tr_velo_to_cam is rigid only to float32 rounding
  EXPECT_LT(worst_centre_px, 1e-3);   // center_2d is stored as float32
  EXPECT_LT(worst_depth, 1e-5);
  EXPECT_GT(worst_iou, 0.7);
}

// The same frame through KITTI's own files (derived from this info by ../shared's README §6): the same boxes.
TEST(KittiInfo, V1GivesTheBoxesOfTheKittiFolder) {
  SD_REQUIRE_SHARED(derived, "driving/kitti-mmdet3d/demo/derived_kitti_format");
  TempDir tmp;
  const fs::path split = tmp / "training";
  for (const char* d : {"calib", "label_2", "velodyne", "image_2"}) fs::create_directories(split / d);
  fs::copy_file(derived / "calib/000008.txt", split / "calib/000008.txt");
  fs::copy_file(derived / "label_2/000008.txt", split / "label_2/000008.txt");
  fs::create_symlink(RepoData("driving/kitti-mmdet3d-pkl-000008/v1x_format/000008.bin"), split / "velodyne/000008.bin");
  fs::create_symlink(RepoData("driving/kitti-mmdet3d-pkl-000008/v1x_format/000008.png"), split / "image_2/000008.png");
  const Log kitti = OpenLog(tmp.path());
  ASSERT_EQ(kitti.format, LogFormat::kKitti);
  const Log info = OpenLog(RepoData(kKittiV1));
  const Frame &k = kitti.frames.at(0), &i = info.frames.at(0);
  EXPECT_EQ(k.token, i.token);
  EXPECT_LT(MaxDiff(k.cameras[0].T_ego_cam, i.cameras[0].T_ego_cam), 1e-9);
  EXPECT_NEAR(k.cameras[0].intrinsics.fx, i.cameras[0].intrinsics.fx, 1e-9);
  EXPECT_NEAR(k.cameras[0].intrinsics.cy, i.cameras[0].intrinsics.cy, 1e-9);
  EXPECT_EQ(k.lidar->spin_direction, i.lidar->spin_direction);
  EXPECT_EQ(k.lidar->start_azimuth, i.lidar->start_azimuth);
  EXPECT_EQ(k.lidar->motion_compensated, i.lidar->motion_compensated);
  EXPECT_EQ(k.lidar->layout.num_features, i.lidar->layout.num_features);
  EXPECT_EQ(kitti.sequential, info.sequential);
  EXPECT_EQ(kitti.ego_origin_on_ground, info.ego_origin_on_ground);
  ASSERT_EQ(k.annotations.size(), i.annotations.size());
  for (size_t a = 0; a < k.annotations.size(); ++a) {
    EXPECT_EQ(k.annotations[a].category, i.annotations[a].category);
    ExpectSameBox(k.annotations[a].box, i.annotations[a].box, 1e-6);  // the calib text holds 13 digits of the info's float32s
    EXPECT_EQ(k.annotations[a].truncation, i.annotations[a].truncation);
    EXPECT_EQ(k.annotations[a].visibility, i.annotations[a].visibility);
    EXPECT_EQ(k.annotations[a].box2d_by_camera.at("image_2").x1, i.annotations[a].box2d_by_camera.at("CAM2").x1);
    EXPECT_EQ(k.annotations[a].box2d_by_camera.at("image_2").y2, i.annotations[a].box2d_by_camera.at("CAM2").y2);
  }
}

// The old list-of-dicts info of the same frame: dimensions are l h w (the label's h w l reordered), location the
// bottom centre; calib in float64 where v1 stores float32.
TEST(KittiInfo, V0ListOfDictsGivesTheV1Boxes) {
  const fs::path file = RepoData(kKittiV0);
  const Log v0 = OpenLog(file), v1 = OpenLog(RepoData(kKittiV1));
  EXPECT_EQ(v0.format, LogFormat::kMmdet3dKitti);
  ASSERT_EQ(v0.frames.size(), 1u);
  const Frame &a = v0.frames[0], &b = v1.frames[0];
  EXPECT_EQ(a.token, "000008");
  ASSERT_EQ(a.annotations.size(), 6u);
  double worst = 0;
  for (size_t k = 0; k < a.annotations.size(); ++k) {
    EXPECT_EQ(a.annotations[k].category, "Car");
    EXPECT_EQ(a.annotations[k].num_lidar_pts, b.annotations[k].num_lidar_pts);
    EXPECT_EQ(a.annotations[k].truncation, b.annotations[k].truncation);
    EXPECT_EQ(a.annotations[k].visibility, b.annotations[k].visibility);
    EXPECT_EQ(a.annotations[k].box.size, b.annotations[k].box.size);
    const auto ca = a.annotations[k].box.Corners(), cb = b.annotations[k].box.Corners();
    for (int c = 0; c < 8; ++c) worst = std::max(worst, (ca[c] - cb[c]).norm());
  }
  std::cout << "KITTI 000008 v0 vs v1 info boxes: " << worst << " m\n";
  EXPECT_LT(worst, 1e-5);
  ASSERT_EQ(a.cameras.size(), 1u);
  EXPECT_EQ(a.cameras[0].intrinsics.width, 1242);  // image absent: image_shape
  EXPECT_EQ(a.cameras[0].intrinsics.height, 375);
  // Paths under training/ as written; the repo copy ships no such folder: reading works, the sweep names itself.
  EXPECT_EQ(a.lidar->path, file.parent_path() / "training/velodyne/000008.bin");
  try {
    ReadLidar(*a.lidar);
    ADD_FAILURE() << "no InputError for the missing sweep";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("training/velodyne/000008.bin"), std::string::npos) << e.what();
  }
}

// mmdet3d's create_data output (v1.1, categories with DontCare: -1, files under training/) of KITTI frame 000000,
// which the repo also holds as a KITTI folder.
TEST(KittiInfo, CreateDataInfoOfFrame000000) {
  SD_REQUIRE_SHARED(info, "driving/kitti-mmdet3d/tests/kitti_infos_train.pkl");
  const Log log = OpenLog(info);
  EXPECT_EQ(log.format, LogFormat::kMmdet3dKitti);
  ASSERT_EQ(log.categories.size(), 8u);
  EXPECT_EQ(log.categories[0], "Pedestrian");
  const Frame& f = log.frames.at(0);
  EXPECT_EQ(f.token, "000000");
  EXPECT_EQ(f.lidar->path, info.parent_path() / "training/velodyne_reduced/000000.bin");
  EXPECT_EQ(f.cameras.at(0).image_path, info.parent_path() / "training/image_2/000000.png");
  EXPECT_EQ(f.cameras[0].intrinsics.width, 1224);
  const Log kitti = OpenLog(RepoData("driving/kitti-object"));
  ASSERT_EQ(f.annotations.size(), 1u);
  const Annotation& ped = kitti.frames.at(0).annotations.at(0);
  EXPECT_EQ(f.annotations[0].category, ped.category);
  ExpectSameBox(f.annotations[0].box, ped.box, 1e-5);
  EXPECT_EQ(f.annotations[0].box2d_by_camera.at("CAM2").x2, ped.box2d_by_camera.at("image_2").x2);
  SD_REQUIRE_SHARED(mono, "driving/kitti-mmdet3d/tests/kitti_infos_mono3d.pkl");  // v0 list of dicts
  const Log m = OpenLog(mono);
  ASSERT_EQ(m.frames.size(), 1u);
  EXPECT_EQ(m.frames[0].annotations.size(), 4u);  // 3 Car + 1 Cyclist; 2 DontCare rows
}

// A hostile pickle: reading it must not run it, and refuses it in one located line.
TEST(Mmdet3dPickle, RefusesAPickleThatWouldRunCode) {
  SD_REQUIRE_PANDAS_PYTHON();
  TempDir tmp;
  const fs::path evil = tmp / "evil_info.pkl", marker = tmp / "ran";
  std::string output;
  ASSERT_EQ(RunCheck({"evil", evil.string(), marker.string()}, &output), 0) << output;
  for (const OpenLogOptions& options : {OpenLogOptions{}, OpenLogOptions{.format = LogFormat::kMmdet3dV1, .data_root = {}}}) {
    try {
      OpenLog(evil, options);
      ADD_FAILURE() << "the hostile pickle was read";
    } catch (const InputError& e) {
      const std::string what = e.what();
      EXPECT_EQ(what.find('\n'), std::string::npos) << what;
      EXPECT_NE(what.find("evil_info.pkl"), std::string::npos) << what;
      EXPECT_NE(what.find("refusing to load global"), std::string::npos) << what;
      EXPECT_NE(what.find("system'"), std::string::npos) << what;  // os.system pickles as 'posix.system' on Linux
    }
  }
  EXPECT_FALSE(fs::exists(marker));
}

// ---------------------------------------------------------------------------------------------------------
// Writing

// (a) the repo's nuScenes keyframe, v1: the .pkl derivative holds what the .json writer adds, typed like the
// record's own instances (numpy int64 num_lidar_pts, numpy bool bbox_3d_isvalid, numpy float64 cam bbox).
TEST(WritePickle, NuScenesKeyframeV1) {
  SD_REQUIRE_PANDAS_PYTHON();
  const fs::path in = RepoData(kKf0Pkl);
  const Log log = OpenLog(in);
  const Frame& f = log.frames[0];
  FrameEdit edit;
  edit.added = {AddedLidarYaw("warning_tripod", f, 0.4, {8.0, 1.5, 0.3}), AddedLidarYaw("car", f, -1.0, {15.0, -3.0, 0.9})};
  TempDir out, twin, dir;
  const WriteOptions options{.unchanged = UnchangedFiles::kSymlink};
  const auto written = WriteDerivative(log, {edit}, out.path(), options);
  ASSERT_EQ(written.size(), 1u);
  EXPECT_EQ(written[0], out / "mmdet3d_info/n015-2018-07-24-11-22-45+0800.pkl");
  EXPECT_EQ(ProtocolOfFile(written[0]), 2);
  const auto twin_written = WriteDerivative(OpenLog(RepoData(kKf0Json)), {edit}, twin.path(), options);

  json cam = json::array();
  for (size_t k = 0; k < edit.added.size(); ++k) cam.push_back({{"bbox", {500.0, 300.0, 560.0, 350.0}}});
  std::vector<std::string> classes = log.categories;
  classes.push_back("warning_tripod");
  const json spec = {{"input", in.string()},
                     {"output", written[0].string()},
                     {"json_output", twin_written[0].string()},
                     {"list_key", "data_list"},
                     {"classes", classes},
                     {"records", {{{"input_index", 0},
                                   {"insert_at", nullptr},
                                   {"lists", {{"instances", {V1Expected(edit.added[0], f, 10), V1Expected(edit.added[1], f, 0)}},
                                              {"cam_instances/CAM_FRONT", cam}}}}}}};
  ExpectPythonAgrees(spec, dir.path());

  const Log back = OpenLog(written[0]);
  EXPECT_EQ(back.format, LogFormat::kMmdet3dV1);
  EXPECT_EQ(back.categories.size(), 11u);
  ASSERT_EQ(back.frames.size(), 1u);
  ExpectReadBack(back.frames[0], f, edit, {"warning_tripod", "car"});
  EXPECT_EQ(back.frames[0].annotations[69].box2d_by_camera.at("CAM_FRONT").x1, 500);
  EXPECT_EQ(ReadLidar(*back.frames[0].lidar).size(), ReadLidar(*f.lidar).size());
}

// (b) ../shared's nuScenes mini val infos, v0: numpy columns get rows, gt_names widens from <U10 to <U14.
TEST(WritePickle, NuScenesMiniValV0) {
  SD_REQUIRE_PANDAS_PYTHON();
  SD_REQUIRE_SHARED(in, kMiniValPkl);
  const Log log = OpenLog(in);
  std::vector<FrameEdit> edits;
  json records = json::array();
  for (size_t index : {size_t(33), size_t(2)}) {  // 33 holds NaN velocities; out of order on purpose
    const Frame& f = log.frames[index];
    FrameEdit e;
    e.frame_index = index;
    e.added = {AddedLidarYaw("warning_tripod", f, 0.4, {8.0, 1.5, 0.3}), AddedLidarYaw("car", f, -1.0, {15.0, -3.0, 0.9})};
    json boxes = json::array(), names = json::array();
    for (const AddedObject& obj : e.added) {
      const Box3 b = obj.annotation.box.Transformed(f.lidar->T_ego_lidar.Inverse());
      const double yaw_old = std::remainder(-b.Yaw() - std::numbers::pi / 2, 2 * std::numbers::pi);
      boxes.push_back({b.center().x(), b.center().y(), b.center().z(), b.size.y(), b.size.x(), b.size.z(), yaw_old});
      names.push_back(obj.category);
    }
    records.push_back({{"input_index", index},
                       {"insert_at", nullptr},
                       {"lists", {{"gt_boxes", boxes}, {"gt_names", names}, {"gt_velocity", {{0.0, 0.0}, {0.0, 0.0}}},
                                  {"num_lidar_pts", {42, 42}}, {"num_radar_pts", {0, 0}}, {"valid_flag", {true, true}}}}});
    edits.push_back(e);
  }
  TempDir out, twin, dir;
  const WriteOptions options{.unchanged = UnchangedFiles::kSymlink, .require_sensor_files = false};
  const auto written = WriteDerivative(log, edits, out.path(), options);
  const auto twin_written = WriteDerivative(OpenLog(SharedData(kMiniValJson)), edits, twin.path(), options);
  ExpectPythonAgrees({{"input", in.string()}, {"output", written.at(0).string()}, {"json_output", twin_written.at(0).string()},
                      {"list_key", "infos"}, {"records", records}},
                     dir.path());
  const Log back = OpenLog(written[0], {.format = {}, .data_root = out.path()});
  EXPECT_EQ(back.format, LogFormat::kMmdet3dV0);
  ASSERT_EQ(back.frames.size(), 2u);
  ExpectReadBack(back.frames[0], log.frames[33], edits[0], {"warning_tripod", "car"});
  ExpectReadBack(back.frames[1], log.frames[2], edits[1], {"warning_tripod", "car"});
}

// A protocol-4, gzipped copy of the keyframe info: the derivative keeps both.
TEST(WritePickle, KeepsProtocolFourAndGzip) {
  SD_REQUIRE_PANDAS_PYTHON();
  TempDir tmp, out, dir;
  const fs::path in = tmp / "mmdet3d_info/info.pkl.gz";
  fs::create_directories(in.parent_path());
  std::string output;
  ASSERT_EQ(RunCheck({"redump", RepoData(kKf0Pkl).string(), in.string(), "4", "gzip"}, &output), 0) << output;
  const fs::path scene = RepoData("driving/nuscenes-scene0061-kf0");
  const OpenLogOptions options{.format = LogFormat::kMmdet3dV1, .data_root = scene};  // .pkl.gz is not probed
  const Log log = OpenLog(in, options);
  ExpectSameLog(log, OpenLog(RepoData(kKf0Pkl), {.format = {}, .data_root = scene}));
  FrameEdit edit;
  edit.added = {AddedLidarYaw("traffic_cone", log.frames[0], 0.0, {9.0, 2.0, 0.5})};
  WriteDerivative(log, {edit}, out.path(), {.unchanged = UnchangedFiles::kSymlink, .require_sensor_files = false});
  // The info lay outside data_root: it is written under its file name.
  const fs::path written = out / "info.pkl.gz";
  ASSERT_TRUE(fs::exists(written));
  EXPECT_TRUE(IsGzip(ReadFileToString(written)));
  EXPECT_EQ(ProtocolOfFile(written), 4);
  json lists = json::object();
  // json::array, not braces: `{one_json}` is a copy under clang and a one-element array under gcc.
  lists["instances"] = json::array({V1Expected(edit.added[0], log.frames[0], 8)});
  lists["cam_instances/CAM_FRONT"] = json::array({{{"bbox", {500.0, 300.0, 560.0, 350.0}}}});
  json records = json::array();
  records.push_back({{"input_index", 0}, {"insert_at", nullptr}, {"lists", lists}});
  ExpectPythonAgrees({{"input", in.string()}, {"output", written.string()}, {"list_key", "data_list"}, {"records", records}}, dir.path());
  const Log back = OpenLog(written, options);
  ExpectReadBack(back.frames.at(0), log.frames[0], edit, {"traffic_cone"});
}

// A KITTI-representable object (rotation about rect cam0's y) from label values chosen here, in the frame of
// `record`: what the writer must write back is these values.
struct KittiObject {
  Eigen::Vector3d bottom;
  double l, h, w, ry;
};

AddedObject AddedKitti(const std::string& category, const KittiObject& o, const json& record) {
  AddedObject obj = Added(category, VeloBoxOfLabel(o.bottom, o.l, o.h, o.w, o.ry, RectFromVelo(record)), "CAM2");
  return obj;
}

const KittiObject kTripod{{1.5, 1.70, 10.0}, 0.45, 0.45, 0.30, 0.3};
const KittiObject kCar{{-4.0, 1.60, 25.0}, 4.20, 1.50, 1.70, -1.2};

// (c) the KITTI v1 pickle: instances [x y z l h w ry] bottom centre, the 2D bbox of the CAM2 camera box,
// center_2d / depth through cam2img; the metainfo has no class list, so a new class writes mmdet3d's whole list.
TEST(WritePickle, KittiV1) {
  SD_REQUIRE_PANDAS_PYTHON();
  const fs::path in = RepoData(kKittiV1);
  const Log log = OpenLog(in);
  const json rec = datasets_internal::ReadInfoJson(in)["data_list"][0];
  FrameEdit edit;
  edit.added = {AddedKitti("warning_tripod", kTripod, rec), AddedKitti("car", kCar, rec)};
  TempDir out, dir;
  const auto written = WriteDerivative(log, {edit}, out.path());
  EXPECT_EQ(written.at(0), out / "000008.pkl");
  EXPECT_EQ(ProtocolOfFile(written[0]), 2);
  EXPECT_EQ(ReadFileToString(out / "000008.bin"), ReadFileToString(log.frames[0].lidar->path));
  const CameraSensor& cam = log.frames[0].cameras[0];
  json instances = json::array();
  int label = 8, index = 6, group = 10;
  for (const auto& [obj, o] : {std::pair{edit.added[0], kTripod}, std::pair{edit.added[1], kCar}}) {
    const Eigen::Vector3d p = cam.T_ego_cam.Inverse() * obj.annotation.box.center();
    const Eigen::Vector2d uv = *cam.intrinsics.Project(p);
    instances.push_back({{"bbox", {500.0, 300.0, 560.0, 350.0}},
                         {"bbox_3d", {o.bottom.x(), o.bottom.y(), o.bottom.z(), o.l, o.h, o.w, o.ry}},
                         {"bbox_label_3d", obj.category == "car" ? 2 : label},
                         {"center_2d", {uv.x(), uv.y()}},
                         {"depth", p.z()},
                         {"num_lidar_pts", 42},
                         {"occluded", 0},     // 90 % visible
                         {"difficulty", 0},   // 50 px tall, fully visible, not truncated: easy
                         {"truncated", 0.0},
                         {"alpha", std::remainder(o.ry - std::atan2(o.bottom.x(), o.bottom.z()), 2 * std::numbers::pi)},
                         {"index", index++},
                         {"group_id", group++},
                         {"synthdrive_asset_id", obj.asset_id}});
  }
  std::vector<std::string> classes = {"Pedestrian", "Cyclist", "Car", "Van", "Truck", "Person_sitting", "Tram", "Misc", "WarningTripod"};
  ExpectPythonAgrees({{"input", in.string()}, {"output", written[0].string()}, {"list_key", "data_list"}, {"classes", classes},
                      {"records", {{{"input_index", 0}, {"insert_at", nullptr}, {"lists", {{"instances", instances}}}}}}},
                     dir.path());
  const Log back = OpenLog(written[0]);
  EXPECT_EQ(back.format, LogFormat::kMmdet3dKitti);
  EXPECT_EQ(back.categories, classes);
  ExpectReadBack(back.frames.at(0), log.frames[0], edit, {"WarningTripod", "Car"});
  EXPECT_EQ(back.frames[0].annotations[6].box2d_by_camera.at("CAM2").y2, 350);
}

// (c) the KITTI v0 list of dicts: rows inserted before the DontCare rows, name widened from <U8 to <U13.
TEST(WritePickle, KittiV0) {
  SD_REQUIRE_PANDAS_PYTHON();
  const fs::path in = RepoData(kKittiV0);
  const Log log = OpenLog(in);
  const json rec = datasets_internal::ReadInfoJson(in)[0];
  FrameEdit edit;
  edit.added = {AddedKitti("warning_tripod", kTripod, rec), AddedKitti("car", kCar, rec)};
  TempDir out, dir;
  const auto written = WriteDerivative(log, {edit}, out.path(), {.require_sensor_files = false});  // no training/ files
  EXPECT_EQ(written.at(0), out / "kitti_000008_infos.pkl");
  json lists = json::object();
  for (const char* key : {"name", "location", "dimensions", "rotation_y", "bbox", "index", "group_ids", "num_points_in_gt",
                          "occluded", "truncated", "difficulty", "score", "alpha"})
    lists[std::string("annos/") + key] = json::array();
  for (size_t k = 0; k < 2; ++k) {
    const KittiObject& o = k == 0 ? kTripod : kCar;
    lists["annos/name"].push_back(k == 0 ? "WarningTripod" : "Car");
    lists["annos/location"].push_back(Row(o.bottom));
    lists["annos/dimensions"].push_back({o.l, o.h, o.w});
    lists["annos/rotation_y"].push_back(o.ry);
    lists["annos/alpha"].push_back(std::remainder(o.ry - std::atan2(o.bottom.x(), o.bottom.z()), 2 * std::numbers::pi));
    lists["annos/bbox"].push_back({500.0, 300.0, 560.0, 350.0});
    lists["annos/index"].push_back(6 + k);
    lists["annos/group_ids"].push_back(10 + k);
    lists["annos/num_points_in_gt"].push_back(42);
    lists["annos/occluded"].push_back(0);
    lists["annos/truncated"].push_back(0.0);
    lists["annos/difficulty"].push_back(0);
    lists["annos/score"].push_back(0.0);
  }
  ExpectPythonAgrees({{"input", in.string()}, {"output", written[0].string()}, {"list_key", ""},
                      {"records", {{{"input_index", 0}, {"insert_at", 6}, {"lists", lists}}}}},
                     dir.path());
  const Log back = OpenLog(written[0]);
  EXPECT_EQ(back.format, LogFormat::kMmdet3dKitti);
  ExpectReadBack(back.frames.at(0), log.frames[0], edit, {"WarningTripod", "Car"});
}

// KITTI infos as .json: the text writer splices the same instances (v1) and rows before the DontCare rows (v0),
// keeping every input byte; the .pkl writer adds the same values to the .pkl twin.
TEST(WritePickle, KittiJsonTwinsSpliced) {
  SD_REQUIRE_PANDAS_PYTHON();
  SD_REQUIRE_SHARED(demo_json, "driving/kitti-mmdet3d/demo/000008.json");
  const fs::path demo_pkl = SharedData("driving/kitti-mmdet3d/demo/000008.pkl");
  const Log log_json = OpenLog(demo_json), log_pkl = OpenLog(demo_pkl);
  const json rec = datasets_internal::ReadInfoJson(demo_json)["data_list"][0];
  FrameEdit edit;
  edit.added = {AddedKitti("warning_tripod", kTripod, rec), AddedKitti("car", kCar, rec)};
  TempDir out_json, out_pkl, dir;
  const auto wj = WriteDerivative(log_json, {edit}, out_json.path());
  const auto wp = WriteDerivative(log_pkl, {edit}, out_pkl.path());
  const std::string in_text = ReadFileToString(demo_json), out_text = ReadFileToString(wj.at(0));
  size_t matched = 0;  // the input's bytes, in order, with text inserted only
  for (size_t i = 0; i < out_text.size() && matched < in_text.size(); ++i) matched += out_text[i] == in_text[matched];
  EXPECT_EQ(matched, in_text.size());
  json records = json::array();
  records.push_back({{"input_index", 0}, {"insert_at", nullptr}, {"lists", {{"instances", {json::object(), json::object()}}}}});
  ExpectPythonAgrees({{"input", demo_pkl.string()}, {"output", wp.at(0).string()}, {"json_output", wj[0].string()},
                      {"list_key", "data_list"}, {"records", records}},
                     dir.path());
  ExpectReadBack(OpenLog(wj[0]).frames.at(0), log_json.frames[0], edit, {"WarningTripod", "Car"});

  SD_REQUIRE_SHARED(mono_json, "driving/kitti-mmdet3d/tests/kitti_infos_mono3d.json");
  const Log mono = OpenLog(mono_json);
  const json mono_rec = datasets_internal::ReadInfoJson(mono_json)[0];
  FrameEdit e;
  e.added = {AddedKitti("warning_tripod", kTripod, mono_rec)};
  TempDir out_mono;
  const auto wm = WriteDerivative(mono, {e}, out_mono.path(), {.require_sensor_files = false});
  const json got = datasets_internal::ReadPythonJson(wm.at(0));
  const json& names = got[0]["annos"]["name"];
  ASSERT_EQ(names.size(), 7u);
  EXPECT_EQ(names[4], "WarningTripod");  // after the 4 objects, before the 2 DontCare rows
  EXPECT_EQ(names[5], "DontCare");
  EXPECT_EQ(got[0]["annos"]["index"][4], 4);
  const std::string mono_in = ReadFileToString(mono_json), mono_out = ReadFileToString(wm[0]);
  matched = 0;
  for (size_t i = 0; i < mono_out.size() && matched < mono_in.size(); ++i) matched += mono_out[i] == mono_in[matched];
  EXPECT_EQ(matched, mono_in.size());
  ExpectReadBack(OpenLog(wm[0]).frames.at(0), mono.frames[0], e, {"WarningTripod"});
}

}  // namespace
}  // namespace sd
