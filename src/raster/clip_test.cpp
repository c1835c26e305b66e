#include <gtest/gtest.h>

#include <random>
#include <vector>

#include "raster/raster.h"
#include "raster/test_util.h"

namespace sd::raster {
namespace {

PinholeCamera NuScenesLike() {
  Eigen::Matrix3d K;
  K << 1266.4, 0, 816.3, 0, 1266.4, 491.5, 0, 0, 1;
  return PinholeCamera::FromK(K, 1600, 900);
}

// u = (x/w + 1) W/2 must equal PinholeCamera::Project. The matrix is float, so the tolerance is float
// rounding of clip coordinates of size ~100 (ulp ~1e-5) scaled by W/2 / w: 2e-3 px over these depths.
TEST(ClipFromWorld, ReproducesPinholeProjection) {
  const PinholeCamera cam = NuScenesLike();
  std::mt19937 rng(1);
  std::uniform_real_distribution<double> unit(-1, 1), depth(1.0, 60.0);
  for (int trial = 0; trial < 20; ++trial) {
    const Rigid3d T_cam_world = testing::LookAtOrigin(rng, 5.0);
    const Eigen::Matrix4f M = ClipFromWorld(cam, T_cam_world, 0.5f, 80.f);
    const Rigid3d T_world_cam = T_cam_world.Inverse();
    for (int n = 0; n < 50; ++n) {
      const double Z = depth(rng);
      const Eigen::Vector3d p_cam(unit(rng) * Z, unit(rng) * Z * 0.6, Z);
      const Eigen::Vector3d p_world = T_world_cam * p_cam;
      std::vector<float> clip(4);
      TransformToClip(std::vector<float>{float(p_world.x()), float(p_world.y()), float(p_world.z())}, M, clip);
      const Eigen::Vector2d uv = *cam.Project(p_cam);
      EXPECT_NEAR((clip[0] / clip[3] + 1.0) * cam.width / 2, uv.x(), 2e-3);
      EXPECT_NEAR((clip[1] / clip[3] + 1.0) * cam.height / 2, uv.y(), 2e-3);
      EXPECT_NEAR(clip[3], Z, 1e-4 * Z);
    }
  }
}

TEST(ClipFromWorld, DepthMapsNearFarToMinusOneOne) {
  const PinholeCamera cam = NuScenesLike();
  const Eigen::Matrix4f M = ClipFromWorld(cam, Rigid3d(), 0.5f, 80.f);
  for (auto [Z, expected] : {std::pair{0.5f, -1.0f}, {80.f, 1.0f}}) {
    std::vector<float> clip(4);
    TransformToClip(std::vector<float>{0.3f, -0.2f, Z}, M, clip);
    EXPECT_NEAR(clip[2] / clip[3], expected, 1e-6);
  }
  // Monotone in between: nearer is smaller.
  std::vector<float> clip(8);
  TransformToClip(std::vector<float>{0, 0, 2.f, 0, 0, 3.f}, M, clip);
  EXPECT_LT(clip[2] / clip[3], clip[6] / clip[7]);
}

// The transform is linear, so the backward pass must match central differences to float rounding: with a
// step of 1e-2 on coordinates of size ~1 the FD error is rounding only (~1e-5 relative).
TEST(TransformToClip, BackwardMatchesFiniteDifferences) {
  std::mt19937 rng(2);
  std::uniform_real_distribution<float> unit(-1, 1);
  const Eigen::Matrix4f M = ClipFromWorld(testing::SquareCamera(64), testing::LookAtOrigin(rng, 3.0), 0.1f, 10.f);
  std::vector<float> positions(3 * 5), grad_clip(4 * 5);
  for (float& p : positions) p = unit(rng);
  for (float& g : grad_clip) g = unit(rng);
  std::vector<float> grad_positions(positions.size(), 0.5f);  // non-zero: checks accumulation
  TransformToClipBackward(M, grad_clip, grad_positions);
  auto loss = [&](const std::vector<float>& pos) {
    std::vector<float> clip(grad_clip.size());
    TransformToClip(pos, M, clip);
    double l = 0;
    for (size_t n = 0; n < clip.size(); ++n) l += double(clip[n]) * grad_clip[n];
    return l;
  };
  const float h = 1e-2f;
  for (size_t n = 0; n < positions.size(); ++n) {
    std::vector<float> plus = positions, minus = positions;
    plus[n] += h, minus[n] -= h;
    const double fd = (loss(plus) - loss(minus)) / (double(plus[n]) - minus[n]);
    EXPECT_NEAR(grad_positions[n] - 0.5f, fd, 1e-3 * (1 + std::abs(fd))) << n;
  }
}

}  // namespace
}  // namespace sd::raster
