// The device switch, and agreement of the CUDA ops with the CPU ops on the same inputs (skipped where no
// CUDA GPU is visible: build with -DSYNTHDRIVE_WITH_CUDA=ON and run on a GPU machine). The gradient tests of
// the other raster test files run on the GPU too with SYNTHDRIVE_DEVICE=cuda.
//
// Tolerances, as raster.h states them: the forward ops and the antialias backward must agree bit for bit
// (the same shared.h arithmetic, no FMA, the antialias per-pair loops on the host in the same order); the
// gradient scatters of RasterizeBackward / InterpolateBackward sum in another order, so they get a relative
// bound of 1e-6 of the largest gradient.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdlib>
#include <random>
#include <vector>

#include "core/error.h"
#include "raster/normal_mask_loss.h"
#include "raster/raster.h"
#include "raster/test_util.h"

namespace sd::raster {
namespace {

// Everything the ops produce for one mesh and camera: a normal-map-like interpolation, its antialiasing, and
// the whole backward chain from a random upstream gradient.
struct ChainResult {
  RasterBuffer rast;
  std::vector<float> interpolated, antialiased;
  AntialiasRecord record;
  std::vector<float> grad_color_aa, grad_clip_aa;        // AntialiasBackward alone
  std::vector<float> grad_attr, grad_bary, grad_clip;    // InterpolateBackward + RasterizeBackward (with depth)
};

ChainResult RunChain(const std::vector<float>& clip, const std::vector<int32_t>& tris, int size,
                     const std::vector<float>& vertex_attr, const std::vector<float>& grad_out, bool color_gradient) {
  ChainResult r;
  Rasterize({clip, tris, size, size}, &r.rast);
  r.interpolated.resize(3 * r.rast.NumPixels());
  Interpolate({vertex_attr, 3, tris, r.rast}, r.interpolated);
  const EdgeTopology topology = BuildEdgeTopology(tris, static_cast<int>(clip.size() / 4));
  r.antialiased.resize(r.interpolated.size());
  Antialias({r.interpolated, 3, r.rast, clip, tris, topology}, r.antialiased, &r.record, color_gradient);
  r.grad_color_aa.assign(r.interpolated.size(), 0.0f);
  r.grad_clip_aa.assign(clip.size(), 0.0f);
  AntialiasBackward({r.interpolated, 3, r.rast, clip, tris, topology}, r.record, grad_out, r.grad_color_aa,
                    r.grad_clip_aa);
  r.grad_attr.assign(vertex_attr.size(), 0.0f);
  r.grad_bary.assign(2 * r.rast.NumPixels(), 0.0f);
  InterpolateBackward({vertex_attr, 3, tris, r.rast}, r.grad_color_aa, r.grad_attr, r.grad_bary);
  r.grad_clip.assign(clip.size(), 0.0f);
  RasterizeBackward({clip, tris, size, size}, r.rast, r.grad_bary, r.rast.depth, r.grad_clip);
  return r;
}

// Largest |a - b| relative to the largest |a|.
double RelativeError(const std::vector<float>& a, const std::vector<float>& b) {
  EXPECT_EQ(a.size(), b.size());
  double diff = 0, scale = 0;
  for (size_t i = 0; i < std::min(a.size(), b.size()); ++i) {
    diff = std::max(diff, static_cast<double>(std::abs(a[i] - b[i])));
    scale = std::max(scale, static_cast<double>(std::abs(a[i])));
  }
  return scale > 0 ? diff / scale : diff;
}

bool SamePairs(const AntialiasRecord& a, const AntialiasRecord& b) {
  if (a.pairs.size() != b.pairs.size()) return false;
  for (size_t i = 0; i < a.pairs.size(); ++i) {
    const auto &p = a.pairs[i], &q = b.pairs[i];
    if (p.pixel_a != q.pixel_a || p.pixel_b != q.pixel_b || p.triangle != q.triangle || p.edge != q.edge ||
        p.alpha != q.alpha)
      return false;
  }
  return true;
}

class DeviceScope {  // restores the CPU when a test ends, whatever happens
 public:
  ~DeviceScope() { SetDevice(Device::kCpu); }
};

TEST(Device, ParseAndRefusal) {
  DeviceScope scope;
  EXPECT_EQ(ParseDevice("cpu"), Device::kCpu);
  EXPECT_EQ(ParseDevice("cuda"), Device::kCuda);
  EXPECT_THROW(ParseDevice("gpu"), InputError);
  EXPECT_STREQ(ToString(Device::kCuda), "cuda");
  SetDevice(Device::kCpu);
  EXPECT_FALSE(UseCuda());
  EXPECT_THROW(NormalMaskLoss({}), InputError);  // the device-resident loss is for CUDA only
  SetDevice(Device::kCuda);
  if (CudaAvailable()) {
    EXPECT_TRUE(UseCuda());
  } else {
    // Asked for the GPU without one: every op refuses rather than quietly running on the CPU.
    EXPECT_THROW(UseCuda(), InputError);
    RasterBuffer rast;
    EXPECT_THROW(Rasterize({{}, {}, 4, 4}, &rast), InputError);
  }
}

#define SD_REQUIRE_CUDA()                                                                          \
  do {                                                                                             \
    if (!CudaAvailable()) GTEST_SKIP() << "no CUDA GPU visible (or a build without CUDA): CPU/GPU " \
                                          "agreement not checked";                                 \
  } while (0)

TEST(CudaAgreement, BumpySpheresAtRandomCameras) {
  SD_REQUIRE_CUDA();
  DeviceScope scope;
  std::printf("device: %s\n", CudaDeviceDescription().c_str());
  std::mt19937 rng(31);
  std::uniform_real_distribution<float> unit(0, 1);
  int checked = 0;
  for (const auto& [stacks, size, bump] : std::vector<std::tuple<int, int, float>>{
           {12, 64, 0.0f}, {40, 160, 0.1f}, {80, 320, 0.15f}, {120, 257, 0.05f}}) {
    const testing::Mesh mesh = testing::Sphere(stacks, 2 * stacks, 1.0f, bump, static_cast<uint32_t>(stacks));
    for (int view = 0; view < 3; ++view) {
      const std::vector<float> clip = testing::ToClip(
          mesh.positions, ClipFromWorld(testing::SquareCamera(size), testing::LookAtOrigin(rng, 3.0), 0.5f, 6.f));
      std::vector<float> attr(3 * mesh.NumVertices());
      for (float& a : attr) a = unit(rng);
      std::vector<float> grad_out(3 * static_cast<size_t>(size) * size);
      for (float& g : grad_out) g = unit(rng) - 0.5f;
      for (bool color_gradient : {true, false}) {
        SetDevice(Device::kCpu);
        const ChainResult cpu = RunChain(clip, mesh.tris, size, attr, grad_out, color_gradient);
        SetDevice(Device::kCuda);
        const ChainResult gpu = RunChain(clip, mesh.tris, size, attr, grad_out, color_gradient);
        SCOPED_TRACE(::testing::Message() << stacks << " stacks, " << size << " px, view " << view);
        EXPECT_EQ(cpu.rast.triangle, gpu.rast.triangle);
        EXPECT_EQ(cpu.rast.bary, gpu.rast.bary);
        EXPECT_EQ(cpu.rast.depth, gpu.rast.depth);
        EXPECT_EQ(cpu.interpolated, gpu.interpolated);
        EXPECT_TRUE(SamePairs(cpu.record, gpu.record)) << cpu.record.pairs.size() << " vs " << gpu.record.pairs.size();
        EXPECT_EQ(cpu.antialiased, gpu.antialiased);
        EXPECT_EQ(cpu.grad_color_aa, gpu.grad_color_aa);
        EXPECT_EQ(cpu.grad_clip_aa, gpu.grad_clip_aa);
        EXPECT_LE(RelativeError(cpu.grad_bary, gpu.grad_bary), 1e-6);
        EXPECT_LE(RelativeError(cpu.grad_attr, gpu.grad_attr), 1e-6);
        EXPECT_LE(RelativeError(cpu.grad_clip, gpu.grad_clip), 1e-6);
        EXPECT_GT(cpu.record.pairs.size(), 0u);
        ++checked;
      }
    }
  }
  EXPECT_EQ(checked, 24);
}

// Vertices on pixel centres, shared edges through pixel centres, and coplanar overlapping triangles (equal
// depth: the lower index must win on both devices).
TEST(CudaAgreement, TiesOnPixelCentresAndEqualDepth) {
  SD_REQUIRE_CUDA();
  DeviceScope scope;
  constexpr int kSize = 48;
  std::vector<float> clip;
  std::vector<int32_t> tris;
  constexpr int kGrid = 9;  // (kGrid + 1)^2 vertices on pixel centres 4 px apart
  for (int y = 0; y <= kGrid; ++y)
    for (int x = 0; x <= kGrid; ++x) {
      const double u = 4.5 + 4 * x, v = 4.5 + 4 * y;
      clip.insert(clip.end(), {static_cast<float>(2 * u / kSize - 1), static_cast<float>(2 * v / kSize - 1), 0.0f, 1.0f});
    }
  for (int y = 0; y < kGrid; ++y)
    for (int x = 0; x < kGrid; ++x) {
      const int32_t a = y * (kGrid + 1) + x, b = a + 1, c = a + kGrid + 1, d = c + 1;
      tris.insert(tris.end(), {a, b, d, a, d, c});
    }
  const size_t grid_tris = tris.size();
  tris.insert(tris.end(), tris.begin(), tris.begin() + static_cast<std::ptrdiff_t>(grid_tris));  // same depth, higher index
  RasterBuffer cpu, gpu;
  SetDevice(Device::kCpu);
  Rasterize({clip, tris, kSize, kSize}, &cpu);
  SetDevice(Device::kCuda);
  Rasterize({clip, tris, kSize, kSize}, &gpu);
  EXPECT_EQ(cpu.triangle, gpu.triangle);
  EXPECT_EQ(cpu.bary, gpu.bary);
  EXPECT_EQ(cpu.depth, gpu.depth);
  for (int32_t t : gpu.triangle) EXPECT_LT(t, static_cast<int32_t>(grid_tris / 3));
}

TEST(CudaAgreement, EmptyInputsAndDeviceCopyReuse) {
  SD_REQUIRE_CUDA();
  DeviceScope scope;
  SetDevice(Device::kCuda);
  RasterBuffer rast;
  Rasterize({{}, {}, 16, 8}, &rast);
  EXPECT_EQ(std::count(rast.triangle.begin(), rast.triangle.end(), -1), 16 * 8);
  Rasterize({{}, {}, 0, 0}, &rast);
  EXPECT_EQ(rast.NumPixels(), 0u);
  // Two rasterizations in flight, and one changed by the caller: the ops must read each one's own data.
  const testing::Mesh mesh = testing::Sphere(20, 40, 1.0f);
  std::mt19937 rng(5);
  const std::vector<float> clip_a = testing::ToClip(
      mesh.positions, ClipFromWorld(testing::SquareCamera(64), testing::LookAtOrigin(rng, 3.0), 0.5f, 6.f));
  const std::vector<float> clip_b = testing::ToClip(
      mesh.positions, ClipFromWorld(testing::SquareCamera(64), testing::LookAtOrigin(rng, 3.0), 0.5f, 6.f));
  RasterBuffer a, b;
  Rasterize({clip_a, mesh.tris, 64, 64}, &a);
  Rasterize({clip_b, mesh.tris, 64, 64}, &b);
  b.bary[2 * (32 * 64 + 32)] += 0.25f;  // what the finite-difference tests do to a copy
  std::vector<float> ia(3 * a.NumPixels()), ib(ia.size());
  Interpolate({mesh.positions, 3, mesh.tris, a}, ia);
  Interpolate({mesh.positions, 3, mesh.tris, b}, ib);
  SetDevice(Device::kCpu);
  std::vector<float> ca(ia.size()), cb(ib.size());
  Interpolate({mesh.positions, 3, mesh.tris, a}, ca);
  Interpolate({mesh.positions, 3, mesh.tris, b}, cb);
  EXPECT_EQ(ia, ca);
  EXPECT_EQ(ib, cb);
}

// The device-resident refinement loss against the same two terms evaluated on the CPU with the ops, the way
// assetgen/refine.cpp does: interpolated normals vs a target normal map, antialiased coverage vs a mask.
NormalMaskLoss::Terms CpuNormalMaskLoss(const NormalMaskView& v, const std::vector<float>& positions,
                                        const std::vector<float>& normals, const std::vector<int32_t>& tris,
                                        const EdgeTopology& topology, std::vector<float>* grad_positions,
                                        std::vector<float>* grad_normals) {
  const size_t nv = positions.size() / 3, np = static_cast<size_t>(v.width) * v.height;
  std::vector<float> clip(4 * nv);
  TransformToClip(positions, v.clip_from_world, clip);
  const RasterizeInputs raster_in{clip, tris, v.width, v.height};
  RasterBuffer rast;
  Rasterize(raster_in, &rast);
  std::vector<float> grad_clip(4 * nv, 0.0f), grad_bary(2 * np, 0.0f), img(3 * np), grad_img(3 * np, 0.0f);
  NormalMaskLoss::Terms terms;
  Interpolate({normals, 3, tris, rast}, img);
  double sum = 0;
  for (size_t p = 0; p < np; ++p) {
    const Eigen::Vector3f t = Eigen::Map<const Eigen::Vector3f>(&v.normals[3 * p]);
    const Eigen::Vector3f n = Eigen::Map<const Eigen::Vector3f>(&img[3 * p]);
    const float len = n.norm();
    if (rast.triangle[p] < 0 || v.mask[p] <= 0.5f || t.squaredNorm() < 0.5f || len < 1e-8f) continue;
    const Eigen::Vector3f nh = n / len, d = nh - t;
    sum += d.squaredNorm();
    const Eigen::Vector3f g = v.normal_grad_scale * 2.0f * (d - nh * nh.dot(d)) / len;
    for (int c = 0; c < 3; ++c) grad_img[3 * p + c] = g[c];
  }
  terms.normal = sum * v.normal_loss_scale;
  grad_normals->assign(3 * nv, 0.0f);
  InterpolateBackward({normals, 3, tris, rast}, grad_img, *grad_normals, grad_bary);
  RasterizeBackward(raster_in, rast, grad_bary, {}, grad_clip);
  std::vector<float> coverage(np), aa(np), grad_aa(np), grad_coverage(np, 0.0f);
  for (size_t p = 0; p < np; ++p) coverage[p] = rast.triangle[p] >= 0 ? 1.0f : 0.0f;
  AntialiasRecord record;
  Antialias({coverage, 1, rast, clip, tris, topology}, aa, &record, /*color_gradient=*/false);
  sum = 0;
  for (size_t p = 0; p < np; ++p) {
    if (v.mask[p] < 0) {  // unknown: past the source image's border
      grad_aa[p] = 0;
      continue;
    }
    const float d = aa[p] - v.mask[p];
    sum += d * d;
    grad_aa[p] = v.mask_grad_scale * 2.0f * d;
  }
  terms.mask = sum * v.mask_loss_scale;
  AntialiasBackward({coverage, 1, rast, clip, tris, topology}, record, grad_aa, grad_coverage, grad_clip);
  grad_positions->assign(3 * nv, 0.0f);
  TransformToClipBackward(v.clip_from_world, grad_clip, *grad_positions);
  return terms;
}

TEST(CudaAgreement, DeviceResidentRefinementLossMatchesTheOps) {
  SD_REQUIRE_CUDA();
  DeviceScope scope;
  constexpr int kSize = 200;
  // Targets: a bumpy sphere's normals and coverage; the mesh evaluated: a smooth sphere of another radius.
  const testing::Mesh target = testing::Sphere(40, 80, 1.0f, 0.08f, 3);
  const testing::Mesh mesh = testing::Sphere(30, 60, 0.9f);
  const EdgeTopology target_topology = BuildEdgeTopology(target.tris, target.NumVertices());
  const EdgeTopology topology = BuildEdgeTopology(mesh.tris, mesh.NumVertices());
  auto normals_of = [](const testing::Mesh& m) {  // unit radial directions: a sphere's normals
    std::vector<float> n(m.positions.size());
    for (size_t v = 0; v < n.size() / 3; ++v) {
      const Eigen::Vector3f p = Eigen::Map<const Eigen::Vector3f>(&m.positions[3 * v]);
      Eigen::Map<Eigen::Vector3f> out(&n[3 * v]);
      out = p.normalized();
    }
    return n;
  };
  const std::vector<float> target_normals = normals_of(target), normals = normals_of(mesh);
  std::mt19937 rng(8);
  std::vector<NormalMaskView> views;
  SetDevice(Device::kCpu);
  for (int i = 0; i < 3; ++i) {
    NormalMaskView v;
    v.clip_from_world = ClipFromWorld(testing::SquareCamera(kSize), testing::LookAtOrigin(rng, 3.0), 0.5f, 6.f);
    v.width = v.height = kSize;
    const std::vector<float> clip = testing::ToClip(target.positions, v.clip_from_world);
    RasterBuffer rast;
    Rasterize({clip, target.tris, kSize, kSize}, &rast);
    v.normals.resize(3 * rast.NumPixels());
    Interpolate({target_normals, 3, target.tris, rast}, v.normals);
    std::vector<float> coverage(rast.NumPixels());
    for (size_t p = 0; p < coverage.size(); ++p) coverage[p] = rast.triangle[p] >= 0 ? 1.0f : 0.0f;
    v.mask.resize(coverage.size());
    AntialiasRecord record;
    Antialias({coverage, 1, rast, clip, target.tris, target_topology}, v.mask, &record, false);
    v.normal_grad_scale = 0.5f / 5000, v.normal_loss_scale = 1.0f / 5000;
    v.mask_grad_scale = 0.7f / 8000, v.mask_loss_scale = 1.0f / 8000;
    // The last view is cut by an image border: its left third unknown (a negative target, no term).
    if (i == 2)
      for (size_t p = 0; p < v.mask.size(); ++p)
        if (static_cast<int>(p % kSize) < kSize / 3) v.mask[p] = -1.0f;
    views.push_back(std::move(v));
  }
  SetDevice(Device::kCuda);
  NormalMaskLoss loss(views);
  // One evaluation against the CPU: per view its terms, and the gradients summed over the views in view order.
  auto check = [&](const testing::Mesh& m, const EdgeTopology& m_topology) {
    const std::vector<float> m_normals = normals_of(m);
    const size_t nv = m.positions.size() / 3;
    std::vector<float> cpu_gp(3 * nv, 0.0f), cpu_gn(3 * nv, 0.0f);
    std::vector<NormalMaskLoss::Terms> cpu_terms;
    SetDevice(Device::kCpu);
    for (const NormalMaskView& v : views) {
      std::vector<float> gp, gn;
      cpu_terms.push_back(CpuNormalMaskLoss(v, m.positions, m_normals, m.tris, m_topology, &gp, &gn));
      for (size_t i = 0; i < 3 * nv; ++i) cpu_gp[i] += gp[i], cpu_gn[i] += gn[i];
    }
    SetDevice(Device::kCuda);
    std::vector<float> gp(3 * nv), gn(3 * nv);
    const std::vector<NormalMaskLoss::Terms> terms =
        loss.Evaluate({m.positions, m_normals, m.tris, m_topology}, gp, gn);
    ASSERT_EQ(terms.size(), views.size());
    for (size_t v = 0; v < views.size(); ++v) {
      SCOPED_TRACE(::testing::Message() << "view " << v);
      EXPECT_GT(cpu_terms[v].normal, 0);
      EXPECT_GT(cpu_terms[v].mask, 0);
      EXPECT_NEAR(terms[v].normal, cpu_terms[v].normal, 1e-5 * cpu_terms[v].normal);
      EXPECT_NEAR(terms[v].mask, cpu_terms[v].mask, 1e-5 * cpu_terms[v].mask);
    }
    EXPECT_LE(RelativeError(cpu_gp, gp), 1e-5);
    EXPECT_LE(RelativeError(cpu_gn, gn), 1e-5);
  };
  {
    SCOPED_TRACE("smooth sphere");
    check(mesh, topology);
  }
  // Another connectivity, as after a remeshing pass: the loss must not evaluate the first mesh's triangles
  // (it uploads the connectivity only when it changes).
  const testing::Mesh finer = testing::Sphere(36, 72, 0.95f, 0.02f, 5);
  {
    SCOPED_TRACE("finer sphere");
    check(finer, BuildEdgeTopology(finer.tris, finer.NumVertices()));
  }
  {
    SCOPED_TRACE("smooth sphere again");
    check(mesh, topology);
  }
}

// The loss's kernels index positions and normals by tris without checks: a tris array naming a vertex past
// them stops at the entry with the culprit named.
TEST(CudaAgreementDeathTest, RefinementLossRefusesIndicesPastTheVertices) {
  SD_REQUIRE_CUDA();
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  DeviceScope scope;
  constexpr int kSize = 16;
  const testing::Mesh mesh = testing::Sphere(6, 10, 1.0f);
  const EdgeTopology topology = BuildEdgeTopology(mesh.tris, mesh.NumVertices());
  std::mt19937 rng(2);
  NormalMaskView v;
  v.clip_from_world = ClipFromWorld(testing::SquareCamera(kSize), testing::LookAtOrigin(rng, 3.0), 0.5f, 6.f);
  v.width = v.height = kSize;
  v.normals.assign(3 * kSize * kSize, 0.0f);
  v.mask.assign(kSize * kSize, 0.0f);
  v.mask_grad_scale = v.mask_loss_scale = 1.0f;
  SetDevice(Device::kCuda);
  NormalMaskLoss loss({v});
  const std::vector<float> too_few(mesh.positions.begin(), mesh.positions.end() - 3);
  std::vector<float> g(too_few.size());
  EXPECT_DEATH(loss.Evaluate({too_few, too_few, mesh.tris, topology}, g, g), "names vertex");
  std::vector<float> gp(mesh.positions.size()), gn(mesh.positions.size());
  loss.Evaluate({mesh.positions, mesh.positions, mesh.tris, topology}, gp, gn);
}

}  // namespace
}  // namespace sd::raster
