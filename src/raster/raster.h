#pragma once
// Differentiable triangle rasterizer: the forward ops and their hand-written backward passes.
//
// The ops follow one pattern (one file per op: rasterize.cpp, interpolate.cpp, antialias.cpp, clip.cpp, and the
// per-pixel loss terms of loss.h; after nvdiffrast's per-op params structs): an op with more than a handful of inputs takes them as one plain
// `OpInputs` struct of views (Spans and references, nothing owned; the caller keeps them alive for the call).
// `Op(inputs, outputs)` computes; `OpBackward(the same inputs, forward outputs, grad_outputs, grad_inputs)`
// ACCUMULATES (+=) into the gradients it is given, so callers can sum several views into one buffer.
// Buffers are flat float / int32 arrays, structure of arrays; nothing here depends on a tensor framework.
// One image per call; loops over views are the caller's.
//
// Where an op runs follows where its buffers live (buffer.h): all of an op's buffers on the host, or all on
// the device (a mix is a contract violation; an empty Span goes with either).
//  - Host buffers: the CPU, with work spread over threads by core/parallel.h and deterministic (no float
//    atomics: per-thread partial gradients are summed in a fixed order). When the process's device is CUDA
//    (device.cpp: one switch for the process) the op uploads, runs its kernels and downloads instead.
//  - Device buffers: the kernels, queued on the calling thread's stream; outputs stay on the device, so a
//    chain of ops (refinement's loss: assetgen/refine.cpp) crosses the bus only where its caller copies.
// Both devices run the same per-triangle and per-pixel code (shared.h) and agree (see UseCuda).
//
// Conventions
//  - Clip space: 4 floats (x, y, z, w) per vertex. Pixel coordinates follow OpenCV / core/camera.h:
//      u = (x/w + 1) * W / 2,  v = (y/w + 1) * H / 2   (v grows DOWN the image),
//    and pixel (i, j) is sampled at its centre (i + 0.5, j + 0.5). Depth is z/w in [-1, 1], smaller is
//    nearer. Triangles with any vertex at w <= 0 are not drawn (callers keep geometry in front of the
//    near plane; the refinement cameras always do).
//  - Triangles: 3 int32 vertex indices each; both windings are drawn (no culling).
//  - Barycentrics are perspective-correct, (b0, b1) of the triangle's vertices 0 and 1; b2 = 1 - b0 - b1.
//  - Contracts (SD_CHECK, abort with the culprit named): buffer sizes, every index of `tris` within the vertices
//    of clip_pos / attr, every triangle id of a RasterBuffer within `tris` (a buffer of another mesh) and its
//    resolution the one it is used with. Each op checks its own inputs on every call: one pass over `tris` and
//    one over the raster's triangle ids (~40 us at 512x512 on one core). On device buffers the kernels check
//    each index as they read it, and a failure aborts at the next download (buffer.h). Non-finite clip
//    positions are not drawn.
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/camera.h"
#include "core/device.h"
#include "core/rigid3.h"
#include "raster/buffer.h"
#include "raster/shared.h"  // shared::PairGeometry, the device record's element

namespace sd::raster {

// Rasterize's output, one entry per pixel (row-major, width * height), on the host or the device: Rasterize
// fills it where it already lives.
struct RasterBuffer {
  explicit RasterBuffer(Memory where = Memory::kHost) : bary(where), depth(where), triangle(where) {}
  int width = 0, height = 0;
  Buffer<float> bary;        // 2 per pixel: b0, b1 (0 where background)
  Buffer<float> depth;       // 1 per pixel: z/w (1 where background)
  Buffer<int32_t> triangle;  // 1 per pixel: triangle index, -1 where background

  size_t NumPixels() const { return static_cast<size_t>(width) * height; }
  Memory where() const { return triangle.where(); }
};

// --- device.cpp ----------------------------------------------------------------------------------------
// Where the ops run: the process's device (core/device.h: SetDevice, --device, $SYNTHDRIVE_DEVICE). On
// Device::kCuda every op below runs its CUDA kernels on the same host buffers (inputs are uploaded, outputs
// downloaded), so callers do not change. CPU and CUDA agree: Rasterize, Interpolate, Antialias and the
// antialias backward bit for bit; the gradient scatters of RasterizeBackward and InterpolateBackward sum in
// another order (double atomics), so their float results may differ in the last bit (relative 1e-6 is the
// tested bound, raster_cuda_test.cpp).
bool CudaAvailable();                 // built with CUDA (SYNTHDRIVE_WITH_CUDA) and a GPU is visible
std::string CudaDeviceDescription();  // "NVIDIA H100 80GB HBM3, 132 SMs, 79 GiB"; empty without one
// True when the ops run on CUDA; InputError when the device is kCuda but CUDA cannot run them.
bool UseCuda();

// --- rasterize.cpp -------------------------------------------------------------------------------------
// Per pixel centre: the nearest covering triangle (smallest z/w, ties to the lower triangle index), its
// perspective-correct barycentrics and depth. Pixels where a triangle's z/w falls outside [-1, 1] are not
// drawn by it (per-pixel depth clip, as GPUs do). A pixel centre exactly on an edge shared by two triangles
// (same vertex positions) is covered by exactly one of them (top-left rule); see rasterize.cpp.
struct RasterizeInputs {
  Span<const float> clip_pos;  // 4 per vertex
  Span<const int32_t> tris;    // 3 per triangle
  int width = 0, height = 0;        // pixels
};
void Rasterize(const RasterizeInputs& in, RasterBuffer* out);
// Gradients of the loss with respect to clip positions through the barycentrics (and depth, when
// grad_depth is non-empty) at fixed triangle assignment. rast: Rasterize's output for `in`; grad_bary: 2 per
// pixel; grad_depth: empty or 1 per pixel; grad_clip: 4 per vertex, accumulated.
void RasterizeBackward(const RasterizeInputs& in, const RasterBuffer& rast, Span<const float> grad_bary,
                       Span<const float> grad_depth, Span<float> grad_clip);

// --- interpolate.cpp -----------------------------------------------------------------------------------
// out[pixel] = sum_k b_k * attr[tri_k] for covered pixels, 0 for background.
struct InterpolateInputs {
  Span<const float> attr;    // `channels` per vertex
  int channels = 0;
  Span<const int32_t> tris;  // 3 per triangle, indexing attr's vertices
  const RasterBuffer& rast;       // rasterised with the same tris
};
// out: `channels` per pixel.
void Interpolate(const InterpolateInputs& in, Span<float> out);
// grad_out: `channels` per pixel. grad_attr: `channels` per vertex, accumulated; grad_bary: 2 per pixel,
// accumulated (may be empty when the caller does not need gradients to geometry).
void InterpolateBackward(const InterpolateInputs& in, Span<const float> grad_out, Span<float> grad_attr,
                         Span<float> grad_bary);

// --- antialias.cpp -------------------------------------------------------------------------------------
// Analytic anti-aliasing of silhouette edges, after nvdiffrast's idea (Laine et al. 2020): for each pair of
// horizontally or vertically adjacent pixels whose triangles differ, if a silhouette edge of the nearer
// triangle (a mesh boundary edge, or an edge between a front- and a back-facing triangle in screen space)
// crosses the segment between the two pixel centres, the colours of the pair are blended by the fraction of
// the segment on each side. The blend is differentiable in the edge's projected endpoints, so a loss on
// the antialiased image moves the outline (gradients to clip positions), and in the colours.
struct EdgeTopology {  // built once per mesh topology, reused across views and iterations
  // For each triangle, for each of its 3 edges (v0v1, v1v2, v2v0): the adjacent triangle across it, or -1
  // (boundary). Non-manifold edges (more than two triangles) are treated as boundaries. Built on the host;
  // `neighbour.CopyFrom` puts a copy on the device for the device ops.
  Buffer<int32_t> neighbour;  // 3 per triangle
};
EdgeTopology BuildEdgeTopology(std::span<const int32_t> tris, int num_vertices);

// What the forward pass found, kept for the backward pass.
struct AntialiasRecord {
  struct PixelPair {
    int32_t pixel_a, pixel_b;  // pixel indices; a is left of / above b
    int32_t triangle;          // the triangle owning the silhouette edge (the owner pixel's, or one reached
                               // from it across non-silhouette edges: see antialias.cpp)
    int32_t edge;              // 0, 1, 2: which of its edges
    float alpha;               // blend weight moved across the pair
  };
  std::vector<PixelPair> pairs;  // host buffers: the pairs in row order
  // Device buffers: one slot per pixel and neighbour (right, lower), whether it holds a pair and the pair's
  // geometry, left uncompacted so that no count is read back; the backward pass reuses the geometry.
  Buffer<int32_t> device_found{Memory::kDevice};
  Buffer<shared::PairGeometry> device_geometry{Memory::kDevice};
};
struct AntialiasInputs {
  Span<const float> color;      // `channels` per pixel: an interpolated attribute, a 1-channel coverage mask
  int channels = 0;
  const RasterBuffer& rast;     // Rasterize's output for clip_pos and tris; gives the resolution
  Span<const float> clip_pos;   // 4 per vertex
  Span<const int32_t> tris;     // 3 per triangle
  const EdgeTopology& topology; // BuildEdgeTopology(tris, ...), on the side of the other buffers
};
// out: `channels` per pixel, not the same buffer as in.color. `record` is overwritten.
// color_gradient = false promises that the caller will not use AntialiasBackward's grad_color: pairs whose
// colours are equal are then skipped — their blend changes nothing and moves no vertex, only the colour
// gradient needs them. For a coverage mask that leaves only the outline against the background, which
// makes the op several times cheaper on a finely tessellated mesh; out and grad_clip are unchanged.
void Antialias(const AntialiasInputs& in, Span<float> out, AntialiasRecord* record, bool color_gradient = true);
// record: the forward pass's for the same inputs. grad_out: `channels` per pixel. grad_color: `channels` per
// pixel, accumulated, or empty when the caller wants no colour gradient; grad_clip: 4 per vertex, accumulated.
void AntialiasBackward(const AntialiasInputs& in, const AntialiasRecord& record, Span<const float> grad_out,
                       Span<float> grad_color, Span<float> grad_clip);

// --- clip.cpp ------------------------------------------------------------------------------------------
// 4x4 matrix taking homogeneous world points to clip space for a pinhole camera (distortion ignored),
// following the conventions above; z/w maps camera depth near..far to -1..1.
Eigen::Matrix4f ClipFromWorld(const PinholeCamera& camera, const Rigid3d& T_cam_world, float near, float far);
// clip[4v..4v+3] = M * (p_v, 1). positions: 3 per vertex.
void TransformToClip(Span<const float> positions, const Eigen::Matrix4f& M, Span<float> clip);
// grad_positions (3 per vertex, accumulated) from grad_clip (4 per vertex).
void TransformToClipBackward(const Eigen::Matrix4f& M, Span<const float> grad_clip, Span<float> grad_positions);

}  // namespace sd::raster
