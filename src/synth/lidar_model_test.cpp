#include "synth/lidar_model.h"

#include <cmath>
#include <fstream>
#include <random>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "datasets/readers.h"
#include "synth/lidar_sim.h"
#include "testing/testing.h"

namespace sd {
namespace {

constexpr double kDeg = M_PI / 180.0;

PointCloud ReadRaw(const std::filesystem::path& file, std::vector<std::string> names) {
  std::ifstream in(file, std::ios::binary);
  PointCloud c;
  c.num_features = static_cast<int>(names.size());
  c.feature_names = std::move(names);
  in.seekg(0, std::ios::end);
  c.data.resize(static_cast<size_t>(in.tellg()) / 4);
  in.seekg(0);
  in.read(reinterpret_cast<char*>(c.data.data()), static_cast<std::streamsize>(c.data.size() * 4));
  return c;
}

struct NuScenesSweep {
  PointCloud sweep;
  LidarFitOptions fit;
};

NuScenesSweep RepoNuScenes() {
  const Log log = OpenLog(testing::RepoData("driving/nuscenes-scene0061-kf0/mmdet3d_info/n015-2018-07-24-11-22-45+0800.json"));
  const Frame& f = log.frames.at(0);
  NuScenesSweep s;
  s.sweep = ReadLidar(*f.lidar);
  const Rigid3d T_lidar_ego = f.lidar->T_ego_lidar.Inverse();
  for (const auto& a : f.annotations) s.fit.annotated.push_back({a.category, a.box.Transformed(T_lidar_ego)});
  return s;
}

const LidarModel& NuScenesModel() {
  static const LidarModel model = [] {
    const NuScenesSweep s = RepoNuScenes();
    return FitLidarModel(s.sweep, s.fit);
  }();
  return model;
}

TEST(LidarModel, NuScenesSweepGivesTheHdl32eBeamPatternAndTiming) {
  const LidarModel& m = NuScenesModel();
  std::cout << "nuScenes: " << m.Summary() << "\n";
  ASSERT_EQ(m.beams.size(), 32u);
  EXPECT_TRUE(m.rings_from_feature);
  // HDL-32E: -30.67 .. +10.67 deg in 4/3 deg steps.
  EXPECT_NEAR(m.beams.front().elevation / kDeg, -30.67, 0.15);
  EXPECT_NEAR(m.beams.back().elevation / kDeg, 10.67, 0.15);
  // Every laser within 0.35 deg of the spec grid (the sweep is motion-compensated, so its returns are not
  // exact cones; the worst laser, ring 7, is 0.31 deg off, the median error is below 0.1 deg).
  double max_err = 0;
  for (size_t k = 0; k < m.beams.size(); ++k) {
    const double err = std::abs(m.beams[k].elevation / kDeg - (-30.67 + 4.0 / 3.0 * static_cast<double>(k)));
    EXPECT_LT(err, 0.35) << k;
    max_err = std::max(max_err, err);
  }
  std::cout << "nuScenes max elevation error vs HDL-32E spec: " << max_err << " deg\n";
  // nuScenes rings are numbered bottom-up and fire in ring order.
  for (size_t k = 0; k < m.beams.size(); ++k) {
    EXPECT_EQ(m.beams[k].laser, static_cast<int>(k));
    EXPECT_EQ(m.beams[k].firing_position, static_cast<int>(k));
  }
  // 1084 firings per turn at 20 Hz (46.08 us firing cycle), clockwise.
  EXPECT_NEAR(m.firings_per_revolution, 1084, 3);
  EXPECT_NEAR(m.spin_hz, 20.0, 0.05);
  EXPECT_EQ(m.spin_direction, -1);
  // Range noise of a few cm; dropout a probability; intensity exponent and reflectivities positive.
  EXPECT_GT(m.RangeSigma(10), 0.005);
  EXPECT_LT(m.RangeSigma(10), 0.10);
  EXPECT_GT(m.noise_samples, 500);
  for (double p : m.dropout_probability) {
    EXPECT_GE(p, 0.0);
    EXPECT_LT(p, 0.5);
  }
  // Ground intensity hardly depends on incidence here (the sensor compensates range; measured n ~ -0.06):
  // the fitted power law explains the data better than Lambertian.
  EXPECT_GT(m.intensity_exponent, -0.5);
  EXPECT_LT(m.intensity_exponent, 1.5);
  EXPECT_LT(m.intensity_rms_log, m.intensity_rms_log_lambertian);
  EXPECT_GT(m.ground_reflectivity, 1.0);
  EXPECT_TRUE(m.category_reflectivity.count("car"));
  // The firing time follows the azimuth: a quarter turn clockwise from the start is a quarter period.
  EXPECT_NEAR(m.FiringTime(m.start_azimuth - M_PI / 2), 0.25 * m.SweepPeriod(), 1e-9);
}

void ExpectHdl64e(const LidarModel& m) {
  ASSERT_EQ(m.beams.size(), 64u);
  EXPECT_FALSE(m.rings_from_feature);
  // HDL-64E: +2.0 .. -24.8 deg (Velodyne spec), upper block ~1/3 deg, lower block ~1/2 deg apart.
  EXPECT_NEAR(m.beams.back().elevation / kDeg, 2.0, 0.25);
  EXPECT_NEAR(m.beams.front().elevation / kDeg, -24.8, 0.5);
  for (size_t k = 1; k < m.beams.size(); ++k) {
    const double d = (m.beams[k].elevation - m.beams[k - 1].elevation) / kDeg;
    EXPECT_GT(d, 0.15) << k;
    EXPECT_LT(d, 0.8) << k;
  }
  EXPECT_GT(m.RangeSigma(10), 0.002);
  EXPECT_LT(m.RangeSigma(10), 0.10);
}

TEST(LidarModel, KittiScanLinesAreRecoveredWithoutARingFeature) {
  for (const char* name : {"000000", "000001", "000002"}) {
    const PointCloud c = ReadRaw(testing::RepoData(std::string("driving/kitti-object/training/velodyne/") + name + ".bin"),
                                 {"x", "y", "z", "reflectance"});
    const LidarModel m = FitLidarModel(c);
    std::cout << "KITTI " << name << ": " << m.Summary() << "\n";
    ExpectHdl64e(m);
  }
}

TEST(LidarModel, SharedKittiScans) {
  SD_REQUIRE_SHARED(dir, "driving/kitti-object-openpcdet/training/velodyne");
  int n = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir)) {
    const LidarModel m = FitLidarModel(ReadRaw(e.path(), {"x", "y", "z", "reflectance"}));
    std::cout << "KITTI " << e.path().filename() << ": " << m.Summary() << "\n";
    ExpectHdl64e(m);
    ++n;
  }
  EXPECT_GE(n, 5);
}

TEST(LidarModel, SharedArgoverse2UpLidarIsAVlp32c) {
  SD_REQUIRE_SHARED(dir, "driving/argoverse2-av2-api/val/7fab2350-7eaf-3b7e-a39d-6937a4c1bede");
  std::ifstream cj(dir / "calibration/egovehicle_SE3_sensor.json");
  const nlohmann::json calib = nlohmann::json::parse(cj);
  Rigid3d T_ego_up;
  for (const auto& r : calib)
    if (r["sensor_name"] == "up_lidar")
      T_ego_up = Rigid3d::FromWxyz(r["qw"], r["qx"], r["qy"], r["qz"], Eigen::Vector3d(r["tx_m"], r["ty_m"], r["tz_m"]));
  int n = 0;
  for (const auto& e : std::filesystem::directory_iterator(dir / "sensors/lidar")) {
    if (e.path().string().find(".xyzil.f32.bin") == std::string::npos) continue;
    const PointCloud ego = ReadRaw(e.path(), {"x", "y", "z", "intensity", "laser_number"});
    // The converted sweep is in the ego frame and holds both lidars; lasers 0..31 are the upper one.
    PointCloud up = ego;
    up.data.clear();
    const Rigid3d T_up_ego = T_ego_up.Inverse();
    for (size_t i = 0; i < ego.size(); ++i) {
      if (ego.feature(i, 4) >= 32) continue;
      const Eigen::Vector3d p = T_up_ego * ego.xyz(i).cast<double>();
      const float rec[5] = {static_cast<float>(p.x()), static_cast<float>(p.y()), static_cast<float>(p.z()), ego.feature(i, 3), ego.feature(i, 4)};
      up.Append(rec);
    }
    const LidarModel m = FitLidarModel(up);
    std::cout << "AV2 up_lidar " << e.path().filename() << ": " << m.Summary() << "\n";
    ASSERT_EQ(m.beams.size(), 32u);
    // VLP-32C: -25 .. +15 deg, densest around the horizon (0.33 deg).
    EXPECT_NEAR(m.beams.front().elevation / kDeg, -25.0, 0.5);
    EXPECT_NEAR(m.beams.back().elevation / kDeg, 15.0, 0.5);
    double min_gap = 1e9;
    for (size_t k = 1; k < m.beams.size(); ++k) min_gap = std::min(min_gap, m.beams[k].elevation - m.beams[k - 1].elevation);
    EXPECT_NEAR(min_gap / kDeg, 0.33, 0.1);
    ++n;
  }
  EXPECT_EQ(n, 2);
}

// A synthetic raw sweep with known parameters: 16 lasers at -15..0 deg (1 deg apart) 1.8 m above flat
// ground, a cylindrical wall at 30 m, 0.2 deg azimuth step, clockwise at 10 Hz from azimuth pi, range noise
// 2 cm, 5 % dropout, intensity 50 cos^0.6, a per-point time feature in seconds.
TEST(LidarModel, FitRecoversTheParametersOfASyntheticSweep) {
  std::mt19937 rng(11);
  std::normal_distribution<double> noise(0.0, 0.02);
  std::uniform_real_distribution<double> u(0.0, 1.0);
  PointCloud c;
  c.num_features = 6;
  c.feature_names = {"x", "y", "z", "intensity", "ring", "time"};
  const int firings = 1800;
  for (int f = 0; f < firings; ++f) {
    const double t = 0.1 * f / firings;
    const double az = M_PI - 2 * M_PI * f / firings;
    for (int l = 0; l < 16; ++l) {
      const double el = (-15.0 + l) * kDeg;
      const Eigen::Vector3d d(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el));
      double r = d.z() < 0 ? -1.8 / d.z() : 1e9;
      double cosi = -d.z();
      if (r * std::cos(el) > 30.0) r = 30.0 / std::cos(el), cosi = std::cos(el);
      if (u(rng) < 0.05) continue;
      const double rn = r + noise(rng);
      const float rec[6] = {static_cast<float>(rn * d.x()), static_cast<float>(rn * d.y()), static_cast<float>(rn * d.z()),
                            static_cast<float>(50.0 * std::pow(cosi, 0.6)), static_cast<float>(l), static_cast<float>(t)};
      c.Append(rec);
    }
  }
  const LidarModel m = FitLidarModel(c);
  std::cout << "synthetic: " << m.Summary() << "\n";
  ASSERT_EQ(m.beams.size(), 16u);
  for (size_t k = 0; k < 16; ++k) EXPECT_NEAR(m.beams[k].elevation / kDeg, -15.0 + static_cast<double>(k), 0.02) << k;
  EXPECT_NEAR(m.azimuth_step / kDeg, 0.2, 1e-3);
  EXPECT_TRUE(m.timing_from_data);
  EXPECT_NEAR(m.spin_hz, 10.0, 0.01);
  EXPECT_EQ(m.spin_direction, -1);
  EXPECT_NEAR(std::remainder(m.start_azimuth - M_PI, 2 * M_PI), 0.0, 0.01);
  EXPECT_NEAR(m.RangeSigma(8), 0.02, 0.003);
  EXPECT_NEAR(m.DropoutProbability(8), 0.05, 0.015);
  EXPECT_NEAR(m.DropoutProbability(25), 0.05, 0.015);
  EXPECT_NEAR(m.intensity_exponent, 0.6, 0.05);
}

// A flat square target of half-size `half` metres facing -x at x = `x`, in the ego = LiDAR frame.
Asset WallAsset(double x, double half_y, double half_z, double z0) {
  Asset a;
  a.info.category = "barrier";
  a.mesh.positions = {Eigen::Vector3f(x, -half_y, z0 - half_z), Eigen::Vector3f(x, half_y, z0 - half_z),
                      Eigen::Vector3f(x, half_y, z0 + half_z), Eigen::Vector3f(x, -half_y, z0 + half_z)};
  a.mesh.faces = {Eigen::Vector3i(0, 1, 2), Eigen::Vector3i(0, 2, 3)};
  return a;
}

struct WallSetup {
  NuScenesSweep s = RepoNuScenes();
  Asset wall = WallAsset(12.0, 3.0, 1.0, 0.0);
  PlacedObject placed;
  LidarSimInput in;
  WallSetup() {
    placed.asset = &wall;
    in.sweep = &s.sweep;
    in.objects = {&placed};
    in.reference_intensity = {20.0f};
  }
};

TEST(LidarSim, FittedNoiseAndDropoutAreReproducedOnAFlatTarget) {
  const LidarModel& m = NuScenesModel();
  WallSetup w;
  // Truth without realism: every return on the wall lies on x = 12.
  const LidarSimResult exact = SimulateLidar(w.in);
  ASSERT_GT(exact.object_points.size(), 300u);
  for (const auto& [i, k] : exact.object_points) EXPECT_NEAR(exact.cloud.xyz(i).x(), 12.0f, 1e-3);

  LidarModel model = m;
  w.in.realism.model = &model;
  w.in.realism.noise = w.in.realism.dropout = true;
  std::vector<double> err;
  int dropped = 0, kept = 0;
  double expected_sigma = 0, expected_drop = 0;
  for (uint64_t seed = 1; seed <= 20; ++seed) {
    w.in.realism.seed = seed;
    const LidarSimResult r = SimulateLidar(w.in);
    for (const auto& [i, k] : r.object_points) {
      const Eigen::Vector3f p = r.cloud.xyz(i);
      const double true_range = 12.0 * p.norm() / p.x();
      err.push_back(p.norm() - true_range);
      expected_sigma += model.RangeSigma(true_range);
      expected_drop += model.DropoutProbability(true_range);
    }
    dropped += r.dropped;
    kept += static_cast<int>(r.object_points.size());
    EXPECT_EQ(r.moved + r.added, static_cast<int>(r.object_points.size()));
  }
  expected_sigma /= static_cast<double>(err.size());
  expected_drop /= static_cast<double>(err.size());
  double ss = 0, mean = 0;
  for (double e : err) mean += e;
  mean /= static_cast<double>(err.size());
  for (double e : err) ss += (e - mean) * (e - mean);
  const double sigma = std::sqrt(ss / static_cast<double>(err.size()));
  const double drop = static_cast<double>(dropped) / (dropped + kept);
  std::cout << "wall at 12 m: range sigma " << sigma << " (model " << expected_sigma << "), mean " << mean << ", dropout "
            << drop << " (model " << expected_drop << "), " << err.size() << " returns\n";
  EXPECT_NEAR(sigma, expected_sigma, 0.05 * expected_sigma);
  EXPECT_NEAR(mean, 0.0, 3 * expected_sigma / std::sqrt(static_cast<double>(err.size())) + 1e-4);
  const double n = dropped + kept;
  EXPECT_NEAR(drop, expected_drop, 4 * std::sqrt(expected_drop * (1 - expected_drop) / n) + 1e-3);

  // Same seed, same output.
  w.in.realism.seed = 7;
  const LidarSimResult a = SimulateLidar(w.in), b = SimulateLidar(w.in);
  EXPECT_EQ(a.cloud.data, b.cloud.data);
}

TEST(LidarSim, ModelIntensityIsReflectivityTimesCosinePower) {
  LidarModel model = NuScenesModel();
  model.category_reflectivity["barrier"] = 40.0;
  model.intensity_exponent = 1.7;
  WallSetup w;
  w.in.realism.model = &model;
  w.in.realism.intensity = true;
  const LidarSimResult r = SimulateLidar(w.in);
  ASSERT_GT(r.object_points.size(), 300u);
  for (const auto& [i, k] : r.object_points) {
    const Eigen::Vector3f p = r.cloud.xyz(i);
    const double c = p.x() / p.norm();  // the wall's normal is x
    EXPECT_NEAR(r.cloud.feature(i, 3), std::min(40.0 * std::pow(c, 1.7), static_cast<double>(model.intensity_max)), 1e-3);
  }
}

TEST(LidarSim, EgoMotionSkewsAWallAsTheRealSweepWould) {
  const LidarModel& model = NuScenesModel();
  WallSetup w;
  const LidarSimResult still = SimulateLidar(w.in);

  // Zero motion with the realism switches off except ego motion: bit-identical to today's output.
  w.in.realism.model = &model;
  w.in.realism.ego_motion = true;
  const LidarSimResult zero = SimulateLidar(w.in);
  EXPECT_EQ(zero.cloud.data, still.cloud.data);
  EXPECT_EQ(zero.object_points, still.object_points);

  // 10 m/s forward (towards the wall); reference = sweep start. A beam fired t seconds in meets the wall
  // (x = 12 in the reference frame) from x = v t, so the raw point lies at x = 12 - v t(azimuth).
  const double v = 10.0;
  const auto [start, end] = ConstantVelocitySweepPoses(Eigen::Vector3d(v, 0, 0), 0.0, model.SweepPeriod(), 0.0);
  EXPECT_NEAR((end.translation - start.translation).x(), v * model.SweepPeriod(), 1e-12);
  {
    // The same from two logged poses 0.5 s apart (world heading 30 deg, driving straight).
    const Rigid3d T_world_ref = Rigid3d::FromYaw(M_PI / 6, Eigen::Vector3d(100, 50, 0));
    const Rigid3d T_world_b = T_world_ref * Rigid3d::FromYaw(0.0, Eigen::Vector3d(v * 0.5, 0, 0));
    const auto [s2, e2] = SweepPosesFromEgoPoses(T_world_ref, T_world_ref, 0.0, T_world_b, 0.5, model.SweepPeriod(), 0.0);
    EXPECT_NEAR((s2.translation - start.translation).norm(), 0.0, 1e-9);
    EXPECT_NEAR((e2.translation - end.translation).norm(), 0.0, 1e-9);
    EXPECT_NEAR(e2.rotation.angularDistance(end.rotation), 0.0, 1e-9);
  }
  w.in.realism.T_ref_ego_start = start;
  w.in.realism.T_ref_ego_end = end;
  const LidarSimResult raw = SimulateLidar(w.in);
  ASSERT_GT(raw.object_points.size(), 300u);
  double min_x = 1e9, max_x = -1e9;
  for (const auto& [i, k] : raw.object_points) {
    const Eigen::Vector3f p = raw.cloud.xyz(i);
    const double t = model.FiringTime(std::atan2(p.y(), p.x()));
    EXPECT_NEAR(p.x(), 12.0 - v * t, 2e-3) << "t=" << t;
    min_x = std::min(min_x, static_cast<double>(p.x()));
    max_x = std::max(max_x, static_cast<double>(p.x()));
  }
  std::cout << "skew across the wall: " << (max_x - min_x) * 100 << " cm\n";
  EXPECT_GT(max_x - min_x, 0.02);  // the wall spans ~28 deg of azimuth: ~3.9 ms at 20 Hz, ~3.9 cm at 10 m/s

  // De-skewed output: back on the plane.
  w.in.realism.motion_compensated_output = true;
  const LidarSimResult comp = SimulateLidar(w.in);
  for (const auto& [i, k] : comp.object_points) EXPECT_NEAR(comp.cloud.xyz(i).x(), 12.0f, 2e-3);
}

}  // namespace
}  // namespace sd
