#include "synth/ground.h"

#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "datasets/readers.h"
#include "testing/testing.h"

namespace sd {
namespace {

// A synthetic sweep: a road tilted by `slope` along x, kerbs of `kerb` metres at |y| > 4, a wall of points at
// y = 9, and a box-shaped obstacle on the road.
std::vector<Eigen::Vector3d> SyntheticScene(double slope, double kerb, double offset) {
  std::mt19937 rng(3);
  std::normal_distribution<double> noise(0.0, 0.01);
  std::vector<Eigen::Vector3d> pts;
  for (double x = -30; x <= 40; x += 0.25)
    for (double y = -12; y <= 12; y += 0.25) {
      double z = offset + slope * x + noise(rng);
      if (std::abs(y) > 4) z += kerb;
      pts.emplace_back(x, y, z);
    }
  for (double x = -30; x <= 40; x += 0.3)
    for (double z = 0; z < 3; z += 0.2) pts.emplace_back(x, 9.0, offset + slope * x + kerb + z);  // wall
  for (double x = 14; x <= 18; x += 0.1)
    for (double z = 0.3; z < 1.5; z += 0.1) pts.emplace_back(x, 1.0, offset + slope * x + z);  // car side
  return pts;
}

TEST(Ground, RecoversTiltedRoadHeightAndNormal) {
  const double slope = 0.03;  // 1.7 degrees
  const auto pts = SyntheticScene(slope, 0.15, -0.2);
  const GroundModel g = GroundModel::Estimate(pts, {});
  for (double x : {5.0, 15.0, 25.0}) {
    const auto s = g.SurfaceAt(x, -2.0);
    EXPECT_NEAR(s.height, -0.2 + slope * x, 0.02) << "x=" << x;
    const double expected_tilt = std::atan(slope);
    EXPECT_NEAR(std::acos(s.normal.z()), expected_tilt, 0.5 * M_PI / 180.0);
    EXPECT_GT(s.support, 8);
  }
}

TEST(Ground, KerbStopsTheDrivableArea) {
  const GroundModel g = GroundModel::Estimate(SyntheticScene(0.0, 0.15, 0.0), {});
  EXPECT_TRUE(g.IsDrivable(10, 0));
  EXPECT_TRUE(g.IsDrivable(30, 3));
  EXPECT_FALSE(g.IsDrivable(10, 6));    // pavement behind the kerb
  EXPECT_FALSE(g.IsDrivable(10, -7));
}

TEST(Ground, ObstaclePointsAreNotGround) {
  const auto pts = SyntheticScene(0.0, 0.15, 0.0);
  const GroundModel g = GroundModel::Estimate(pts, {});
  for (int i : g.ground_indices()) EXPECT_LT(std::abs(pts[i].z() - (std::abs(pts[i].y()) > 4 ? 0.15 : 0.0)), 0.1);
  EXPECT_NEAR(g.HeightAboveGround(Eigen::Vector3d(16, 1.0, 1.0)), 1.0, 0.05);
}

TEST(Ground, TooFewPointsIsAnError) {
  std::vector<Eigen::Vector3d> pts = {{5, 0, 0}, {6, 0, 0}};
  EXPECT_THROW(GroundModel::Estimate(pts, {}), InputError);
}

// On the real nuScenes keyframe: the ego origin is the rear axle projected on the ground, so the road
// right around the car is at z ~ 0, and the ground is nearly level.
TEST(Ground, NuScenesKeyframeRoadIsAtEgoZeroAndLevel) {
  const Log log = OpenLog(testing::RepoData("driving/nuscenes-scene0061-kf0/mmdet3d_info/n015-2018-07-24-11-22-45+0800.json"));
  const Frame& f = log.frames.at(0);
  const PointCloud sweep = ReadLidar(*f.lidar);
  std::vector<Eigen::Vector3d> pts;
  for (size_t i = 0; i < sweep.size(); ++i) pts.push_back(f.lidar->T_ego_lidar * sweep.xyz(i).cast<double>());
  std::vector<Box3> boxes;
  for (const auto& a : f.annotations) boxes.push_back(a.box);
  const GroundModel g = GroundModel::Estimate(pts, boxes);
  EXPECT_NEAR(g.seed_plane().HeightAt(0, 0), 0.0, 0.15);
  EXPECT_GT(g.seed_plane().normal.z(), std::cos(5 * M_PI / 180));
  const auto s = g.SurfaceAt(8, 0);
  EXPECT_NEAR(s.height, 0.0, 0.2);
  EXPECT_GT(s.support, 8);
  EXPECT_TRUE(g.IsDrivable(6, 0));
  // No annotated object's points are ground.
  for (int i : g.ground_indices())
    for (const auto& b : boxes) ASSERT_FALSE(b.Contains(pts[i], 0.0));
  EXPECT_GT(g.ground_indices().size(), sweep.size() / 5);
}

}  // namespace
}  // namespace sd
