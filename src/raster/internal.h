#pragma once
// Helpers shared by the raster ops' .cpp files; not part of the public interface.
#include <cstddef>
#include <cstdint>
#include <initializer_list>
#include <span>

#include "core/error.h"
#include "raster/raster.h"
#include "raster/shared.h"
#if SYNTHDRIVE_WITH_CUDA
#include "raster/cuda/raster_cuda.h"
#endif

namespace sd::raster::internal {

// Image rows handled by one task. Small enough that a 320-row image gives 2 cores many tasks to balance,
// large enough that a typical triangle (a few pixels tall) lands in one or two bands.
inline constexpr int kBandRows = 8;

inline int NumBands(int height) { return (height + kBandRows - 1) / kBandRows; }

using shared::ClipToPixel;
using shared::PixelCentreNdc;

inline size_t NumVertices(Span<const float> clip_pos) { return clip_pos.size() / 4; }

// Where an op runs (raster.h): the one side all its buffers are on. An empty Span goes with either side; a
// Memory argument (an output's side) always counts.
struct Side {
  Memory where;
  bool counts;
};
template <typename T>
Side SideOf(const Span<T>& s) {
  return {s.where(), !s.empty()};
}
inline Side SideOf(const RasterBuffer& r) { return {r.where(), r.NumPixels() > 0}; }
inline Side SideOf(Memory where) { return {where, true}; }
template <typename... Args>
Memory CommonMemory(const char* op, const Args&... args) {
  bool host = false, device = false;
  for (const Side& s : {SideOf(args)...})
    if (s.counts) (s.where == Memory::kHost ? host : device) = true;
  SD_CHECK(!(host && device), << op << ": some buffers are on the host and some on the device");
  return device ? Memory::kDevice : Memory::kHost;
}

// Refuses device buffers in a build without CUDA (they cannot have been made; an empty one can).
inline void CheckDeviceBuild([[maybe_unused]] const char* op) {
#if !SYNTHDRIVE_WITH_CUDA
  SD_CHECK(false, << op << ": device buffers in a build without CUDA");
#endif
}

inline void CheckTriangles(Span<const float> clip_pos, Span<const int32_t> tris) {
  SD_CHECK(clip_pos.size() % 4 == 0, << "clip_pos holds 4 floats per vertex, got " << clip_pos.size());
  SD_CHECK(tris.size() % 3 == 0, << "tris holds 3 indices per triangle, got " << tris.size());
}

// Whether every value lies in [lo, hi). Branch-free so that it vectorises: every op runs it over a whole raster
// buffer on every call (about 40 us for 512x512 ids against 80 us with a branch per pixel, one core); callers
// look for the culprit, comparing exactly, only when it fails. hi is clamped to INT32_MAX, so an id of exactly
// INT32_MAX costs that slow pass and no more.
inline bool AllWithin(std::span<const int32_t> values, int32_t lo, size_t hi) {
  const int32_t end = hi > static_cast<size_t>(INT32_MAX) ? INT32_MAX : static_cast<int32_t>(hi);
  uint32_t outside = 0;
  for (const int32_t v : values) outside |= static_cast<uint32_t>((v < lo) | (v >= end));
  return outside == 0;
}

// Every vertex index of `tris` names one of `num_vertices` vertices (the per-pixel code indexes without checks).
// Device buffers are checked by the kernels as they read each index (buffer.h).
inline void CheckVertexIndices(Span<const int32_t> device_or_host_tris, size_t num_vertices) {
  if (device_or_host_tris.where() == Memory::kDevice) return;
  const std::span<const int32_t> tris = device_or_host_tris.host();
  if (AllWithin(tris, 0, num_vertices)) return;
  for (size_t k = 0; k < tris.size(); ++k)
    SD_CHECK(tris[k] >= 0 && static_cast<size_t>(tris[k]) < num_vertices,
             << "triangle " << k / 3 << " names vertex " << tris[k] << " of " << num_vertices);
}

// Every pixel's triangle id is -1 or one of `tris`' triangles: a raster buffer of another mesh is refused here
// instead of reading out of bounds.
inline void CheckRasterTriangles(const RasterBuffer& rast, Span<const int32_t> tris) {
  const size_t num_triangles = tris.size() / 3;
  if (rast.where() == Memory::kDevice) return;  // checked by the kernels (buffer.h)
  if (AllWithin(rast.triangle, -1, num_triangles)) return;
  for (size_t p = 0; p < rast.triangle.size(); ++p)
    SD_CHECK(rast.triangle[p] == -1 || (rast.triangle[p] >= 0 && static_cast<size_t>(rast.triangle[p]) < num_triangles),
             << "pixel " << p << " holds triangle " << rast.triangle[p] << " of " << num_triangles
             << " (a raster buffer of another mesh?)");
}

inline void CheckRaster(const RasterBuffer& rast) {
  SD_CHECK(rast.width >= 0 && rast.height >= 0);
  SD_CHECK(rast.bary.size() == 2 * rast.NumPixels() && rast.depth.size() == rast.NumPixels() &&
               rast.triangle.size() == rast.NumPixels(),
           << "RasterBuffer buffers do not match " << rast.width << "x" << rast.height);
}


#if SYNTHDRIVE_WITH_CUDA
// The public inputs as the CUDA side's raw pointers and counts (raster_cuda.h), field for field.
inline cuda::RasterView View(const RasterBuffer& rast) {
  return {rast.width, rast.height, rast.bary.data(), rast.depth.data(), rast.triangle.data()};
}
inline cuda::RasterizeInputs ToCuda(const RasterizeInputs& in) {
  return {in.clip_pos.data(), NumVertices(in.clip_pos), in.tris.data(), in.tris.size() / 3, in.width, in.height};
}
inline cuda::InterpolateInputs ToCuda(const InterpolateInputs& in) {
  return {in.attr.data(), in.attr.size() / static_cast<size_t>(in.channels), in.channels, in.tris.data(),
          in.tris.size() / 3, View(in.rast)};
}
inline cuda::AntialiasInputs ToCuda(const AntialiasInputs& in) {
  return {in.color.data(), in.channels, View(in.rast), in.clip_pos.data(), NumVertices(in.clip_pos), in.tris.data(),
          in.tris.size() / 3, in.topology.neighbour.data()};
}
#endif

}  // namespace sd::raster::internal
