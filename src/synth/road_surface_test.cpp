#include "synth/road_surface.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <iostream>
#include <set>

#include "core/error.h"
#include "datasets/categories.h"
#include "datasets/readers.h"
#include "testing/testing.h"

namespace sd {
namespace {

const char* kAv2Log = "driving/argoverse2-av2-api/val/7fab2350-7eaf-3b7e-a39d-6937a4c1bede";
const char* kKf0Info = "driving/nuscenes-scene0061-kf0/mmdet3d_info/n015-2018-07-24-11-22-45+0800.json";

double Median(std::vector<double> v) {
  if (v.empty()) return std::numeric_limits<double>::quiet_NaN();
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
  return v[v.size() / 2];
}

// Analytic scene: a plane tilted 3 % along x and 2 % along y; a 0.15 m kerb at y = 3 with the sidewalk
// beyond, a wall at y = 8, an annotated car standing on the road at (10, -3) hiding the road under it, and
// the ego at the origin (its body hides a 2.5 m disc).
constexpr double kKerbY = 3.0, kKerb = 0.15, kWallY = 8.0;
double TruthZ(double x, double y) { return 1.0 + 0.03 * x + 0.02 * y + (y >= kKerbY ? kKerb : 0.0); }

Box3 SyntheticCar() {
  Box3 car;
  car.size = Eigen::Vector3d(4.5, 2.0, 1.5);
  car.T_frame_box = Rigid3d::FromYaw(0.3, Eigen::Vector3d(10, -3, TruthZ(10, -3) + 0.75));
  return car;
}

SweepInWorld SyntheticSweep() {
  SweepInWorld sw;
  sw.sensor_origin = Eigen::Vector3d(0, 0, TruthZ(0, 0) + 1.8);
  const Box3 car = SyntheticCar();
  sw.objects.push_back(car);
  uint32_t state = 12345;
  auto noise = [&] {  // deterministic +-5 mm
    state = state * 1664525u + 1013904223u;
    return (static_cast<double>(state >> 8) / static_cast<double>(1u << 24) - 0.5) * 0.01;
  };
  for (int i = 0; i <= 500; ++i)
    for (int j = 0; j <= 180; ++j) {
      const double x = -20 + 0.1 * i, y = -10 + 0.1 * j;
      const Eigen::Vector3d p(x, y, TruthZ(x, y) + noise());
      // The car hides the road under it (and a little around it: the grown box).
      if (car.Contains(Eigen::Vector3d(x, y, car.center().z()), 0.0)) continue;
      sw.points.push_back(p);
    }
  // The car's sides and roof (annotated: never ground).
  for (double u = -2.25; u <= 2.25; u += 0.1)
    for (double w = -0.75; w <= 0.75; w += 0.1) {
      sw.points.push_back(car.T_frame_box * Eigen::Vector3d(u, -1.0, w));
      sw.points.push_back(car.T_frame_box * Eigen::Vector3d(u, 0, 0.75));
    }
  // The wall (not annotated), from the ground up.
  for (int i = 0; i <= 500; ++i)
    for (int k = 0; k <= 30; ++k) {
      const double x = -20 + 0.1 * i;
      sw.points.emplace_back(x, kWallY + 0.05, TruthZ(x, kWallY) + 0.1 * k);
    }
  return sw;
}

TEST(RoadSurface, SyntheticPlaneKerbOccluderFillAndDrivable) {
  const SweepInWorld sweep = SyntheticSweep();
  const RoadSurface surface = RoadSurface::Build({sweep});
  const Box3 car = SyntheticCar();
  int checked = 0, under_car = 0, ego_filled = 0;
  for (int iy = 0; iy < surface.ny(); ++iy)
    for (int ix = 0; ix < surface.nx(); ++ix) {
      const Eigen::Vector2d xy = surface.CellCentre(ix, iy);
      if (xy.x() < -15 || xy.x() > 25 || xy.y() < -8 || xy.y() > kWallY - 0.5) continue;
      const auto sp = surface.At(xy);
      ASSERT_TRUE(sp) << xy.transpose();
      ++checked;
      const bool near_kerb = std::abs(xy.y() - kKerbY) <= 1.0;
      if (!near_kerb) {
        EXPECT_NEAR(sp->height, TruthZ(xy.x(), xy.y()), 0.01) << xy.transpose();
        EXPECT_NEAR(sp->normal.x(), -0.03, 0.01) << xy.transpose();
        EXPECT_NEAR(sp->normal.y(), -0.02, 0.01) << xy.transpose();
        // Exactly the road side of the kerb is drivable.
        EXPECT_EQ(surface.IsDrivable(xy), xy.y() < kKerbY) << xy.transpose();
      }
      const Eigen::Vector3d in_car = car.T_frame_box.Inverse() * Eigen::Vector3d(xy.x(), xy.y(), car.center().z());
      if (std::abs(in_car.x()) < 2.0 && std::abs(in_car.y()) < 0.8) {
        ++under_car;
        EXPECT_FALSE(sp->observed) << xy.transpose();
        EXPECT_TRUE(surface.IsDrivable(xy)) << xy.transpose();
      }
      if (xy.norm() < 2.0) {
        ++ego_filled;
        EXPECT_FALSE(sp->observed);
      }
    }
  EXPECT_GT(checked, 3000);
  EXPECT_GT(under_car, 30);
  EXPECT_GT(ego_filled, 50);
  // Beyond the wall nothing was measured; the wall above its foot (band + inlier) is not ground.
  EXPECT_FALSE(surface.At(Eigen::Vector2d(0, kWallY + 3)));
  const std::vector<int>& ground = surface.ground_indices()[0];
  const std::set<int> ground_set(ground.begin(), ground.end());
  for (size_t i = 0; i < sweep.points.size(); ++i) {
    const Eigen::Vector3d& p = sweep.points[i];
    if (p.z() > TruthZ(p.x(), std::min(p.y(), kWallY)) + 0.2) {
      EXPECT_FALSE(ground_set.count(static_cast<int>(i))) << p.transpose();
    }
  }
  EXPECT_LT(surface.stats().median_abs_residual, 0.004);

  // A map raster (Argoverse 2 Sim(2) convention, 2 px per metre) that says only x < 5 is drivable.
  RoadSurface narrowed = surface;
  const Eigen::Affine2d T_pixel_world = RoadSurface::Sim2ToAffine(2.0, Eigen::Matrix2d::Identity(), Eigen::Vector2d(25, 15));
  std::vector<uint8_t> raster(100 * 60, 0);
  for (int r = 0; r < 60; ++r)
    for (int c = 0; c < 100; ++c) raster[static_cast<size_t>(r * 100 + c)] = (c / 2.0 - 25 < 5) ? 1 : 0;
  EXPECT_GT(narrowed.IntersectDrivableRaster(raster, 100, 60, T_pixel_world), 0u);
  EXPECT_TRUE(narrowed.IsDrivable(Eigen::Vector2d(0.1, -5.1)));
  EXPECT_FALSE(narrowed.IsDrivable(Eigen::Vector2d(10.1, -6.1)));
  EXPECT_TRUE(surface.IsDrivable(Eigen::Vector2d(10.1, -6.1)));
}

TEST(RoadSurface, RefusesInputWithoutGround) {
  EXPECT_THROW(RoadSurface::Build({}), InputError);
  SweepInWorld wall;  // a vertical wall only: no ground plane to seed from
  for (int i = 0; i < 100; ++i)
    for (int k = 0; k < 30; ++k) wall.points.emplace_back(5.0, -5 + 0.1 * i, 0.1 * k);
  EXPECT_THROW(RoadSurface::Build({wall}), InputError);
}

struct BoxBottomFit {
  std::vector<double> errors;  // |box bottom z - surface height| at the footprint centre
  int without_surface = 0;
};

BoxBottomFit BoxBottoms(const RoadSurface& surface, const std::vector<Box3>& boxes, double max_range,
                        const Eigen::Vector3d& sensor) {
  BoxBottomFit fit;
  for (const Box3& b : boxes) {
    if ((b.center() - sensor).head<2>().norm() > max_range) continue;
    const Eigen::Vector3d bottom = b.T_frame_box * Eigen::Vector3d(0, 0, -0.5 * b.size.z());
    const auto sp = surface.At(bottom.head<2>());
    if (!sp) {
      ++fit.without_surface;
      continue;
    }
    fit.errors.push_back(std::abs(bottom.z() - sp->height));
  }
  return fit;
}

TEST(RoadSurface, Argoverse2TwoSweeps) {
  SD_REQUIRE_SHARED(dir, kAv2Log);
  const Log log = ReadArgoverse2(dir);
  const std::vector<SweepInWorld> sweeps = SweepsFromLog(log, 0, log.frames.size());
  ASSERT_EQ(sweeps.size(), 2u);
  ASSERT_EQ(sweeps[0].objects.size(), 81u);
  const RoadSurface surface = RoadSurface::Build(sweeps);
  const auto& st = surface.stats();
  std::cout << "AV2: ground points " << st.ground_points << ", observed cells " << st.observed_cells << ", filled "
            << st.filled_cells << ", drivable " << st.drivable_cells << ", median residual "
            << st.median_abs_residual * 100 << " cm\n";
  EXPECT_LT(st.median_abs_residual, 0.03);
  EXPECT_GT(st.ground_points, 25000u);  // of 198,695 points: most returns are buildings, vegetation and vehicles

  // The two sweeps' own surfaces agree where both observed the road.
  const RoadSurface s0 = RoadSurface::Build({sweeps[0]});
  const RoadSurface s1 = RoadSurface::Build({sweeps[1]});
  std::vector<double> diffs;
  for (int iy = 0; iy < surface.ny(); ++iy)
    for (int ix = 0; ix < surface.nx(); ++ix) {
      const Eigen::Vector2d xy = surface.CellCentre(ix, iy);
      const auto a = s0.At(xy), b = s1.At(xy);
      if (a && b && a->observed && b->observed) diffs.push_back(std::abs(a->height - b->height));
    }
  const double overlap = Median(diffs);
  std::cout << "AV2: sweep overlap cells " << diffs.size() << ", median |h0 - h1| " << overlap * 100 << " cm\n";
  EXPECT_GT(diffs.size(), 1000u);
  EXPECT_LT(overlap, 0.02);  // measured 1.1 cm over 1,294 cells

  // Annotated boxes stand on the surface.
  const BoxBottomFit fit = BoxBottoms(surface, sweeps[0].objects, 40.0, sweeps[0].sensor_origin);
  const double box_median = Median(fit.errors);
  std::cout << "AV2: box bottoms within 40 m: " << fit.errors.size() << " on the surface, " << fit.without_surface
            << " off it, median |bottom - surface| " << box_median * 100 << " cm\n";
  EXPECT_GT(fit.errors.size(), 30u);
  EXPECT_LT(box_median, 0.08);  // measured 5.4 cm over 31 boxes

  // Holes filled under vehicles within 25 m: the road under them has heights, marked not observed.
  int samples = 0, with_height = 0, unobserved = 0;
  const Frame* f0 = nullptr;
  for (const Frame& f : log.frames)
    if (f.lidar) {
      f0 = &f;
      break;
    }
  ASSERT_TRUE(f0);
  for (const Annotation& a : f0->annotations) {
    const auto cat = FindCategory(a.category);
    if (!cat || (cat->name != "car" && cat->name != "truck")) continue;
    if (a.box.center().head<2>().norm() > 25.0) continue;
    const Box3 world = a.box.Transformed(f0->T_world_ego);
    for (double u = -0.5 * world.size.x() + 0.3; u <= 0.5 * world.size.x() - 0.3; u += 0.3)
      for (double v = -0.5 * world.size.y() + 0.3; v <= 0.5 * world.size.y() - 0.3; v += 0.3) {
        const Eigen::Vector3d p = world.T_frame_box * Eigen::Vector3d(u, v, 0);
        const auto sp = surface.At(p.head<2>());
        ++samples;
        with_height += sp.has_value();
        unobserved += sp && !sp->observed;
      }
  }
  std::cout << "AV2: under vehicles within 25 m: " << samples << " samples, " << with_height << " with a height, "
            << unobserved << " filled\n";
  EXPECT_GT(samples, 100);
  EXPECT_GT(with_height, 0.95 * samples);
  EXPECT_GT(unobserved, 0.9 * samples);

  // The ego trajectory is drivable; so is the road under most vehicles, while most pedestrians are not on it.
  for (const SweepInWorld& sw : sweeps) EXPECT_TRUE(surface.IsDrivable(sw.sensor_origin.head<2>()));
  int vehicles = 0, vehicles_drivable = 0, pedestrians = 0, pedestrians_drivable = 0;
  for (const Annotation& a : f0->annotations) {
    if (a.box.center().head<2>().norm() > 30.0) continue;
    const auto cat = FindCategory(a.category);
    const bool drivable = surface.IsDrivable((f0->T_world_ego * a.box.center()).head<2>());
    if (cat && (cat->name == "car" || cat->name == "truck" || cat->name == "bus")) {
      ++vehicles;
      vehicles_drivable += drivable;
    } else if (cat && cat->name == "pedestrian") {
      ++pedestrians;
      pedestrians_drivable += drivable;
    }
  }
  std::cout << "AV2: within 30 m, vehicles on drivable cells " << vehicles_drivable << "/" << vehicles
            << ", pedestrians " << pedestrians_drivable << "/" << pedestrians << "\n";
  EXPECT_GE(vehicles, 10);
  EXPECT_GE(vehicles_drivable, 0.6 * vehicles);  // measured 10 / 15: parked cars beside a kerb may fall off it
}

TEST(RoadSurface, NuScenesKeyframeBoxBottoms) {
  const Log log = OpenLog(testing::RepoData(kKf0Info));
  const std::vector<SweepInWorld> sweeps = SweepsFromLog(log, 0, 1);
  ASSERT_EQ(sweeps.size(), 1u);
  const RoadSurface surface = RoadSurface::Build(sweeps);
  const BoxBottomFit fit = BoxBottoms(surface, sweeps[0].objects, 40.0, sweeps[0].sensor_origin);
  const double box_median = Median(fit.errors);
  std::cout << "nuScenes kf0: median residual " << surface.stats().median_abs_residual * 100 << " cm; box bottoms "
            << fit.errors.size() << " on the surface, " << fit.without_surface << " off it, median |bottom - surface| "
            << box_median * 100 << " cm\n";
  EXPECT_LT(surface.stats().median_abs_residual, 0.03);
  EXPECT_GT(fit.errors.size(), 20u);
  EXPECT_LT(box_median, 0.08);  // measured 4.5 cm over 26 boxes
  EXPECT_TRUE(surface.IsDrivable(sweeps[0].sensor_origin.head<2>()));
}

}  // namespace
}  // namespace sd
