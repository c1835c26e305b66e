#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>
#include <vector>

#include "core/parallel.h"
#include "raster/raster.h"
#include "raster/test_util.h"

namespace sd::raster {
namespace {

// Clip coordinates of a point given in pixels (u, v) with depth z/w = `depth` and homogeneous weight w:
// the inverse of u = (x/w + 1) W/2.
void PushPixelVertex(std::vector<float>* clip, double u, double v, int width, int height, double w = 1.0,
                     double depth = 0.0) {
  clip->push_back(static_cast<float>((2.0 * u / width - 1.0) * w));
  clip->push_back(static_cast<float>((2.0 * v / height - 1.0) * w));
  clip->push_back(static_cast<float>(depth * w));
  clip->push_back(static_cast<float>(w));
}

std::vector<int32_t> Tris(std::initializer_list<int32_t> indices) { return indices; }

int CountCovered(const RasterBuffer& rast) {
  return static_cast<int>(std::count_if(rast.triangle.begin(), rast.triangle.end(), [](int32_t t) { return t >= 0; }));
}

// --- analytic coverage ------------------------------------------------------------------------------------

TEST(Rasterize, TriangleCoverageCountMatchesArea) {
  // A pixel-centre count deviates from the area only along the outline; for these triangles (area ~1000 to
  // ~8000 px) the per-triangle deviation stays well under perimeter / 4, and over 60 triangles the signed
  // errors average out to well under 1% of the total area.
  constexpr int kSize = 128;
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> coord(4.0, kSize - 4.0), w(0.5, 3.0);
  double total_area = 0, total_count = 0;
  for (int trial = 0; trial < 60; ++trial) {
    double u[3], v[3];
    std::vector<float> clip;
    for (int k = 0; k < 3; ++k) {
      u[k] = coord(rng), v[k] = coord(rng);
      PushPixelVertex(&clip, u[k], v[k], kSize, kSize, w(rng));  // w only rescales clip: same screen triangle
    }
    const double area = 0.5 * std::abs((u[1] - u[0]) * (v[2] - v[0]) - (u[2] - u[0]) * (v[1] - v[0]));
    if (area < 1000) continue;
    double perimeter = 0;
    for (int k = 0; k < 3; ++k) perimeter += std::hypot(u[(k + 1) % 3] - u[k], v[(k + 1) % 3] - v[k]);
    RasterBuffer rast;
    Rasterize({clip, std::vector<int32_t>{0, 1, 2}, kSize, kSize}, &rast);
    const int count = CountCovered(rast);
    EXPECT_LE(std::abs(count - area), perimeter / 4) << "trial " << trial;
    total_area += area, total_count += count;
  }
  ASSERT_GT(total_area, 10000);
  EXPECT_NEAR(total_count / total_area, 1.0, 0.01);
}

// An axis-aligned rectangle made of two triangles covers exactly its area, both when its sides lie between
// pixel centres (integer corners) and when they pass exactly through pixel centres (half-integer corners:
// the top-left rule keeps the left and top rows and drops the right and bottom ones). Image sizes and w are
// powers of two so that the clip coordinates, hence the edges, are exact in float.
TEST(Rasterize, AxisAlignedRectangleCoverageIsExact) {
  constexpr int kW = 64, kH = 32;
  for (double offset : {0.0, 0.5}) {
    for (bool flip_winding : {false, true}) {
      const double u0 = 10 + offset, u1 = 37 + offset, v0 = 5 + offset, v1 = 30 + offset;  // 27 x 25
      std::vector<float> clip;
      PushPixelVertex(&clip, u0, v0, kW, kH, 4.0);
      PushPixelVertex(&clip, u1, v0, kW, kH, 0.5);
      PushPixelVertex(&clip, u1, v1, kW, kH, 2.0);
      PushPixelVertex(&clip, u0, v1, kW, kH, 1.0);
      std::vector<int32_t> tris = {0, 1, 2, 0, 2, 3};
      if (flip_winding) tris = {0, 2, 1, 0, 3, 2};
      RasterBuffer rast;
      Rasterize({clip, tris, kW, kH}, &rast);
      EXPECT_EQ(CountCovered(rast), 27 * 25) << "offset " << offset << " flip " << flip_winding;
      // And the covered pixels are exactly those whose centre lies in [u0, u1) x [v0, v1).
      for (int j = 0; j < kH; ++j)
        for (int i = 0; i < kW; ++i) {
          const bool inside = i + 0.5 >= u0 && i + 0.5 < u1 && j + 0.5 >= v0 && j + 0.5 < v1;
          ASSERT_EQ(rast.triangle[j * kW + i] >= 0, inside) << i << "," << j;
        }
    }
  }
}

// Counts, per pixel, how many triangles cover it when each triangle is rasterised on its own.
std::vector<int> CoverageCounts(const std::vector<float>& clip, const std::vector<int32_t>& tris, int width,
                                int height) {
  std::vector<int> count(static_cast<size_t>(width) * height, 0);
  for (size_t t = 0; t < tris.size() / 3; ++t) {
    RasterBuffer rast;
    Rasterize({clip, std::vector<int32_t>(tris.begin() + 3 * t, tris.begin() + 3 * t + 3), width, height}, &rast);
    for (size_t p = 0; p < count.size(); ++p) count[p] += rast.triangle[p] >= 0;
  }
  return count;
}

// The diagonal of the quad passes exactly through pixel centres; each must belong to exactly one of the two
// triangles, for both diagonals and both windings, and with different w per vertex (perspective).
TEST(Rasterize, SharedDiagonalThroughPixelCentresIsCoveredExactlyOnce) {
  constexpr int kSize = 64;
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> w(0.3, 4.0);
  for (int trial = 0; trial < 8; ++trial) {
    std::vector<float> clip;
    // Corners at pixel corners 10 and 50: the diagonals u = v and u + v = 60 hit the centres (i+.5, i+.5).
    PushPixelVertex(&clip, 10, 10, kSize, kSize, w(rng));
    PushPixelVertex(&clip, 50, 10, kSize, kSize, w(rng));
    PushPixelVertex(&clip, 50, 50, kSize, kSize, w(rng));
    PushPixelVertex(&clip, 10, 50, kSize, kSize, w(rng));
    const bool main_diagonal = trial % 2 == 0, flip = (trial / 2) % 2 == 1;
    std::vector<int32_t> tris = main_diagonal ? std::vector<int32_t>{0, 1, 2, 0, 2, 3}
                                              : std::vector<int32_t>{0, 1, 3, 1, 2, 3};
    if (flip) std::swap(tris[1], tris[2]), std::swap(tris[4], tris[5]);
    const std::vector<int> count = CoverageCounts(clip, tris, kSize, kSize);
    for (int j = 0; j < kSize; ++j)
      for (int i = 0; i < kSize; ++i) {
        const bool inside = i >= 10 && i < 50 && j >= 10 && j < 50;
        ASSERT_EQ(count[j * kSize + i], inside ? 1 : 0) << i << "," << j << " trial " << trial;
      }
  }
}

// A grid of quads whose vertices sit exactly on pixel centres, with random diagonals: every pixel centre
// inside is covered exactly once, including those at vertices shared by six triangles.
TEST(Rasterize, GridWithVerticesOnPixelCentresHasNoGapsOrOverlaps) {
  constexpr int kSize = 64, kCells = 8, kStep = 6, kOrigin = 5;
  std::mt19937 rng(11);
  std::vector<float> clip;
  for (int j = 0; j <= kCells; ++j)
    for (int i = 0; i <= kCells; ++i)
      PushPixelVertex(&clip, kOrigin + 0.5 + kStep * i, kOrigin + 0.5 + kStep * j, kSize, kSize);
  std::vector<int32_t> tris;
  auto id = [](int i, int j) { return static_cast<int32_t>(j * (kCells + 1) + i); };
  for (int j = 0; j < kCells; ++j)
    for (int i = 0; i < kCells; ++i) {
      if (rng() % 2) {
        tris.insert(tris.end(), {id(i, j), id(i + 1, j), id(i + 1, j + 1), id(i, j), id(i + 1, j + 1), id(i, j + 1)});
      } else {
        tris.insert(tris.end(), {id(i, j), id(i + 1, j), id(i, j + 1), id(i + 1, j), id(i + 1, j + 1), id(i, j + 1)});
      }
    }
  const std::vector<int> count = CoverageCounts(clip, tris, kSize, kSize);
  const int lo = kOrigin, hi = kOrigin + kStep * kCells;  // covered centres: i in [lo, hi)
  for (int j = 0; j < kSize; ++j)
    for (int i = 0; i < kSize; ++i) {
      const bool inside = i >= lo && i < hi && j >= lo && j < hi;
      ASSERT_EQ(count[j * kSize + i], inside ? 1 : 0) << i << "," << j;
    }
}

// A closed sphere seen from random cameras: no pixel inside the outline is missed, i.e. the front faces tile
// the disc (checked against the analytic projected outline, away from its boundary).
TEST(Rasterize, ClosedMeshHasNoHoles) {
  const testing::Mesh mesh = testing::Sphere(24, 48, 1.0f);
  std::mt19937 rng(5);
  constexpr int kSize = 96;
  const PinholeCamera cam = testing::SquareCamera(kSize);
  for (int trial = 0; trial < 4; ++trial) {
    const Rigid3d T_cam_world = testing::LookAtOrigin(rng, 4.0);
    const std::vector<float> clip = testing::ToClip(mesh.positions, ClipFromWorld(cam, T_cam_world, 0.1f, 20.f));
    RasterBuffer rast;
    Rasterize({clip, mesh.tris, kSize, kSize}, &rast);
    // Sphere radius 1 at distance 4: the outline is a circle of angular radius asin(1/4) about the centre.
    const double outline_px = cam.fx * std::tan(std::asin(0.25));
    for (int j = 0; j < kSize; ++j)
      for (int i = 0; i < kSize; ++i) {
        const double r = std::hypot(i + 0.5 - cam.cx, j + 0.5 - cam.cy);
        if (r < outline_px * 0.95) {
          ASSERT_GE(rast.triangle[j * kSize + i], 0) << i << "," << j;
        }
        if (r > outline_px * 1.01) {
          ASSERT_EQ(rast.triangle[j * kSize + i], -1) << i << "," << j;
        }
      }
  }
}

// --- depth and barycentrics -------------------------------------------------------------------------------

// A tilted plane in front of a pinhole camera: at every covered pixel the depth equals the analytic z/w of
// the plane point seen through the pixel centre, and the interpolated world position is that point
// (perspective-correct barycentrics). Tolerances: 2e-6 on z/w and 1e-4 m on positions are float rounding
// of clip coordinates of size ~5 (ulp ~5e-7) amplified a few times.
TEST(Rasterize, PlaneDepthAndPositionsMatchAnalytic) {
  PinholeCamera cam;
  cam.width = 80, cam.height = 60, cam.fx = 70, cam.fy = 75, cam.cx = 41.3, cam.cy = 28.9;
  const float near = 0.5f, far = 30.f;
  const Rigid3d T_cam_world;  // world = camera frame
  // Plane through (0, 0, 4) with normal n; a large quad on it.
  const Eigen::Vector3d n = Eigen::Vector3d(0.3, -0.2, -1.0).normalized(), q(0, 0, 4);
  const Eigen::Vector3d t1 = n.cross(Eigen::Vector3d::UnitX()).normalized(), t2 = n.cross(t1);
  std::vector<float> positions;
  for (auto [a, b] : {std::pair{-6, -6}, {6, -6}, {6, 6}, {-6, 6}}) {
    const Eigen::Vector3d p = q + a * t1 + b * t2;
    positions.insert(positions.end(), {float(p.x()), float(p.y()), float(p.z())});
  }
  const std::vector<int32_t> tris = {0, 1, 2, 0, 2, 3};
  const std::vector<float> clip = testing::ToClip(positions, ClipFromWorld(cam, T_cam_world, near, far));
  RasterBuffer rast;
  Rasterize({clip, tris, cam.width, cam.height}, &rast);
  std::vector<float> interpolated(3 * rast.NumPixels());
  Interpolate({positions, 3, tris, rast}, interpolated);
  ASSERT_EQ(CountCovered(rast), cam.width * cam.height);
  for (int j = 0; j < cam.height; ++j)
    for (int i = 0; i < cam.width; ++i) {
      const Eigen::Vector3d ray((i + 0.5 - cam.cx) / cam.fx, (j + 0.5 - cam.cy) / cam.fy, 1.0);
      const Eigen::Vector3d hit = ray * (n.dot(q) / n.dot(ray));
      const double Z = hit.z();
      const double expected_depth = ((far + near) / (far - near) * Z - 2.0 * far * near / (far - near)) / Z;
      const size_t pixel = static_cast<size_t>(j) * cam.width + i;
      ASSERT_NEAR(rast.depth[pixel], expected_depth, 2e-6) << i << "," << j;
      for (int c = 0; c < 3; ++c) ASSERT_NEAR(interpolated[3 * pixel + c], hit[c], 1e-4) << i << "," << j;
    }
}

TEST(Rasterize, NearestWinsAndEqualDepthGoesToLowerIndex) {
  constexpr int kSize = 32;
  std::vector<float> clip;
  // Triangles 0 and 2 at depth 0.5, triangle 1 at depth -0.2 (nearer), all covering the image centre.
  for (double depth : {0.5, -0.2, 0.5}) {
    PushPixelVertex(&clip, 2, 2, kSize, kSize, 1.0, depth);
    PushPixelVertex(&clip, 30, 4, kSize, kSize, 2.0, depth);
    PushPixelVertex(&clip, 10, 30, kSize, kSize, 0.5, depth);
  }
  RasterBuffer rast;
  Rasterize({clip, Tris({0, 1, 2, 3, 4, 5, 6, 7, 8}), kSize, kSize}, &rast);
  const size_t centre = 12 * kSize + 12;
  EXPECT_EQ(rast.triangle[centre], 1);
  EXPECT_NEAR(rast.depth[centre], -0.2, 1e-6);
  // Without the near one, the two identical far triangles tie: the lower index wins in either order.
  Rasterize({clip, Tris({6, 7, 8, 0, 1, 2}), kSize, kSize}, &rast);
  EXPECT_EQ(rast.triangle[centre], 0);
  EXPECT_NEAR(rast.depth[centre], 0.5, 1e-6);
  Rasterize({clip, Tris({0, 1, 2, 6, 7, 8}), kSize, kSize}, &rast);
  EXPECT_EQ(rast.triangle[centre], 0);
}

TEST(Rasterize, BackgroundAndUndrawableTriangles) {
  constexpr int kSize = 16;
  std::vector<float> clip;
  PushPixelVertex(&clip, 0, 0, kSize, kSize);
  PushPixelVertex(&clip, 16, 0, kSize, kSize);
  PushPixelVertex(&clip, 0, 16, kSize, kSize);
  clip.insert(clip.end(), {0.f, 0.f, 0.f, -1.f});  // a vertex behind the eye
  RasterBuffer rast;
  Rasterize({clip, Tris({0, 1, 3}), kSize, kSize}, &rast);  // w <= 0: not drawn
  EXPECT_EQ(CountCovered(rast), 0);
  for (float d : rast.depth) ASSERT_EQ(d, 1.0f);
  for (float b : rast.bary) ASSERT_EQ(b, 0.0f);
  // Depth outside [-1, 1] is clipped per pixel.
  std::vector<float> far_clip = clip;
  for (int v = 0; v < 3; ++v) far_clip[4 * v + 2] = 1.5f;
  Rasterize({far_clip, Tris({0, 1, 2}), kSize, kSize}, &rast);
  EXPECT_EQ(CountCovered(rast), 0);
  Rasterize({clip, Tris({0, 1, 2}), kSize, kSize}, &rast);
  EXPECT_EQ(CountCovered(rast), 15 * 16 / 2);  // centres with i + j < 15; the hypotenuse row (i + j = 15) is a
                                              // bottom-right edge, excluded by the top-left rule
}

TEST(Rasterize, EmptyMeshAndEmptyImage) {
  RasterBuffer rast;
  Rasterize({{}, {}, 8, 4}, &rast);
  EXPECT_EQ(rast.NumPixels(), 32u);
  EXPECT_EQ(CountCovered(rast), 0);
  for (float d : rast.depth) EXPECT_EQ(d, 1.0f);
  std::vector<float> clip;
  PushPixelVertex(&clip, 0, 0, 8, 8);
  PushPixelVertex(&clip, 8, 0, 8, 8);
  PushPixelVertex(&clip, 0, 8, 8, 8);
  Rasterize({clip, Tris({0, 1, 2}), 0, 0}, &rast);
  EXPECT_EQ(rast.NumPixels(), 0u);
  EXPECT_TRUE(rast.bary.empty());
}

TEST(Rasterize, ResultDoesNotDependOnThreadCount) {
  const testing::Mesh mesh = testing::Sphere(30, 60, 1.0f, 0.15f);
  std::mt19937 rng(9);
  const PinholeCamera cam = testing::SquareCamera(200);
  const std::vector<float> clip =
      testing::ToClip(mesh.positions, ClipFromWorld(cam, testing::LookAtOrigin(rng, 3.5), 0.1f, 10.f));
  RasterBuffer many, one;
  Rasterize({clip, mesh.tris, 200, 200}, &many);
  SetMaxThreads(1);
  Rasterize({clip, mesh.tris, 200, 200}, &one);
  SetMaxThreads(0);
  EXPECT_EQ(many.triangle, one.triangle);
  EXPECT_EQ(many.bary, one.bary);
  EXPECT_EQ(many.depth, one.depth);
}

// --- backward ---------------------------------------------------------------------------------------------

// RasterizeBackward against central differences of L = sum_p (wb0 b0 + wb1 b1 + wd z/w) over random weights,
// perturbing each clip coordinate of each vertex of a bumpy sphere seen by random cameras. A perturbation
// may move a pixel to another triangle (a jump, not a derivative): such pixels are dropped from both the
// FD loss and the analytic gradient (its incoming gradients are zeroed there), so both sides differentiate
// the same smooth sum at fixed triangle assignment, which is what the backward pass promises.
// Step h = 5e-4 in clip units (~0.003 px here), chosen from measurements: barycentrics and depth are rounded
// to float once per pixel, which puts ~2e-4 (relative to 1 + |fd|) of noise into the FD at this step
// (it grows as 1/h: 5e-4 at h = 3e-4), while the truncation error grows as h^2 (1.2e-3 at h = 1e-3 on the
// most curved coordinate of seed 1, 1e-2 at h = 3e-3). Tolerance: 2e-3 * (1 + |fd|), observed max 6e-4.
TEST(RasterizeBackward, MatchesFiniteDifferencesAtFixedTriangleAssignment) {
  constexpr int kSize = 40;
  for (uint32_t seed : {1u, 2u, 3u}) {
    const testing::Mesh mesh = testing::Sphere(6, 10, 1.0f, 0.15f, seed);
    std::mt19937 rng(seed);
    const PinholeCamera cam = testing::SquareCamera(kSize, 0.9);
    const std::vector<float> clip =
        testing::ToClip(mesh.positions, ClipFromWorld(cam, testing::LookAtOrigin(rng, 3.0), 0.5f, 6.f));
    std::uniform_real_distribution<float> unit(-1, 1);
    const size_t num_pixels = static_cast<size_t>(kSize) * kSize;
    std::vector<float> w_bary(2 * num_pixels), w_depth(num_pixels);
    for (float& w : w_bary) w = unit(rng);
    for (float& w : w_depth) w = unit(rng);

    const RasterizeInputs in{clip, mesh.tris, kSize, kSize};
    RasterBuffer base;
    Rasterize(in, &base);
    auto loss = [&](const RasterBuffer& rast, const std::vector<uint8_t>& keep) {
      double l = 0;
      for (size_t p = 0; p < num_pixels; ++p) {
        if (!keep[p]) continue;
        l += double(w_bary[2 * p]) * rast.bary[2 * p] + double(w_bary[2 * p + 1]) * rast.bary[2 * p + 1] +
             double(w_depth[p]) * rast.depth[p];
      }
      return l;
    };
    const float h = 5e-4f;
    int checked = 0;
    double max_err = 0;
    for (size_t n = 0; n < clip.size(); ++n) {
      std::vector<float> plus = clip, minus = clip;
      plus[n] += h, minus[n] -= h;
      RasterBuffer rast_plus, rast_minus;
      Rasterize({plus, mesh.tris, kSize, kSize}, &rast_plus);
      Rasterize({minus, mesh.tris, kSize, kSize}, &rast_minus);
      std::vector<uint8_t> keep(num_pixels);
      for (size_t p = 0; p < num_pixels; ++p)
        keep[p] = base.triangle[p] >= 0 && rast_plus.triangle[p] == base.triangle[p] &&
                  rast_minus.triangle[p] == base.triangle[p];
      const double fd = (loss(rast_plus, keep) - loss(rast_minus, keep)) / (double(plus[n]) - minus[n]);

      std::vector<float> g_bary(2 * num_pixels, 0.0f), g_depth(num_pixels, 0.0f);
      for (size_t p = 0; p < num_pixels; ++p) {
        if (!keep[p]) continue;
        g_bary[2 * p] = w_bary[2 * p], g_bary[2 * p + 1] = w_bary[2 * p + 1], g_depth[p] = w_depth[p];
      }
      std::vector<float> grad_clip(clip.size(), 0.0f);
      RasterizeBackward(in, base, g_bary, g_depth, grad_clip);
      const double err = std::abs(grad_clip[n] - fd);
      max_err = std::max(max_err, err / (1 + std::abs(fd)));
      ASSERT_LE(err, 2e-3 * (1 + std::abs(fd))) << "seed " << seed << " coordinate " << n << " analytic "
                                                  << grad_clip[n] << " fd " << fd;
      checked += fd != 0.0;
    }
    EXPECT_GT(checked, static_cast<int>(clip.size() / 3)) << "too few coordinates influence visible pixels";
    std::printf("seed %u: %d coordinates, max |analytic - fd| / (1 + |fd|) = %.2e\n", seed, checked, max_err);
  }
}

// The per-pixel gradient indexes without checks: a tris array naming vertices past the clip positions, a
// raster buffer of a bigger mesh, or one of another resolution, stop at the entry with the culprit named.
TEST(RasterizeBackwardDeathTest, IndicesOutsideTheirBuffersAreContractViolations) {
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  const testing::Mesh mesh = testing::Sphere(6, 10, 1.0f);
  std::mt19937 rng(4);
  const std::vector<float> clip = testing::ToClip(
      mesh.positions, ClipFromWorld(testing::SquareCamera(16, 0.9), testing::LookAtOrigin(rng, 3.0), 0.5f, 6.f));
  const RasterizeInputs in{clip, mesh.tris, 16, 16};
  RasterBuffer rast;
  Rasterize(in, &rast);
  std::vector<float> g_bary(2 * rast.NumPixels(), 1.0f), grad_clip(clip.size());
  const std::vector<float> too_few(clip.begin(), clip.end() - 4);
  std::vector<float> grad_too_few(too_few.size());
  EXPECT_DEATH(RasterizeBackward({too_few, mesh.tris, 16, 16}, rast, g_bary, {}, grad_too_few), "names vertex");
  const std::vector<int32_t> first_triangle(mesh.tris.begin(), mesh.tris.begin() + 3);
  EXPECT_DEATH(RasterizeBackward({clip, first_triangle, 16, 16}, rast, g_bary, {}, grad_clip),
               "a raster buffer of another mesh");
  std::vector<float> g_bary_wide(2 * 32 * 8, 1.0f);
  EXPECT_DEATH(RasterizeBackward({clip, mesh.tris, 32, 8}, rast, g_bary_wide, {}, grad_clip), "for inputs of 32x8");
  RasterizeBackward(in, rast, g_bary, {}, grad_clip);
}

// Gradients accumulate, and an empty grad_depth means "barycentrics only".
TEST(RasterizeBackward, AccumulatesAndAcceptsEmptyDepthGradient) {
  const testing::Mesh mesh = testing::Sphere(6, 10, 1.0f);
  std::mt19937 rng(4);
  const PinholeCamera cam = testing::SquareCamera(32, 0.9);
  const std::vector<float> clip =
      testing::ToClip(mesh.positions, ClipFromWorld(cam, testing::LookAtOrigin(rng, 3.0), 0.5f, 6.f));
  const RasterizeInputs in{clip, mesh.tris, 32, 32};
  RasterBuffer rast;
  Rasterize(in, &rast);
  std::vector<float> g_bary(2 * rast.NumPixels(), 0.7f), zeros(rast.NumPixels(), 0.0f);
  std::vector<float> once(clip.size(), 0.0f), twice(clip.size(), 0.0f), with_zero_depth(clip.size(), 0.0f);
  RasterizeBackward(in, rast, g_bary, {}, once);
  RasterizeBackward(in, rast, g_bary, {}, twice);
  RasterizeBackward(in, rast, g_bary, {}, twice);
  RasterizeBackward(in, rast, g_bary, zeros, with_zero_depth);
  for (size_t n = 0; n < clip.size(); ++n) {
    EXPECT_FLOAT_EQ(twice[n], 2 * once[n]);
    EXPECT_EQ(with_zero_depth[n], once[n]);
  }
}

}  // namespace
}  // namespace sd::raster
