#pragma once
// CUDA implementations of the raster ops, behind the public ops in raster.h (which dispatch here when the
// device is kCuda). Internal: raw host pointers in and out, so this header needs neither Eigen nor the
// public types, and nvcc compiles the .cu without them.
//
// The kernels run the per-triangle and per-pixel code of raster/shared.h, the same the CPU ops run. What
// differs is only how work is spread:
//  - Rasterize: one thread per (triangle, pixel of its bounding box), balanced by a prefix sum over the boxes;
//    the depth test is one 64-bit atomicMin on (depth bits, triangle index) per pixel, which picks the same
//    winner as the CPU's strict in-order test (nearest, ties to the lower index); a second pass computes the
//    winner's barycentrics.
//  - Gradient scatters to vertices use double atomics (the CPU sums in pixel order): the float results agree
//    with the CPU's to the last bit almost everywhere, not bit for bit everywhere (raster_cuda_test.cpp).
//  - Antialias: the pair search (the expensive, per-pixel part) runs on the GPU; the blend of the pairs it
//    found, and the backward pass's per-pair arithmetic, run on the host in pair order from the geometry the
//    GPU returns, so they are the CPU's own loops.
// Every op uploads what it reads: a RasterBuffer is a plain host value that callers may copy and change (the
// finite-difference tests do), so a device copy kept between calls could silently go stale. Device memory is
// kept per host thread and only grows.
#include <cstddef>
#include <cstdint>
#include <vector>

#include "raster/shared.h"

namespace sd::raster::cuda {

// Built with CUDA and at least one GPU visible to this process.
bool Available();
// "NVIDIA H100 80GB HBM3, 132 SMs, 79 GiB" (empty when not available).
const char* DeviceDescription();

// Each op's inputs struct mirrors raster.h's of the same name, field for field, as host pointers and counts
// (internal.h converts); the public op has checked them before it calls here.
struct RasterView {  // a RasterBuffer on the host
  int width = 0, height = 0;
  const float* bary = nullptr;
  const float* depth = nullptr;
  const int32_t* triangle = nullptr;
};

struct RasterizeInputs {
  const float* clip = nullptr;  // 4 per vertex
  size_t num_vertices = 0;
  const int32_t* tris = nullptr;
  size_t num_tris = 0;
  int width = 0, height = 0;
};
struct RasterOut {  // host buffers of in.width x in.height pixels
  float* bary = nullptr;
  float* depth = nullptr;
  int32_t* triangle = nullptr;
};
void Rasterize(const RasterizeInputs& in, RasterOut out);
// grad_clip_sum: host, 4 per vertex, OVERWRITTEN with the sum over pixels (the caller adds it).
void RasterizeBackward(const RasterizeInputs& in, const RasterView& rast, const float* grad_bary,
                       const float* grad_depth /* nullable */, double* grad_clip_sum);

struct InterpolateInputs {
  const float* attr = nullptr;  // `channels` per vertex
  size_t num_attr_vertices = 0;
  int channels = 0;
  const int32_t* tris = nullptr;
  size_t num_tris = 0;
  RasterView rast;
};
void Interpolate(const InterpolateInputs& in, float* out);
// grad_attr_sum: host, OVERWRITTEN with the sum over pixels; grad_bary: host, accumulated (+=), nullable.
void InterpolateBackward(const InterpolateInputs& in, const float* grad_out, double* grad_attr_sum, float* grad_bary);

struct AntialiasInputs {
  const float* color = nullptr;  // `channels` per pixel
  int channels = 0;
  RasterView rast;
  const float* clip = nullptr;  // 4 per vertex
  size_t num_vertices = 0;
  const int32_t* tris = nullptr;
  size_t num_tris = 0;
  const int32_t* neighbour = nullptr;  // EdgeTopology::neighbour, 3 per triangle
};
struct PairRecord {  // layout of raster.h's AntialiasRecord::PixelPair
  int32_t pixel_a, pixel_b, triangle, edge;
  float alpha;
};
// The silhouette pairs of the image in the CPU's order (row by row, the right neighbour before the lower),
// with each pair's geometry. skip_equal_colors: Antialias's color_gradient = false.
void FindAntialiasPairs(const AntialiasInputs& in, bool skip_equal_colors, std::vector<PairRecord>* pairs,
                        std::vector<shared::PairGeometry>* geometry);
// The geometry of recorded pairs, recomputed (in.color is not read); returns false when a record does not
// match the inputs.
bool RecordedPairGeometry(const AntialiasInputs& in, const PairRecord* pairs, size_t num_pairs,
                          std::vector<shared::PairGeometry>* geometry);

}  // namespace sd::raster::cuda

namespace sd::raster::cuda {

// The refinement loss of a set of views evaluated on the device in one pass per view (normal_mask_loss.h):
// the targets are uploaded once, each evaluation uploads positions and vertex normals and downloads the
// gradients, and everything between stays on the device.
struct LossViewHost {
  float clip_from_world[16];  // row-major
  int width = 0, height = 0;
  const float* normals = nullptr;  // 3 per pixel
  const float* mask = nullptr;     // 1 per pixel
  float normal_grad_scale = 0, normal_loss_scale = 0, mask_grad_scale = 0, mask_loss_scale = 0;
};
class LossTargets;
LossTargets* UploadLossTargets(const LossViewHost* views, size_t num_views);
void FreeLossTargets(LossTargets* targets);
struct NormalMaskInputs {  // normal_mask_loss.h's
  const float* positions = nullptr;  // 3 per vertex
  const float* normals = nullptr;    // 3 per vertex
  size_t num_vertices = 0;
  const int32_t* tris = nullptr;
  size_t num_tris = 0;
  const int32_t* neighbour = nullptr;  // 3 per triangle
};
// losses: 2 per view (normal, mask); grad_positions / grad_normals: 3 per vertex, the views' shares summed in
// view order, overwritten. The whole evaluation is queued on the calling thread's stream before the one wait
// for its results.
void EvaluateLoss(LossTargets& targets, const NormalMaskInputs& in, double* losses, float* grad_positions,
                  float* grad_normals);

}  // namespace sd::raster::cuda
