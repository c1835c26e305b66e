// Synthesis on logs without LiDAR (issue "Logs as users have them", §2): the road from the cameras, camera
// images and labels written, the LiDAR reported absent and never made up.
#include <gtest/gtest.h>

#include <cmath>
#include <filesystem>
#include <fstream>

#include <nlohmann/json.hpp>

#include "core/error.h"
#include "datasets/readers.h"
#include "io/files.h"
#include "synth/batch.h"
#include "synth/frame.h"
#include "synth/scenario.h"
#include "synth/test_assets.h"
#include "testing/testing.h"

namespace sd {
namespace {

namespace fs = std::filesystem;

const char* kKeyframe = "driving/nuscenes-scene0061-kf0";
const char* kInfo = "driving/nuscenes-scene0061-kf0/mmdet3d_info/n015-2018-07-24-11-22-45+0800.json";

bool BoxesOverlapInPlan(const Box3& a, const Box3& b) {
  // Separating axes of two rectangles in the ground plane.
  const auto corners = [](const Box3& box) {
    std::vector<Eigen::Vector2d> c;
    for (const Eigen::Vector3d& p : box.Corners()) c.push_back(p.head<2>());
    return c;
  };
  const auto ca = corners(a), cb = corners(b);
  for (const Box3* box : {&a, &b}) {
    const Eigen::Matrix3d R = box->T_frame_box.Rotation();
    for (int axis = 0; axis < 2; ++axis) {
      const Eigen::Vector2d n = R.col(axis).head<2>().normalized();
      double a0 = 1e18, a1 = -1e18, b0 = 1e18, b1 = -1e18;
      for (const auto& p : ca) a0 = std::min(a0, n.dot(p)), a1 = std::max(a1, n.dot(p));
      for (const auto& p : cb) b0 = std::min(b0, n.dot(p)), b1 = std::max(b1, n.dot(p));
      if (a1 <= b0 || b1 <= a0) return false;
    }
  }
  return true;
}

TEST(CameraOnlySynthesis, AKeyframeWithoutItsSweepGetsImagesAndLabelsAndNoSweep) {
  testing::TempDir dir;
  Log log = OpenLog(testing::RepoData(kInfo));
  const double lidar_road_at_ego = [&] {
    const PointCloud sweep = ReadLidar(*log.frames[0].lidar);
    const GroundModel g = EstimateFrameGround(log.frames[0], sweep, PointsInEgo(log.frames[0], sweep), Scenario{});
    return g.SurfaceAt(8, 0).height;
  }();
  log.frames[0].lidar.reset();
  const std::vector<Asset> assets = testing::ImportDemoAssets(dir.path());
  const Scenario scenario = ReadScenario(testing::RepoData("scenarios/demo.json"));
  SynthOptions options;
  options.samples_per_pixel = 1;
  options.ao_samples = 4;
  const FrameOutcome o = SynthesizeFrame(log, 0, assets, scenario, options);

  EXPECT_FALSE(o.edit.points.has_value());
  EXPECT_EQ(o.lidar_model, kNoLidar);
  // One keyframe: no neighbour in time for stereo, so the road is the level plane at the boxes' bottoms.
  EXPECT_EQ(o.road.rfind("assumed:", 0), 0u) << o.road;
  EXPECT_NE(o.road.find("no neighbouring frame"), std::string::npos) << o.road;
  const double prior = RoadPriorHeight(log, log.frames[0]);
  EXPECT_NEAR(prior, lidar_road_at_ego, 0.15) << "the boxes' bottoms against the LiDAR road 8 m ahead";

  ASSERT_FALSE(o.objects.empty());
  for (const ObjectOutcome& ob : o.objects) {
    const Box3& b = ob.placement.box;
    EXPECT_NEAR(b.center().z() - 0.5 * b.size.z(), prior, 1e-6) << ob.label.asset_id << " stands on the plane";
    EXPECT_EQ(ob.lidar_points, 0);
    EXPECT_FALSE(ob.label.camera_boxes.empty()) << ob.label.asset_id << " is labelled in some camera";
    for (const Annotation& a : log.frames[0].annotations)
      EXPECT_FALSE(BoxesOverlapInPlan(b, a.box)) << ob.label.asset_id << " overlaps a real " << a.category;
  }
  ASSERT_FALSE(o.cameras.empty());
  size_t changed = 0;
  for (const CameraOutcome& c : o.cameras)
    for (size_t i = 0; i < c.after.size(); ++i) changed += c.after.data()[i] != c.before.data()[i];
  EXPECT_GT(changed, 1000u);
}

// The whole command on a camera-only info file: the derivative dataset has the cameras and the labels, its info
// lists no sweep, and synth.json says where the road came from and that the LiDAR was absent.
TEST(CameraOnlySynthesis, TheCommandWritesCamerasAndLabelsAndSaysTheLidarWasAbsent) {
  testing::TempDir dir;
  // The keyframe's info as a camera-only rig's would be: no lidar_points, boxes in the ego frame (mmdet3d keeps
  // them in the LiDAR frame, which such an info cannot place).
  nlohmann::json info = nlohmann::json::parse(ReadFileToString(testing::RepoData(kInfo)));
  for (auto& d : info["data_list"]) {
    Eigen::Matrix4d T = Eigen::Matrix4d::Identity();
    for (int r = 0; r < 4; ++r)
      for (int c = 0; c < 4; ++c) T(r, c) = d["lidar_points"]["lidar2ego"][r][c].get<double>();
    for (auto& inst : d["instances"]) {
      auto& b = inst["bbox_3d"];
      const Eigen::Vector3d p = T.topLeftCorner<3, 3>() * Eigen::Vector3d(b[0], b[1], b[2]) + T.topRightCorner<3, 1>();
      for (int k = 0; k < 3; ++k) b[k] = p[k];
      b[6] = b[6].get<double>() + std::atan2(T(1, 0), T(0, 0));
      if (inst.contains("velocity") && inst["velocity"][0].is_number() && inst["velocity"][1].is_number()) {
        const Eigen::Vector2d v = T.topLeftCorner<2, 2>() * Eigen::Vector2d(inst["velocity"][0], inst["velocity"][1]);
        inst["velocity"] = {v.x(), v.y()};
      }
    }
    d.erase("lidar_points");
    for (auto& [channel, cam] : d["images"].items()) cam.erase("lidar2cam");
  }
  const fs::path info_file = dir / "cameras_only.json";
  std::ofstream(info_file) << info.dump();

  const std::vector<Asset> assets = testing::ImportDemoAssets(dir / "assets");
  SynthRequest r;
  r.log = info_file;
  r.log_options.data_root = testing::RepoData(kKeyframe);
  for (const Asset& a : assets) r.assets.push_back(a.dir);
  r.scenario = testing::RepoData("scenarios/demo.json");
  r.out = dir / "out";
  r.options.samples_per_pixel = 1;
  r.options.ao_samples = 2;
  const SynthSummary s = RunSynth(r);
  EXPECT_GT(s.objects, 0u);

  const nlohmann::json synth = nlohmann::json::parse(ReadFileToString(r.out / "synth.json"));
  ASSERT_EQ(synth["frames"].size(), 1u);
  EXPECT_EQ(synth["frames"][0]["lidar_model"], kNoLidar);
  EXPECT_EQ(synth["frames"][0]["road"].get<std::string>().rfind("assumed:", 0), 0u) << synth["frames"][0]["road"];
  // The boxes' bottoms give the road: a few centimetres from the ego origin's height (nuScenes' is on the road).
  for (const auto& o : synth["frames"][0]["objects"]) EXPECT_NEAR(o["ground_height_m"].get<double>(), 0.0, 0.15) << o;
  size_t sweeps = 0, images = 0;
  for (const auto& e : fs::recursive_directory_iterator(r.out)) {
    const std::string name = e.path().filename().string();
    sweeps += name.find("LIDAR") != std::string::npos || e.path().extension() == ".bin";
    images += e.path().extension() == ".jpg";
  }
  EXPECT_EQ(sweeps, 0u) << "a camera-only log gets no sweep";
  EXPECT_GT(images, 0u);
  const Log written = OpenLog(r.out / info_file.filename(), {});
  ASSERT_EQ(written.frames.size(), 1u);
  EXPECT_FALSE(written.frames[0].lidar.has_value());
  const Log original = OpenLog(info_file, r.log_options);
  EXPECT_EQ(written.frames[0].annotations.size(), original.frames[0].annotations.size() + s.objects);
}

// PandaSet with its LiDAR held back: the road comes from the cameras' stereo against the neighbouring frames, and
// the objects stand where the LiDAR road is.
TEST(CameraOnlySynthesis, PandaSetWithoutLidarStandsTheObjectsOnTheStereoRoad) {
  SD_REQUIRE_SHARED(root, "driving/pandaset-002-f44-55");
  Log log = OpenLog(root);
  const size_t k = 5;
  const PointCloud sweep = ReadLidar(*log.frames[k].lidar);
  const GroundModel lidar_ground = EstimateFrameGround(log.frames[k], sweep, PointsInEgo(log.frames[k], sweep), Scenario{});
  for (Frame& f : log.frames) f.lidar.reset();
  const CameraGround g = EstimateCameraGround(log, k, Scenario{});
  ASSERT_TRUE(g.from_stereo) << g.source;
  EXPECT_EQ(g.source.rfind("cameras:", 0), 0u) << g.source;
  // Where both saw the road within 20 m (a LiDAR ground cell within 1 m: the rings leave gaps between them), the
  // stereo surface is the LiDAR's within a few centimetres.
  const auto lidar_saw = [&](const Eigen::Vector3d& p) {
    for (double dx = -1; dx <= 1; dx += 0.5)
      for (double dy = -1; dy <= 1; dy += 0.5)
        if (lidar_ground.IsObserved(p.x() + dx, p.y() + dy)) return true;
    return false;
  };
  std::vector<double> errors;
  for (const Eigen::Vector3d& p : g.ground.ground_points())
    if (p.head<2>().norm() < 20 && lidar_ground.IsDrivable(p.x(), p.y()) && lidar_saw(p))
      errors.push_back(std::abs(g.ground.SurfaceAt(p.x(), p.y()).height - lidar_ground.SurfaceAt(p.x(), p.y()).height));
  ASSERT_GE(errors.size(), 200u);
  std::sort(errors.begin(), errors.end());
  EXPECT_LT(errors[errors.size() / 2], 0.05);
  EXPECT_LT(errors[errors.size() * 9 / 10], 0.15);

  // The whole frame without its sweep: the stereo's points stand in for the sweep's in placement and occlusion.
  testing::TempDir dir;
  const std::vector<Asset> assets = testing::ImportDemoAssets(dir.path());
  WriteFileAtomic(dir / "cones.json", R"({"seed": 3, "margin_m": 0.5, "objects": [
    {"category": "traffic_cone", "count": 2, "distance_m": [5, 15], "lateral_m": [-3, 3], "yaw": "random"}]})");
  SynthOptions options;
  options.samples_per_pixel = 1;
  options.ao_samples = 2;
  const FrameOutcome o = SynthesizeFrame(log, k, assets, ReadScenario(dir / "cones.json"), options);
  EXPECT_FALSE(o.edit.points.has_value());
  EXPECT_EQ(o.road.rfind("cameras:", 0), 0u) << o.road;
  ASSERT_EQ(o.objects.size(), 2u);
  for (const ObjectOutcome& ob : o.objects) {
    const Box3& b = ob.placement.box;
    EXPECT_NEAR(b.center().z() - 0.5 * b.size.z(), lidar_ground.SurfaceAt(b.center().x(), b.center().y()).height, 0.15)
        << "the cone stands on the real road";
    EXPECT_FALSE(ob.label.camera_boxes.empty());
  }
}

}  // namespace
}  // namespace sd
