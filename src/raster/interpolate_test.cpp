#include <gtest/gtest.h>

#include <random>
#include <vector>

#include "raster/raster.h"
#include "raster/test_util.h"

namespace sd::raster {
namespace {

struct Scene {
  testing::Mesh mesh;
  std::vector<float> clip;
  RasterBuffer rast;
};

Scene SphereScene(int size, uint32_t seed) {
  Scene s;
  s.mesh = testing::Sphere(6, 10, 1.0f, 0.1f, seed);
  std::mt19937 rng(seed);
  const PinholeCamera cam = testing::SquareCamera(size, 0.9);
  s.clip = testing::ToClip(s.mesh.positions, ClipFromWorld(cam, testing::LookAtOrigin(rng, 3.0), 0.1f, 10.f));
  Rasterize({s.clip, s.mesh.tris, size, size}, &s.rast);
  return s;
}

TEST(Interpolate, ReproducesConstantAndVertexValues) {
  const Scene s = SphereScene(48, 1);
  const int V = s.mesh.NumVertices();
  std::vector<float> attr(2 * V);
  for (int v = 0; v < V; ++v) attr[2 * v] = 3.5f, attr[2 * v + 1] = static_cast<float>(v);
  std::vector<float> out(2 * s.rast.NumPixels());
  Interpolate({attr, 2, s.mesh.tris, s.rast}, out);
  int covered = 0;
  for (size_t p = 0; p < s.rast.NumPixels(); ++p) {
    if (s.rast.triangle[p] < 0) {
      ASSERT_EQ(out[2 * p], 0.0f);
      continue;
    }
    ++covered;
    ASSERT_NEAR(out[2 * p], 3.5f, 1e-5);  // barycentrics sum to one
    // Second channel: the vertex ids, so the value lies within the triangle's min..max id.
    const int32_t* tri = &s.mesh.tris[3 * s.rast.triangle[p]];
    const float lo = static_cast<float>(std::min({tri[0], tri[1], tri[2]}));
    const float hi = static_cast<float>(std::max({tri[0], tri[1], tri[2]}));
    ASSERT_GE(out[2 * p + 1], lo - 1e-2f);
    ASSERT_LE(out[2 * p + 1], hi + 1e-2f);
  }
  EXPECT_GT(covered, 200);
}

// Interpolate is linear in attr and bilinear in (attr, bary), so central differences are exact up to float
// rounding; step 1e-2, tolerance 1e-3 relative.
// The per-pixel code indexes without checks: indices past the attributes, or a raster buffer of a bigger mesh,
// stop at the op's entry with the culprit named instead of reading out of bounds.
TEST(InterpolateDeathTest, IndicesOutsideTheirBuffersAreContractViolations) {
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  const Scene s = SphereScene(16, 3);
  const int V = s.mesh.NumVertices();
  std::vector<float> attr(static_cast<size_t>(V)), out(s.rast.NumPixels());
  const std::vector<float> too_few(static_cast<size_t>(V - 1));
  EXPECT_DEATH(Interpolate({too_few, 1, s.mesh.tris, s.rast}, out), "names vertex");
  const std::vector<int32_t> first_triangle(s.mesh.tris.begin(), s.mesh.tris.begin() + 3);
  EXPECT_DEATH(Interpolate({attr, 1, first_triangle, s.rast}, out), "a raster buffer of another mesh");
  Interpolate({attr, 1, s.mesh.tris, s.rast}, out);  // the matching buffers pass
}

TEST(InterpolateDeathTest, BackwardRefusesIndicesOutsideTheirBuffers) {
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  const Scene s = SphereScene(16, 3);
  const int V = s.mesh.NumVertices();
  const size_t np = s.rast.NumPixels();
  std::vector<float> attr(static_cast<size_t>(V)), grad_out(np, 1.0f), grad_attr(attr.size()), grad_bary(2 * np);
  const std::vector<float> too_few(static_cast<size_t>(V - 1));
  std::vector<float> grad_too_few(too_few.size());
  EXPECT_DEATH(InterpolateBackward({too_few, 1, s.mesh.tris, s.rast}, grad_out, grad_too_few, grad_bary),
               "names vertex");
  const std::vector<int32_t> first_triangle(s.mesh.tris.begin(), s.mesh.tris.begin() + 3);
  EXPECT_DEATH(InterpolateBackward({attr, 1, first_triangle, s.rast}, grad_out, grad_attr, grad_bary),
               "a raster buffer of another mesh");
  InterpolateBackward({attr, 1, s.mesh.tris, s.rast}, grad_out, grad_attr, grad_bary);
}

TEST(Interpolate, BackwardMatchesFiniteDifferences) {
  Scene s = SphereScene(24, 2);
  const int C = 3, V = s.mesh.NumVertices();
  std::mt19937 rng(4);
  std::uniform_real_distribution<float> unit(-1, 1);
  std::vector<float> attr(C * V), grad_out(C * s.rast.NumPixels());
  for (float& a : attr) a = unit(rng);
  for (float& g : grad_out) g = unit(rng);
  auto loss = [&](const std::vector<float>& a, const RasterBuffer& rast) {
    std::vector<float> out(grad_out.size());
    Interpolate({a, C, s.mesh.tris, rast}, out);
    double l = 0;
    for (size_t n = 0; n < out.size(); ++n) l += double(out[n]) * grad_out[n];
    return l;
  };
  std::vector<float> grad_attr(attr.size(), 0.25f), grad_bary(2 * s.rast.NumPixels(), 0.25f);
  InterpolateBackward({attr, C, s.mesh.tris, s.rast}, grad_out, grad_attr, grad_bary);
  const float h = 1e-2f;
  for (size_t n = 0; n < attr.size(); ++n) {
    std::vector<float> plus = attr, minus = attr;
    plus[n] += h, minus[n] -= h;
    const double fd = (loss(plus, s.rast) - loss(minus, s.rast)) / (2.0 * h);
    ASSERT_NEAR(grad_attr[n] - 0.25f, fd, 1e-3 * (1 + std::abs(fd))) << "attr " << n;
  }
  int checked = 0;
  for (size_t n = 0; n < s.rast.bary.size(); ++n) {
    if (s.rast.triangle[n / 2] < 0) continue;
    RasterBuffer plus = s.rast, minus = s.rast;
    plus.bary[n] += h, minus.bary[n] -= h;
    const double fd = (loss(attr, plus) - loss(attr, minus)) / (2.0 * h);
    ASSERT_NEAR(grad_bary[n] - 0.25f, fd, 1e-3 * (1 + std::abs(fd))) << "bary " << n;
    ++checked;
  }
  EXPECT_GT(checked, 50);
  // The geometry gradient is optional.
  std::vector<float> grad_attr2(attr.size(), 0.0f);
  InterpolateBackward({attr, C, s.mesh.tris, s.rast}, grad_out, grad_attr2, {});
  for (size_t n = 0; n < attr.size(); ++n) ASSERT_FLOAT_EQ(grad_attr2[n] + 0.25f, grad_attr[n]);
}

}  // namespace
}  // namespace sd::raster
