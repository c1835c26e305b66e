#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <iomanip>
#include <numbers>
#include <set>

#include "core/error.h"

#include "datasets/categories.h"
#include "datasets/readers.h"
#include "io/files.h"
#include "testing/testing.h"

namespace sd {
namespace {

const char* kAv2Log = "driving/argoverse2-av2-api/val/7fab2350-7eaf-3b7e-a39d-6937a4c1bede";
constexpr int64_t kSweep0 = 315966265259836000;
constexpr int64_t kSweep1 = 315966265360032000;

TEST(Argoverse2, FramesAreSweepsAndAnnotatedTimestamps) {
  SD_REQUIRE_SHARED(dir, kAv2Log);
  const Log log = OpenLog(dir);  // probed
  EXPECT_EQ(log.format, LogFormat::kArgoverse2);
  ASSERT_EQ(log.frames.size(), 156u);
  size_t boxes = 0, with_lidar = 0;
  std::set<std::string> tracks;
  for (size_t i = 0; i < log.frames.size(); ++i) {
    const Frame& f = log.frames[i];
    EXPECT_TRUE(f.has_annotations);
    EXPECT_TRUE(f.cameras.empty());
    if (i > 0) {
      EXPECT_GT(f.timestamp, log.frames[i - 1].timestamp);
    }
    boxes += f.annotations.size();
    for (const Annotation& a : f.annotations) tracks.insert(a.instance_token);
    if (f.lidar) {
      ++with_lidar;
      EXPECT_TRUE(f.token == std::to_string(kSweep0) || f.token == std::to_string(kSweep1)) << f.token;
      EXPECT_NEAR(f.lidar->T_ego_lidar.translation.norm(), 0.0, 1e-12);
      EXPECT_EQ(f.lidar->layout.num_features, 5);
    }
  }
  EXPECT_EQ(boxes, 11364u);
  EXPECT_EQ(tracks.size(), 114u);
  EXPECT_EQ(with_lidar, 2u);
  // Forcing the format reads the same log.
  OpenLogOptions forced;
  forced.format = LogFormat::kArgoverse2;
  EXPECT_EQ(OpenLog(dir, forced).frames.size(), 156u);
}

TEST(Argoverse2, BoxesContainExactlyTheirInteriorPoints) {
  SD_REQUIRE_SHARED(dir, kAv2Log);
  const Log log = ReadArgoverse2(dir);
  const auto it = std::find_if(log.frames.begin(), log.frames.end(),
                               [](const Frame& f) { return f.token == std::to_string(kSweep0); });
  ASSERT_NE(it, log.frames.end());
  ASSERT_TRUE(it->lidar);
  const PointCloud pc = ReadLidar(*it->lidar);
  EXPECT_EQ(pc.size(), 99229u);
  ASSERT_EQ(it->annotations.size(), 81u);
  int mapped = 0;
  for (const Annotation& a : it->annotations) {
    int inside = 0;
    for (size_t i = 0; i < pc.size(); ++i) inside += a.box.Contains(it->lidar->T_ego_lidar * pc.xyz(i).cast<double>());
    EXPECT_EQ(inside, a.num_lidar_pts) << a.category << " " << a.instance_token;
    mapped += FindCategory(a.category).has_value();
    EXPECT_GT(a.box.size.x(), 0);
  }
  EXPECT_GT(mapped, 40);  // vehicles and pedestrians map to canonical classes
}

TEST(Argoverse2, PosesInterpolateContinuously) {
  SD_REQUIRE_SHARED(dir, kAv2Log);
  const Log log = ReadArgoverse2(dir);
  // Consecutive frames (~0.1 s apart) move the ego by less than 3 m and turn it by less than 5 degrees; the
  // ego z axis stays near world up.
  for (size_t i = 1; i < log.frames.size(); ++i) {
    const Rigid3d& a = log.frames[i - 1].T_world_ego;
    const Rigid3d& b = log.frames[i].T_world_ego;
    const double dt = log.frames[i].timestamp - log.frames[i - 1].timestamp;
    EXPECT_LT((b.translation - a.translation).norm(), 30.0 * dt + 1e-3) << i;
    EXPECT_LT(a.rotation.angularDistance(b.rotation), 0.9 * dt + 1e-4) << i;
    EXPECT_GT((a.rotation * Eigen::Vector3d::UnitZ()).z(), 0.98);
  }
  // The first pose row of the table: 315966253572412942 -> (5172.668, 2419.103, 66.930). The first frame
  // (315966253660357000) is 88 ms later: within 2 m of it, and interpolation midway between two sweeps'
  // poses lies between them.
  EXPECT_NEAR((log.frames.front().T_world_ego.translation - Eigen::Vector3d(5172.668, 2419.103, 66.930)).norm(), 0, 2.0);
  const Frame* f0 = nullptr;
  const Frame* f1 = nullptr;
  for (const Frame& f : log.frames) {
    if (f.token == std::to_string(kSweep0)) f0 = &f;
    if (f.token == std::to_string(kSweep1)) f1 = &f;
  }
  ASSERT_TRUE(f0 && f1);
  // The ego's boxes of a static object (same track) map to nearly the same world position in both sweeps.
  int static_pairs = 0;
  for (const Annotation& a0 : f0->annotations)
    for (const Annotation& a1 : f1->annotations)
      if (a0.instance_token == a1.instance_token && a0.category == "BOLLARD") {
        const Eigen::Vector3d w0 = f0->T_world_ego * a0.box.center();
        const Eigen::Vector3d w1 = f1->T_world_ego * a1.box.center();
        EXPECT_LT((w0 - w1).norm(), 0.25) << a0.instance_token;
        ++static_pairs;
      }
  EXPECT_GT(static_pairs, 0);
}

// A two-pose log written here pins the interpolation and the frame rules exactly.
TEST(Argoverse2, InterpolatesPosesAndKeepsFramesWithoutSweeps) {
  const testing::TempDir dir;
  const double s = std::sqrt(0.5);
  WriteFileAtomic(dir / "city_SE3_egovehicle.json",
                  (Msg() << std::setprecision(17) << R"([{"timestamp_ns":1000000000,"qw":)" << s
                         << R"(,"qx":0,"qy":0,"qz":)" << s << R"(,"tx_m":10,"ty_m":0,"tz_m":2},)"
                         << R"({"timestamp_ns":0,"qw":1,"qx":0,"qy":0,"qz":0,"tx_m":0,"ty_m":0,"tz_m":0}])")
                      .str());
  WriteFileAtomic(dir / "annotations.json",
                  R"([{"timestamp_ns":500000000,"track_uuid":"t1","category":"REGULAR_VEHICLE","length_m":4,)"
                  R"("width_m":2,"height_m":1.5,"qw":1,"qx":0,"qy":0,"qz":0,"tx_m":5,"ty_m":1,"tz_m":0.75,)"
                  R"("num_interior_pts":7}])");
  std::filesystem::create_directories(dir / "sensors" / "lidar");
  const float rec[5] = {1, 2, 3, 40, 5};
  WriteFileAtomic(dir / "sensors" / "lidar" / "250000000.xyzil.f32.bin",
                  std::string(reinterpret_cast<const char*>(rec), sizeof rec));
  const Log log = OpenLog(dir.path());
  EXPECT_EQ(log.format, LogFormat::kArgoverse2);
  ASSERT_EQ(log.frames.size(), 2u);
  const Frame& sweep = log.frames[0];
  const Frame& annotated = log.frames[1];
  EXPECT_EQ(sweep.token, "250000000");
  ASSERT_TRUE(sweep.lidar);
  EXPECT_FALSE(sweep.has_annotations);
  EXPECT_EQ(ReadLidar(*sweep.lidar).size(), 1u);
  EXPECT_EQ(annotated.token, "500000000");
  EXPECT_FALSE(annotated.lidar);
  EXPECT_NEAR(annotated.timestamp, 0.5, 1e-12);
  // Halfway: translation (5, 0, 1), yaw 45 degrees; a quarter: (2.5, 0, 0.5), yaw 22.5 degrees.
  EXPECT_NEAR((annotated.T_world_ego.translation - Eigen::Vector3d(5, 0, 1)).norm(), 0, 1e-9);
  EXPECT_NEAR(annotated.T_world_ego.Yaw(), std::numbers::pi / 4, 1e-9);
  EXPECT_NEAR((sweep.T_world_ego.translation - Eigen::Vector3d(2.5, 0, 0.5)).norm(), 0, 1e-9);
  EXPECT_NEAR(sweep.T_world_ego.Yaw(), std::numbers::pi / 8, 1e-9);
  ASSERT_EQ(annotated.annotations.size(), 1u);
  const Annotation& a = annotated.annotations[0];
  EXPECT_EQ(a.category, "REGULAR_VEHICLE");
  EXPECT_EQ(a.instance_token, "t1");
  EXPECT_EQ(a.num_lidar_pts, 7);
  EXPECT_NEAR((a.box.center() - Eigen::Vector3d(5, 1, 0.75)).norm(), 0, 1e-12);
  EXPECT_NEAR((a.box.size - Eigen::Vector3d(4, 2, 1.5)).norm(), 0, 1e-12);
}

TEST(Argoverse2, MissingPosesIsAnInputErrorNamingTheDirectory) {
  const testing::TempDir dir;
  try {
    ReadArgoverse2(dir.path());
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find(dir.path().string()), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("city_SE3_egovehicle.json"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace sd
