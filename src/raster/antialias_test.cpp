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

// Clip coordinates (w = 1, depth 0) of a point given in pixels.
void PushPixelVertex(std::vector<float>* clip, double u, double v, int width, int height) {
  clip->insert(clip->end(), {static_cast<float>(2.0 * u / width - 1.0), static_cast<float>(2.0 * v / height - 1.0),
                             0.0f, 1.0f});
}

// 1 where covered, 0 on background: the coverage mask as a colour.
std::vector<float> CoverageMask(const RasterBuffer& rast) {
  std::vector<float> mask(rast.NumPixels());
  for (size_t p = 0; p < mask.size(); ++p) mask[p] = rast.triangle[p] >= 0 ? 1.0f : 0.0f;
  return mask;
}

// Two triangles covering the axis-aligned rectangle [u0, u1] x [v0, v1] (pixels).
struct Quad {
  std::vector<float> clip;
  std::vector<int32_t> tris = {0, 1, 2, 0, 2, 3};
};
Quad MakeQuad(double u0, double v0, double u1, double v1, int width, int height) {
  Quad q;
  PushPixelVertex(&q.clip, u0, v0, width, height);
  PushPixelVertex(&q.clip, u1, v0, width, height);
  PushPixelVertex(&q.clip, u1, v1, width, height);
  PushPixelVertex(&q.clip, u0, v1, width, height);
  return q;
}

std::vector<float> AntialiasedMask(const std::vector<float>& clip, const std::vector<int32_t>& tris,
                                   const EdgeTopology& topology, int width, int height, RasterBuffer* rast,
                                   AntialiasRecord* record) {
  Rasterize({clip, tris, width, height}, rast);
  const std::vector<float> mask = CoverageMask(*rast);
  std::vector<float> out(mask.size());
  Antialias({mask, 1, *rast, clip, tris, topology}, out, record);
  return out;
}

// --- topology ----------------------------------------------------------------------------------------------

TEST(BuildEdgeTopology, ClosedMeshQuadAndNonManifoldEdges) {
  const testing::Mesh sphere = testing::Sphere(6, 9, 1.0f);
  const EdgeTopology closed = BuildEdgeTopology(sphere.tris, sphere.NumVertices());
  ASSERT_EQ(closed.neighbour.size(), sphere.tris.size());
  for (size_t slot = 0; slot < closed.neighbour.size(); ++slot) {
    const int32_t n = closed.neighbour[slot];
    ASSERT_GE(n, 0) << "closed mesh has no boundary";
    // Symmetric: the neighbour lists this triangle back.
    const int32_t t = static_cast<int32_t>(slot / 3);
    EXPECT_TRUE(closed.neighbour[3 * n] == t || closed.neighbour[3 * n + 1] == t || closed.neighbour[3 * n + 2] == t);
  }
  // Quad 0-1-2-3 split along 0-2: edges v2v0 of triangle 0 and v0v1 of triangle 1 are shared.
  const EdgeTopology quad = BuildEdgeTopology(std::vector<int32_t>{0, 1, 2, 0, 2, 3}, 4);
  EXPECT_EQ(quad.neighbour, (std::vector<int32_t>{-1, -1, 1, 0, -1, -1}));
  // Three triangles on edge 0-1: non-manifold, all treated as boundaries.
  const EdgeTopology fin = BuildEdgeTopology(std::vector<int32_t>{0, 1, 2, 1, 0, 3, 0, 1, 4}, 5);
  EXPECT_EQ(fin.neighbour[0], -1);
  EXPECT_EQ(fin.neighbour[3], -1);
  EXPECT_EQ(fin.neighbour[6], -1);
}

// --- forward: analytic coverage ----------------------------------------------------------------------------

// A vertical edge at u = e: the antialiased mask of a row must integrate to exactly e (a box filter of a
// straight edge is exact), whether the edge lies left or right of the nearest pixel boundary.
TEST(Antialias, VerticalEdgeRowSumEqualsEdgePosition) {
  constexpr int kW = 32, kH = 16;
  for (double edge : {20.0, 20.1, 20.3, 20.5, 20.7, 20.95, 21.25}) {
    const Quad q = MakeQuad(-4.0, 2.0, edge, 14.0, kW, kH);  // left side off screen: a silhouette only at u = edge
    const EdgeTopology topology = BuildEdgeTopology(q.tris, 4);
    RasterBuffer rast;
    AntialiasRecord record;
    const std::vector<float> out = AntialiasedMask(q.clip, q.tris, topology, kW, kH, &rast, &record);
    for (int j = 3; j < 13; ++j) {  // rows away from the top and bottom edges
      double sum = 0;
      for (int i = 0; i < kW; ++i) sum += out[j * kW + i];
      EXPECT_NEAR(sum, edge, 1e-5) << "edge " << edge << " row " << j;
    }
  }
}

// A rotated square: the antialiased mask integrates to its area much more closely than the raw pixel count
// (the raw count's error is a random walk along the outline; the box-filtered one's is only at corners and
// for the ~45-degree edges, where a 1D filter along one axis is an approximation).
TEST(Antialias, RotatedSquareMaskIntegratesToArea) {
  constexpr int kSize = 96;
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> angle(0, 1.5), offset(-3, 3);
  double worst_aa = 0, worst_raw = 0;
  for (int trial = 0; trial < 10; ++trial) {
    const double a = angle(rng), half = 25.0, cu = 48 + offset(rng), cv = 48 + offset(rng);
    std::vector<float> clip;
    for (int k = 0; k < 4; ++k) {
      const double phi = a + k * 3.14159265358979 / 2;
      PushPixelVertex(&clip, cu + half * std::sqrt(2.0) * std::cos(phi), cv + half * std::sqrt(2.0) * std::sin(phi),
                      kSize, kSize);
    }
    const std::vector<int32_t> tris = {0, 1, 2, 0, 2, 3};
    const EdgeTopology topology = BuildEdgeTopology(tris, 4);
    RasterBuffer rast;
    AntialiasRecord record;
    const std::vector<float> out = AntialiasedMask(clip, tris, topology, kSize, kSize, &rast, &record);
    double sum = 0, raw = 0;
    for (size_t p = 0; p < out.size(); ++p) sum += out[p], raw += rast.triangle[p] >= 0;
    const double area = 4 * half * half;
    worst_aa = std::max(worst_aa, std::abs(sum - area)), worst_raw = std::max(worst_raw, std::abs(raw - area));
    EXPECT_NEAR(sum, area, 0.004 * area) << "trial " << trial;
    for (float o : out) ASSERT_TRUE(o >= 0.0f && o <= 1.0f);
  }
  std::printf("worst |sum - area|: antialiased %.2f px, raw count %.2f px (area 2500)\n", worst_aa, worst_raw);
}

// A finely tessellated sphere is seen with sliver triangles along its outline, so the pixel next to the
// background is usually covered by a triangle several slivers away from the silhouette edge; the search must
// still find the edge. Check: outline pixels (covered, with a background 4-neighbour) take part in a blended
// pair. Not all of them can: each silhouette edge blends along one axis only (the one closer to its normal),
// and the silhouette of a triangulated sphere zigzags, so a pixel whose only background neighbour lies across
// a locally near-horizontal sliver edge, in an outline that is vertical overall, is left unblended (2-4% of
// outline pixels here; with the walk disabled, i.e. the owner's triangle only, 99% were missed).
TEST(Antialias, FindsTheOutlineOfAFinelyTessellatedSphere) {
  constexpr int kSize = 128;
  const testing::Mesh mesh = testing::Sphere(50, 100, 1.0f);  // 9,900 triangles
  const EdgeTopology topology = BuildEdgeTopology(mesh.tris, mesh.NumVertices());
  const PinholeCamera cam = testing::SquareCamera(kSize, 1.0);
  std::mt19937 rng(8);
  for (int trial = 0; trial < 3; ++trial) {
    const std::vector<float> clip =
        testing::ToClip(mesh.positions, ClipFromWorld(cam, testing::LookAtOrigin(rng, 3.0), 0.5f, 6.f));
    RasterBuffer rast;
    AntialiasRecord record;
    AntialiasedMask(clip, mesh.tris, topology, kSize, kSize, &rast, &record);
    std::vector<uint8_t> blended(rast.NumPixels(), 0);
    for (const auto& p : record.pairs) blended[p.pixel_a] = blended[p.pixel_b] = 1;
    int outline = 0, missed = 0;
    for (int j = 1; j + 1 < kSize; ++j)
      for (int i = 1; i + 1 < kSize; ++i) {
        const int32_t p = j * kSize + i;
        if (rast.triangle[p] < 0) continue;
        if (rast.triangle[p - 1] >= 0 && rast.triangle[p + 1] >= 0 && rast.triangle[p - kSize] >= 0 &&
            rast.triangle[p + kSize] >= 0)
          continue;
        ++outline;
        missed += !blended[p];
      }
    EXPECT_GT(outline, 150);
    std::printf("outline pixels: %d, not blended: %d\n", outline, missed);
    EXPECT_LE(missed, outline / 20) << "trial " << trial << ": " << missed << " of " << outline << " missed";
  }
}

// An internal (non-silhouette) edge between two triangles facing the same way is never blended, and pairs
// with the same triangle are never examined: a quad filling the image is left untouched.
TEST(Antialias, InteriorEdgesAreNotBlended) {
  constexpr int kSize = 16;
  const Quad q = MakeQuad(-2, -2, 18, 18, kSize, kSize);
  const EdgeTopology topology = BuildEdgeTopology(q.tris, 4);
  RasterBuffer rast;
  Rasterize({q.clip, q.tris, kSize, kSize}, &rast);
  std::vector<float> color(rast.NumPixels());
  for (size_t p = 0; p < color.size(); ++p) color[p] = static_cast<float>(rast.triangle[p]);  // differs across diagonal
  std::vector<float> out(color.size());
  AntialiasRecord record;
  Antialias({color, 1, rast, q.clip, q.tris, topology}, out, &record);
  EXPECT_TRUE(record.pairs.empty());
  EXPECT_EQ(out, color);
}

// --- backward ----------------------------------------------------------------------------------------------

struct SphereView {
  testing::Mesh mesh;
  EdgeTopology topology;
  std::vector<float> clip;
  RasterBuffer rast;
  std::vector<float> color;  // 3 channels, interpolated random vertex colours
};

SphereView MakeSphereView(int size, uint32_t seed) {
  SphereView s;
  s.mesh = testing::Sphere(8, 14, 1.0f, 0.2f, seed);  // bumpy: folds add silhouette edges inside the outline
  s.topology = BuildEdgeTopology(s.mesh.tris, s.mesh.NumVertices());
  std::mt19937 rng(seed);
  const PinholeCamera cam = testing::SquareCamera(size, 0.8);
  s.clip = testing::ToClip(s.mesh.positions, ClipFromWorld(cam, testing::LookAtOrigin(rng, 3.0), 0.5f, 6.f));
  Rasterize({s.clip, s.mesh.tris, size, size}, &s.rast);
  std::uniform_real_distribution<float> unit(0, 1);
  std::vector<float> vertex_color(3 * s.mesh.NumVertices());
  for (float& c : vertex_color) c = unit(rng);
  s.color.resize(3 * s.rast.NumPixels());
  Interpolate({vertex_color, 3, s.mesh.tris, s.rast}, s.color);
  return s;
}

bool SamePairs(const AntialiasRecord& x, const AntialiasRecord& y) {
  if (x.pairs.size() != y.pairs.size()) return false;
  for (size_t n = 0; n < x.pairs.size(); ++n) {
    const auto &p = x.pairs[n], &q = y.pairs[n];
    if (p.pixel_a != q.pixel_a || p.pixel_b != q.pixel_b || p.triangle != q.triangle || p.edge != q.edge) return false;
  }
  return true;
}

// A pair whose crossing t is within the perturbation of 1/2: alpha = |t - 1/2| has a kink there (the
// receiving pixel switches), where a central difference averages two different one-sided derivatives.
bool CrossesHalf(const AntialiasRecord& base, const AntialiasRecord& plus, const AntialiasRecord& minus) {
  for (size_t n = 0; n < base.pairs.size(); ++n) {
    // Away from the kink the forward and backward changes agree to second order; across it they differ by
    // up to the whole step.
    const double a = base.pairs[n].alpha, up = plus.pairs[n].alpha - a, down = a - minus.pairs[n].alpha;
    if (a < 1e-2 && std::abs(up - down) > 0.1 * std::max(std::abs(up), std::abs(down))) return true;
  }
  return false;
}

// The geometry gradient against central differences of L = sum w . out with the raster buffer and colours
// held fixed (they are inputs of Antialias; their own derivatives are RasterizeBackward's and
// InterpolateBackward's business). How silhouette pixels are handled: at fixed raster buffer, out is a
// smooth function of the clip positions as long as the set of blended pairs is the same, since each alpha
// is |t - 1/2| with t the edge's crossing of the pixel pair. A perturbation that makes an edge enter or leave
// a pair (crossing leaving [0, 1] along either segment, or a neighbour's facing flipping) is a jump, and a
// crossing passing t = 1/2 is a kink: such coordinates are skipped (and counted, so the test cannot pass by
// skipping everything). Step h = 3e-4 clip units (~0.003 px), from measurements: the error (relative to
// 1 + |fd|) was ~1e-4 at this step, ~4e-4 at 1e-4 (float rounding of the outputs, growing as 1/h) and up
// to 1e-2 at 1e-3 (kinks and jumps not caught by the filters above). Tolerance 2e-3 * (1 + |fd|).
TEST(AntialiasBackward, GeometryGradientMatchesFiniteDifferences) {
  constexpr int kSize = 64;
  for (uint32_t seed : {1u, 2u, 3u}) {
    const SphereView s = MakeSphereView(kSize, seed);
    std::mt19937 rng(100 + seed);
    std::uniform_real_distribution<float> unit(-1, 1);
    std::vector<float> weights(s.color.size());
    for (float& w : weights) w = unit(rng);
    auto run = [&](const std::vector<float>& clip, AntialiasRecord* record) {
      std::vector<float> out(s.color.size());
      Antialias({s.color, 3, s.rast, clip, s.mesh.tris, s.topology}, out, record);
      double l = 0;
      for (size_t n = 0; n < out.size(); ++n) l += double(weights[n]) * out[n];
      return l;
    };
    AntialiasRecord record;
    run(s.clip, &record);
    ASSERT_GT(record.pairs.size(), 100u) << "the silhouette should cross many pixel pairs";
    std::vector<float> grad_color(s.color.size(), 0.0f), grad_clip(s.clip.size(), 0.0f);
    AntialiasBackward({s.color, 3, s.rast, s.clip, s.mesh.tris, s.topology}, record, weights, grad_color, grad_clip);

    const float h = 3e-4f;
    int checked = 0, nonzero = 0, skipped = 0;
    double max_err = 0;
    for (size_t n = 0; n < s.clip.size(); ++n) {
      std::vector<float> plus = s.clip, minus = s.clip;
      plus[n] += h, minus[n] -= h;
      AntialiasRecord rec_plus, rec_minus;
      const double l_plus = run(plus, &rec_plus), l_minus = run(minus, &rec_minus);
      if (!SamePairs(rec_plus, record) || !SamePairs(rec_minus, record) || CrossesHalf(record, rec_plus, rec_minus)) {
        ++skipped;
        continue;
      }
      const double fd = (l_plus - l_minus) / (double(plus[n]) - minus[n]);
      const double err = std::abs(grad_clip[n] - fd) / (1 + std::abs(fd));
      max_err = std::max(max_err, err);
      EXPECT_LE(err, 2e-3) << "seed " << seed << " coordinate " << n << " analytic " << grad_clip[n] << " fd " << fd;
      ++checked;
      nonzero += std::abs(fd) > 1e-3;
    }
    EXPECT_GT(nonzero, 20) << "too few coordinates move the silhouette";
    EXPECT_LT(skipped, checked / 10 + 2);
    std::printf("seed %u: %zu pairs, %d coordinates checked (%d with non-zero gradient), %d skipped, max err %.2e\n",
                seed, record.pairs.size(), checked, nonzero, skipped, max_err);
  }
}

// The colour gradient: out is linear in the colours at fixed geometry, so FD is exact up to float rounding.
// Skipping equal-colour pairs (color_gradient = false) is exact for the output and the geometry gradient: on
// a coverage mask only the outline against the background is left, and nothing else changes.
TEST(Antialias, SkippingEqualColoursKeepsOutputAndGeometryGradient) {
  constexpr int kSize = 96;
  const SphereView s = MakeSphereView(kSize, 7);
  std::vector<float> coverage(s.rast.NumPixels());
  for (size_t p = 0; p < coverage.size(); ++p) coverage[p] = s.rast.triangle[p] >= 0 ? 1.0f : 0.0f;
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> unit(-1, 1);
  std::vector<float> grad_out(coverage.size());
  for (float& g : grad_out) g = unit(rng);
  std::vector<float> out_full(coverage.size()), out_fast(coverage.size());
  AntialiasRecord full, fast;
  Antialias({coverage, 1, s.rast, s.clip, s.mesh.tris, s.topology}, out_full, &full, true);
  Antialias({coverage, 1, s.rast, s.clip, s.mesh.tris, s.topology}, out_fast, &fast, false);
  EXPECT_LT(fast.pairs.size(), full.pairs.size());  // the bumpy sphere has interior silhouettes
  EXPECT_GT(fast.pairs.size(), 0u);
  EXPECT_EQ(out_full, out_fast);
  std::vector<float> gc_full(coverage.size()), gc_fast(coverage.size());
  std::vector<float> gx_full(s.clip.size()), gx_fast(s.clip.size());
  AntialiasBackward({coverage, 1, s.rast, s.clip, s.mesh.tris, s.topology}, full, grad_out, gc_full, gx_full);
  AntialiasBackward({coverage, 1, s.rast, s.clip, s.mesh.tris, s.topology}, fast, grad_out, gc_fast, gx_fast);
  for (size_t i = 0; i < gx_full.size(); ++i) EXPECT_NEAR(gx_full[i], gx_fast[i], 1e-5f * (1 + std::abs(gx_full[i]))) << i;
}

TEST(AntialiasBackward, ColorGradientMatchesFiniteDifferences) {
  constexpr int kSize = 24;
  const SphereView s = MakeSphereView(kSize, 4);
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> unit(-1, 1);
  std::vector<float> weights(s.color.size());
  for (float& w : weights) w = unit(rng);
  auto loss = [&](const std::vector<float>& color) {
    std::vector<float> out(color.size());
    AntialiasRecord record;
    Antialias({color, 3, s.rast, s.clip, s.mesh.tris, s.topology}, out, &record);
    double l = 0;
    for (size_t n = 0; n < out.size(); ++n) l += double(weights[n]) * out[n];
    return l;
  };
  AntialiasRecord record;
  std::vector<float> out(s.color.size());
  Antialias({s.color, 3, s.rast, s.clip, s.mesh.tris, s.topology}, out, &record);
  std::vector<float> grad_color(s.color.size(), 0.0f), grad_clip(s.clip.size(), 0.0f);
  AntialiasBackward({s.color, 3, s.rast, s.clip, s.mesh.tris, s.topology}, record, weights, grad_color, grad_clip);
  const float h = 1e-2f;
  for (size_t n = 0; n < s.color.size(); ++n) {
    std::vector<float> plus = s.color, minus = s.color;
    plus[n] += h, minus[n] -= h;
    const double fd = (loss(plus) - loss(minus)) / (2.0 * h);
    ASSERT_NEAR(grad_color[n], fd, 1e-3 * (1 + std::abs(fd))) << n;
  }
}

// The per-pair code indexes vertices and triangles without checks: a tris array naming vertices past the clip
// positions, or a raster buffer of a bigger mesh (here: the same sphere, of which only the first triangles are
// passed), stop both passes at their entry with the culprit named instead of reading out of bounds.
TEST(AntialiasDeathTest, IndicesOutsideTheirBuffersAreContractViolations) {
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  const SphereView s = MakeSphereView(24, 2);
  std::vector<float> out(s.color.size()), grad_color(s.color.size()), grad_clip(s.clip.size());
  AntialiasRecord record;
  const std::vector<float> too_few(s.clip.begin(), s.clip.end() - 4);  // the south pole's vertex is missing
  std::vector<float> grad_too_few(too_few.size());
  EXPECT_DEATH(Antialias({s.color, 3, s.rast, too_few, s.mesh.tris, s.topology}, out, &record), "names vertex");
  EXPECT_DEATH(AntialiasBackward({s.color, 3, s.rast, too_few, s.mesh.tris, s.topology}, record, s.color,
                                 grad_color, grad_too_few),
               "names vertex");
  const std::vector<int32_t> first_triangles(s.mesh.tris.begin(), s.mesh.tris.begin() + 3 * 14);
  const EdgeTopology first_topology = BuildEdgeTopology(first_triangles, s.mesh.NumVertices());
  ASSERT_GT(*std::max_element(s.rast.triangle.begin(), s.rast.triangle.end()), 13);
  EXPECT_DEATH(Antialias({s.color, 3, s.rast, s.clip, first_triangles, first_topology}, out, &record),
               "a raster buffer of another mesh");
  EXPECT_DEATH(AntialiasBackward({s.color, 3, s.rast, s.clip, first_triangles, first_topology}, record, s.color,
                                 grad_color, grad_clip),
               "a raster buffer of another mesh");
  const AntialiasInputs matching{s.color, 3, s.rast, s.clip, s.mesh.tris, s.topology};
  Antialias(matching, out, &record);
  AntialiasBackward(matching, record, s.color, grad_color, grad_clip);
}

// --- the whole chain ---------------------------------------------------------------------------------------

// World positions -> TransformToClip -> Rasterize -> Interpolate (vertex colours) -> Antialias -> sum w . out,
// differentiated by chaining the four backward passes the way mesh refinement does, against central
// differences on the world positions. A perturbation that changes any pixel's triangle, the set of blended
// pairs, or passes a crossing through t = 1/2, is a jump or a kink of the rendered image: those coordinates
// are skipped (a few percent at this step; the count is checked). Step h = 5e-4 world units (~0.01 px at this
// camera), from measurements: the error (relative to 1 + |fd|) is float noise of the outputs and shrinks as
// the step grows: 4.7e-3 at h = 1e-4, 2.4e-3 at 2e-4, 6e-4 at 5e-4, while skips grow (2%, 2%, 5%).
// Tolerance 3e-3 * (1 + |fd|).
TEST(AntialiasBackward, WholeChainMatchesFiniteDifferencesOnWorldPositions) {
  constexpr int kSize = 48;
  for (uint32_t seed : {5u, 6u}) {
    const testing::Mesh mesh = testing::Sphere(8, 14, 1.0f, 0.2f, seed);
    const EdgeTopology topology = BuildEdgeTopology(mesh.tris, mesh.NumVertices());
    std::mt19937 rng(seed);
    const Eigen::Matrix4f M =
        ClipFromWorld(testing::SquareCamera(kSize, 0.8), testing::LookAtOrigin(rng, 3.0), 0.5f, 6.f);
    std::uniform_real_distribution<float> unit(0, 1);
    std::vector<float> vertex_color(3 * mesh.NumVertices());
    for (float& c : vertex_color) c = unit(rng);
    std::vector<float> weights(3 * static_cast<size_t>(kSize) * kSize);
    for (float& w : weights) w = 2 * unit(rng) - 1;

    struct Forward {
      std::vector<float> clip, color, out;
      RasterBuffer rast;
      AntialiasRecord record;
      double loss = 0;
    };
    auto forward = [&](const std::vector<float>& positions) {
      Forward f;
      f.clip = testing::ToClip(positions, M);
      Rasterize({f.clip, mesh.tris, kSize, kSize}, &f.rast);
      f.color.resize(3 * f.rast.NumPixels());
      Interpolate({vertex_color, 3, mesh.tris, f.rast}, f.color);
      f.out.resize(f.color.size());
      Antialias({f.color, 3, f.rast, f.clip, mesh.tris, topology}, f.out, &f.record);
      for (size_t n = 0; n < f.out.size(); ++n) f.loss += double(weights[n]) * f.out[n];
      return f;
    };
    const Forward base = forward(mesh.positions);
    std::vector<float> grad_color(base.color.size(), 0.0f), grad_clip(base.clip.size(), 0.0f);
    AntialiasBackward({base.color, 3, base.rast, base.clip, mesh.tris, topology}, base.record, weights, grad_color,
                      grad_clip);
    std::vector<float> grad_attr(vertex_color.size(), 0.0f), grad_bary(2 * base.rast.NumPixels(), 0.0f);
    InterpolateBackward({vertex_color, 3, mesh.tris, base.rast}, grad_color, grad_attr, grad_bary);
    RasterizeBackward({base.clip, mesh.tris, kSize, kSize}, base.rast, grad_bary, {}, grad_clip);
    std::vector<float> grad_positions(mesh.positions.size(), 0.0f);
    TransformToClipBackward(M, grad_clip, grad_positions);

    const float h = 5e-4f;
    int checked = 0, skipped = 0;
    double max_err = 0;
    for (size_t n = 0; n < mesh.positions.size(); ++n) {
      std::vector<float> plus = mesh.positions, minus = mesh.positions;
      plus[n] += h, minus[n] -= h;
      const Forward fp = forward(plus), fm = forward(minus);
      if (fp.rast.triangle != base.rast.triangle || fm.rast.triangle != base.rast.triangle ||
          !SamePairs(fp.record, base.record) || !SamePairs(fm.record, base.record) ||
          CrossesHalf(base.record, fp.record, fm.record)) {
        ++skipped;
        continue;
      }
      const double fd = (fp.loss - fm.loss) / (double(plus[n]) - minus[n]);
      const double err = std::abs(grad_positions[n] - fd) / (1 + std::abs(fd));
      max_err = std::max(max_err, err);
      EXPECT_LE(err, 3e-3) << "seed " << seed << " coordinate " << n << " analytic " << grad_positions[n] << " fd "
                           << fd;
      ++checked;
    }
    EXPECT_GT(checked, 2 * skipped) << "too many coordinates skipped";
    std::printf("seed %u: %d coordinates checked, %d skipped, max err %.2e\n", seed, checked, skipped, max_err);
  }
}

// Deterministic whatever the thread count: forward outputs and every gradient are bitwise equal with one
// thread and with all of them.
TEST(AntialiasBackward, ChainIsIndependentOfThreadCount) {
  constexpr int kSize = 160;
  const testing::Mesh mesh = testing::Sphere(30, 60, 1.0f, 0.1f);
  const EdgeTopology topology = BuildEdgeTopology(mesh.tris, mesh.NumVertices());
  std::mt19937 rng(12);
  const std::vector<float> clip = testing::ToClip(
      mesh.positions, ClipFromWorld(testing::SquareCamera(kSize), testing::LookAtOrigin(rng, 3.0), 0.5f, 6.f));
  std::vector<float> vertex_color(3 * mesh.NumVertices());
  std::uniform_real_distribution<float> unit(0, 1);
  for (float& c : vertex_color) c = unit(rng);
  std::vector<float> grad_out(3 * static_cast<size_t>(kSize) * kSize);
  for (float& g : grad_out) g = unit(rng) - 0.5f;
  auto run = [&]() {
    RasterBuffer rast;
    Rasterize({clip, mesh.tris, kSize, kSize}, &rast);
    std::vector<float> color(3 * rast.NumPixels()), out(color.size());
    Interpolate({vertex_color, 3, mesh.tris, rast}, color);
    AntialiasRecord record;
    Antialias({color, 3, rast, clip, mesh.tris, topology}, out, &record);
    std::vector<float> grad_color(color.size(), 0.0f), grad_clip(clip.size(), 0.0f);
    AntialiasBackward({color, 3, rast, clip, mesh.tris, topology}, record, grad_out, grad_color, grad_clip);
    std::vector<float> grad_attr(vertex_color.size(), 0.0f), grad_bary(2 * rast.NumPixels(), 0.0f);
    InterpolateBackward({vertex_color, 3, mesh.tris, rast}, grad_color, grad_attr, grad_bary);
    RasterizeBackward({clip, mesh.tris, kSize, kSize}, rast, grad_bary, rast.depth, grad_clip);
    return std::vector<std::vector<float>>{out, grad_clip, grad_attr};
  };
  const auto all_threads = run();
  SetMaxThreads(1);
  const auto one_thread = run();
  SetMaxThreads(0);
  EXPECT_EQ(all_threads, one_thread);
}

// --- gradient descent: the outline moves ---------------------------------------------------------------------

// A 1-channel coverage mask of a square, antialiased, L2 against the antialiased mask of the same square
// shifted by (1.5, 1.0) px. Plain gradient descent on the 4 vertices' positions must bring the square onto
// the target; the only gradient to the geometry is the antialiasing one (a coverage mask has no gradient
// through the barycentrics), so this proves that the outline moves the right way.
TEST(Antialias, GradientDescentMovesSquareOntoShiftedTarget) {
  constexpr int kSize = 48;
  const std::vector<int32_t> tris = {0, 1, 2, 0, 2, 3};
  const EdgeTopology topology = BuildEdgeTopology(tris, 4);
  const double shift_u = 1.5, shift_v = 1.0;
  const Quad target_quad = MakeQuad(14.3 + shift_u, 12.6 + shift_v, 33.8 + shift_u, 31.2 + shift_v, kSize, kSize);
  RasterBuffer rast;
  AntialiasRecord record;
  const std::vector<float> target = AntialiasedMask(target_quad.clip, tris, topology, kSize, kSize, &rast, &record);

  Quad q = MakeQuad(14.3, 12.6, 33.8, 31.2, kSize, kSize);
  auto loss_and_gradient = [&](std::vector<float>* grad_clip) {
    const std::vector<float> out = AntialiasedMask(q.clip, tris, topology, kSize, kSize, &rast, &record);
    std::vector<float> grad_out(out.size());
    double loss = 0;
    for (size_t p = 0; p < out.size(); ++p) {
      loss += (out[p] - target[p]) * (out[p] - target[p]);
      grad_out[p] = 2 * (out[p] - target[p]);
    }
    const std::vector<float> mask = CoverageMask(rast);
    std::vector<float> grad_color(mask.size(), 0.0f);
    grad_clip->assign(q.clip.size(), 0.0f);
    AntialiasBackward({mask, 1, rast, q.clip, tris, topology}, record, grad_out, grad_color, *grad_clip);
    return loss;
  };
  std::vector<float> grad_clip;
  const double initial_loss = loss_and_gradient(&grad_clip);
  // Step in pixels: du = -rate * dL/du, where dL/du = dL/dx * 2/W (w = 1). Each vertex sits on two edges
  // ~20 px long, so dL/du is ~20 x the per-row error: rate 0.02 moves ~0.4 px per step at first.
  const double rate = 0.02, px_per_clip = kSize / 2.0;
  double loss = initial_loss;
  for (int step = 0; step < 60; ++step) {
    for (int v = 0; v < 4; ++v)
      for (int c = 0; c < 2; ++c) {
        const double dL_dpx = grad_clip[4 * v + c] / px_per_clip;
        q.clip[4 * v + c] -= static_cast<float>(rate * dL_dpx / px_per_clip);
      }
    loss = loss_and_gradient(&grad_clip);
  }
  std::printf("loss %.4f -> %.6f\n", initial_loss, loss);
  EXPECT_LT(loss, 1e-3 * initial_loss);
  for (int v = 0; v < 4; ++v) {
    EXPECT_NEAR(q.clip[4 * v], target_quad.clip[4 * v], 0.05 / px_per_clip) << "vertex " << v << " u";
    EXPECT_NEAR(q.clip[4 * v + 1], target_quad.clip[4 * v + 1], 0.05 / px_per_clip) << "vertex " << v << " v";
  }
}

}  // namespace
}  // namespace sd::raster
