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
#include "raster/loss.h"
#include "raster/normals.h"
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

// Refinement's loss (assetgen/refine.cpp) composed of the ops, on buffers of one side: the normal term
// (interpolated normals against a target normal map) and the silhouette term (antialiased coverage against a
// mask), and beside them an antialiased 3-channel colour with its colour gradient. Everything comes back to
// the host for comparison.
struct LossTargets {
  Eigen::Matrix4f clip_from_world;
  std::vector<float> normals, mask;  // 3 and 1 per pixel; mask < 0: unknown
};
struct LossChain {
  std::vector<int32_t> triangle;
  std::vector<float> bary, depth, normal_img, aa, color_aa;
  std::vector<double> sums;  // normal, mask
  std::vector<float> grad_positions, grad_normals, grad_color, grad_color_clip;
};

LossChain RunLossChain(Memory where, const LossTargets& v, int size, const std::vector<float>& positions_h,
                       const std::vector<float>& normals_h, const std::vector<int32_t>& tris_h,
                       const EdgeTopology& topology_h) {
  const size_t nv = positions_h.size() / 3, np = static_cast<size_t>(size) * size;
  std::vector<float> color_upstream(3 * np);
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> unit(-1, 1);
  for (float& g : color_upstream) g = unit(rng);
  auto on_side = [&](const auto& host) {
    Buffer<typename std::decay_t<decltype(host)>::value_type> b(where);
    b.CopyFrom(host);
    return b;
  };
  const Buffer<float> positions = on_side(positions_h), normals = on_side(normals_h);
  const Buffer<float> target_normals = on_side(v.normals), target_mask = on_side(v.mask);
  const Buffer<int32_t> tris = on_side(tris_h);
  EdgeTopology topology{Buffer<int32_t>(where)};
  topology.neighbour.CopyFrom(topology_h.neighbour.host());
  Buffer<float> clip(where, 4 * nv), grad_clip(where), img(where, 3 * np), grad_img(where, 3 * np),
      grad_bary(where), coverage(where, np), aa(where, np), grad_aa(where, np), grad_positions(where),
      grad_normals(where), color_aa(where, 3 * np), grad_color(where), grad_color_clip(where);
  Buffer<double> sums(where);
  sums.assign(2, 0.0);
  grad_clip.assign(4 * nv, 0.0f);
  grad_bary.assign(2 * np, 0.0f);
  grad_positions.assign(3 * nv, 0.0f);
  grad_normals.assign(3 * nv, 0.0f);
  grad_color.assign(3 * np, 0.0f);
  grad_color_clip.assign(4 * nv, 0.0f);
  const Span<double> normal_sum(sums.data(), 1, where), mask_sum(sums.data() + 1, 1, where);

  TransformToClip(positions, v.clip_from_world, clip);
  const RasterizeInputs raster_in{clip, tris, size, size};
  RasterBuffer rast(where);
  Rasterize(raster_in, &rast);
  const InterpolateInputs normals_in{normals, 3, tris, rast};
  Interpolate(normals_in, img);
  UnitVectorLoss({img, rast, target_normals, target_mask}, 0.5f / 5000, grad_img, normal_sum);
  InterpolateBackward(normals_in, grad_img, grad_normals, grad_bary);
  RasterizeBackward(raster_in, rast, grad_bary, {}, grad_clip);
  Coverage(rast, coverage);
  const AntialiasInputs coverage_in{coverage, 1, rast, clip, tris, topology};
  AntialiasRecord record;
  Antialias(coverage_in, aa, &record, /*color_gradient=*/false);
  SquaredErrorLoss(aa, target_mask, 0.7f / 8000, grad_aa, mask_sum);
  AntialiasBackward(coverage_in, record, grad_aa, {}, grad_clip);
  TransformToClipBackward(v.clip_from_world, grad_clip, grad_positions);
  // The interpolated normals as a colour, antialiased with its colour gradient, from a random upstream gradient.
  const AntialiasInputs color_in{img, 3, rast, clip, tris, topology};
  AntialiasRecord color_record;
  Antialias(color_in, color_aa, &color_record, /*color_gradient=*/true);
  AntialiasBackward(color_in, color_record, on_side(color_upstream), grad_color, grad_color_clip);

  LossChain out;
  out.triangle = rast.triangle.ToHost();
  out.bary = rast.bary.ToHost();
  out.depth = rast.depth.ToHost();
  out.normal_img = img.ToHost();
  out.aa = aa.ToHost();
  out.color_aa = color_aa.ToHost();
  out.sums = sums.ToHost();
  out.grad_positions = grad_positions.ToHost();
  out.grad_normals = grad_normals.ToHost();
  out.grad_color = grad_color.ToHost();
  out.grad_color_clip = grad_color_clip.ToHost();
  return out;
}

TEST(DeviceBuffers, TheLossComposedOnTheDeviceMatchesTheHost) {
  SD_REQUIRE_CUDA();
  DeviceScope scope;
  SetDevice(Device::kCpu);  // host buffers run on the CPU; device buffers on the GPU whatever the switch says
  constexpr int kSize = 200;
  // Targets: a bumpy sphere's normals and antialiased coverage; the meshes evaluated: other spheres.
  const testing::Mesh target = testing::Sphere(40, 80, 1.0f, 0.08f, 3);
  const EdgeTopology target_topology = BuildEdgeTopology(target.tris, target.NumVertices());
  auto normals_of = [](const testing::Mesh& m) {  // unit radial directions: a sphere's normals
    std::vector<float> n(m.positions.size());
    for (size_t v = 0; v < n.size() / 3; ++v) {
      Eigen::Map<Eigen::Vector3f> out(&n[3 * v]);
      out = Eigen::Map<const Eigen::Vector3f>(&m.positions[3 * v]).normalized();
    }
    return n;
  };
  const std::vector<float> target_normals = normals_of(target);
  std::mt19937 rng(8);
  std::vector<LossTargets> views;
  for (int i = 0; i < 3; ++i) {
    LossTargets v;
    v.clip_from_world = ClipFromWorld(testing::SquareCamera(kSize), testing::LookAtOrigin(rng, 3.0), 0.5f, 6.f);
    const std::vector<float> clip = testing::ToClip(target.positions, v.clip_from_world);
    RasterBuffer rast;
    Rasterize({clip, target.tris, kSize, kSize}, &rast);
    v.normals.resize(3 * rast.NumPixels());
    Interpolate({target_normals, 3, target.tris, rast}, v.normals);
    std::vector<float> coverage(rast.NumPixels());
    Coverage(rast, coverage);
    v.mask.resize(coverage.size());
    AntialiasRecord record;
    Antialias({coverage, 1, rast, clip, target.tris, target_topology}, v.mask, &record, false);
    // The last view is cut by an image border: its left third unknown (a negative target, no term).
    if (i == 2)
      for (size_t p = 0; p < v.mask.size(); ++p)
        if (static_cast<int>(p % kSize) < kSize / 3) v.mask[p] = -1.0f;
    views.push_back(std::move(v));
  }
  auto check = [&](const testing::Mesh& m) {
    const EdgeTopology topology = BuildEdgeTopology(m.tris, m.NumVertices());
    const std::vector<float> normals = normals_of(m);
    for (size_t vi = 0; vi < views.size(); ++vi) {
      SCOPED_TRACE(::testing::Message() << "view " << vi);
      const LossChain host = RunLossChain(Memory::kHost, views[vi], kSize, m.positions, normals, m.tris, topology);
      const LossChain device = RunLossChain(Memory::kDevice, views[vi], kSize, m.positions, normals, m.tris, topology);
      // The forward ops run the same shared.h arithmetic: bit for bit.
      EXPECT_EQ(host.triangle, device.triangle);
      EXPECT_EQ(host.bary, device.bary);
      EXPECT_EQ(host.depth, device.depth);
      EXPECT_EQ(host.normal_img, device.normal_img);
      // Blends and sums meet in another order on the device (float atomics per pixel, double per vertex).
      EXPECT_LE(RelativeError(host.aa, device.aa), 1e-6);
      EXPECT_LE(RelativeError(host.color_aa, device.color_aa), 1e-6);
      ASSERT_EQ(device.sums.size(), 2u);
      EXPECT_GT(host.sums[0], 0);
      EXPECT_GT(host.sums[1], 0);
      EXPECT_NEAR(device.sums[0], host.sums[0], 1e-5 * host.sums[0]);
      EXPECT_NEAR(device.sums[1], host.sums[1], 1e-5 * host.sums[1]);
      EXPECT_LE(RelativeError(host.grad_positions, device.grad_positions), 1e-5);
      EXPECT_LE(RelativeError(host.grad_normals, device.grad_normals), 1e-5);
      EXPECT_LE(RelativeError(host.grad_color, device.grad_color), 1e-5);
      EXPECT_LE(RelativeError(host.grad_color_clip, device.grad_color_clip), 1e-5);
    }
  };
  {
    SCOPED_TRACE("smooth sphere");
    check(testing::Sphere(30, 60, 0.9f));
  }
  {
    SCOPED_TRACE("finer bumpy sphere");  // another connectivity, as after a remeshing pass
    check(testing::Sphere(36, 72, 0.95f, 0.02f, 5));
  }
}

// The vertex normals and their backward gather per vertex in the host's order: the same bits on the device.
TEST(DeviceBuffers, VertexNormalsAndTheirBackwardMatchTheHostBitForBit) {
  SD_REQUIRE_CUDA();
  testing::Mesh m = testing::Sphere(60, 120, 1.0f, 0.1f, 4);
  m.tris.insert(m.tris.end(), {3, 3, 9});                     // a degenerate face
  m.positions.insert(m.positions.end(), {2.0f, 0.5f, -0.25f});  // a vertex without faces
  const size_t nv = m.positions.size() / 3;
  const VertexFaces host_incidence = BuildVertexFaces(m.tris, m.NumVertices());
  std::vector<float> normals(3 * nv), grad(3 * nv), grad_normals(3 * nv);
  std::vector<double> sums(3 * nv);
  std::mt19937 rng(6);
  std::uniform_real_distribution<float> unit(-1, 1);
  for (float& g : grad_normals) g = unit(rng);
  for (float& g : grad) g = unit(rng);
  const std::vector<float> start = grad;
  VertexNormals(m.positions, m.tris, host_incidence, normals, sums);
  VertexNormalsBackward(m.positions, m.tris, host_incidence, sums, grad_normals, grad);

  Buffer<float> d_positions(Memory::kDevice), d_normals(Memory::kDevice, 3 * nv), d_grad(Memory::kDevice),
      d_grad_normals(Memory::kDevice);
  Buffer<double> d_sums(Memory::kDevice, 3 * nv);
  Buffer<int32_t> d_tris(Memory::kDevice);
  VertexFaces incidence{Buffer<int32_t>(Memory::kDevice), Buffer<int32_t>(Memory::kDevice)};
  d_positions.CopyFrom(m.positions);
  d_grad.CopyFrom(start);
  d_grad_normals.CopyFrom(grad_normals);
  d_tris.CopyFrom(m.tris);
  incidence.offset.CopyFrom(std::span<const int32_t>(host_incidence.offset.host()));
  incidence.corner.CopyFrom(std::span<const int32_t>(host_incidence.corner.host()));
  VertexNormals(d_positions, d_tris, incidence, d_normals, d_sums);
  VertexNormalsBackward(d_positions, d_tris, incidence, d_sums, d_grad_normals, d_grad);
  EXPECT_EQ(d_normals.ToHost(), normals);
  EXPECT_EQ(d_sums.ToHost(), sums);
  EXPECT_EQ(d_grad.ToHost(), grad);
}

// On device buffers the index contracts are kernels: a tris array naming a vertex past the positions, or a
// raster of another mesh, aborts at the next download with the contract named, and the kernels in between
// read nothing out of bounds (compute-sanitizer would say).
TEST(DeviceBuffersDeathTest, IndicesOutsideTheirBuffersAbortAtTheDownload) {
  SD_REQUIRE_CUDA();
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  DeviceScope scope;
  constexpr int kSize = 16;
  const testing::Mesh mesh = testing::Sphere(6, 10, 1.0f);
  std::mt19937 rng(2);
  const Eigen::Matrix4f M = ClipFromWorld(testing::SquareCamera(kSize), testing::LookAtOrigin(rng, 3.0), 0.5f, 6.f);
  const std::vector<float> clip_h = testing::ToClip(mesh.positions, M);
  Buffer<float> clip(Memory::kDevice), too_few(Memory::kDevice);
  clip.CopyFrom(clip_h);
  too_few.CopyFrom(std::span<const float>(clip_h.data(), clip_h.size() - 4));
  Buffer<int32_t> tris(Memory::kDevice);
  tris.CopyFrom(mesh.tris);
  auto rasterize_past_the_vertices = [&] {
    RasterBuffer rast(Memory::kDevice);
    Rasterize({too_few, tris, kSize, kSize}, &rast);
    rast.triangle.ToHost();
  };
  EXPECT_DEATH(rasterize_past_the_vertices(), "naming a vertex past");
  auto interpolate_another_mesh = [&] {  // a raster of the whole sphere used with only its first triangle
    RasterBuffer rast(Memory::kDevice);
    Rasterize({clip, tris, kSize, kSize}, &rast);
    Buffer<float> attr(Memory::kDevice), out(Memory::kDevice, 3 * rast.NumPixels());
    attr.CopyFrom(mesh.positions);
    Interpolate({attr, 3, Span<const int32_t>(tris.data(), 3, Memory::kDevice), rast}, out);
    out.ToHost();
  };
  EXPECT_DEATH(interpolate_another_mesh(), "raster buffer whose triangle ids");
  auto normals_of_another_mesh = [&] {  // an incidence whose last corner lies past the triangles
    VertexFaces host = BuildVertexFaces(mesh.tris, mesh.NumVertices());
    host.corner.host().back() = static_cast<int32_t>(mesh.tris.size());
    VertexFaces incidence{Buffer<int32_t>(Memory::kDevice), Buffer<int32_t>(Memory::kDevice)};
    incidence.offset.CopyFrom(std::span<const int32_t>(host.offset.host()));
    incidence.corner.CopyFrom(std::span<const int32_t>(host.corner.host()));
    Buffer<float> positions(Memory::kDevice), normals(Memory::kDevice, mesh.positions.size());
    Buffer<double> sums(Memory::kDevice, mesh.positions.size());
    positions.CopyFrom(mesh.positions);
    VertexNormals(positions, tris, incidence, normals, sums);
    normals.ToHost();
  };
  EXPECT_DEATH(normals_of_another_mesh(), "vertex-face incidence that does not fit");
  // Within the contracts nothing is raised.
  RasterBuffer rast(Memory::kDevice);
  Rasterize({clip, tris, kSize, kSize}, &rast);
  const std::vector<int32_t> triangle = rast.triangle.ToHost();
  EXPECT_GT(std::count_if(triangle.begin(), triangle.end(), [](int32_t t) { return t >= 0; }), 0);
}

}  // namespace
}  // namespace sd::raster
