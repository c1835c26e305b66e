#include "render/lidar_cast.h"

#include <cmath>

#include <gtest/gtest.h>

#include "render/test_meshes.h"

namespace sd {
namespace {

// A plane z = -1.8 (the ground under a roof-mounted LiDAR) seen from the origin: a ray at angle theta from
// straight down has range h / cos(theta) and incidence cos(theta).
TEST(LidarCast, PlaneAtKnownRange) {
  const float h = 1.8f;
  RayScene scene;
  scene.AddMesh(testmesh::Quad({0, 0, -h}, {1, 0, 0}, {0, 1, 0}, 100, 100));  // faces +z
  scene.Commit();
  std::vector<Eigen::Vector3f> dirs;
  std::vector<float> thetas;
  for (int i = 0; i < 80; ++i) {
    const float theta = 0.018f * i;  // 0 .. 1.42 rad from nadir
    const float az = 0.37f * i;
    thetas.push_back(theta);
    dirs.emplace_back(std::sin(theta) * std::cos(az), std::sin(theta) * std::sin(az), -std::cos(theta));
  }
  dirs.emplace_back(0, 0, 1);  // up: miss
  const float max_range = 12.0f;
  const std::vector<LidarReturn> returns = CastLidarRays(scene, Eigen::Vector3f::Zero(), dirs, max_range);
  ASSERT_EQ(returns.size(), dirs.size());
  for (size_t i = 0; i < thetas.size(); ++i) {
    const float range = h / std::cos(thetas[i]);
    const LidarReturn& r = returns[i];
    if (range > max_range) {
      EXPECT_FALSE(r.hit) << i;
      continue;
    }
    ASSERT_TRUE(r.hit) << i;
    EXPECT_NEAR(r.range, range, 1e-5f * range) << i;
    EXPECT_NEAR(r.cos_incidence, std::cos(thetas[i]), 1e-5f) << i;
    EXPECT_NEAR(r.point.z(), -h, 1e-5f) << i;
    EXPECT_NEAR((r.point - range * dirs[i]).norm(), 0.0f, 1e-4f) << i;
    EXPECT_NEAR(r.normal.z(), 1.0f, 1e-6f) << i;
    EXPECT_EQ(r.mesh, 0);
    EXPECT_GE(r.face, 0);
  }
  EXPECT_FALSE(returns.back().hit);
  EXPECT_EQ(returns.back().mesh, -1);
}

// The normal faces the sensor even when the ray hits the back of a face.
TEST(LidarCast, BackFaceNormalFacesSensor) {
  RayScene scene;
  scene.AddMesh(testmesh::Quad({5, 0, 0}, {0, 1, 0}, {0, 0, 1}, 2, 2));  // faces +x, away from the origin
  scene.Commit();
  const Eigen::Vector3f dir = Eigen::Vector3f(1, 0.2f, 0).normalized();
  const auto r = CastLidarRays(scene, Eigen::Vector3f::Zero(), {dir}, 100.0f);
  ASSERT_TRUE(r[0].hit);
  EXPECT_NEAR(r[0].range, 5.0f / dir.x(), 1e-5f);
  EXPECT_NEAR(r[0].normal.x(), -1.0f, 1e-6f);
  EXPECT_NEAR(r[0].cos_incidence, dir.x(), 1e-6f);
}

}  // namespace
}  // namespace sd
