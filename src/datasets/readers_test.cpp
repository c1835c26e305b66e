#include "datasets/readers.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <functional>
#include <cmath>
#include <fstream>
#include <numbers>
#include <sstream>

#include "core/error.h"
#include "datasets/internal.h"
#include "io/files.h"
#include "io/image_io.h"
#include "io/json.h"
#include "testing/testing.h"

namespace sd {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;
using sd::testing::RepoData;
using sd::testing::TempDir;

const char* kKf0 = "driving/nuscenes-scene0061-kf0";
const char* kKf0Info = "driving/nuscenes-scene0061-kf0/mmdet3d_info/n015-2018-07-24-11-22-45+0800.json";

double AngleDiff(double a, double b) { return std::abs(std::remainder(a - b, 2 * std::numbers::pi)); }

std::vector<int> CountPointsInBoxes(const Frame& frame) {
  const PointCloud pc = ReadLidar(*frame.lidar);
  std::vector<Eigen::Vector3d> pts(pc.size());
  for (size_t i = 0; i < pc.size(); ++i) pts[i] = frame.lidar->T_ego_lidar * pc.xyz(i).cast<double>();
  std::vector<int> counts;
  for (const Annotation& a : frame.annotations)
    counts.push_back(static_cast<int>(std::count_if(pts.begin(), pts.end(), [&](const Eigen::Vector3d& p) { return a.box.Contains(p); })));
  return counts;
}

// Expects InputError whose message names `file` (its file name at least).
template <typename F>
void ExpectInputErrorNaming(F&& f, const fs::path& file) {
  try {
    f();
    ADD_FAILURE() << "no InputError for " << file;
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(file.filename().string()), std::string::npos) << e.what();
  }
}

TEST(Mmdet3dV1, NuScenesKeyframeBoxesHoldTheirLidarPoints) {
  const Log log = OpenLog(RepoData(kKf0Info));
  EXPECT_EQ(log.format, LogFormat::kMmdet3dV1);
  EXPECT_EQ(log.version, "v1.0-mini");
  ASSERT_EQ(log.categories.size(), 10u);
  EXPECT_EQ(log.categories[8], "traffic_cone");
  ASSERT_EQ(log.frames.size(), 1u);
  const Frame& f = log.frames[0];
  EXPECT_EQ(f.token, "ca9a282c9e77460f8360f564131a8af5");
  EXPECT_NEAR(f.timestamp, 1532402927.647951, 1e-6);
  ASSERT_EQ(f.cameras.size(), 6u);
  ASSERT_TRUE(f.lidar);
  EXPECT_TRUE(fs::exists(f.lidar->path)) << f.lidar->path;
  for (const CameraSensor& c : f.cameras) {
    EXPECT_TRUE(fs::exists(c.image_path)) << c.image_path;
    EXPECT_EQ(c.intrinsics.width, 1600);
    EXPECT_EQ(c.intrinsics.height, 900);
  }
  // The lidar sits 1.84 m above the ego origin, rotated ~+90 deg in yaw.
  EXPECT_NEAR(f.lidar->T_ego_lidar.translation.z(), 1.84, 0.01);
  EXPECT_NEAR(f.lidar->T_ego_lidar.Yaw(), -std::numbers::pi / 2, 0.02);
  ASSERT_EQ(f.annotations.size(), 69u);
  EXPECT_EQ(std::count_if(f.annotations.begin(), f.annotations.end(), [](const Annotation& a) { return a.category.empty(); }), 1);
  EXPECT_TRUE(f.has_annotations);

  const std::vector<int> counts = CountPointsInBoxes(f);
  int exact = 0;
  for (size_t i = 0; i < counts.size(); ++i) exact += counts[i] == f.annotations[i].num_lidar_pts;
  std::cout << "nuScenes kf0: " << exact << "/69 boxes contain exactly num_lidar_pts points\n";
  EXPECT_GE(exact, 61);
}

TEST(Mmdet3dV1, CamInstancesProjectThroughTEgoCam) {
  const fs::path info = RepoData(kKf0Info);
  const Log log = ReadMmdet3dInfo(info);
  const Frame& f = log.frames[0];
  const json j = ReadJsonFile(info);
  int checked = 0;
  double worst_px = 0, worst_yaw = 0;
  for (const auto& [channel, list] : j["data_list"][0]["cam_instances"].items()) {
    const CameraSensor* cam = f.FindCamera(channel);
    ASSERT_NE(cam, nullptr) << channel;
    const Rigid3d T_cam_ego = cam->T_ego_cam.Inverse();
    for (const json& ci : list) {
      const Eigen::Vector3d c3(ci["bbox_3d"][0].get<double>(), ci["bbox_3d"][1].get<double>(), ci["bbox_3d"][2].get<double>());
      // The annotation this camera instance came from: the one whose centre lands on it in this camera.
      const Annotation* best = nullptr;
      double best_d = 1e9;
      for (const Annotation& a : f.annotations) {
        const double d = (T_cam_ego * a.box.center() - c3).norm();
        if (d < best_d) best_d = d, best = &a;
      }
      ASSERT_LT(best_d, 1e-3) << channel;
      const Box3 bc = best->box.Transformed(T_cam_ego);
      const auto uv = cam->intrinsics.Project(bc.center());
      ASSERT_TRUE(uv);
      const Eigen::Vector2d c2(ci["center_2d"][0].get<double>(), ci["center_2d"][1].get<double>());
      worst_px = std::max(worst_px, (*uv - c2).norm());
      // Camera-box convention: [x y z l h w yaw], yaw = atan2(-x_axis.z, x_axis.x) in camera coordinates.
      EXPECT_NEAR(ci["bbox_3d"][3].get<double>(), best->box.size.x(), 1e-6);
      EXPECT_NEAR(ci["bbox_3d"][4].get<double>(), best->box.size.z(), 1e-6);
      EXPECT_NEAR(ci["bbox_3d"][5].get<double>(), best->box.size.y(), 1e-6);
      worst_yaw = std::max(worst_yaw, AngleDiff(datasets_internal::CameraYaw(bc.T_frame_box.Rotation()), ci["bbox_3d"][6].get<double>()));
      EXPECT_NEAR(ci["depth"].get<double>(), bc.center().z(), 1e-4);
      ++checked;
    }
  }
  std::cout << "cam_instances checked: " << checked << ", worst centre_2d error " << worst_px << " px, worst yaw " << worst_yaw << " rad\n";
  EXPECT_GT(checked, 30);
  EXPECT_LT(worst_px, 1e-2);
  EXPECT_LT(worst_yaw, 2e-3);  // boxes tilt slightly with the ground; the yaw ignores that
}

// The info's cam_instances become Annotation::box2d_by_camera. Values read by hand from data_list[0]:
// instances[0] (pedestrian) and instances[2] (car, cut by the image's right edge) in CAM_FRONT.
TEST(Mmdet3dV1, CamInstancesBecomeAnnotatedBox2d) {
  const Log log = ReadMmdet3dInfo(RepoData(kKf0Info));
  const Frame& f = log.frames[0];
  size_t boxes = 0;
  for (const Annotation& a : f.annotations) boxes += a.box2d_by_camera.size();
  EXPECT_EQ(boxes, 84u);  // 47 + 18 + 2 + 10 + 2 + 5 cam_instances, each matched to one annotation
  const Annotation& ped = f.annotations[0];
  ASSERT_EQ(ped.box2d_by_camera.count("CAM_FRONT"), 1u);
  const Box2 b = ped.box2d_by_camera.at("CAM_FRONT");
  EXPECT_NEAR(b.x1, 1206.5693751819117, 1e-9);
  EXPECT_NEAR(b.y1, 477.86111828160216, 1e-9);
  EXPECT_NEAR(b.x2, 1225.8893058022245, 1e-9);
  EXPECT_NEAR(b.y2, 513.6450176828284, 1e-9);
  const Annotation& car = f.annotations[2];
  ASSERT_EQ(car.box2d_by_camera.count("CAM_FRONT"), 1u);
  EXPECT_NEAR(car.box2d_by_camera.at("CAM_FRONT").x1, 1504.5998756594938, 1e-9);
  EXPECT_NEAR(car.box2d_by_camera.at("CAM_FRONT").x2, 1600.0, 1e-9);
  EXPECT_NEAR(car.box2d_by_camera.at("CAM_FRONT").y2, 523.157376459145, 1e-9);
  // Every matched 2D box contains the projection of its annotation's centre (when that lies in the image).
  for (const Annotation& a : f.annotations) {
    for (const auto& [channel, box] : a.box2d_by_camera) {
      const CameraSensor* cam = f.FindCamera(channel);
      ASSERT_NE(cam, nullptr);
      const auto uv = cam->intrinsics.Project(cam->T_ego_cam.Inverse() * a.box.center());
      ASSERT_TRUE(uv) << channel;
      if (cam->intrinsics.InImage(*uv)) {
        EXPECT_TRUE(uv->x() >= box.x1 - 1 && uv->x() <= box.x2 + 1 && uv->y() >= box.y1 - 1 && uv->y() <= box.y2 + 1) << channel;
      }
    }
  }
}

TEST(NuScenesTables, SubsetAgreesWithTheInfo) {
  const Log tables = OpenLog(RepoData(kKf0));
  EXPECT_EQ(tables.format, LogFormat::kNuScenesTables);
  EXPECT_EQ(tables.version, "v1.0-subset");
  EXPECT_EQ(tables.name, "scene-0061");
  EXPECT_FALSE(tables.location);  // no log table in the subset
  ASSERT_EQ(tables.frames.size(), 1u);
  const Frame& t = tables.frames[0];
  EXPECT_FALSE(t.has_annotations);
  EXPECT_TRUE(t.annotations.empty());
  ASSERT_TRUE(t.lidar);
  EXPECT_EQ(t.lidar->channel, "LIDAR_TOP");
  EXPECT_TRUE(fs::exists(t.lidar->path));
  EXPECT_NEAR(t.timestamp, 1532402927.647951, 1e-6);

  const Log info = ReadMmdet3dInfo(RepoData(kKf0Info));
  const Frame& i = info.frames[0];
  // The info stores float32: 1 ulp at 1180 m is 1.2e-4 m, so translations agree to that, rotations to 1e-6.
  EXPECT_LT((t.T_world_ego.Rotation() - i.T_world_ego.Rotation()).cwiseAbs().maxCoeff(), 1e-6);
  EXPECT_LT((t.T_world_ego.translation - i.T_world_ego.translation).cwiseAbs().maxCoeff(), 1.2e-4);
  EXPECT_LT((t.lidar->T_ego_lidar.Matrix() - i.lidar->T_ego_lidar.Matrix()).cwiseAbs().maxCoeff(), 1e-6);
  ASSERT_EQ(t.cameras.size(), 6u);
  for (const CameraSensor& ct : t.cameras) {
    const CameraSensor* ci = i.FindCamera(ct.channel);
    ASSERT_NE(ci, nullptr) << ct.channel;
    EXPECT_EQ(ct.intrinsics.width, 1600);
    EXPECT_EQ(ct.intrinsics.height, 900);
    EXPECT_TRUE(fs::exists(ct.image_path));
    EXPECT_EQ(ct.image_path.filename(), ci->image_path.filename());
    EXPECT_NEAR(ct.intrinsics.fx, ci->intrinsics.fx, 1e-6);
    EXPECT_NEAR(ct.intrinsics.cx, ci->intrinsics.cx, 1e-6);
    EXPECT_LT((ct.T_egocam_cam.Matrix() - ci->T_egocam_cam.Matrix()).cwiseAbs().maxCoeff(), 1e-6) << ct.channel;
    // Ego motion between the camera and LiDAR timestamps is folded in identically by both readers.
    EXPECT_LT((ct.T_ego_cam.Matrix() - ci->T_ego_cam.Matrix()).cwiseAbs().maxCoeff(), 1e-4) << ct.channel;
    EXPECT_LT((ct.T_world_egocam.Matrix() - ci->T_world_egocam.Matrix()).cwiseAbs().maxCoeff(), 1e-4) << ct.channel;
  }
}

TEST(NuScenesTables, LyftFixtureAnnotationsConvertSize) {
  const fs::path root = RepoData("driving/lyft-tables/v1.01-train");
  const Log log = OpenLog(root);
  EXPECT_EQ(log.format, LogFormat::kNuScenesTables);
  EXPECT_EQ(log.version, "v1.01-train");
  EXPECT_FALSE(log.location);  // Palo Alto is not a nuScenes map
  ASSERT_EQ(log.frames.size(), 1u);
  const Frame& f = log.frames[0];
  EXPECT_TRUE(f.has_annotations);
  ASSERT_EQ(f.annotations.size(), 4u);
  ASSERT_TRUE(f.lidar);
  EXPECT_EQ(f.lidar->channel, "LIDAR_TOP");
  EXPECT_EQ(f.cameras.size(), 7u);
  const CameraSensor* front = f.FindCamera("CAM_FRONT");
  ASSERT_NE(front, nullptr);
  EXPECT_GT(front->intrinsics.width, 0);

  const json table = ReadJsonFile(root / "v1.01-train" / "sample_annotation.json");
  for (const json& rec : table) {
    const auto it = std::find_if(f.annotations.begin(), f.annotations.end(),
                                 [&](const Annotation& a) { return a.token == rec["token"].get<std::string>(); });
    ASSERT_NE(it, f.annotations.end());
    EXPECT_EQ(it->category, "car");
    EXPECT_NEAR(it->box.size.x(), rec["size"][1].get<double>(), 1e-12);  // length = size[1]
    EXPECT_NEAR(it->box.size.y(), rec["size"][0].get<double>(), 1e-12);  // width = size[0]
    EXPECT_NEAR(it->box.size.z(), rec["size"][2].get<double>(), 1e-12);
    const Box3 global = it->box.Transformed(f.T_world_ego);
    for (int k = 0; k < 3; ++k) EXPECT_NEAR(global.center()[k], rec["translation"][k].get<double>(), 1e-6);
    const Eigen::Quaterniond q(rec["rotation"][0].get<double>(), rec["rotation"][1].get<double>(), rec["rotation"][2].get<double>(),
                               rec["rotation"][3].get<double>());
    EXPECT_NEAR(std::abs(global.T_frame_box.rotation.dot(q.normalized())), 1.0, 1e-9);
    EXPECT_EQ(it->visibility, -1);  // empty visibility_token in Lyft
  }
}

TEST(NuScenesTables, LocationOfNuScenesMaps) {
  TempDir tmp;
  // The keyframe's own tables (a nuScenes v1.0 release: its cameras 1600x900) with the log put in Boston.
  const fs::path root = tmp / "nuscenes";
  fs::create_directories(root);
  fs::copy(RepoData("driving/nuscenes-scene0061-kf0/v1.0-subset"), root / "v1.0-subset", fs::copy_options::recursive);
  fs::create_directory_symlink(fs::absolute(RepoData("driving/nuscenes-scene0061-kf0/samples")), root / "samples");
  // The subset ships without log.json (optional): one naming the scene's log.
  const json scene = ReadJsonFile(root / "v1.0-subset" / "scene.json");
  WriteJsonFile(root / "v1.0-subset" / "log.json",
                json::array({{{"token", scene[0]["log_token"]}, {"logfile", "n015-2018-07-24-11-22-45+0800"},
                              {"vehicle", "n015"}, {"date_captured", "2018-07-24"}, {"location", "boston-seaport"}}}));
  const Log log = OpenLog(root);
  ASSERT_TRUE(log.location);
  EXPECT_EQ(log.location->name, "boston-seaport");
  EXPECT_NEAR(log.location->latitude_deg, 42.34, 0.03);
  EXPECT_NEAR(log.location->longitude_deg, -71.06, 0.03);
}

TEST(Mmdet3dV0, MiniValInfosBoxesAndVelocityHeading) {
  SD_REQUIRE_SHARED(info, "driving/nuscenes-mini-val-infos/nuscenes_infos_val.json");
  const Log log = OpenLog(info);
  EXPECT_EQ(log.format, LogFormat::kMmdet3dV0);
  EXPECT_EQ(log.version, "v1.0-mini");
  ASSERT_EQ(log.frames.size(), 81u);
  size_t boxes = 0;
  std::vector<double> errors;
  for (const Frame& f : log.frames) {
    boxes += f.annotations.size();
    EXPECT_EQ(f.cameras.size(), 6u);
    for (const Annotation& a : f.annotations) {
      if (a.category != "car" || !a.velocity.allFinite() || a.velocity.norm() < 1.0) continue;
      errors.push_back(AngleDiff(std::atan2(a.velocity.y(), a.velocity.x()), a.box.Yaw()));
    }
  }
  EXPECT_EQ(boxes, 4514u);
  ASSERT_GT(errors.size(), 50u);
  std::nth_element(errors.begin(), errors.begin() + errors.size() / 2, errors.end());
  const double median = errors[errors.size() / 2];
  std::cout << "v0: " << errors.size() << " moving cars, median heading error " << median << " rad\n";
  EXPECT_LT(median, 0.05);
  // The sensor files are not shipped: the model reads, ReadLidar names the missing file.
  const Frame& f0 = log.frames[0];
  EXPECT_NE(f0.lidar->path.generic_string().find("samples/LIDAR_TOP/"), std::string::npos);
  ExpectInputErrorNaming([&] { ReadLidar(*f0.lidar); }, f0.lidar->path);
}

TEST(Mmdet3dV1, LyftInfosLoad) {
  SD_REQUIRE_SHARED(info, "driving/lyft-mmdet3d-tests/lyft_infos.json");
  const Log log = OpenLog(info);
  EXPECT_EQ(log.format, LogFormat::kMmdet3dV1);
  ASSERT_FALSE(log.frames.empty());
  ASSERT_EQ(log.categories.size(), 9u);  // metainfo.CLASSES list
  EXPECT_EQ(log.categories[3], "emergency_vehicle");
  const Frame& f = log.frames[0];
  EXPECT_EQ(f.cameras.size(), 6u);
  EXPECT_FALSE(f.annotations.empty());
  for (const Annotation& a : f.annotations) EXPECT_GT(a.box.size.minCoeff(), 0.0);
}

// Checks each labelled KITTI box: it contains Velodyne points and its projected centre lies in its 2D box.
void CheckKittiFrames(const Log& log, const fs::path& split, size_t expected_frames) {
  ASSERT_EQ(log.frames.size(), expected_frames);
  for (const Frame& f : log.frames) {
    ASSERT_TRUE(f.lidar);
    ASSERT_EQ(f.cameras.size(), 1u);
    const CameraSensor& cam = f.cameras[0];
    EXPECT_GT(cam.intrinsics.width, 1000);
    std::vector<std::array<double, 4>> boxes2d;
    std::istringstream in(ReadFileToString(split / "label_2" / (f.token + ".txt")));
    std::string line;
    while (std::getline(in, line)) {
      std::istringstream ls(line);
      std::string type;
      double tr, oc, al, x1, y1, x2, y2;
      if (!(ls >> type >> tr >> oc >> al >> x1 >> y1 >> x2 >> y2) || type == "DontCare") continue;
      boxes2d.push_back({x1, y1, x2, y2});
    }
    ASSERT_EQ(boxes2d.size(), f.annotations.size()) << f.token;
    const std::vector<int> counts = CountPointsInBoxes(f);
    for (size_t k = 0; k < f.annotations.size(); ++k) {
      const Annotation& a = f.annotations[k];
      EXPECT_GT(counts[k], 0) << f.token << " " << a.category;
      const auto uv = cam.intrinsics.Project(cam.T_ego_cam.Inverse() * a.box.center());
      ASSERT_TRUE(uv);
      EXPECT_TRUE(uv->x() >= boxes2d[k][0] && uv->x() <= boxes2d[k][2] && uv->y() >= boxes2d[k][1] && uv->y() <= boxes2d[k][3])
          << f.token << " " << a.category << " centre " << uv->transpose();
    }
    if (f.token == "000000") {
      ASSERT_EQ(f.annotations.size(), 1u);
      EXPECT_EQ(f.annotations[0].category, "Pedestrian");
      std::cout << "KITTI 000000 pedestrian: " << counts[0] << " points\n";
      EXPECT_NEAR(counts[0], 376, 10);
      EXPECT_EQ(cam.intrinsics.width, 1224);
      EXPECT_EQ(cam.intrinsics.height, 370);
    }
  }
}

TEST(Kitti, RepoFramesBoxesHoldPointsAndProjectIntoLabels) {
  const fs::path root = RepoData("driving/kitti-object");
  const Log log = OpenLog(root);
  EXPECT_EQ(log.format, LogFormat::kKitti);
  CheckKittiFrames(log, root / "training", 3);
  // Ego = Velodyne: the camera looks forward (+x); Tr_velo_to_cam puts the Velodyne 0.33 m behind cam0.
  const CameraSensor& cam = log.frames[0].cameras[0];
  EXPECT_GT((cam.T_ego_cam.rotation * Eigen::Vector3d::UnitZ()).x(), 0.99);
  EXPECT_NEAR(cam.T_ego_cam.translation.x(), 0.33, 0.01);
  const Annotation& ped = log.frames[0].annotations[0];
  EXPECT_NEAR(ped.box.size.x(), 1.20, 1e-9);  // l
  EXPECT_NEAR(ped.box.size.y(), 0.48, 1e-9);  // w
  EXPECT_NEAR(ped.box.size.z(), 1.89, 1e-9);  // h
  EXPECT_EQ(log.frames[1].annotations[2].visibility, 3);  // the Cyclist of 000001: occluded 3
  // label_2 columns 4-7 (left top right bottom) -> the image_2 box; values read from the label files.
  ASSERT_EQ(ped.box2d_by_camera.count("image_2"), 1u);
  const Box2 pb = ped.box2d_by_camera.at("image_2");
  EXPECT_DOUBLE_EQ(pb.x1, 712.40);
  EXPECT_DOUBLE_EQ(pb.y1, 143.00);
  EXPECT_DOUBLE_EQ(pb.x2, 810.73);
  EXPECT_DOUBLE_EQ(pb.y2, 307.92);
  const Box2 tb = log.frames[1].annotations[0].box2d_by_camera.at("image_2");  // 000001 Truck
  EXPECT_DOUBLE_EQ(tb.x1, 599.41);
  EXPECT_DOUBLE_EQ(tb.y1, 156.40);
  EXPECT_DOUBLE_EQ(tb.x2, 629.75);
  EXPECT_DOUBLE_EQ(tb.y2, 189.25);
}

TEST(Kitti, OpenPcdetFrames) {
  SD_REQUIRE_SHARED(root, "driving/kitti-object-openpcdet");
  CheckKittiFrames(OpenLog(root), root / "training", 5);
}

TEST(BadInput, EachErrorNamesTheFile) {
  TempDir tmp;
  const fs::path missing = tmp / "nope.json";
  ExpectInputErrorNaming([&] { ReadMmdet3dInfo(missing); }, missing);
  ExpectInputErrorNaming([&] { OpenLog(missing); }, missing);

  const fs::path bad = tmp / "bad_info.json";
  WriteFileAtomic(bad, "{\"data_list\": [ {\"token\": ");
  ExpectInputErrorNaming([&] { OpenLog(bad); }, bad);

  const fs::path wrong = tmp / "wrong_shape.json";
  WriteFileAtomic(wrong, R"({"data_list": [{"token": "a", "ego2global": [[1,0,0],[0,1,0],[0,0,1]]}]})");
  ExpectInputErrorNaming([&] { OpenLog(wrong); }, wrong);

  const fs::path truncated = tmp / "truncated.bin";
  WriteFileAtomic(truncated, std::string(23, '\0'));
  LidarSensor l;
  l.path = truncated;
  l.layout = PointLayout::NuScenes();
  ExpectInputErrorNaming([&] { ReadLidar(l); }, truncated);

  const fs::path kitti = tmp / "kitti";
  fs::create_directories(kitti / "label_2");
  const std::string calib = ReadFileToString(RepoData("driving/kitti-object/training/calib/000000.txt"));
  std::string short_p2 = calib;
  const size_t p2 = short_p2.find("P2:");
  const size_t eol = short_p2.find('\n', p2);
  short_p2.replace(p2, eol - p2, "P2: 7.07e+02 0 6.04e+02 4.5e+01");
  WriteFileAtomic(kitti / "calib" / "000000.txt", short_p2);
  ExpectInputErrorNaming([&] { OpenLog(kitti); }, kitti / "calib" / "000000.txt");
  WriteFileAtomic(kitti / "calib" / "000000.txt", "P2 7 0 6\n");
  ExpectInputErrorNaming([&] { OpenLog(kitti); }, kitti / "calib" / "000000.txt");

  const fs::path unknown = tmp / "some_folder";
  fs::create_directories(unknown / "images");
  ExpectInputErrorNaming([&] { OpenLog(unknown); }, unknown);

  const fs::path tables = tmp / "v1.0-x";
  fs::create_directories(tables);
  WriteFileAtomic(tables / "sample.json", "[]");
  ExpectInputErrorNaming([&] { OpenLog(tmp.path() / "v1.0-x"); }, tables / "sample_data.json");
}

// The repo keyframe's info with one calibration field broken, read where the keyframe's files are (so that only
// the calibration is wrong): each is refused with one line naming the file, the field and what is wrong. Before,
// a zero focal length aborted inside Embree, a LiDAR 1e17 m up crashed the road model, and a non-rigid lidar2cam
// (re-orthonormalised), a zero bottom row and a negative focal length produced a "successful" dataset.
TEST(BadInput, ImpossibleCalibrationIsRefusedWithItsField) {
  TempDir tmp;
  const fs::path info = RepoData(kKf0Info);
  const json original = ReadJsonFile(info);
  struct Case {
    const char* name;
    std::function<void(json&)> corrupt;
    const char* field;
    const char* problem;
  };
  const std::vector<Case> cases = {
      {"focal_zero", [](json& d) { d["data_list"][0]["images"]["CAM_FRONT"]["cam2img"][0][0] = 0; },
       "CAM_FRONT.cam2img", "impossible focal lengths"},
      {"focal_negative", [](json& d) { d["data_list"][0]["images"]["CAM_BACK"]["cam2img"][1][1] = -809.2; },
       "CAM_BACK.cam2img", "impossible focal lengths"},
      {"principal_point", [](json& d) { d["data_list"][0]["images"]["CAM_BACK"]["cam2img"][0][2] = 1e5; },
       "CAM_BACK.cam2img", "principal point (100000, 481.778) lies outside the 1600x900 image"},
      {"lidar_far", [](json& d) { d["data_list"][0]["lidar_points"]["lidar2ego"][2][3] = 1e17; },
       "lidar_points.lidar2ego", "translation is 1e+17 m"},
      {"lidar_null", [](json& d) { d["data_list"][0]["lidar_points"]["lidar2ego"][0][3] = nullptr; },
       "lidar_points.lidar2ego[0][3]", "expected a number"},
      {"bottom_row", [](json& d) { d["data_list"][0]["lidar_points"]["lidar2ego"][3] = {0, 0, 0, 0}; },
       "lidar_points.lidar2ego", "bottom row"},
      {"scaled_rotation",
       [](json& d) {
         json& m = d["data_list"][0]["images"]["CAM_FRONT"]["lidar2cam"];
         for (int i = 0; i < 3; ++i)
           for (int j = 0; j < 3; ++j) m[i][j] = m[i][j].get<double>() * 2;
       },
       "CAM_FRONT.lidar2cam", "not orthonormal"},
      {"reflection",
       [](json& d) {
         json& m = d["data_list"][0]["images"]["CAM_FRONT"]["cam2ego"];
         for (int i = 0; i < 3; ++i) m[i][0] = -m[i][0].get<double>();
       },
       "CAM_FRONT.cam2ego", "reflection"},
      {"ego_pose", [](json& d) { d["data_list"][0]["ego2global"][0][3] = 1e12; }, "ego2global", "translation"},
  };
  for (const Case& c : cases) {
    json broken = original;
    c.corrupt(broken);
    // In a temporary folder, its sensor paths resolved against the keyframe's own.
    const fs::path file = tmp / (std::string("broken_") + c.name + ".json");
    WriteJsonFile(file, broken);
    std::string message;
    try {
      OpenLogOptions options;
      options.data_root = RepoData(kKf0);
      OpenLog(file, options);
    } catch (const InputError& e) {
      message = e.what();
    }
    EXPECT_NE(message.find(file.filename().string()), std::string::npos) << c.name << ": " << message;
    EXPECT_NE(message.find(c.field), std::string::npos) << c.name << ": " << message;
    EXPECT_NE(message.find(c.problem), std::string::npos) << c.name << ": " << message;
  }
  EXPECT_NO_THROW(OpenLog(info));

  // CAM_FRONT's image at half the size its calibration was made for (the other images absent: only the sizes
  // the file headers give are compared).
  const std::string front = original["data_list"][0]["images"]["CAM_FRONT"]["img_path"].get<std::string>();
  const fs::path front_image = RepoData(kKf0) / "samples" / "CAM_FRONT" / fs::path(front).filename();
  const ImageU8 full = ReadImage(front_image, 3);
  ImageU8 half(full.width() / 2, full.height() / 2, 3);
  for (int y = 0; y < half.height(); ++y)
    for (int x = 0; x < half.width(); ++x)
      for (int c = 0; c < 3; ++c) half.at(x, y, c) = full.at(2 * x, 2 * y, c);
  const fs::path resized_root = tmp / "resized";
  WriteImage(resized_root / "samples" / "CAM_FRONT" / fs::path(front).filename(), half);
  std::string message;
  try {
    OpenLogOptions options;
    options.data_root = resized_root;
    OpenLog(info, options);
  } catch (const InputError& e) {
    message = e.what();
  }
  EXPECT_NE(message.find("CAM_FRONT.cam2img: the principal point"), std::string::npos) << message;
  EXPECT_NE(message.find("outside the 800x450 image"), std::string::npos) << message;
}

}  // namespace
}  // namespace sd
