// Rasterize / RasterizeBackward.
//
// Math. With h_k = (x_k, y_k, w_k) the homogeneous 2D clip coordinates of vertex k and p = (px, py, 1) a
// pixel centre in NDC, the point of the triangle seen through p is P = sum_k b_k h_k with P parallel to p,
// so b = H^-1 p up to scale (H = [h0 h1 h2]). Written with cross products,
//     e_k = (h_{k+1} x h_{k+2}) . p,   b_k = e_k / (e0 + e1 + e2),
// which are the perspective-correct barycentrics (Olano & Greer 1997, "Triangle scan conversion using 2D
// homogeneous coordinates"), with no division by w and no near-plane special case. Because w > 0 at the
// vertices, sign(e_k) is the sign of the screen-space edge function, so the same e_k decide coverage.
// Depth is the clip-space interpolation P_z / P_w with P = sum_k b_k (x, y, z, w)_k.
//
// Shared edges. An edge's plane vector c = h_a x h_b is computed with its endpoints in a canonical order
// (lexicographic on (x, y, w)), so the two triangles sharing an edge hold exactly c and -c and evaluate
// exactly opposite e at every pixel centre. A pixel centre with e == 0 goes to the triangle whose interior
// lies to the right of / below the edge (top-left rule on the inward edge normal); the neighbour sees the
// opposite normal, so exactly one of the two covers it.
//
// Work split. Triangles are set up in parallel, binned into bands of kBandRows image rows (in index order),
// and each band is rasterised by one task: no two tasks write the same pixel, and within a band triangles
// are visited in index order with a strict depth test, so ties go to the lower index whatever the threads.
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>

#include "core/parallel.h"
#include "raster/internal.h"
#include "raster/raster.h"

namespace sd::raster {
namespace {

using internal::kBandRows;

using shared::TriangleSetup;

// Triangle indices per band, each band's list in increasing triangle index.
struct Bins {
  std::vector<uint32_t> offset;  // NumBands + 1
  std::vector<int32_t> triangle;
};

Bins BinTriangles(const std::vector<TriangleSetup>& setups, int height) {
  const int num_bands = internal::NumBands(height);
  Bins bins;
  bins.offset.assign(num_bands + 1, 0);
  for (const TriangleSetup& s : setups) {
    if (s.Empty()) continue;
    for (int b = s.y0 / kBandRows; b <= s.y1 / kBandRows; ++b) ++bins.offset[b + 1];
  }
  for (int b = 0; b < num_bands; ++b) bins.offset[b + 1] += bins.offset[b];
  bins.triangle.resize(bins.offset[num_bands]);
  std::vector<uint32_t> cursor(bins.offset.begin(), bins.offset.end() - 1);
  for (size_t t = 0; t < setups.size(); ++t) {
    const TriangleSetup& s = setups[t];
    if (s.Empty()) continue;
    for (int b = s.y0 / kBandRows; b <= s.y1 / kBandRows; ++b) bins.triangle[cursor[b]++] = static_cast<int32_t>(t);
  }
  return bins;
}

// Draws triangle t's pixels in rows [row_begin, row_end] into the band's buffers (raw pointers: the compiler
// must not fear that a depth write aliases the setup).
void DrawTriangleRows(const TriangleSetup& s, int32_t t, int row_begin, int row_end, int width,
                      const double* column_ndc, const double* row_ndc, float* depth_buf, int32_t* triangle_buf,
                      float* bary_buf) {
  for (int j = row_begin; j <= row_end; ++j) {
    const double py = row_ndc[j];
    const double r0 = shared::EdgeRow(s.edge[0], py), r1 = shared::EdgeRow(s.edge[1], py),
                 r2 = shared::EdgeRow(s.edge[2], py);
    const size_t row_offset = static_cast<size_t>(j) * width;
    for (int i = s.x0; i <= s.x1; ++i) {
      float depth_f;
      double e[3];
      if (!shared::CoverPixel(s, column_ndc[i], r0, r1, r2, &depth_f, e)) continue;
      const size_t pixel = row_offset + i;
      if (!(depth_f < depth_buf[pixel])) continue;  // strict: equal depth keeps the lower triangle index
      depth_buf[pixel] = depth_f;
      triangle_buf[pixel] = t;
      shared::Barycentrics(e, &bary_buf[2 * pixel], &bary_buf[2 * pixel + 1]);
    }
  }
}

void RasterizeBand(const std::vector<TriangleSetup>& setups, const Bins& bins, const std::vector<double>& column_ndc,
                   const std::vector<double>& row_ndc, int band, RasterBuffer* out) {
  const int width = out->width;
  const int row0 = band * kBandRows, row1 = std::min(out->height, row0 + kBandRows);  // [row0, row1)
  const size_t first = static_cast<size_t>(row0) * width, last = static_cast<size_t>(row1) * width;
  std::fill(out->depth.begin() + first, out->depth.begin() + last, std::numeric_limits<float>::infinity());
  std::fill(out->triangle.begin() + first, out->triangle.begin() + last, -1);
  std::fill(out->bary.begin() + 2 * first, out->bary.begin() + 2 * last, 0.0f);
  for (uint32_t n = bins.offset[band]; n < bins.offset[band + 1]; ++n) {
    const int32_t t = bins.triangle[n];
    const TriangleSetup& s = setups[t];
    DrawTriangleRows(s, t, std::max(row0, s.y0), std::min(row1 - 1, s.y1), width, column_ndc.data(), row_ndc.data(),
                     out->depth.data(), out->triangle.data(), out->bary.data());
  }
  for (size_t pixel = first; pixel < last; ++pixel)
    if (out->triangle[pixel] < 0) out->depth[pixel] = 1.0f;
}

}  // namespace

void Rasterize(const RasterizeInputs& in, RasterBuffer* out) {
  const int width = in.width, height = in.height;
  internal::CheckTriangles(in.clip_pos, in.tris);
  SD_CHECK(width >= 0 && height >= 0 && out != nullptr);
  const Memory where = internal::CommonMemory("Rasterize", in.clip_pos, in.tris, out->where());
  internal::CheckVertexIndices(in.tris, internal::NumVertices(in.clip_pos));

  out->width = width;
  out->height = height;
  out->bary.resize(2 * out->NumPixels());
  out->depth.resize(out->NumPixels());
  out->triangle.resize(out->NumPixels());
  if (out->NumPixels() == 0) return;
  if (where == Memory::kDevice) {
    internal::CheckDeviceBuild("Rasterize");
#if SYNTHDRIVE_WITH_CUDA
    cuda::DeviceRasterize(internal::ToCuda(in), {out->bary.data(), out->depth.data(), out->triangle.data()});
#endif
    return;
  }
  if (UseCuda()) {
#if SYNTHDRIVE_WITH_CUDA
    cuda::Rasterize(internal::ToCuda(in), {out->bary.data(), out->depth.data(), out->triangle.data()});
    return;
#endif
  }

  const std::span<const float> clip_pos = in.clip_pos.host();
  const std::span<const int32_t> tris = in.tris.host();
  const size_t num_tris = tris.size() / 3;
  std::vector<TriangleSetup> setups(num_tris);
  ParallelForRange(0, num_tris, 256, [&](size_t begin, size_t end) {
    for (size_t t = begin; t < end; ++t) setups[t] = shared::SetUpTriangle(clip_pos.data(), tris.data(), t, width, height);
  });
  const Bins bins = BinTriangles(setups, height);
  // Tables, not a division per pixel; every triangle reads the same doubles.
  std::vector<double> column_ndc(width), row_ndc(height);
  for (int i = 0; i < width; ++i) column_ndc[i] = internal::PixelCentreNdc(i, width);
  for (int j = 0; j < height; ++j) row_ndc[j] = internal::PixelCentreNdc(j, height);
  ParallelFor(0, static_cast<size_t>(internal::NumBands(height)),
              [&](size_t band) { RasterizeBand(setups, bins, column_ndc, row_ndc, static_cast<int>(band), out); });
}

// Backward. For a covered pixel, let G_k = dL/db_k with the three b_k treated as independent (b2 = e2 / S
// carries no output gradient of its own, since the output stores b0, b1 only; depth adds to all three).
// With S = e0 + e1 + e2: dL/de_j = (G_j - sum_k G_k b_k) / S. Then e_j = (h_{j+1} x h_{j+2}) . p gives
//   de_j/dh_{j+1} = h_{j+2} x p,   de_j/dh_{j+2} = p x h_{j+1}   ((a x b) . p = a . (b x p) = b . (p x a)).
// Depth d = P_z / P_w, P = sum_k b_k (z_k, w_k): dd/db_k = (z_k - d w_k) / P_w, dd/dz_k = b_k / P_w,
// dd/dw_k = -d b_k / P_w.
namespace {

// dL/d(x, y, z, w) of the triangle's three vertices at one pixel.
using PixelGrad = std::array<float, 12>;

}  // namespace

void RasterizeBackward(const RasterizeInputs& in, const RasterBuffer& rast, Span<const float> grad_bary_in,
                       Span<const float> grad_depth_in, Span<float> grad_clip_in) {
  internal::CheckTriangles(in.clip_pos, in.tris);
  const Memory where = internal::CommonMemory("RasterizeBackward", in.clip_pos, in.tris, rast, grad_bary_in,
                                              grad_depth_in, grad_clip_in);
  internal::CheckVertexIndices(in.tris, internal::NumVertices(in.clip_pos));
  internal::CheckRaster(rast);
  SD_CHECK(rast.width == in.width && rast.height == in.height,
           << "RasterBuffer of " << rast.width << "x" << rast.height << " for inputs of " << in.width << "x"
           << in.height);
  internal::CheckRasterTriangles(rast, in.tris);
  const size_t num_pixels = rast.NumPixels();
  SD_CHECK(grad_bary_in.size() == 2 * num_pixels, << "grad_bary: " << grad_bary_in.size());
  SD_CHECK(grad_depth_in.empty() || grad_depth_in.size() == num_pixels, << "grad_depth: " << grad_depth_in.size());
  SD_CHECK(grad_clip_in.size() == in.clip_pos.size(), << "grad_clip: " << grad_clip_in.size());
  if (num_pixels == 0) return;
  if (where == Memory::kDevice) {
    internal::CheckDeviceBuild("RasterizeBackward");
#if SYNTHDRIVE_WITH_CUDA
    cuda::DeviceRasterizeBackward(internal::ToCuda(in), internal::View(rast), grad_bary_in.data(),
                                  grad_depth_in.empty() ? nullptr : grad_depth_in.data(), grad_clip_in.data());
#endif
    return;
  }
  const std::span<const float> clip_pos = in.clip_pos.host(), grad_bary = grad_bary_in.host(),
                               grad_depth = grad_depth_in.host();
  const std::span<const int32_t> tris = in.tris.host();
  const std::span<float> grad_clip = grad_clip_in.host();
  if (UseCuda()) {
#if SYNTHDRIVE_WITH_CUDA
    std::vector<double> sum(grad_clip.size());
    cuda::RasterizeBackward(internal::ToCuda(in), internal::View(rast), grad_bary.data(),
                            grad_depth.empty() ? nullptr : grad_depth.data(), sum.data());
    for (size_t n = 0; n < sum.size(); ++n) grad_clip[n] += static_cast<float>(sum[n]);
    return;
#endif
  }

  // Per-pixel gradients in parallel, then summed into the vertices serially in pixel order: deterministic
  // whatever the thread count, and the scatter is a small part of the cost.
  std::vector<PixelGrad> pixel_grad(num_pixels);
  std::vector<uint8_t> has_grad(num_pixels, 0);
  const int width = rast.width, height = rast.height;
  std::vector<double> column_ndc(width);
  for (int i = 0; i < width; ++i) column_ndc[i] = internal::PixelCentreNdc(i, width);
  ParallelFor(0, static_cast<size_t>(height), [&](size_t j) {
    const double py = internal::PixelCentreNdc(static_cast<int>(j), height);
    for (int i = 0; i < width; ++i) {
      const size_t pixel = j * width + i;
      const int32_t t = rast.triangle[pixel];
      if (t < 0) continue;
      const float gb0 = grad_bary[2 * pixel], gb1 = grad_bary[2 * pixel + 1];
      const float gd = grad_depth.empty() ? 0.0f : grad_depth[pixel];
      if (gb0 == 0.0f && gb1 == 0.0f && gd == 0.0f) continue;
      has_grad[pixel] = shared::PixelGradient(clip_pos.data(), tris.data(), t, column_ndc[i], py, gb0, gb1, gd,
                                              pixel_grad[pixel].data());
    }
  });
  std::vector<double> sum(grad_clip.size(), 0.0);
  for (size_t pixel = 0; pixel < num_pixels; ++pixel) {
    if (!has_grad[pixel]) continue;
    const size_t t = static_cast<size_t>(rast.triangle[pixel]);
    for (int k = 0; k < 3; ++k) {
      const size_t v = static_cast<size_t>(tris[3 * t + k]);
      for (int c = 0; c < 4; ++c) sum[4 * v + c] += pixel_grad[pixel][4 * k + c];
    }
  }
  for (size_t n = 0; n < sum.size(); ++n) grad_clip[n] += static_cast<float>(sum[n]);
}

}  // namespace sd::raster
