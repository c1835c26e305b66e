#pragma once
// Helpers shared by the raster ops' .cpp files; not part of the public interface.
#include <cstddef>
#include <cstdint>
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

inline size_t NumVertices(std::span<const float> clip_pos) { return clip_pos.size() / 4; }

inline void CheckTriangles(std::span<const float> clip_pos, std::span<const int32_t> tris) {
  SD_CHECK(clip_pos.size() % 4 == 0, << "clip_pos holds 4 floats per vertex, got " << clip_pos.size());
  SD_CHECK(tris.size() % 3 == 0, << "tris holds 3 indices per triangle, got " << tris.size());
}

// Every vertex index of `tris` names one of `num_vertices` vertices (the per-pixel code indexes without checks).
inline void CheckVertexIndices(std::span<const int32_t> tris, size_t num_vertices) {
  for (size_t k = 0; k < tris.size(); ++k)
    SD_CHECK(tris[k] >= 0 && static_cast<size_t>(tris[k]) < num_vertices,
             << "triangle " << k / 3 << " names vertex " << tris[k] << " of " << num_vertices);
}

// Every pixel's triangle id is -1 or one of `tris`' triangles: a raster buffer of another mesh is refused here
// instead of reading out of bounds.
inline void CheckRasterTriangles(const RasterBuffer& rast, std::span<const int32_t> tris) {
  const int64_t num_triangles = static_cast<int64_t>(tris.size() / 3);
  for (size_t p = 0; p < rast.triangle.size(); ++p)
    SD_CHECK(rast.triangle[p] >= -1 && rast.triangle[p] < num_triangles,
             << "pixel " << p << " holds triangle " << rast.triangle[p] << " of " << num_triangles
             << " (a raster buffer of another mesh?)");
}

inline void CheckRaster(const RasterBuffer& rast) {
  SD_CHECK(rast.width >= 0 && rast.height >= 0);
  SD_CHECK(rast.bary.size() == 2 * rast.NumPixels() && rast.depth.size() == rast.NumPixels() &&
               rast.triangle.size() == rast.NumPixels(),
           << "RasterBuffer buffers do not match " << rast.width << "x" << rast.height);
}

inline bool TriangleDrawable(std::span<const float> clip_pos, std::span<const int32_t> tris, size_t t) {
  return shared::TriangleDrawable(clip_pos.data(), tris.data(), t);
}

#if SYNTHDRIVE_WITH_CUDA
inline cuda::RasterView View(const RasterBuffer& rast) {
  return {rast.width, rast.height, rast.bary.data(), rast.depth.data(), rast.triangle.data()};
}
#endif

}  // namespace sd::raster::internal
