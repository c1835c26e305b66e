// Interpolate / InterpolateBackward: out = b0 a0 + b1 a1 + (1 - b0 - b1) a2 per covered pixel, so
// dL/db0 = g . (a0 - a2), dL/db1 = g . (a1 - a2) and dL/da_k = b_k g.
#include <vector>

#include "core/parallel.h"
#include "raster/internal.h"
#include "raster/raster.h"

namespace sd::raster {
namespace {

void CheckInterpolateArgs(std::span<const float> attr, int channels, std::span<const int32_t> tris,
                          const RasterBuffer& rast) {
  SD_CHECK(channels > 0, << "channels " << channels);
  SD_CHECK(attr.size() % channels == 0, << "attr: " << attr.size() << " floats for " << channels << " channels");
  SD_CHECK(tris.size() % 3 == 0);
  internal::CheckVertexIndices(tris, attr.size() / channels);
  internal::CheckRaster(rast);
  internal::CheckRasterTriangles(rast, tris);
}

// Rows per task: interpolation is cheap per pixel, so tasks need a few rows to be worth scheduling.
constexpr size_t kRowsPerTask = 8;

}  // namespace

void Interpolate(std::span<const float> attr, int channels, std::span<const int32_t> tris, const RasterBuffer& rast,
                 std::span<float> out) {
  CheckInterpolateArgs(attr, channels, tris, rast);
  const size_t C = static_cast<size_t>(channels);
  SD_CHECK(out.size() == C * rast.NumPixels(), << "out: " << out.size());
  if (UseCuda()) {
#if SYNTHDRIVE_WITH_CUDA
    cuda::Interpolate(attr.data(), attr.size() / C, channels, tris.data(), tris.size() / 3, internal::View(rast),
                      out.data());
    return;
#endif
  }
  const size_t width = static_cast<size_t>(rast.width);
  ParallelForRange(0, static_cast<size_t>(rast.height), kRowsPerTask, [&](size_t row0, size_t row1) {
    for (size_t pixel = row0 * width; pixel < row1 * width; ++pixel)
      shared::InterpolatePixel(attr.data(), C, tris.data(), rast.triangle[pixel], rast.bary[2 * pixel],
                               rast.bary[2 * pixel + 1], &out[C * pixel]);
  });
}

void InterpolateBackward(std::span<const float> attr, int channels, std::span<const int32_t> tris,
                         const RasterBuffer& rast, std::span<const float> grad_out, std::span<float> grad_attr,
                         std::span<float> grad_bary) {
  CheckInterpolateArgs(attr, channels, tris, rast);
  const size_t C = static_cast<size_t>(channels);
  const size_t num_pixels = rast.NumPixels();
  SD_CHECK(grad_out.size() == C * num_pixels, << "grad_out: " << grad_out.size());
  SD_CHECK(grad_attr.size() == attr.size(), << "grad_attr: " << grad_attr.size());
  SD_CHECK(grad_bary.empty() || grad_bary.size() == 2 * num_pixels, << "grad_bary: " << grad_bary.size());

  std::vector<double> sum(grad_attr.size(), 0.0);
  if (UseCuda()) {
#if SYNTHDRIVE_WITH_CUDA
    cuda::InterpolateBackward(attr.data(), attr.size() / C, channels, tris.data(), tris.size() / 3,
                              internal::View(rast), grad_out.data(), sum.data(),
                              grad_bary.empty() ? nullptr : grad_bary.data());
    for (size_t n = 0; n < sum.size(); ++n) grad_attr[n] += static_cast<float>(sum[n]);
    return;
#endif
  }
  const size_t width = static_cast<size_t>(rast.width);
  if (!grad_bary.empty()) {
    ParallelForRange(0, static_cast<size_t>(rast.height), kRowsPerTask, [&](size_t row0, size_t row1) {
      for (size_t pixel = row0 * width; pixel < row1 * width; ++pixel) {
        const int32_t t = rast.triangle[pixel];
        if (t < 0) continue;
        float d0, d1;
        shared::InterpolateBaryGradient(attr.data(), C, tris.data(), t, &grad_out[C * pixel], &d0, &d1);
        grad_bary[2 * pixel] += d0;
        grad_bary[2 * pixel + 1] += d1;
      }
    });
  }

  // Scatter to vertices serially in pixel order (deterministic), summing in double.
  for (size_t pixel = 0; pixel < num_pixels; ++pixel) {
    const int32_t t = rast.triangle[pixel];
    if (t < 0) continue;
    const float b0 = rast.bary[2 * pixel], b1 = rast.bary[2 * pixel + 1];
    const float b[3] = {b0, b1, 1.0f - b0 - b1};
    const float* g = &grad_out[C * pixel];
    for (int k = 0; k < 3; ++k) {
      double* s = &sum[C * static_cast<size_t>(tris[3 * static_cast<size_t>(t) + k])];
      for (size_t c = 0; c < C; ++c) s[c] += static_cast<double>(b[k]) * g[c];
    }
  }
  for (size_t n = 0; n < sum.size(); ++n) grad_attr[n] += static_cast<float>(sum[n]);
}

}  // namespace sd::raster
