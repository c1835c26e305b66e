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
//  - Antialias on host buffers: the pair search (the expensive, per-pixel part) runs on the GPU; the blend of
//    the pairs it found, and the backward pass's per-pair arithmetic, run on the host in pair order from the
//    geometry the GPU returns, so they are the CPU's own loops. On device buffers the blend and the backward
//    run on the GPU too, with float atomics per pixel (the order of a pixel's few blends may differ).
// The functions that take host pointers upload what they read and download what they write (the ops given
// host buffers while the device is CUDA); the Device* functions below take device pointers and chain without
// a transfer (the ops given device buffers, raster/buffer.h). Scratch memory is kept per host thread and only
// grows.
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

// ---- device memory (raster/buffer.h's backend) ----------------------------------------------------------------
void* Allocate(size_t bytes);
void Free(void* ptr);
// Between any two sides on the calling thread's stream; a copy to the host waits for it.
void Copy(void* dst, bool dst_on_device, const void* src, bool src_on_device, size_t bytes);
void Fill32(void* ptr, uint32_t pattern, size_t count);
void Fill64(void* ptr, uint64_t pattern, size_t count);
// The calling thread's contract flag (0: none; else a ContractViolation), read and cleared; waits.
int TakeContractViolation();
enum ContractViolation { kVertexIndex = 1, kRasterTriangle = 2, kVertexFaces = 3 };

// ---- the ops on device-resident buffers ------------------------------------------------------------------------
// Every pointer below is device memory (the inputs structs above then hold device pointers); the work is
// queued on the calling thread's stream and nothing waits. Sizes were checked on the host; the kernels check
// each index as they read it (a vertex of `tris` within the vertices, a raster's triangle id within `tris`),
// raise the thread's flag on one out of range and do not use it, and do nothing once the flag is up.
// Gradients are ACCUMULATED into float outputs (the scatters sum in double first), as the host ops do.
void TransformToClip(const float* positions, size_t num_vertices, const float M[16], float* clip);
void TransformToClipBackward(const float M[16], const float* grad_clip, size_t num_vertices, float* grad_positions);
void DeviceRasterize(const RasterizeInputs& in, RasterOut out);
void DeviceRasterizeBackward(const RasterizeInputs& in, const RasterView& rast, const float* grad_bary,
                             const float* grad_depth /* nullable */, float* grad_clip);
void DeviceInterpolate(const InterpolateInputs& in, float* out);
void DeviceInterpolateBackward(const InterpolateInputs& in, const float* grad_out, float* grad_attr,
                               float* grad_bary /* nullable */);
// The pairs stay uncompacted, one slot per pixel and direction (2 per pixel: right, lower neighbour), so that
// no count is read back: found[slot] says whether the slot holds a silhouette pair, geometry[slot] its geometry.
void DeviceAntialias(const AntialiasInputs& in, bool skip_equal_colors, float* out, int32_t* found,
                     shared::PairGeometry* geometry);
void DeviceAntialiasBackward(const AntialiasInputs& in, const int32_t* found, const shared::PairGeometry* geometry,
                             const float* grad_out, float* grad_color, float* grad_clip);
// The loss ops of raster/loss.h; loss_sum (1 double) is accumulated.
void Coverage(const int32_t* triangle, size_t num_pixels, float* coverage);
void UnitVectorLoss(const float* prediction, const int32_t* triangle, const float* target, const float* mask,
                    size_t num_pixels, float grad_scale, float* grad_prediction, double* loss_sum);
void SquaredErrorLoss(const float* prediction, const float* target, size_t num_pixels, float grad_scale,
                      float* grad_prediction, double* loss_sum);
// The vertex normals of raster/normals.h, one thread per vertex; sums and dL/ds: 3 doubles per vertex.
struct VertexNormalsInputs {
  const float* positions = nullptr;  // 3 per vertex
  size_t num_vertices = 0;
  const int32_t* tris = nullptr;
  size_t num_tris = 0;
  const int32_t* offset = nullptr;  // VertexFaces, num_vertices + 1
  const int32_t* corner = nullptr;  // VertexFaces, 3 per triangle
};
void DeviceVertexNormals(const VertexNormalsInputs& in, float* normals, double* sums);
void DeviceVertexNormalsBackward(const VertexNormalsInputs& in, const double* sums, const float* grad_normals,
                                 float* grad_positions);

}  // namespace sd::raster::cuda
