// Interpolate / InterpolateBackward: out = b0 a0 + b1 a1 + (1 - b0 - b1) a2 per covered pixel, so
// dL/db0 = g . (a0 - a2), dL/db1 = g . (a1 - a2) and dL/da_k = b_k g.
#include <vector>

#include "core/parallel.h"
#include "raster/internal.h"
#include "raster/raster.h"

namespace sd::raster {
namespace {

void CheckInputs(const InterpolateInputs& in) {
  SD_CHECK(in.channels > 0, << "channels " << in.channels);
  SD_CHECK(in.attr.size() % in.channels == 0,
           << "attr: " << in.attr.size() << " floats for " << in.channels << " channels");
  SD_CHECK(in.tris.size() % 3 == 0);
  internal::CommonMemory("Interpolate", in.attr, in.tris, in.rast);
  internal::CheckVertexIndices(in.tris, in.attr.size() / in.channels);
  internal::CheckRaster(in.rast);
  internal::CheckRasterTriangles(in.rast, in.tris);
}

// Rows per task: interpolation is cheap per pixel, so tasks need a few rows to be worth scheduling.
constexpr size_t kRowsPerTask = 8;

}  // namespace

void Interpolate(const InterpolateInputs& in, Span<float> out_in) {
  CheckInputs(in);
  const RasterBuffer& rast = in.rast;
  const size_t C = static_cast<size_t>(in.channels);
  SD_CHECK(out_in.size() == C * rast.NumPixels(), << "out: " << out_in.size());
  if (internal::CommonMemory("Interpolate", in.attr, in.tris, rast, out_in) == Memory::kDevice) {
    internal::CheckDeviceBuild("Interpolate");
#if SYNTHDRIVE_WITH_CUDA
    cuda::DeviceInterpolate(internal::ToCuda(in), out_in.data());
#endif
    return;
  }
  const std::span<const float> attr = in.attr.host();
  const std::span<const int32_t> tris = in.tris.host();
  const std::span<float> out = out_in.host();
  if (UseCuda()) {
#if SYNTHDRIVE_WITH_CUDA
    cuda::Interpolate(internal::ToCuda(in), out.data());
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

void InterpolateBackward(const InterpolateInputs& in, Span<const float> grad_out_in, Span<float> grad_attr_in,
                         Span<float> grad_bary_in) {
  CheckInputs(in);
  const RasterBuffer& rast = in.rast;
  const size_t C = static_cast<size_t>(in.channels);
  const size_t num_pixels = rast.NumPixels();
  SD_CHECK(grad_out_in.size() == C * num_pixels, << "grad_out: " << grad_out_in.size());
  SD_CHECK(grad_attr_in.size() == in.attr.size(), << "grad_attr: " << grad_attr_in.size());
  SD_CHECK(grad_bary_in.empty() || grad_bary_in.size() == 2 * num_pixels, << "grad_bary: " << grad_bary_in.size());
  if (internal::CommonMemory("InterpolateBackward", in.attr, in.tris, rast, grad_out_in, grad_attr_in,
                             grad_bary_in) == Memory::kDevice) {
    internal::CheckDeviceBuild("InterpolateBackward");
#if SYNTHDRIVE_WITH_CUDA
    cuda::DeviceInterpolateBackward(internal::ToCuda(in), grad_out_in.data(), grad_attr_in.data(),
                                    grad_bary_in.empty() ? nullptr : grad_bary_in.data());
#endif
    return;
  }
  const std::span<const float> attr = in.attr.host(), grad_out = grad_out_in.host();
  const std::span<const int32_t> tris = in.tris.host();
  const std::span<float> grad_attr = grad_attr_in.host(), grad_bary = grad_bary_in.host();

  std::vector<double> sum(grad_attr.size(), 0.0);
  if (UseCuda()) {
#if SYNTHDRIVE_WITH_CUDA
    cuda::InterpolateBackward(internal::ToCuda(in), grad_out.data(), sum.data(),
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
