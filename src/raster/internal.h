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
