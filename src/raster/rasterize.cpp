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

struct Vec3d {
  double x, y, z;
};
inline Vec3d Cross(const Vec3d& a, const Vec3d& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
inline double Dot(const Vec3d& a, const Vec3d& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
inline bool LexLess(const Vec3d& a, const Vec3d& b) {
  if (a.x != b.x) return a.x < b.x;
  if (a.y != b.y) return a.y < b.y;
  return a.z < b.z;
}

Vec3d Homogeneous2d(std::span<const float> clip_pos, int32_t v) {
  const float* c = &clip_pos[4 * static_cast<size_t>(v)];
  return {c[0], c[1], c[3]};
}

struct TriangleSetup {
  std::array<Vec3d, 3> edge;          // e_k(p) = edge[k] . (px, py, 1), k = edge opposite vertex k, > 0 inside
  std::array<bool, 3> owns_zero;      // top-left rule: does a pixel centre with e_k == 0 belong here
  std::array<float, 3> z, w;          // per-vertex clip z and w, for the depth
  int x0 = 0, x1 = -1, y0 = 0, y1 = -1;  // inclusive pixel bounding box; empty when x0 > x1
};

TriangleSetup SetUpTriangle(std::span<const float> clip_pos, std::span<const int32_t> tris, size_t t, int width,
                            int height) {
  TriangleSetup s;
  if (!internal::TriangleDrawable(clip_pos, tris, t)) return s;
  std::array<Vec3d, 3> h;
  for (int k = 0; k < 3; ++k) {
    const int32_t v = tris[3 * t + k];
    h[k] = Homogeneous2d(clip_pos, v);
    s.z[k] = clip_pos[4 * static_cast<size_t>(v) + 2];
    s.w[k] = clip_pos[4 * static_cast<size_t>(v) + 3];
  }
  for (int k = 0; k < 3; ++k) {
    const Vec3d& a = h[(k + 1) % 3];
    const Vec3d& b = h[(k + 2) % 3];
    if (LexLess(b, a)) {
      const Vec3d c = Cross(b, a);
      s.edge[k] = {-c.x, -c.y, -c.z};  // negation is exact: the neighbour holds exactly c
    } else {
      s.edge[k] = Cross(a, b);
    }
  }
  const double det = Dot(s.edge[0], h[0]);
  if (!(det != 0.0) || !std::isfinite(det)) return s;  // degenerate in screen space (or NaN input)
  const double orientation = det > 0 ? 1.0 : -1.0;  // sign of det H: the screen-space winding
  for (int k = 0; k < 3; ++k) {
    // Orient the edge functions positive inside (exact: a sign flip). Barycentrics e_k / sum(e) and the
    // depth ratio are unchanged, and a neighbour on the other side of an edge now holds exactly -edge.
    s.edge[k] = {orientation * s.edge[k].x, orientation * s.edge[k].y, orientation * s.edge[k].z};
    // (edge.x, edge.y) is the inward normal in NDC (x right, y down the image, as v grows with y).
    s.owns_zero[k] = s.edge[k].x > 0 || (s.edge[k].x == 0 && s.edge[k].y > 0);
  }
  // Pixel centres inside the screen-space bounding box. The 1e-4 px slack keeps centres that lie exactly on a
  // vertex's row or column (where u is rounded differently from the edge functions); the edge functions
  // have the last word.
  double umin = 1e300, umax = -1e300, vmin = 1e300, vmax = -1e300;
  for (int k = 0; k < 3; ++k) {
    const double u = internal::ClipToPixel(h[k].x, h[k].z, width);
    const double v = internal::ClipToPixel(h[k].y, h[k].z, height);
    umin = std::min(umin, u), umax = std::max(umax, u), vmin = std::min(vmin, v), vmax = std::max(vmax, v);
  }
  constexpr double kSlack = 1e-4;
  if (!(umax >= -1.0 && vmax >= -1.0 && umin <= width + 1.0 && vmin <= height + 1.0)) return s;  // off screen
  auto clamp_to = [](double x, int hi) { return static_cast<int>(std::clamp(x, -1.0, static_cast<double>(hi))); };
  s.x0 = std::max(0, clamp_to(std::ceil(umin - 0.5 - kSlack), width));
  s.x1 = clamp_to(std::floor(umax - 0.5 + kSlack), width - 1);
  s.y0 = std::max(0, clamp_to(std::ceil(vmin - 0.5 - kSlack), height));
  s.y1 = clamp_to(std::floor(vmax - 0.5 + kSlack), height - 1);
  return s;
}

// e is an oriented edge function (positive inside).
inline bool Inside(double e, bool owns_zero) { return (e > 0) | ((e == 0) & owns_zero); }

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
    if (s.x0 > s.x1 || s.y0 > s.y1) continue;
    for (int b = s.y0 / kBandRows; b <= s.y1 / kBandRows; ++b) ++bins.offset[b + 1];
  }
  for (int b = 0; b < num_bands; ++b) bins.offset[b + 1] += bins.offset[b];
  bins.triangle.resize(bins.offset[num_bands]);
  std::vector<uint32_t> cursor(bins.offset.begin(), bins.offset.end() - 1);
  for (size_t t = 0; t < setups.size(); ++t) {
    const TriangleSetup& s = setups[t];
    if (s.x0 > s.x1 || s.y0 > s.y1) continue;
    for (int b = s.y0 / kBandRows; b <= s.y1 / kBandRows; ++b) bins.triangle[cursor[b]++] = static_cast<int32_t>(t);
  }
  return bins;
}

// Draws triangle t's pixels in rows [row_begin, row_end] into the band's buffers (raw pointers: the compiler
// must not fear that a depth write aliases the setup).
void DrawTriangleRows(const TriangleSetup& s, int32_t t, int row_begin, int row_end, int width,
                      const double* column_ndc, const double* row_ndc, float* depth_buf, int32_t* triangle_buf,
                      float* bary_buf) {
  const Vec3d g0 = s.edge[0], g1 = s.edge[1], g2 = s.edge[2];
  const bool own0 = s.owns_zero[0], own1 = s.owns_zero[1], own2 = s.owns_zero[2];
  const double z0 = s.z[0], z1 = s.z[1], z2 = s.z[2], w0 = s.w[0], w1 = s.w[1], w2 = s.w[2];
  for (int j = row_begin; j <= row_end; ++j) {
    const double py = row_ndc[j];
    // Row-constant parts, evaluated as (g.y * py + g.z) by every triangle alike so shared edges stay exact.
    const double r0 = g0.y * py + g0.z, r1 = g1.y * py + g1.z, r2 = g2.y * py + g2.z;
    const size_t row_offset = static_cast<size_t>(j) * width;
    for (int i = s.x0; i <= s.x1; ++i) {
      const double px = column_ndc[i];
      const double e0 = g0.x * px + r0, e1 = g1.x * px + r1, e2 = g2.x * px + r2;
      // Bitwise &: one hard-to-predict branch per pixel instead of several.
      if (!(Inside(e0, own0) & Inside(e1, own1) & Inside(e2, own2))) continue;
      // z/w = sum b_k z_k / sum b_k w_k; the normalisation of b cancels, so the depth test costs one division
      // and only winners pay for the barycentrics.
      const double depth = (e0 * z0 + e1 * z1 + e2 * z2) / (e0 * w0 + e1 * w1 + e2 * w2);
      // Per-pixel depth clipping to [-1, 1] (near..far), as a GPU's depth clip does.
      if (!(depth >= -1.0 && depth <= 1.0)) continue;
      const size_t pixel = row_offset + i;
      const float depth_f = static_cast<float>(depth);
      if (!(depth_f < depth_buf[pixel])) continue;  // strict: equal depth keeps the lower triangle index
      const double inv_sum = 1.0 / (e0 + e1 + e2);
      depth_buf[pixel] = depth_f;
      triangle_buf[pixel] = t;
      bary_buf[2 * pixel] = static_cast<float>(e0 * inv_sum);
      bary_buf[2 * pixel + 1] = static_cast<float>(e1 * inv_sum);
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

void Rasterize(std::span<const float> clip_pos, std::span<const int32_t> tris, int width, int height,
               RasterBuffer* out) {
  internal::CheckTriangles(clip_pos, tris);
  SD_CHECK(width >= 0 && height >= 0 && out != nullptr);
  const size_t num_vertices = internal::NumVertices(clip_pos);
  for (int32_t v : tris) SD_CHECK(v >= 0 && static_cast<size_t>(v) < num_vertices, << "vertex index " << v);

  out->width = width;
  out->height = height;
  out->bary.resize(2 * out->NumPixels());
  out->depth.resize(out->NumPixels());
  out->triangle.resize(out->NumPixels());
  if (out->NumPixels() == 0) return;

  const size_t num_tris = tris.size() / 3;
  std::vector<TriangleSetup> setups(num_tris);
  ParallelForRange(0, num_tris, 256, [&](size_t begin, size_t end) {
    for (size_t t = begin; t < end; ++t) setups[t] = SetUpTriangle(clip_pos, tris, t, width, height);
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

bool PixelGradient(std::span<const float> clip_pos, std::span<const int32_t> tris, int32_t t, double px, double py,
                   float grad_b0, float grad_b1, float grad_d, PixelGrad* g) {
  std::array<Vec3d, 3> h;
  std::array<double, 3> z;
  for (int k = 0; k < 3; ++k) {
    const int32_t v = tris[3 * static_cast<size_t>(t) + k];
    h[k] = Homogeneous2d(clip_pos, v);
    z[k] = clip_pos[4 * static_cast<size_t>(v) + 2];
  }
  const Vec3d p{px, py, 1.0};
  std::array<double, 3> e;
  for (int k = 0; k < 3; ++k) e[k] = Dot(Cross(h[(k + 1) % 3], h[(k + 2) % 3]), p);
  const double sum = e[0] + e[1] + e[2];
  if (sum == 0.0) return false;
  const std::array<double, 3> b{e[0] / sum, e[1] / sum, e[2] / sum};

  std::array<double, 3> dL_db{grad_b0, grad_b1, 0.0};
  std::array<double, 3> dL_dz{0, 0, 0}, dL_dw_direct{0, 0, 0};
  if (grad_d != 0.0f) {
    const double P_z = b[0] * z[0] + b[1] * z[1] + b[2] * z[2];
    const double P_w = b[0] * h[0].z + b[1] * h[1].z + b[2] * h[2].z;
    const double d = P_z / P_w;
    for (int k = 0; k < 3; ++k) {
      dL_db[k] += grad_d * (z[k] - d * h[k].z) / P_w;
      dL_dz[k] = grad_d * b[k] / P_w;
      dL_dw_direct[k] = -grad_d * d * b[k] / P_w;
    }
  }
  const double weighted = dL_db[0] * b[0] + dL_db[1] * b[1] + dL_db[2] * b[2];
  std::array<Vec3d, 3> dL_dh{};  // (x, y, w) per vertex
  for (int j = 0; j < 3; ++j) {
    const double dL_de = (dL_db[j] - weighted) / sum;
    const int a = (j + 1) % 3, c = (j + 2) % 3;
    const Vec3d de_da = Cross(h[c], p), de_dc = Cross(p, h[a]);
    dL_dh[a] = {dL_dh[a].x + dL_de * de_da.x, dL_dh[a].y + dL_de * de_da.y, dL_dh[a].z + dL_de * de_da.z};
    dL_dh[c] = {dL_dh[c].x + dL_de * de_dc.x, dL_dh[c].y + dL_de * de_dc.y, dL_dh[c].z + dL_de * de_dc.z};
  }
  for (int k = 0; k < 3; ++k) {
    (*g)[4 * k + 0] = static_cast<float>(dL_dh[k].x);
    (*g)[4 * k + 1] = static_cast<float>(dL_dh[k].y);
    (*g)[4 * k + 2] = static_cast<float>(dL_dz[k]);
    (*g)[4 * k + 3] = static_cast<float>(dL_dh[k].z + dL_dw_direct[k]);
  }
  return true;
}

}  // namespace

void RasterizeBackward(std::span<const float> clip_pos, std::span<const int32_t> tris, const RasterBuffer& rast,
                       std::span<const float> grad_bary, std::span<const float> grad_depth,
                       std::span<float> grad_clip) {
  internal::CheckTriangles(clip_pos, tris);
  internal::CheckRaster(rast);
  const size_t num_pixels = rast.NumPixels();
  SD_CHECK(grad_bary.size() == 2 * num_pixels, << "grad_bary: " << grad_bary.size());
  SD_CHECK(grad_depth.empty() || grad_depth.size() == num_pixels, << "grad_depth: " << grad_depth.size());
  SD_CHECK(grad_clip.size() == clip_pos.size(), << "grad_clip: " << grad_clip.size());
  if (num_pixels == 0) return;

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
      has_grad[pixel] = PixelGradient(clip_pos, tris, t, column_ndc[i], py, gb0, gb1, gd, &pixel_grad[pixel]);
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
