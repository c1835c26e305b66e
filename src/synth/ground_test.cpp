#include "synth/ground.h"

#include <cmath>
#include <cstdio>
#include <random>

#include <gtest/gtest.h>

#include "core/error.h"
#include "datasets/readers.h"
#include "testing/testing.h"

namespace sd {
namespace {

// A synthetic sweep: a road tilted by `slope` along x, kerbs of `kerb` metres at |y| > 4, a wall of points at
// y = 9, and a box-shaped obstacle on the road. Heights carry 5 mm of noise, a LiDAR's on the road (same-ring
// neighbours on the repo keyframe differ by 3-7 mm).
std::vector<Eigen::Vector3d> SyntheticScene(double slope, double kerb, double offset) {
  std::mt19937 rng(3);
  std::normal_distribution<double> noise(0.0, 0.005);
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

// A spinning 32-beam LiDAR (HDL-32E geometry: elevations -30.67..+10.67 deg, 0.2 deg azimuth steps, 1.84 m up,
// 1.5 cm range noise) over a road with a 1 % grade and a 2 % camber falling towards a kerb of `kerb` metres at
// y = -4.5 (the right), a flat pavement behind it, and the road falling 2 % to the left too from a crown at y = 0.
// Rays are cast analytically against the road and pavement planes and the kerb face.
std::vector<Eigen::Vector3d> SpinningLidarOverKerb(double kerb, uint32_t seed) {
  constexpr double kKerbY = -4.5;
  const Eigen::Vector3d o(0, 0, 1.84);
  std::mt19937 rng(seed);
  std::normal_distribution<double> noise(0.0, 0.015);
  std::vector<Eigen::Vector3d> pts;
  for (int ring = 0; ring < 32; ++ring) {
    const double el = (-30.67 + 1.333 * ring) * M_PI / 180.0;
    if (el >= 0) continue;
    for (double az = -180; az < 180; az += 0.2) {
      const double a = az * M_PI / 180.0;
      const Eigen::Vector3d d(std::cos(el) * std::cos(a), std::cos(el) * std::sin(a), std::sin(el));
      // Road: z = 0.01 x + s y, s = +0.02 right of the crown (y < 0) and -0.02 left of it.
      auto plane_hit = [&](double sx, double sy, double c) {
        return (c + sx * o.x() + sy * o.y() - o.z()) / (d.z() - sx * d.x() - sy * d.y());
      };
      double t = -1;
      for (const double sy : {0.02, -0.02}) {
        const double tr = plane_hit(0.01, sy, 0.0);
        const Eigen::Vector3d p = o + tr * d;
        if (tr > 0 && (sy > 0 ? p.y() <= 0 : p.y() >= 0) && p.y() >= kKerbY) t = tr;
      }
      if (t < 0 && d.y() < 0) {  // past the kerb line: the kerb face, or the pavement behind it
        const double tk = (kKerbY - o.y()) / d.y();
        const Eigen::Vector3d k = o + tk * d;
        const double pavement_top = 0.01 * k.x() + 0.02 * kKerbY + kerb;
        t = k.z() <= pavement_top ? tk : plane_hit(0.01, 0.0, 0.02 * kKerbY + kerb);
      }
      if (t <= 0 || t > 60) continue;
      pts.push_back(o + (t + noise(rng)) * d);
    }
  }
  return pts;
}

// How far a kerb of each height keeps objects off the pavement (the sensor's ring gaps grow with range, and a
// step hidden between two rings reads as a grade): no cone footprint (0.4 m square) standing wholly on the
// pavement within `seen_to` metres of the sensor passes placement's test (90 % drivable), and the road in front
// of the kerb is drivable. Without a kerb, the change of camber at the same line stops nothing.
TEST(Ground, LowKerbsKeepObjectsOffThePavementAndCamberDoesNot) {
  struct Case { double kerb, seen_to; };
  for (const Case c : {Case{0.0, 0}, Case{0.04, 10}, Case{0.06, 12}, Case{0.10, 20}}) {
    const GroundModel g = GroundModel::Estimate(SpinningLidarOverKerb(c.kerb, 7), {});
    int road = 0, road_drivable = 0, pavement = 0, pavement_drivable = 0;
    double nearest_cone = 1e9;
    for (double x = -20; x <= 20; x += 0.25) {
      if (x > -1.5 && x < 4.0) continue;  // beside the ego body, where no ring reaches the road
      for (double y = -10; y <= 4; y += 0.25) {
        if (std::abs(y + 4.5) < 0.5) continue;  // the half metre either side of the kerb
        const double range = std::hypot(x, y);
        if (range > 20) continue;
        const bool drivable = g.IsDrivable(x, y);
        if (y > -4.5) {
          ++road;
          road_drivable += drivable;
          continue;
        }
        if (range <= (c.kerb > 0 ? c.seen_to : 20.0)) {
          ++pavement;
          pavement_drivable += drivable;
        }
        const Box3 cone{Rigid3d(Eigen::Matrix3d::Identity(), Eigen::Vector3d(x, y, 0.35)), Eigen::Vector3d(0.4, 0.4, 0.7)};
        if (g.DrivableFraction(cone) >= 0.9) nearest_cone = std::min(nearest_cone, range);
      }
    }
    SCOPED_TRACE((Msg() << "kerb " << c.kerb << " m: nearest cone placeable on the pavement at " << nearest_cone << " m, "
                       << pavement_drivable << " of " << pavement << " pavement samples within " << c.seen_to << " m drivable").str());
    std::printf("kerb %.2f m: nearest cone placeable on the pavement at %.1f m (1e9: none within 20 m); drivable: %d of %d road samples, %d of %d pavement samples\n",
                c.kerb, nearest_cone, road_drivable, road, pavement_drivable, pavement);
    EXPECT_GT(road_drivable, 0.9 * road);
    if (c.kerb > 0) {
      EXPECT_GT(nearest_cone, c.seen_to);
      EXPECT_LT(pavement_drivable, 0.05 * pavement);
    } else {
      EXPECT_GT(pavement_drivable, 0.9 * pavement);
    }
  }
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
  GroundOptions options;
  options.sensor_xy = f.lidar->T_ego_lidar.translation.head<2>();
  const GroundModel g = GroundModel::Estimate(pts, boxes, options);
  EXPECT_NEAR(g.seed_plane().HeightAt(0, 0), 0.0, 0.15);
  EXPECT_GT(g.seed_plane().normal.z(), std::cos(5 * M_PI / 180));
  const auto s = g.SurfaceAt(8, 0);
  EXPECT_NEAR(s.height, 0.0, 0.2);
  EXPECT_GT(s.support, 8);
  EXPECT_TRUE(g.IsDrivable(6, 0));
  // The kerbs CAM_FRONT_LEFT shows: the painted 10 cm kerb 5.1 m to the left of the LiDAR, and the 20 cm one at
  // 8.2 m on the 45 degree ray; the road before them is drivable, the verge behind them is not.
  const Eigen::Vector2d lidar = options.sensor_xy;
  const auto at = [&](double azimuth_deg, double range) {
    const double a = azimuth_deg * M_PI / 180.0;
    return g.IsDrivable(lidar.x() + range * std::cos(a), lidar.y() + range * std::sin(a));
  };
  EXPECT_TRUE(at(90, 4.5));
  EXPECT_FALSE(at(90, 6.0));
  EXPECT_TRUE(at(45, 6.5));
  EXPECT_FALSE(at(45, 9.5));
  // No annotated object's points are ground.
  for (int i : g.ground_indices())
    for (const auto& b : boxes) ASSERT_FALSE(b.Contains(pts[i], 0.0));
  EXPECT_GT(g.ground_indices().size(), sweep.size() / 5);
}

}  // namespace
}  // namespace sd
