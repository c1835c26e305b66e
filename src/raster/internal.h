#pragma once
// Helpers shared by the raster ops' .cpp files; not part of the public interface.
#include <cstddef>
#include <cstdint>
#include <span>

#include "core/error.h"
#include "raster/raster.h"

namespace sd::raster::internal {

// Image rows handled by one task. Small enough that a 320-row image gives 2 cores many tasks to balance,
// large enough that a typical triangle (a few pixels tall) lands in one or two bands.
inline constexpr int kBandRows = 8;

inline int NumBands(int height) { return (height + kBandRows - 1) / kBandRows; }

// Pixel centre (i + 0.5) in normalised device coordinates: the inverse of u = (x/w + 1) * W / 2. Every
// triangle evaluates its edge functions at exactly these doubles, which the shared-edge rule relies on.
inline double PixelCentreNdc(int i, int size) { return (2.0 * i + 1.0) / size - 1.0; }

// Continuous pixel coordinate of a clip-space coordinate: u = (x/w + 1) * W / 2.
inline double ClipToPixel(double x, double w, int size) { return (x / w + 1.0) * 0.5 * size; }

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

// A triangle is drawn only when all its vertices are in front of the eye (w > 0, see raster.h); the other
// ops must skip the same triangles.
inline bool TriangleDrawable(std::span<const float> clip_pos, std::span<const int32_t> tris, size_t t) {
  for (int k = 0; k < 3; ++k) {
    const float w = clip_pos[4 * static_cast<size_t>(tris[3 * t + k]) + 3];
    if (!(w > 0.0f)) return false;
  }
  return true;
}

}  // namespace sd::raster::internal
