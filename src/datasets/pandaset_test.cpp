// PandaSet's conventions pinned on the real sequence 002, frames 44-55 (../shared/data/driving/pandaset-002-f44-55).
#include <gtest/gtest.h>

#include <algorithm>
#include <cstring>
#include <cmath>
#include <fstream>
#include <map>
#include <numbers>
#include <regex>
#include <sstream>

#include "core/error.h"
#include "datasets/categories.h"
#include "datasets/readers.h"
#include "datasets/writers.h"
#include "io/files.h"
#include "io/image_io.h"
#include "io/json.h"
#include "testing/testing.h"

namespace sd {
namespace {

const char* kSeq = "driving/pandaset-002-f44-55";

double AngleDiff(double a, double b) { return std::abs(std::remainder(a - b, 2 * std::numbers::pi)); }

TEST(PandaSet, SequenceFramesCamerasAndLidar) {
  SD_REQUIRE_SHARED(dir, kSeq);
  const Log log = OpenLog(dir);  // probed
  EXPECT_EQ(log.format, LogFormat::kPandaSet);
  EXPECT_TRUE(log.sequential);
  EXPECT_FALSE(log.ego_origin_on_ground);
  ASSERT_EQ(log.frames.size(), 12u);
  EXPECT_EQ(log.frames.front().token, "44");
  EXPECT_EQ(log.frames.back().token, "55");
  ASSERT_TRUE(log.location);
  EXPECT_NEAR(log.location->latitude_deg, 37.776, 0.01);  // San Francisco
  EXPECT_NEAR(log.location->longitude_deg, -122.399, 0.01);
  for (size_t i = 0; i < log.frames.size(); ++i) {
    const Frame& f = log.frames[i];
    ASSERT_EQ(f.cameras.size(), 6u);
    for (const CameraSensor& c : f.cameras) {
      EXPECT_EQ(c.intrinsics.width, 1920);
      EXPECT_EQ(c.intrinsics.height, 1080);
      // Cameras fire up to ~0.1 s before the LiDAR stamp; the ego moves ~0.45 m per frame.
      EXPECT_LT(std::abs(c.timestamp - f.timestamp), 0.1);
    }
    ASSERT_TRUE(f.lidar);
    EXPECT_EQ(f.lidar->T_lidar_sensors.size(), 2u);
    if (i > 0) {
      EXPECT_NEAR(f.timestamp - log.frames[i - 1].timestamp, 0.1, 0.002);
      // Ego x is forward: the ego moves along its own +x.
      const Eigen::Vector3d step = log.frames[i - 1].T_world_ego.Inverse() * f.T_world_ego.translation;
      EXPECT_GT(step.x(), 0.3);
      EXPECT_LT(std::abs(step.y()), 0.05);
    }
  }
}

// The Pandar64 in the ego frame from each camera's own world pose and the devkit's static calibration (camera <-
// Pandar64): T_world_p64 = T_world_cam * T_cam_p64 must equal the reader's T_world_ego(t_cam) * T_ego_lidar.
TEST(PandaSet, RigConstantsAgreeWithTheCamerasAndTheDevkitCalibration) {
  SD_REQUIRE_SHARED(dir, kSeq);
  const std::string yaml = "\n" + ReadFileToString(dir / "static_extrinsic_calibration.yaml");
  auto numbers_of = [&](const std::string& name, const std::string& key) {
    const size_t at = yaml.find("\n" + name + ":");
    EXPECT_NE(at, std::string::npos) << name;
    const size_t k = yaml.find(key + ": {", at), end = yaml.find('}', k);
    std::map<std::string, double> v;
    const std::string body = yaml.substr(k + key.size() + 3, end - k - key.size() - 3);
    const std::regex pair(R"(([a-z]+):\s*([-0-9.eE]+))");
    for (auto it = std::sregex_iterator(body.begin(), body.end(), pair); it != std::sregex_iterator(); ++it)
      v[(*it)[1]] = std::stod((*it)[2]);
    return v;
  };
  const Log log = OpenLog(dir);
  double worst_t = 0, worst_r = 0;
  int checked = 0;
  for (const Frame& f : log.frames) {
    for (const CameraSensor& c : f.cameras) {
      auto r = numbers_of(c.channel, "rotation"), t = numbers_of(c.channel, "translation");
      const Rigid3d T_cam_p64 = Rigid3d::FromWxyz(r["w"], r["x"], r["y"], r["z"], Eigen::Vector3d(t["x"], t["y"], t["z"]));
      const Rigid3d T_world_cam = c.T_world_egocam * c.T_egocam_cam;
      const Rigid3d from_camera = T_world_cam * T_cam_p64;
      const Rigid3d from_rig = c.T_world_egocam * f.lidar->T_ego_lidar;
      worst_t = std::max(worst_t, (from_camera.translation - from_rig.translation).norm());
      worst_r = std::max(worst_r, from_camera.rotation.angularDistance(from_rig.rotation));
      // T_ego_cam folds the ego motion to the LiDAR time in: the camera's world pose either way.
      EXPECT_LT(((f.T_world_ego * c.T_ego_cam).translation - T_world_cam.translation).norm(), 1e-9);
      ++checked;
    }
  }
  EXPECT_EQ(checked, 72);
  EXPECT_LT(worst_t, 0.03) << "m";
  EXPECT_LT(worst_r, 0.2 * std::numbers::pi / 180) << "rad";
}

TEST(PandaSet, SweepsAreTheFilesPointsInTheSensorFrame) {
  SD_REQUIRE_SHARED(dir, kSeq);
  const Log log = OpenLog(dir);
  const Frame& f = log.frames[0];
  const PointCloud pc = ReadLidar(*f.lidar);
  EXPECT_EQ(pc.size(), 164108u);  // rows of lidar/44.pkl.gz
  const int ti = pc.FeatureIndex("time"), si = pc.FeatureIndex("sensor");
  ASSERT_GE(ti, 0);
  ASSERT_GE(si, 0);
  size_t pandar64 = 0;
  float t_min = 1e9f, t_max = -1e9f;
  for (size_t i = 0; i < pc.size(); ++i) {
    pandar64 += pc.feature(i, si) == 0;
    t_min = std::min(t_min, pc.feature(i, ti));
    t_max = std::max(t_max, pc.feature(i, ti));
  }
  EXPECT_EQ(pandar64, 106417u);
  // The sweep is stamped at its end: times run over the 0.1 s before it (the PandarGT's a little earlier).
  EXPECT_GT(t_min, -0.15f);
  EXPECT_LT(t_max, 0.01f);
  // The road (the lowest dense layer around the car) lies 0.30 m below the ego origin and 2.15 m below the
  // Pandar64: what the rig constants say.
  std::vector<double> z;
  for (size_t i = 0; i < pc.size(); ++i) {
    const Eigen::Vector3d p = f.lidar->T_ego_lidar * pc.xyz(i).cast<double>();
    if (std::hypot(p.x(), p.y()) > 5 && std::hypot(p.x(), p.y()) < 12 && p.z() < 0.3) z.push_back(p.z());
  }
  std::nth_element(z.begin(), z.begin() + z.size() / 2, z.end());
  EXPECT_NEAR(z[z.size() / 2], -0.30, 0.08);
}

TEST(PandaSet, BoxesHoldTheirPointsAndMovingTracksHeadWhereTheyGo) {
  SD_REQUIRE_SHARED(dir, kSeq);
  const Log log = OpenLog(dir);
  // Frame 44 has 119 cuboid rows, 24 of them PandarGT duplicates of Pandar64 boxes.
  EXPECT_EQ(log.frames[0].annotations.size(), 95u);
  const PointCloud pc = ReadLidar(*log.frames[0].lidar);
  std::vector<Eigen::Vector3d> pts;
  for (size_t i = 0; i < pc.size(); ++i) pts.push_back(log.frames[0].lidar->T_ego_lidar * pc.xyz(i).cast<double>());
  int near_cars = 0, filled = 0;
  for (const Annotation& a : log.frames[0].annotations) {
    if (a.category != "Car" || a.box.center().head<2>().norm() > 25) continue;
    ++near_cars;
    int inside = 0, beside = 0;
    Box3 shifted = a.box;
    shifted.T_frame_box.translation += a.box.T_frame_box.rotation * Eigen::Vector3d(0, 0, a.box.size.z() + 0.5);
    for (const auto& p : pts) {
      inside += a.box.Contains(p);
      beside += shifted.Contains(p);
    }
    // The box holds its car's returns, the same box floated above it holds (nearly) none.
    if (inside >= 20 && beside <= inside / 10) ++filled;
  }
  EXPECT_GE(near_cars, 10);
  EXPECT_GE(filled, near_cars * 9 / 10) << filled << " of " << near_cars;
  // Heading = yaw + pi/2: the velocity of moving tracks points along the box x axis (length).
  int moving = 0, agree = 0;
  for (const Frame& f : log.frames)
    for (const Annotation& a : f.annotations) {
      if (!a.velocity.allFinite() || a.velocity.norm() < 2.0) continue;
      ++moving;
      agree += AngleDiff(std::atan2(a.velocity.y(), a.velocity.x()), a.box.Yaw()) < 0.2;
    }
  EXPECT_GE(moving, 100);
  EXPECT_GE(agree, moving * 9 / 10) << agree << " of " << moving;
  // Tracks: the same uuid in every frame; cones are canonical traffic cones.
  std::map<std::string, int> seen;
  for (const Frame& f : log.frames)
    for (const Annotation& a : f.annotations) ++seen[a.instance_token];
  int full = 0;
  for (const auto& [uuid, n] : seen) full += n == 12;
  EXPECT_GE(full, 80);
  EXPECT_EQ(FindCategory("Cones")->name, "traffic_cone");
  EXPECT_EQ(FindCategory("Pedestrian with Object")->name, "pedestrian");
  EXPECT_EQ(DatasetCategoryName(*FindCategory("traffic_cone"), LogFormat::kPandaSet), "Cones");
}

// Projected boxes land on the objects: PandaSet's cones are orange, and the pixels inside each cone's projected
// box are far more often orange than the image as a whole. (The images are dark: a cone's pixels are about
// (56, 38, 28), so orange is a hue test, red over green over blue, not a brightness one.)
TEST(PandaSet, ConeBoxesProjectOntoOrangePixels) {
  SD_REQUIRE_SHARED(dir, kSeq);
  const Log log = OpenLog(dir);
  auto orange = [](const uint8_t* p) { return p[0] > 1.25 * p[1] && p[0] > 1.4 * p[2] && p[0] > p[2] + 15; };
  // Share of orange pixels inside the projection of `box` (nullopt when it is not wholly in the image within 25 m).
  auto orange_share = [&](const CameraSensor& cam, const ImageU8& image, const Box3& box) -> std::optional<double> {
    const Rigid3d T_cam_ego = cam.T_ego_cam.Inverse();
    double x1 = 1e9, y1 = 1e9, x2 = -1e9, y2 = -1e9;
    for (const auto& c : box.Corners()) {
      const Eigen::Vector3d pc = T_cam_ego * c;
      const auto uv = cam.intrinsics.Project(pc, 0.5);
      if (!uv || pc.z() > 25) return std::nullopt;
      x1 = std::min(x1, uv->x()), y1 = std::min(y1, uv->y()), x2 = std::max(x2, uv->x()), y2 = std::max(y2, uv->y());
    }
    if (x1 < 0 || y1 < 0 || x2 >= image.width() || y2 >= image.height()) return std::nullopt;
    size_t n = 0, hits = 0;
    for (int y = static_cast<int>(y1); y <= static_cast<int>(y2); ++y)
      for (int x = static_cast<int>(x1); x <= static_cast<int>(x2); ++x, ++n) hits += orange(image.pixel(x, y));
    return double(hits) / std::max<size_t>(n, 1);
  };
  int projected = 0, on_cones = 0, shifted = 0, shifted_orange = 0;
  double share_on = 0, share_beside = 0;
  for (size_t fi = 0; fi < log.frames.size(); fi += 3) {
    const Frame& f = log.frames[fi];
    for (const CameraSensor& cam : f.cameras) {
      std::optional<ImageU8> image;
      for (const Annotation& a : f.annotations) {
        if (a.category != "Cones") continue;
        if (!image) image = ReadImage(cam.image_path, 3);
        if (const auto share = orange_share(cam, *image, a.box)) {
          ++projected;
          on_cones += *share > 0.05;
          share_on += *share;
        }
        // The control: the same box 1.2 m to the side of the cone.
        Box3 beside = a.box;
        beside.T_frame_box.translation += Eigen::Vector3d(0, 1.2, 0);
        if (const auto share = orange_share(cam, *image, beside)) {
          ++shifted;
          shifted_orange += *share > 0.05;
          share_beside += *share;
        }
      }
    }
  }
  // 13 projections; the cone next to the ego in right_camera stands behind a parked car, and one in back_camera
  // is hidden by a car in the foreground in the early frames: 8 of them show the cone.
  EXPECT_GE(projected, 12);
  EXPECT_GE(on_cones, 8) << on_cones << " of " << projected;
  EXPECT_GE(shifted, 10);
  // Beside the cones (where a shifted box can still clip the neighbouring cone) orange is rare.
  EXPECT_LE(shifted_orange, 2) << shifted_orange << " of " << shifted;
  EXPECT_GT(share_on / projected, 5 * share_beside / shifted) << share_on / projected << " vs " << share_beside / shifted;
}

TEST(PandaSet, NotASequenceIsALocatedError) {
  testing::TempDir tmp;
  std::filesystem::create_directories(tmp / "seq" / "lidar");
  std::filesystem::create_directories(tmp / "seq" / "camera");
  WriteFileAtomic(tmp / "seq" / "lidar" / "poses.json", "[{\"position\": {\"x\": 0}}]");
  WriteFileAtomic(tmp / "seq" / "lidar" / "timestamps.json", "[0.0]");
  WriteFileAtomic(tmp / "seq" / "lidar" / "00.pkl.gz", "not gzip");
  try {
    OpenLog(tmp / "seq");
    FAIL() << "accepted a pose without y, z and heading";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("poses.json"), std::string::npos) << e.what();
  }
}

// A derivative written the way synth writes it (one cone added, returns moved onto it, one image replaced) reads
// back through our reader and, row for row, through pandas.
TEST(PandaSet, DerivativeReadsBackAndPandasAgrees) {
  SD_REQUIRE_SHARED(dir, kSeq);
  const Log log = OpenLog(dir);
  const size_t fi = 6;  // frame "50"
  const Frame& f = log.frames[fi];
  FrameEdit e;
  e.frame_index = fi;
  AddedObject cone;
  cone.category = "traffic_cone";
  cone.annotation.box.T_frame_box = Rigid3d::FromYaw(0.3, Eigen::Vector3d(9.0, 1.5, 0.05));
  cone.annotation.box.size = Eigen::Vector3d(0.4, 0.4, 0.7);
  cone.annotation.instance_token = "synthdrive-plan:44:0:cone";
  e.added.push_back(cone);
  ImageU8 img = ReadImage(f.cameras[0].image_path, 3);
  for (int y = 500; y < 540; ++y)
    for (int x = 900; x < 940; ++x) img.pixel(x, y)[0] = 255;
  e.images[f.cameras[0].channel] = img;
  PointCloud pc = ReadLidar(*f.lidar);
  std::vector<int> moved = {3, 1000, 50000, 120000};
  std::string moved_list;
  for (int i : moved) {
    pc.xyz(static_cast<size_t>(i)) += Eigen::Vector3f(0.5f, -0.25f, 0.125f);
    pc.feature(static_cast<size_t>(i), 3) = 42.0f;
    e.point_objects.push_back({i, 0});
    moved_list += (moved_list.empty() ? "" : ",") + std::to_string(i);
  }
  e.points = pc;
  testing::TempDir tmp;
  const auto written = WriteDerivative(log, {e}, tmp.path());
  ASSERT_EQ(written.size(), 1u);
  EXPECT_EQ(written[0], tmp / "annotations" / "cuboids" / "50.pkl.gz");

  const Log back = OpenLog(tmp.path());
  ASSERT_EQ(back.frames.size(), 1u);
  const Frame& g = back.frames[0];
  EXPECT_EQ(g.token, "50");
  ASSERT_EQ(g.annotations.size(), f.annotations.size() + 1);
  const Annotation& a = g.annotations.back();
  EXPECT_EQ(a.category, "Cones");
  EXPECT_LT((a.box.center() - cone.annotation.box.center()).norm(), 1e-9);
  EXPECT_LT((a.box.size - cone.annotation.box.size).norm(), 1e-12);
  // PandaSet keeps only the yaw about world z: the ego frame's tilt against it (~1 degree) moves the yaw read back
  // in the ego frame by a few 1e-4 rad.
  EXPECT_LT(AngleDiff(a.box.Yaw(), 0.3), 2e-3);
  const PointCloud pb = ReadLidar(*g.lidar);
  ASSERT_EQ(pb.size(), pc.size());
  double worst_moved = 0;
  size_t differ = 0;
  for (size_t i = 0; i < pb.size(); ++i) {
    const bool is_moved = std::find(moved.begin(), moved.end(), static_cast<int>(i)) != moved.end();
    if (is_moved) worst_moved = std::max(worst_moved, static_cast<double>((pb.xyz(i) - pc.xyz(i)).norm()));
    else differ += std::memcmp(&pb.data[i * 6], &pc.data[i * 6], 6 * sizeof(float)) != 0;
  }
  EXPECT_LT(worst_moved, 1e-4);  // float32 in the sensor frame, float64 in the world frame on disk
  EXPECT_EQ(differ, 0u);
  EXPECT_GE(ReadImage(g.cameras[0].image_path, 3).pixel(920, 520)[0], 240);  // the replaced image (lossy JPEG)

  SD_REQUIRE_PANDAS_PYTHON();
  std::string output;
  EXPECT_EQ(testing::RunPython("tools/testing/pandaset_check.py",
                               {dir.string(), tmp.path().string(), "50", moved_list, "Cones", "37"}, &output), 0)
      << output;
}

}  // namespace
}  // namespace sd
