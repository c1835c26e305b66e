// CUDA kernels of the raster ops (see raster_cuda.h for how the work is spread). Built with --fmad=false so
// that the arithmetic of raster/shared.h rounds as on the CPU.
#include "raster/cuda/raster_cuda.h"

#include <algorithm>
#include <memory>
#include <stdexcept>
#include <string>

#include <cub/device/device_scan.cuh>
#include <cuda_runtime.h>

namespace sd::raster::cuda {
namespace {

void Check(cudaError_t status, const char* what) {
  if (status != cudaSuccess)
    throw std::runtime_error(std::string("CUDA ") + what + ": " + cudaGetErrorString(status));
}
#define SD_CUDA(call) Check((call), #call)

constexpr int kThreads = 256;
inline unsigned Blocks(size_t n) { return static_cast<unsigned>((n + kThreads - 1) / kThreads); }

// The cover pass's fixed grid: enough resident blocks to fill the device (its threads stride over the work).
unsigned CoverBlocks() {
  static const unsigned blocks = [] {
    int device = 0, sms = 0, per_sm = 0;
    SD_CUDA(cudaGetDevice(&device));
    SD_CUDA(cudaDeviceGetAttribute(&sms, cudaDevAttrMultiProcessorCount, device));
    SD_CUDA(cudaDeviceGetAttribute(&per_sm, cudaDevAttrMaxThreadsPerMultiProcessor, device));
    return static_cast<unsigned>(std::max(1, sms * (per_sm / kThreads)));
  }();
  return blocks;
}

// Device memory that grows and is never given back while its owner lives: the ops run many times on images
// and meshes of similar size, and cudaMalloc per call would cost more than the kernels.
template <typename T>
class Scratch {
 public:
  Scratch() = default;
  Scratch(const Scratch&) = delete;
  Scratch& operator=(const Scratch&) = delete;
  ~Scratch() {
    if (ptr_) cudaFree(ptr_);  // may run after the context is gone at exit: nothing to report then
  }
  T* Get(size_t n) {
    if (n > capacity_) {
      if (ptr_) SD_CUDA(cudaFree(ptr_));
      ptr_ = nullptr;
      const size_t grown = n + n / 4;
      SD_CUDA(cudaMalloc(&ptr_, grown * sizeof(T)));
      capacity_ = grown;
    }
    return ptr_;
  }
  T* Upload(const T* host, size_t n) {
    T* d = Get(n);
    if (n) SD_CUDA(cudaMemcpy(d, host, n * sizeof(T), cudaMemcpyHostToDevice));
    return d;
  }

 private:
  T* ptr_ = nullptr;
  size_t capacity_ = 0;
};

template <typename T>
void Download(T* host, const T* device, size_t n) {
  if (n) SD_CUDA(cudaMemcpy(host, device, n * sizeof(T), cudaMemcpyDeviceToHost));
}

// Per host thread: the ops may be called from several threads at once (views in parallel), each then works
// on its own buffers and, with per-thread default streams, its own stream.
struct Workspace {
  Scratch<float> clip, attr, color, grad_a, grad_b, out;
  Scratch<int32_t> tris, neighbour, pair_offset;
  Scratch<double> sum, normal_ds;
  Scratch<shared::TriangleSetup> setup;
  Scratch<unsigned long long> area, key;
  Scratch<uint8_t> scan_temp;
  Scratch<shared::ScreenVertex> screen;
  Scratch<int8_t> facing;
  Scratch<PairRecord> pairs, compact_pairs;
  Scratch<shared::PairGeometry> geometry, compact_geometry;
  Scratch<float> r_bary, r_depth;  // a rasterization
  Scratch<int32_t> r_triangle;
};
thread_local Workspace workspace;

// ---- rasterize ---------------------------------------------------------------------------------------------

// The index contracts of an op on device buffers (raster/buffer.h), checked by the kernels as they read each
// index: one out of range raises the calling thread's flag and is not used, and once the flag is up the kernels
// that index do nothing. A null flag: the host-staged path, whose inputs the host checked.
struct Contract {
  int32_t* flag = nullptr;
  size_t num_vertices = 0, num_tris = 0;

  __device__ bool Raised() const { return flag != nullptr && *static_cast<volatile int32_t*>(flag) != 0; }
  __device__ bool Raise(int32_t violation) const {
    atomicCAS(flag, 0, violation);
    return false;
  }
  // Triangle t's vertex indices name vertices.
  __device__ bool VerticesOk(const int32_t* tris, size_t t) const {
    if (flag == nullptr) return true;
    for (int k = 0; k < 3; ++k) {
      const int32_t v = tris[3 * t + k];
      if (v < 0 || static_cast<size_t>(v) >= num_vertices) return Raise(kVertexIndex);
    }
    return true;
  }
  // A raster's triangle id t >= 0 names a triangle, whose vertex indices name vertices.
  __device__ bool TriangleOk(const int32_t* tris, int32_t t) const {
    if (flag == nullptr) return true;
    if (static_cast<size_t>(t) >= num_tris) return Raise(kRasterTriangle);
    return VerticesOk(tris, static_cast<size_t>(t));
  }
};

__global__ void SetUpKernel(const float* clip, const int32_t* tris, size_t num_tris, int width, int height,
                            shared::TriangleSetup* setup, unsigned long long* area, Contract contract) {
  const size_t t = blockIdx.x * static_cast<size_t>(blockDim.x) + threadIdx.x;
  if (t >= num_tris) return;
  if (contract.Raised() || !contract.VerticesOk(tris, t)) {  // no pixel reads this triangle's set-up then
    area[t] = 0;
    return;
  }
  const shared::TriangleSetup s = shared::SetUpTriangle(clip, tris, t, width, height);
  setup[t] = s;
  area[t] = s.Empty() ? 0ull : static_cast<unsigned long long>(s.x1 - s.x0 + 1) * (s.y1 - s.y0 + 1);
}

// Monotone map of a float to unsigned bits (negative floats reversed), with -0 folded onto +0 as the CPU's
// comparison treats them.
__device__ __forceinline__ unsigned OrderedBits(float f) {
  if (f == 0.0f) f = 0.0f;
  const unsigned bits = __float_as_uint(f);
  return (bits & 0x80000000u) ? ~bits : (bits | 0x80000000u);
}

// `inclusive_area[num_tris - 1]` is the number of (triangle, pixel) pairs: read here on the device, so the
// host need not wait for the prefix sum to size the grid (a fixed grid strides over however many there are).
__global__ void CoverKernel(const shared::TriangleSetup* setup, const unsigned long long* inclusive_area,
                            size_t num_tris, int width, int height, unsigned long long* key) {
  const unsigned long long total = inclusive_area[num_tris - 1];
  for (unsigned long long idx = blockIdx.x * static_cast<unsigned long long>(blockDim.x) + threadIdx.x; idx < total;
       idx += static_cast<unsigned long long>(gridDim.x) * blockDim.x) {
    // The triangle whose range of the prefix sum holds idx: the first with inclusive_area > idx.
    size_t lo = 0, hi = num_tris;
    while (lo < hi) {
      const size_t mid = (lo + hi) / 2;
      if (inclusive_area[mid] > idx) hi = mid;
      else lo = mid + 1;
    }
    const size_t t = lo;
    const shared::TriangleSetup& s = setup[t];
    const unsigned long long local = idx - (t ? inclusive_area[t - 1] : 0ull);
    const int box_width = s.x1 - s.x0 + 1;
    const int i = s.x0 + static_cast<int>(local % box_width), j = s.y0 + static_cast<int>(local / box_width);
    const double px = shared::PixelCentreNdc(i, width), py = shared::PixelCentreNdc(j, height);
    float depth_f;
    double e[3];
    if (!shared::CoverPixel(s, px, shared::EdgeRow(s.edge[0], py), shared::EdgeRow(s.edge[1], py),
                            shared::EdgeRow(s.edge[2], py), &depth_f, e))
      continue;
    const unsigned long long k = (static_cast<unsigned long long>(OrderedBits(depth_f)) << 32) | static_cast<unsigned>(t);
    atomicMin(&key[static_cast<size_t>(j) * width + i], k);
  }
}

__global__ void ResolveKernel(const shared::TriangleSetup* setup, const unsigned long long* key, int width,
                              int height, float* bary, float* depth, int32_t* triangle) {
  const size_t pixel = blockIdx.x * static_cast<size_t>(blockDim.x) + threadIdx.x;
  if (pixel >= static_cast<size_t>(width) * height) return;
  const unsigned long long k = key[pixel];
  if (k == ~0ull) {
    triangle[pixel] = -1, depth[pixel] = 1.0f, bary[2 * pixel] = 0.0f, bary[2 * pixel + 1] = 0.0f;
    return;
  }
  const int32_t t = static_cast<int32_t>(k & 0xffffffffull);
  const shared::TriangleSetup& s = setup[t];
  const int i = static_cast<int>(pixel % width), j = static_cast<int>(pixel / width);
  const double px = shared::PixelCentreNdc(i, width), py = shared::PixelCentreNdc(j, height);
  float depth_f;
  double e[3];
  shared::CoverPixel(s, px, shared::EdgeRow(s.edge[0], py), shared::EdgeRow(s.edge[1], py),
                     shared::EdgeRow(s.edge[2], py), &depth_f, e);
  triangle[pixel] = t;
  depth[pixel] = depth_f;
  shared::Barycentrics(e, &bary[2 * pixel], &bary[2 * pixel + 1]);
}

// Device copy of a host raster.
struct DeviceRaster {
  const float* bary;
  const float* depth;
  const int32_t* triangle;
};
DeviceRaster Resident(const RasterView& rast) {
  Workspace& ws = workspace;
  const size_t np = static_cast<size_t>(rast.width) * rast.height;
  return {ws.r_bary.Upload(rast.bary, 2 * np), ws.r_depth.Upload(rast.depth, np), ws.r_triangle.Upload(rast.triangle, np)};
}

// Rasterizes clip-space vertices already on the device into the workspace's raster buffers: the set-up, the
// prefix sum of the bounding boxes, the depth test by atomicMin over a fixed grid that strides over the
// summed box areas (no host sync: refinement's loss queues a whole evaluation, every view, before it waits),
// and the winners' barycentrics.
DeviceRaster RasterizeOnDevice(const float* d_clip, const int32_t* d_tris, size_t num_tris, int width, int height,
                               float* bary, float* depth, int32_t* triangle, Contract contract) {
  Workspace& ws = workspace;
  const size_t np = static_cast<size_t>(width) * height;
  unsigned long long* key = ws.key.Get(np);
  SD_CUDA(cudaMemsetAsync(key, 0xff, np * sizeof(unsigned long long), cudaStreamPerThread));
  shared::TriangleSetup* setup = ws.setup.Get(std::max<size_t>(num_tris, 1));
  if (num_tris > 0) {
    unsigned long long* area = ws.area.Get(2 * num_tris);  // [0, n): areas, [n, 2n): inclusive prefix sums
    SetUpKernel<<<Blocks(num_tris), kThreads>>>(d_clip, d_tris, num_tris, width, height, setup, area, contract);
    SD_CUDA(cudaGetLastError());
    size_t temp_bytes = 0;
    SD_CUDA(cub::DeviceScan::InclusiveSum(nullptr, temp_bytes, area, area + num_tris, static_cast<int64_t>(num_tris)));
    SD_CUDA(cub::DeviceScan::InclusiveSum(ws.scan_temp.Get(temp_bytes), temp_bytes, area, area + num_tris,
                                          static_cast<int64_t>(num_tris), cudaStreamPerThread));
    CoverKernel<<<CoverBlocks(), kThreads>>>(setup, area + num_tris, num_tris, width, height, key);
    SD_CUDA(cudaGetLastError());
  }
  ResolveKernel<<<Blocks(np), kThreads>>>(setup, key, width, height, bary, depth, triangle);
  SD_CUDA(cudaGetLastError());
  return {bary, depth, triangle};
}

// ---- rasterize backward / interpolate -----------------------------------------------------------------------

__global__ void RasterizeBackwardKernel(const float* clip, const int32_t* tris, int width, int height,
                                        DeviceRaster rast, const float* grad_bary, const float* grad_depth,
                                        double* sum, Contract contract) {
  const size_t pixel = blockIdx.x * static_cast<size_t>(blockDim.x) + threadIdx.x;
  if (pixel >= static_cast<size_t>(width) * height) return;
  const int32_t t = rast.triangle[pixel];
  if (t < 0 || contract.Raised() || !contract.TriangleOk(tris, t)) return;
  const float gb0 = grad_bary[2 * pixel], gb1 = grad_bary[2 * pixel + 1];
  const float gd = grad_depth ? grad_depth[pixel] : 0.0f;
  if (gb0 == 0.0f && gb1 == 0.0f && gd == 0.0f) return;
  const int i = static_cast<int>(pixel % width), j = static_cast<int>(pixel / width);
  float g[12];
  if (!shared::PixelGradient(clip, tris, t, shared::PixelCentreNdc(i, width), shared::PixelCentreNdc(j, height), gb0,
                             gb1, gd, g))
    return;
  for (int k = 0; k < 3; ++k) {
    double* s = &sum[4 * static_cast<size_t>(tris[3 * static_cast<size_t>(t) + k])];
    for (int c = 0; c < 4; ++c) atomicAdd(&s[c], static_cast<double>(g[4 * k + c]));
  }
}

__global__ void InterpolateKernel(const float* attr, int channels, const int32_t* tris, size_t num_pixels,
                                  DeviceRaster rast, float* out, Contract contract) {
  const size_t pixel = blockIdx.x * static_cast<size_t>(blockDim.x) + threadIdx.x;
  if (pixel >= num_pixels) return;
  const size_t C = static_cast<size_t>(channels);
  int32_t t = rast.triangle[pixel];
  if (t >= 0 && (contract.Raised() || !contract.TriangleOk(tris, t))) t = -1;  // written as background
  shared::InterpolatePixel(attr, C, tris, t, rast.bary[2 * pixel], rast.bary[2 * pixel + 1],
                           &out[C * pixel]);
}

__global__ void InterpolateBackwardKernel(const float* attr, int channels, const int32_t* tris, size_t num_pixels,
                                          DeviceRaster rast, const float* grad_out, double* sum, float* grad_bary,
                                          Contract contract) {
  const size_t pixel = blockIdx.x * static_cast<size_t>(blockDim.x) + threadIdx.x;
  if (pixel >= num_pixels) return;
  const int32_t t = rast.triangle[pixel];
  if (t < 0 || contract.Raised() || !contract.TriangleOk(tris, t)) return;
  const size_t C = static_cast<size_t>(channels);
  const float* g = &grad_out[C * pixel];
  if (grad_bary) {
    float d0, d1;
    shared::InterpolateBaryGradient(attr, C, tris, t, g, &d0, &d1);
    grad_bary[2 * pixel] += d0;
    grad_bary[2 * pixel + 1] += d1;
  }
  const float b0 = rast.bary[2 * pixel], b1 = rast.bary[2 * pixel + 1];
  const float b[3] = {b0, b1, 1.0f - b0 - b1};
  for (int k = 0; k < 3; ++k) {
    double* s = &sum[C * static_cast<size_t>(tris[3 * static_cast<size_t>(t) + k])];
    for (size_t c = 0; c < C; ++c) atomicAdd(&s[c], static_cast<double>(b[k]) * g[c]);
  }
}

// ---- antialias ---------------------------------------------------------------------------------------------

__global__ void ProjectKernel(const float* clip, size_t num_vertices, int width, int height,
                              shared::ScreenVertex* screen) {
  const size_t v = blockIdx.x * static_cast<size_t>(blockDim.x) + threadIdx.x;
  if (v < num_vertices) screen[v] = shared::Project(clip, static_cast<int32_t>(v), width, height);
}

__global__ void FacingKernel(const float* clip, const int32_t* tris, size_t num_tris, int8_t* facing,
                             Contract contract) {
  const size_t t = blockIdx.x * static_cast<size_t>(blockDim.x) + threadIdx.x;
  if (t >= num_tris) return;
  // Every triangle's vertices are checked here, before the pair search walks from triangle to triangle.
  if (contract.Raised() || !contract.VerticesOk(tris, t)) facing[t] = 0;
  else facing[t] = static_cast<int8_t>(shared::ScreenFacing(clip, tris, t));
}

// Slot 2 * pixel + 0: the pair with the right neighbour, + 1: with the lower one (the CPU's order).
__global__ void PairKernel(shared::AntialiasScene sc, const float* color, int channels, bool skip_equal_colors,
                           int32_t* found, PairRecord* pairs /* nullable */, shared::PairGeometry* geometry,
                           Contract contract) {
  const size_t a_index = blockIdx.x * static_cast<size_t>(blockDim.x) + threadIdx.x;
  if (a_index >= static_cast<size_t>(sc.width) * sc.height) return;
  // Both pixels' triangle ids are checked before the search reads their triangles' neighbours.
  auto id_ok = [&](int32_t pixel) {
    const int32_t t = sc.triangle[pixel];
    return contract.flag == nullptr || t < 0 || static_cast<size_t>(t) < contract.num_tris ||
           contract.Raise(kRasterTriangle);
  };
  if (contract.Raised() || !id_ok(static_cast<int32_t>(a_index))) {
    found[2 * a_index] = found[2 * a_index + 1] = 0;
    return;
  }
  const int32_t a = static_cast<int32_t>(a_index);
  const int i = a % sc.width, j = a / sc.width;
  for (int dir = 0; dir < 2; ++dir) {
    const size_t slot = 2 * a_index + dir;
    found[slot] = 0;
    const int32_t b = dir == 0 ? (i + 1 < sc.width ? a + 1 : -1) : (j + 1 < sc.height ? a + sc.width : -1);
    if (b < 0 || sc.triangle[a] == sc.triangle[b] || !id_ok(b)) continue;
    if (skip_equal_colors) {
      bool same = true;
      for (int c = 0; c < channels; ++c)
        if (color[static_cast<size_t>(channels) * a + c] != color[static_cast<size_t>(channels) * b + c]) same = false;
      if (same) continue;
    }
    shared::PairGeometry g;
    if (!shared::ExaminePair(sc, a, b, &g)) continue;
    found[slot] = 1;
    if (pairs) pairs[slot] = {a, b, g.triangle, g.edge, shared::BlendOf(g).alpha};
    geometry[slot] = g;
  }
}

__global__ void CompactKernel(const int32_t* found, const int32_t* offset, size_t num_slots, const PairRecord* pairs,
                              const shared::PairGeometry* geometry, PairRecord* out_pairs,
                              shared::PairGeometry* out_geometry) {
  const size_t slot = blockIdx.x * static_cast<size_t>(blockDim.x) + threadIdx.x;
  if (slot >= num_slots || !found[slot]) return;
  out_pairs[offset[slot]] = pairs[slot];
  out_geometry[offset[slot]] = geometry[slot];
}

__global__ void RecordedGeometryKernel(shared::AntialiasScene sc, const PairRecord* pairs, size_t num_pairs,
                                       shared::PairGeometry* geometry, int32_t* mismatch) {
  const size_t n = blockIdx.x * static_cast<size_t>(blockDim.x) + threadIdx.x;
  if (n >= num_pairs) return;
  const PairRecord& p = pairs[n];
  if (!shared::RecordedPair(sc, p.pixel_a, p.pixel_b, p.triangle, p.edge, &geometry[n])) atomicExch(mismatch, 1);
}

// The antialias scene of device inputs: projected vertices and facings in the thread's scratch, for the pair
// kernels.
shared::AntialiasScene DeviceResidentScene(const AntialiasInputs& in, Contract contract) {
  Workspace& ws = workspace;
  const int width = in.rast.width, height = in.rast.height;
  shared::ScreenVertex* screen = ws.screen.Get(std::max<size_t>(in.num_vertices, 1));
  int8_t* facing = ws.facing.Get(std::max<size_t>(in.num_tris, 1));
  if (in.num_vertices) ProjectKernel<<<Blocks(in.num_vertices), kThreads>>>(in.clip, in.num_vertices, width, height, screen);
  if (in.num_tris) FacingKernel<<<Blocks(in.num_tris), kThreads>>>(in.clip, in.tris, in.num_tris, facing, contract);
  SD_CUDA(cudaGetLastError());
  return {width, height, in.rast.triangle, in.rast.depth, in.tris, in.neighbour, screen, facing};
}

// The same of host inputs, uploaded first (the host checked their indices).
shared::AntialiasScene DeviceScene(const AntialiasInputs& in) {
  Workspace& ws = workspace;
  const DeviceRaster r = Resident(in.rast);
  AntialiasInputs uploaded = in;
  uploaded.rast = {in.rast.width, in.rast.height, r.bary, r.depth, r.triangle};
  uploaded.clip = ws.clip.Upload(in.clip, 4 * in.num_vertices);
  uploaded.tris = ws.tris.Upload(in.tris, 3 * in.num_tris);
  uploaded.neighbour = ws.neighbour.Upload(in.neighbour, 3 * in.num_tris);
  return DeviceResidentScene(uploaded, Contract{});
}

}  // namespace

bool Available() {
  static const bool available = [] {
    int count = 0;
    return cudaGetDeviceCount(&count) == cudaSuccess && count > 0;
  }();
  return available;
}

const char* DeviceDescription() {
  static const std::string description = [] {
    if (!Available()) return std::string();
    int device = 0;
    cudaDeviceProp prop{};
    if (cudaGetDevice(&device) != cudaSuccess || cudaGetDeviceProperties(&prop, device) != cudaSuccess) return std::string();
    const long long gib = static_cast<long long>(static_cast<double>(prop.totalGlobalMem) / (1024.0 * 1024.0 * 1024.0) + 0.5);
    return std::string(prop.name) + ", " + std::to_string(prop.multiProcessorCount) + " SMs, " + std::to_string(gib) + " GiB";
  }();
  return description.c_str();
}

void Rasterize(const RasterizeInputs& in, RasterOut out) {
  Workspace& ws = workspace;
  const size_t np = static_cast<size_t>(in.width) * in.height;
  if (np == 0) return;
  const DeviceRaster r = RasterizeOnDevice(ws.clip.Upload(in.clip, 4 * in.num_vertices),
                                           ws.tris.Upload(in.tris, 3 * in.num_tris), in.num_tris, in.width, in.height,
                                           ws.r_bary.Get(2 * np), ws.r_depth.Get(np), ws.r_triangle.Get(np), Contract{});
  Download(out.bary, r.bary, 2 * np);
  Download(out.depth, r.depth, np);
  Download(out.triangle, r.triangle, np);
}

void RasterizeBackward(const RasterizeInputs& in, const RasterView& rast, const float* grad_bary,
                       const float* grad_depth, double* grad_clip_sum) {
  Workspace& ws = workspace;
  const size_t np = static_cast<size_t>(rast.width) * rast.height, num_vertices = in.num_vertices;
  const DeviceRaster r = Resident(rast);
  const float* d_clip = ws.clip.Upload(in.clip, 4 * num_vertices);
  const int32_t* d_tris = ws.tris.Upload(in.tris, 3 * in.num_tris);
  const float* d_grad_bary = ws.grad_a.Upload(grad_bary, 2 * np);
  const float* d_grad_depth = grad_depth ? ws.grad_b.Upload(grad_depth, np) : nullptr;
  double* sum = ws.sum.Get(4 * num_vertices);
  SD_CUDA(cudaMemset(sum, 0, 4 * num_vertices * sizeof(double)));
  if (np) {
    RasterizeBackwardKernel<<<Blocks(np), kThreads>>>(d_clip, d_tris, rast.width, rast.height, r, d_grad_bary,
                                                      d_grad_depth, sum, Contract{});
    SD_CUDA(cudaGetLastError());
  }
  Download(grad_clip_sum, sum, 4 * num_vertices);
}

void Interpolate(const InterpolateInputs& in, float* out) {
  Workspace& ws = workspace;
  const size_t np = static_cast<size_t>(in.rast.width) * in.rast.height, C = static_cast<size_t>(in.channels);
  if (np == 0) return;
  const DeviceRaster r = Resident(in.rast);
  const float* d_attr = ws.attr.Upload(in.attr, C * in.num_attr_vertices);
  const int32_t* d_tris = ws.tris.Upload(in.tris, 3 * in.num_tris);
  float* d_out = ws.out.Get(C * np);
  InterpolateKernel<<<Blocks(np), kThreads>>>(d_attr, in.channels, d_tris, np, r, d_out, Contract{});
  SD_CUDA(cudaGetLastError());
  Download(out, d_out, C * np);
}

void InterpolateBackward(const InterpolateInputs& in, const float* grad_out, double* grad_attr_sum, float* grad_bary) {
  Workspace& ws = workspace;
  const size_t np = static_cast<size_t>(in.rast.width) * in.rast.height, C = static_cast<size_t>(in.channels);
  const size_t num_attr_vertices = in.num_attr_vertices;
  const DeviceRaster r = Resident(in.rast);
  const float* d_attr = ws.attr.Upload(in.attr, C * num_attr_vertices);
  const int32_t* d_tris = ws.tris.Upload(in.tris, 3 * in.num_tris);
  const float* d_grad_out = ws.grad_a.Upload(grad_out, C * np);
  float* d_grad_bary = grad_bary ? ws.grad_b.Upload(grad_bary, 2 * np) : nullptr;
  double* sum = ws.sum.Get(C * num_attr_vertices);
  SD_CUDA(cudaMemset(sum, 0, C * num_attr_vertices * sizeof(double)));
  if (np) {
    InterpolateBackwardKernel<<<Blocks(np), kThreads>>>(d_attr, in.channels, d_tris, np, r, d_grad_out, sum,
                                                        d_grad_bary, Contract{});
    SD_CUDA(cudaGetLastError());
  }
  Download(grad_attr_sum, sum, C * num_attr_vertices);
  if (grad_bary) Download(grad_bary, d_grad_bary, 2 * np);
}

void FindAntialiasPairs(const AntialiasInputs& in, bool skip_equal_colors, std::vector<PairRecord>* pairs,
                        std::vector<shared::PairGeometry>* geometry) {
  Workspace& ws = workspace;
  const size_t np = static_cast<size_t>(in.rast.width) * in.rast.height, slots = 2 * np;
  pairs->clear();
  geometry->clear();
  if (np == 0) return;
  const shared::AntialiasScene sc = DeviceScene(in);
  const float* d_color = skip_equal_colors ? ws.color.Upload(in.color, static_cast<size_t>(in.channels) * np) : nullptr;
  int32_t* found = ws.pair_offset.Get(2 * slots);  // [0, slots): found flags, [slots, 2 slots): offsets
  int32_t* offset = found + slots;
  PairRecord* slot_pairs = ws.pairs.Get(slots);
  shared::PairGeometry* slot_geometry = ws.geometry.Get(slots);
  PairKernel<<<Blocks(np), kThreads>>>(sc, d_color, in.channels, skip_equal_colors, found, slot_pairs, slot_geometry,
                                       Contract{});
  SD_CUDA(cudaGetLastError());
  size_t temp_bytes = 0;
  SD_CUDA(cub::DeviceScan::ExclusiveSum(nullptr, temp_bytes, found, offset, static_cast<int64_t>(slots)));
  SD_CUDA(cub::DeviceScan::ExclusiveSum(ws.scan_temp.Get(temp_bytes), temp_bytes, found, offset,
                                        static_cast<int64_t>(slots)));
  int32_t last_offset = 0, last_found = 0;
  Download(&last_offset, offset + slots - 1, 1);
  Download(&last_found, found + slots - 1, 1);
  const size_t count = static_cast<size_t>(last_offset) + static_cast<size_t>(last_found);
  if (count == 0) return;
  PairRecord* out_pairs = ws.compact_pairs.Get(count);
  shared::PairGeometry* out_geometry = ws.compact_geometry.Get(count);
  CompactKernel<<<Blocks(slots), kThreads>>>(found, offset, slots, slot_pairs, slot_geometry, out_pairs, out_geometry);
  SD_CUDA(cudaGetLastError());
  pairs->resize(count);
  geometry->resize(count);
  Download(pairs->data(), out_pairs, count);
  Download(geometry->data(), out_geometry, count);
}

bool RecordedPairGeometry(const AntialiasInputs& in, const PairRecord* pairs, size_t num_pairs,
                          std::vector<shared::PairGeometry>* geometry) {
  Workspace& ws = workspace;
  geometry->resize(num_pairs);
  if (num_pairs == 0) return true;
  const shared::AntialiasScene sc = DeviceScene(in);
  const PairRecord* d_pairs = ws.pairs.Upload(pairs, num_pairs);
  shared::PairGeometry* d_geometry = ws.geometry.Get(num_pairs);
  int32_t* mismatch = ws.pair_offset.Get(1);
  SD_CUDA(cudaMemset(mismatch, 0, sizeof(int32_t)));
  RecordedGeometryKernel<<<Blocks(num_pairs), kThreads>>>(sc, d_pairs, num_pairs, d_geometry, mismatch);
  SD_CUDA(cudaGetLastError());
  int32_t host_mismatch = 0;
  Download(&host_mismatch, mismatch, 1);
  Download(geometry->data(), d_geometry, num_pairs);
  return host_mismatch == 0;
}

}  // namespace sd::raster::cuda

// ---- device-resident buffers and the ops on them -----------------------------------------------------------
namespace sd::raster::cuda {
namespace {

// The calling thread's contract flag (raster/buffer.h), zeroed when first made.
int32_t* ContractFlag() {
  thread_local Scratch<int32_t> flag;
  thread_local bool zeroed = false;
  int32_t* d = flag.Get(1);
  if (!zeroed) {
    SD_CUDA(cudaMemset(d, 0, sizeof(int32_t)));
    zeroed = true;
  }
  return d;
}

struct Matrix4 {  // row-major, passed by value to the kernels
  float m[16];
};
Matrix4 ToMatrix4(const float M[16]) {
  Matrix4 out;
  std::copy(M, M + 16, out.m);
  return out;
}

template <typename Word>
__global__ void FillKernel(Word* out, Word pattern, size_t n) {
  const size_t i = blockIdx.x * static_cast<size_t>(blockDim.x) + threadIdx.x;
  if (i < n) out[i] = pattern;
}
template <typename Word>
void Fill(void* ptr, Word pattern, size_t count) {
  if (count == 0) return;
  FillKernel<<<Blocks(count), kThreads>>>(static_cast<Word*>(ptr), pattern, count);
  SD_CUDA(cudaGetLastError());
}

// clip = M (p, 1), as clip.cpp's Eigen product rounds it (one product and sum per row, in column order).
__global__ void ToClipKernel(const float* positions, size_t num_vertices, Matrix4 M, float* clip) {
  const size_t v = blockIdx.x * static_cast<size_t>(blockDim.x) + threadIdx.x;
  if (v >= num_vertices) return;
  const float x = positions[3 * v], y = positions[3 * v + 1], z = positions[3 * v + 2];
  for (int r = 0; r < 4; ++r)
    clip[4 * v + r] = M.m[4 * r] * x + M.m[4 * r + 1] * y + M.m[4 * r + 2] * z + M.m[4 * r + 3] * 1.0f;
}

// grad_positions += M[:, 0:3]^T grad_clip per vertex.
__global__ void ToClipBackwardKernel(const float* grad_clip, size_t num_vertices, Matrix4 M, float* grad_positions) {
  const size_t v = blockIdx.x * static_cast<size_t>(blockDim.x) + threadIdx.x;
  if (v >= num_vertices) return;
  const float* g = &grad_clip[4 * v];
  for (int k = 0; k < 3; ++k)
    grad_positions[3 * v + k] += M.m[k] * g[0] + M.m[4 + k] * g[1] + M.m[8 + k] * g[2] + M.m[12 + k] * g[3];
}

__global__ void AddAsFloatKernel(const double* in, size_t n, float* out) {
  const size_t i = blockIdx.x * static_cast<size_t>(blockDim.x) + threadIdx.x;
  if (i < n) out[i] += static_cast<float>(in[i]);
}

__global__ void AddKernel(const float* in, size_t n, float* out) {
  const size_t i = blockIdx.x * static_cast<size_t>(blockDim.x) + threadIdx.x;
  if (i < n) out[i] += in[i];
}

// out_r += alpha (c_s - c_r) for every found pair; out starts as a copy of the colours, which are only read.
__global__ void BlendKernel(const int32_t* found, const shared::PairGeometry* geometry, size_t num_slots,
                            const float* color, int channels, float* out) {
  const size_t slot = blockIdx.x * static_cast<size_t>(blockDim.x) + threadIdx.x;
  if (slot >= num_slots || !found[slot]) return;
  const shared::Blend b = shared::BlendOf(geometry[slot]);
  const size_t C = static_cast<size_t>(channels);
  for (size_t c = 0; c < C; ++c)
    atomicAdd(&out[C * b.receiver + c], b.alpha * (color[C * b.source + c] - color[C * b.receiver + c]));
}

// antialias.cpp's backward per pair: the colour gradient of the blend, and the edge's gradient to the clip
// positions of its end vertices (summed in double).
__global__ void AntialiasBackwardKernel(const int32_t* found, const shared::PairGeometry* geometry, size_t num_slots,
                                        const float* color, int channels, const float* grad_out, int width,
                                        float* grad_color, double* grad_clip) {
  const size_t slot = blockIdx.x * static_cast<size_t>(blockDim.x) + threadIdx.x;
  if (slot >= num_slots || !found[slot]) return;
  const shared::PairGeometry& g = geometry[slot];
  const shared::Blend b = shared::BlendOf(g);
  const size_t C = static_cast<size_t>(channels);
  double dL_dalpha = 0;
  for (size_t c = 0; c < C; ++c) {
    const float g_r = grad_out[C * b.receiver + c];
    dL_dalpha += static_cast<double>(g_r) * (color[C * b.source + c] - color[C * b.receiver + c]);
    if (grad_color) {
      atomicAdd(&grad_color[C * b.source + c], b.alpha * g_r);
      atomicAdd(&grad_color[C * b.receiver + c], -(b.alpha * g_r));
    }
  }
  const double dL_dt = dL_dalpha * b.dalpha_dt;
  if (dL_dt == 0) return;
  double d[2][3];
  shared::CrossingClipGradient(g, width, dL_dt, d);
  for (int e = 0; e < 2; ++e) {
    double* out = &grad_clip[4 * static_cast<size_t>(g.end_vertices[e])];
    atomicAdd(&out[0], d[e][0]);
    atomicAdd(&out[1], d[e][1]);
    atomicAdd(&out[3], d[e][2]);
  }
}

__global__ void CoverageKernel(const int32_t* triangle, size_t num_pixels, float* coverage) {
  const size_t p = blockIdx.x * static_cast<size_t>(blockDim.x) + threadIdx.x;
  if (p < num_pixels) coverage[p] = triangle[p] >= 0 ? 1.0f : 0.0f;
}

// Sums a block's per-thread terms with one atomic per warp, not per pixel.
__device__ __forceinline__ void AddToSum(double local, double* sum) {
  for (int offset = 16; offset > 0; offset /= 2) local += __shfl_down_sync(0xffffffffu, local, offset);
  if ((threadIdx.x & 31) == 0 && local != 0) atomicAdd(sum, local);
}

// loss.cpp's UnitVectorLoss per pixel.
__global__ void UnitVectorLossKernel(const float* prediction, const int32_t* triangle, const float* target,
                                     const float* mask, size_t num_pixels, float grad_scale, float* grad,
                                     double* loss_sum) {
  const size_t p = blockIdx.x * static_cast<size_t>(blockDim.x) + threadIdx.x;
  double local = 0;
  if (p < num_pixels) {
    grad[3 * p] = grad[3 * p + 1] = grad[3 * p + 2] = 0.0f;
    const float t0 = target[3 * p], t1 = target[3 * p + 1], t2 = target[3 * p + 2];
    const float n0 = prediction[3 * p], n1 = prediction[3 * p + 1], n2 = prediction[3 * p + 2];
    const float len = sqrtf(n0 * n0 + n1 * n1 + n2 * n2);
    if (triangle[p] >= 0 && mask[p] > 0.5f && t0 * t0 + t1 * t1 + t2 * t2 >= 0.5f && len >= 1e-8f) {
      const float h0 = n0 / len, h1 = n1 / len, h2 = n2 / len;
      const float d0 = h0 - t0, d1 = h1 - t1, d2 = h2 - t2;
      local = d0 * d0 + d1 * d1 + d2 * d2;
      const float hd = h0 * d0 + h1 * d1 + h2 * d2;
      grad[3 * p] = grad_scale * 2.0f * (d0 - h0 * hd) / len;
      grad[3 * p + 1] = grad_scale * 2.0f * (d1 - h1 * hd) / len;
      grad[3 * p + 2] = grad_scale * 2.0f * (d2 - h2 * hd) / len;
    }
  }
  AddToSum(local, loss_sum);
}

// loss.cpp's SquaredErrorLoss per pixel: a negative target has no term.
__global__ void SquaredErrorLossKernel(const float* prediction, const float* target, size_t num_pixels,
                                       float grad_scale, float* grad, double* loss_sum) {
  const size_t p = blockIdx.x * static_cast<size_t>(blockDim.x) + threadIdx.x;
  double local = 0;
  if (p < num_pixels) {
    const float d = target[p] < 0 ? 0.0f : prediction[p] - target[p];
    local = d * d;
    grad[p] = grad_scale * 2.0f * d;
  }
  AddToSum(local, loss_sum);
}

// A zeroed double accumulator of n values in the thread's scratch.
double* ZeroedSum(size_t n) {
  double* sum = workspace.sum.Get(std::max<size_t>(n, 1));
  SD_CUDA(cudaMemsetAsync(sum, 0, n * sizeof(double), cudaStreamPerThread));
  return sum;
}

void AddSumAsFloat(const double* sum, size_t n, float* out) {
  if (n == 0) return;
  AddAsFloatKernel<<<Blocks(n), kThreads>>>(sum, n, out);
  SD_CUDA(cudaGetLastError());
}

DeviceRaster AsDevice(const RasterView& rast) { return {rast.bary, rast.depth, rast.triangle}; }

// Vertex v's corners [begin, end) in the incidence, each naming a triangle whose vertices name vertices; false
// (and the flag raised) for an incidence of another mesh. Checked as the gathers read, like the other kernels.
__device__ bool VertexCornersOk(const VertexNormalsInputs& in, size_t v, Contract contract, int32_t* begin,
                                int32_t* end) {
  *begin = in.offset[v];
  *end = in.offset[v + 1];
  const size_t num_corners = 3 * in.num_tris;
  if (*begin < 0 || *end < *begin || static_cast<size_t>(*end) > num_corners) return contract.Raise(kVertexFaces);
  for (int32_t i = *begin; i < *end; ++i) {
    const int32_t c = in.corner[i];
    if (c < 0 || static_cast<size_t>(c) >= num_corners) return contract.Raise(kVertexFaces);
    if (!contract.VerticesOk(in.tris, static_cast<size_t>(c / 3))) return false;
  }
  return true;
}

__global__ void VertexNormalsKernel(VertexNormalsInputs in, float* normals, double* sums, Contract contract) {
  const size_t v = blockIdx.x * static_cast<size_t>(blockDim.x) + threadIdx.x;
  if (v >= in.num_vertices || contract.Raised()) return;
  int32_t begin, end;
  if (!VertexCornersOk(in, v, contract, &begin, &end)) return;
  const shared::Vec3d s = shared::VertexNormalSum(in.positions, in.tris, in.corner, begin, end);
  sums[3 * v] = s.x, sums[3 * v + 1] = s.y, sums[3 * v + 2] = s.z;
  shared::NormalFromSum(s, &normals[3 * v]);
}

__global__ void NormalSumGradientKernel(const double* sums, const float* grad_normals, size_t num_vertices, double* ds) {
  const size_t v = blockIdx.x * static_cast<size_t>(blockDim.x) + threadIdx.x;
  if (v >= num_vertices) return;
  const shared::Vec3d d = shared::NormalSumGradient({sums[3 * v], sums[3 * v + 1], sums[3 * v + 2]}, &grad_normals[3 * v]);
  ds[3 * v] = d.x, ds[3 * v + 1] = d.y, ds[3 * v + 2] = d.z;
}

__global__ void VertexPositionGradientKernel(VertexNormalsInputs in, const double* ds, float* grad_positions,
                                             Contract contract) {
  const size_t v = blockIdx.x * static_cast<size_t>(blockDim.x) + threadIdx.x;
  if (v >= in.num_vertices || contract.Raised()) return;
  int32_t begin, end;
  if (!VertexCornersOk(in, v, contract, &begin, &end)) return;
  const shared::Vec3d d = shared::VertexPositionGradient(in.positions, in.tris, ds, in.corner, begin, end);
  grad_positions[3 * v] += static_cast<float>(d.x);
  grad_positions[3 * v + 1] += static_cast<float>(d.y);
  grad_positions[3 * v + 2] += static_cast<float>(d.z);
}

}  // namespace

void* Allocate(size_t bytes) {
  void* ptr = nullptr;
  if (bytes) SD_CUDA(cudaMalloc(&ptr, bytes));
  return ptr;
}

void Free(void* ptr) {
  if (ptr) cudaFree(ptr);  // may run after the context is gone at exit: nothing to report then
}

void Copy(void* dst, bool dst_on_device, const void* src, bool src_on_device, size_t bytes) {
  if (bytes == 0) return;
  const cudaMemcpyKind kind = dst_on_device ? (src_on_device ? cudaMemcpyDeviceToDevice : cudaMemcpyHostToDevice)
                                            : (src_on_device ? cudaMemcpyDeviceToHost : cudaMemcpyHostToHost);
  SD_CUDA(cudaMemcpyAsync(dst, src, bytes, kind, cudaStreamPerThread));
  // The host's memory is the caller's once this returns: a download must have landed, and an upload from
  // pageable memory has been staged by then (cudaMemcpyAsync returns after staging it).
  if (!dst_on_device) SD_CUDA(cudaStreamSynchronize(cudaStreamPerThread));
}

void Fill32(void* ptr, uint32_t pattern, size_t count) { Fill<uint32_t>(ptr, pattern, count); }
void Fill64(void* ptr, uint64_t pattern, size_t count) { Fill<unsigned long long>(ptr, pattern, count); }

int TakeContractViolation() {
  int32_t* flag = ContractFlag();
  int32_t host = 0;
  SD_CUDA(cudaMemcpyAsync(&host, flag, sizeof(int32_t), cudaMemcpyDeviceToHost, cudaStreamPerThread));
  SD_CUDA(cudaStreamSynchronize(cudaStreamPerThread));
  if (host != 0) SD_CUDA(cudaMemsetAsync(flag, 0, sizeof(int32_t), cudaStreamPerThread));
  return host;
}

void TransformToClip(const float* positions, size_t num_vertices, const float M[16], float* clip) {
  if (num_vertices == 0) return;
  ToClipKernel<<<Blocks(num_vertices), kThreads>>>(positions, num_vertices, ToMatrix4(M), clip);
  SD_CUDA(cudaGetLastError());
}

void TransformToClipBackward(const float M[16], const float* grad_clip, size_t num_vertices, float* grad_positions) {
  if (num_vertices == 0) return;
  ToClipBackwardKernel<<<Blocks(num_vertices), kThreads>>>(grad_clip, num_vertices, ToMatrix4(M), grad_positions);
  SD_CUDA(cudaGetLastError());
}

void DeviceRasterize(const RasterizeInputs& in, RasterOut out) {
  if (static_cast<size_t>(in.width) * in.height == 0) return;
  RasterizeOnDevice(in.clip, in.tris, in.num_tris, in.width, in.height, out.bary, out.depth, out.triangle,
                    {ContractFlag(), in.num_vertices, in.num_tris});
}

void DeviceRasterizeBackward(const RasterizeInputs& in, const RasterView& rast, const float* grad_bary,
                             const float* grad_depth, float* grad_clip) {
  const size_t np = static_cast<size_t>(rast.width) * rast.height;
  if (np == 0) return;
  double* sum = ZeroedSum(4 * in.num_vertices);
  RasterizeBackwardKernel<<<Blocks(np), kThreads>>>(in.clip, in.tris, rast.width, rast.height, AsDevice(rast),
                                                    grad_bary, grad_depth, sum,
                                                    {ContractFlag(), in.num_vertices, in.num_tris});
  SD_CUDA(cudaGetLastError());
  AddSumAsFloat(sum, 4 * in.num_vertices, grad_clip);
}

void DeviceInterpolate(const InterpolateInputs& in, float* out) {
  const size_t np = static_cast<size_t>(in.rast.width) * in.rast.height;
  if (np == 0) return;
  InterpolateKernel<<<Blocks(np), kThreads>>>(in.attr, in.channels, in.tris, np, AsDevice(in.rast), out,
                                              {ContractFlag(), in.num_attr_vertices, in.num_tris});
  SD_CUDA(cudaGetLastError());
}

void DeviceInterpolateBackward(const InterpolateInputs& in, const float* grad_out, float* grad_attr, float* grad_bary) {
  const size_t np = static_cast<size_t>(in.rast.width) * in.rast.height;
  if (np == 0) return;
  const size_t n = static_cast<size_t>(in.channels) * in.num_attr_vertices;
  double* sum = ZeroedSum(n);
  InterpolateBackwardKernel<<<Blocks(np), kThreads>>>(in.attr, in.channels, in.tris, np, AsDevice(in.rast), grad_out,
                                                      sum, grad_bary,
                                                      {ContractFlag(), in.num_attr_vertices, in.num_tris});
  SD_CUDA(cudaGetLastError());
  AddSumAsFloat(sum, n, grad_attr);
}

void DeviceAntialias(const AntialiasInputs& in, bool skip_equal_colors, float* out, int32_t* found,
                     shared::PairGeometry* geometry) {
  const size_t np = static_cast<size_t>(in.rast.width) * in.rast.height, C = static_cast<size_t>(in.channels);
  if (np == 0) return;
  SD_CUDA(cudaMemcpyAsync(out, in.color, C * np * sizeof(float), cudaMemcpyDeviceToDevice, cudaStreamPerThread));
  const Contract contract{ContractFlag(), in.num_vertices, in.num_tris};
  const shared::AntialiasScene sc = DeviceResidentScene(in, contract);
  PairKernel<<<Blocks(np), kThreads>>>(sc, in.color, in.channels, skip_equal_colors, found, nullptr, geometry, contract);
  BlendKernel<<<Blocks(2 * np), kThreads>>>(found, geometry, 2 * np, in.color, in.channels, out);
  SD_CUDA(cudaGetLastError());
}

void DeviceAntialiasBackward(const AntialiasInputs& in, const int32_t* found, const shared::PairGeometry* geometry,
                             const float* grad_out, float* grad_color, float* grad_clip) {
  const size_t np = static_cast<size_t>(in.rast.width) * in.rast.height, C = static_cast<size_t>(in.channels);
  if (np == 0) return;
  if (grad_color) {  // out = color + the blends
    AddKernel<<<Blocks(C * np), kThreads>>>(grad_out, C * np, grad_color);
    SD_CUDA(cudaGetLastError());
  }
  double* sum = ZeroedSum(4 * in.num_vertices);
  AntialiasBackwardKernel<<<Blocks(2 * np), kThreads>>>(found, geometry, 2 * np, in.color, in.channels, grad_out,
                                                        in.rast.width, grad_color, sum);
  SD_CUDA(cudaGetLastError());
  AddSumAsFloat(sum, 4 * in.num_vertices, grad_clip);
}

void Coverage(const int32_t* triangle, size_t num_pixels, float* coverage) {
  if (num_pixels == 0) return;
  CoverageKernel<<<Blocks(num_pixels), kThreads>>>(triangle, num_pixels, coverage);
  SD_CUDA(cudaGetLastError());
}

void UnitVectorLoss(const float* prediction, const int32_t* triangle, const float* target, const float* mask,
                    size_t num_pixels, float grad_scale, float* grad_prediction, double* loss_sum) {
  if (num_pixels == 0) return;
  UnitVectorLossKernel<<<Blocks(num_pixels), kThreads>>>(prediction, triangle, target, mask, num_pixels, grad_scale,
                                                         grad_prediction, loss_sum);
  SD_CUDA(cudaGetLastError());
}

void SquaredErrorLoss(const float* prediction, const float* target, size_t num_pixels, float grad_scale,
                      float* grad_prediction, double* loss_sum) {
  if (num_pixels == 0) return;
  SquaredErrorLossKernel<<<Blocks(num_pixels), kThreads>>>(prediction, target, num_pixels, grad_scale,
                                                           grad_prediction, loss_sum);
  SD_CUDA(cudaGetLastError());
}

void DeviceVertexNormals(const VertexNormalsInputs& in, float* normals, double* sums) {
  if (in.num_vertices == 0) return;
  VertexNormalsKernel<<<Blocks(in.num_vertices), kThreads>>>(in, normals, sums,
                                                             {ContractFlag(), in.num_vertices, in.num_tris});
  SD_CUDA(cudaGetLastError());
}

void DeviceVertexNormalsBackward(const VertexNormalsInputs& in, const double* sums, const float* grad_normals,
                                 float* grad_positions) {
  if (in.num_vertices == 0) return;
  double* ds = workspace.normal_ds.Get(3 * in.num_vertices);
  NormalSumGradientKernel<<<Blocks(in.num_vertices), kThreads>>>(sums, grad_normals, in.num_vertices, ds);
  VertexPositionGradientKernel<<<Blocks(in.num_vertices), kThreads>>>(in, ds, grad_positions,
                                                                      {ContractFlag(), in.num_vertices, in.num_tris});
  SD_CUDA(cudaGetLastError());
}

}  // namespace sd::raster::cuda
