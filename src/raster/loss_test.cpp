// The per-pixel loss ops (loss.h) on host buffers: their gradients against finite differences, which pixels
// have a term, and that sums accumulate; and the buffers' own contract (buffer.h) on the host.
#include "raster/loss.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>
#include <vector>

#include "core/error.h"
#include "raster/raster.h"

namespace sd::raster {
namespace {

// A 4x2 raster whose pixels 0..5 are covered and 6, 7 are background.
RasterBuffer SmallRaster() {
  RasterBuffer rast;
  rast.width = 4, rast.height = 2;
  rast.bary.assign(16, 0.25f);
  rast.depth.assign(8, 0.5f);
  rast.triangle = std::vector<int32_t>{0, 0, 0, 1, 1, 1, -1, -1};
  return rast;
}

TEST(Coverage, IsOneWhereATriangleCoversThePixel) {
  const RasterBuffer rast = SmallRaster();
  std::vector<float> out(8, 7.0f);
  Coverage(rast, out);
  EXPECT_EQ(out, (std::vector<float>{1, 1, 1, 1, 1, 1, 0, 0}));
}

TEST(UnitVectorLoss, GradientMatchesFiniteDifferencesAndTermsFollowTheMasks) {
  const RasterBuffer rast = SmallRaster();
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> unit(-1, 1);
  std::vector<float> prediction(24), target(24), mask{1, 1, 1, 0.4f, 1, 1, 1, 1};
  for (float& p : prediction) p = unit(rng);
  for (size_t p = 0; p < 8; ++p) {
    const Eigen::Vector3f t = Eigen::Vector3f(unit(rng), unit(rng), unit(rng)).normalized();
    for (int c = 0; c < 3; ++c) target[3 * p + c] = t[c];
  }
  for (int c = 0; c < 3; ++c) target[3 * 2 + c] = 0;  // pixel 2: no target normal
  const float scale = 0.5f;
  auto loss = [&](const std::vector<float>& pred) {
    std::vector<float> grad(24);
    std::vector<double> sum{0.0};
    UnitVectorLoss({pred, rast, target, mask}, scale, grad, sum);
    return sum[0];
  };
  std::vector<float> grad(24, 9.0f);  // overwritten
  std::vector<double> sum{1.0};       // accumulated
  UnitVectorLoss({prediction, rast, target, mask}, scale, grad, sum);
  EXPECT_NEAR(sum[0] - 1.0, loss(prediction), 1e-12);
  // Terms only at covered pixels inside the mask with a target: 0, 1, 4, 5 (2: no target, 3: mask 0.4,
  // 6 and 7: background).
  double expected = 0;
  for (int p : {0, 1, 4, 5}) {
    const Eigen::Vector3f n = Eigen::Vector3f(&prediction[3 * p]).normalized();
    expected += (n - Eigen::Vector3f(&target[3 * p])).squaredNorm();
  }
  EXPECT_NEAR(sum[0] - 1.0, expected, 1e-5);
  const float h = 1e-3f;
  for (size_t n = 0; n < prediction.size(); ++n) {
    std::vector<float> plus = prediction, minus = prediction;
    plus[n] += h, minus[n] -= h;
    const double fd = scale * (loss(plus) - loss(minus)) / (2.0 * h);
    ASSERT_NEAR(grad[n], fd, 2e-3 * (1 + std::abs(fd))) << "element " << n;
  }
  for (int p : {2, 3, 6, 7})
    for (int c = 0; c < 3; ++c) EXPECT_EQ(grad[3 * p + c], 0.0f) << "pixel " << p;
}

TEST(SquaredErrorLoss, GradientAndUnknownTargets) {
  const std::vector<float> prediction{0.2f, 0.9f, 0.5f, 0.0f}, target{0.0f, 1.0f, -1.0f, 0.25f};
  std::vector<float> grad(4, 9.0f);
  std::vector<double> sum{0.5};
  SquaredErrorLoss(prediction, target, 2.0f, grad, sum);
  EXPECT_NEAR(sum[0], 0.5 + 0.04 + 0.01 + 0.0625, 1e-7);  // element 2's target is unknown: no term
  const std::vector<float> expected{2.0f * 2 * 0.2f, 2.0f * 2 * -0.1f, 0.0f, 2.0f * 2 * -0.25f};
  for (size_t n = 0; n < 4; ++n) EXPECT_NEAR(grad[n], expected[n], 1e-6) << n;
}

TEST(LossDeathTest, SizesAreContracts) {
  const RasterBuffer rast = SmallRaster();
  std::vector<float> short_buffer(23), grad(24), target(24), mask(8);
  std::vector<double> sum(1), two(2);
  EXPECT_DEATH(UnitVectorLoss({short_buffer, rast, target, mask}, 1.0f, grad, sum), "do not match 4x2");
  EXPECT_DEATH(SquaredErrorLoss(mask, mask, 1.0f, mask, two), "one value");
}

TEST(Buffer, HostBuffersReadAsTheirVectors) {
  Buffer<float> b(std::vector<float>{1, 2, 3});
  EXPECT_EQ(b.where(), Memory::kHost);
  b.resize(4);
  b[3] = 4;
  EXPECT_EQ(b.ToHost(), (std::vector<float>{1, 2, 3, 4}));
  Buffer<float> copy = b;
  copy.assign(2, 0.5f);
  EXPECT_EQ(b.size(), 4u);
  EXPECT_EQ(copy.host(), (std::vector<float>{0.5f, 0.5f}));
  const Span<const float> view(b);
  EXPECT_EQ(view.where(), Memory::kHost);
  EXPECT_EQ(view.host()[2], 3.0f);
  copy.CopyFrom(std::span<const float>(b.host()));
  EXPECT_TRUE(copy == b);
}

TEST(Buffer, DeviceMemoryIsRefusedWhereCudaCannotRun) {
  if (CudaAvailable()) GTEST_SKIP() << "a CUDA GPU is visible: device buffers are tested in raster_cuda_test";
  EXPECT_THROW(Buffer<float>(Memory::kDevice, 16), InputError);
  // An empty device buffer needs no memory (the default of AntialiasRecord's device slots).
  const Buffer<int32_t> empty(Memory::kDevice);
  EXPECT_TRUE(empty.empty());
}

TEST(BufferDeathTest, OpsRefuseBuffersOnBothSides) {
  // A device Span (never dereferenced: the op refuses before it reads) beside host ones.
  const std::vector<float> positions(9, 0.0f);
  float fake = 0;
  EXPECT_DEATH(TransformToClip(positions, Eigen::Matrix4f::Identity(), Span<float>(&fake, 12, Memory::kDevice)),
               "some buffers are on the host and some on the device");
}

}  // namespace
}  // namespace sd::raster
