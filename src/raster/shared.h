#pragma once
// The per-triangle and per-pixel arithmetic of the raster ops, written once and compiled twice: by g++ for the
// CPU ops (rasterize.cpp, interpolate.cpp, antialias.cpp) and by nvcc for the CUDA ops (cuda/raster_cuda.cu).
// Not part of the public interface.
//
// Why one copy: the ops' guarantees (a pixel centre on a shared edge is covered by exactly one triangle, ties
// go to the lower triangle index, forward and backward see the same silhouette pairs) rest on every caller
// evaluating exactly the same expressions. Both compilers must also round them the same way, so the CUDA
// files are built with --fmad=false (no fused multiply-add: g++ for x86-64 emits none either) and the CPU and
// GPU results agree bit for bit up to the order of the gradient sums (raster_cuda_test.cpp).
//
// Everything here works on raw pointers and plain arrays: no std::span / std::array / Eigen in device code.
#include <cmath>
#include <cstddef>
#include <cstdint>

#ifdef __CUDACC__
#define SD_HD __host__ __device__ __forceinline__
#else
#define SD_HD inline
#endif

namespace sd::raster::shared {

// ---- small math -------------------------------------------------------------------------------------------

struct Vec3d {
  double x, y, z;
};
SD_HD Vec3d Cross(const Vec3d& a, const Vec3d& b) {
  return {a.y * b.z - a.z * b.y, a.z * b.x - a.x * b.z, a.x * b.y - a.y * b.x};
}
SD_HD double Dot(const Vec3d& a, const Vec3d& b) { return a.x * b.x + a.y * b.y + a.z * b.z; }
SD_HD bool LexLess(const Vec3d& a, const Vec3d& b) {
  if (a.x != b.x) return a.x < b.x;
  if (a.y != b.y) return a.y < b.y;
  return a.z < b.z;
}
SD_HD double Min(double a, double b) { return b < a ? b : a; }
SD_HD double Max(double a, double b) { return a < b ? b : a; }
SD_HD int MinI(int a, int b) { return b < a ? b : a; }
SD_HD int MaxI(int a, int b) { return a < b ? b : a; }
SD_HD double Abs(double a) { return a < 0 ? -a : a; }
SD_HD double Clamp(double x, double lo, double hi) { return x < lo ? lo : (hi < x ? hi : x); }
// Correctly rounded on both sides (IEEE), so host and device agree.
SD_HD double Sqrt(double x) {
#ifdef __CUDA_ARCH__
  return ::sqrt(x);
#else
  return std::sqrt(x);
#endif
}
// False for NaN and +-infinity (x - x is NaN for both), without <cmath> in device code.
SD_HD bool Finite(double x) { return x - x == 0.0; }
// floor / ceil of values already clamped to [-1, size]: exact for the pixel ranges used here.
SD_HD int FloorToInt(double x) {
  const int i = static_cast<int>(x);
  return (static_cast<double>(i) > x) ? i - 1 : i;
}
SD_HD int CeilToInt(double x) {
  const int i = static_cast<int>(x);
  return (static_cast<double>(i) < x) ? i + 1 : i;
}

// ---- conventions (raster.h) -----------------------------------------------------------------------------

// Pixel centre (i + 0.5) in normalised device coordinates: the inverse of u = (x/w + 1) * W / 2. Every
// triangle evaluates its edge functions at exactly these doubles, which the shared-edge rule relies on.
SD_HD double PixelCentreNdc(int i, int size) { return (2.0 * i + 1.0) / size - 1.0; }
// Continuous pixel coordinate of a clip-space coordinate: u = (x/w + 1) * W / 2.
SD_HD double ClipToPixel(double x, double w, int size) { return (x / w + 1.0) * 0.5 * size; }

// A triangle is drawn only when all its vertices are in front of the eye (w > 0); every op skips the same ones.
SD_HD bool TriangleDrawable(const float* clip_pos, const int32_t* tris, size_t t) {
  for (int k = 0; k < 3; ++k) {
    const float w = clip_pos[4 * static_cast<size_t>(tris[3 * t + k]) + 3];
    if (!(w > 0.0f)) return false;
  }
  return true;
}

SD_HD Vec3d Homogeneous2d(const float* clip_pos, int32_t v) {
  const float* c = &clip_pos[4 * static_cast<size_t>(v)];
  return {c[0], c[1], c[3]};
}

// ---- rasterize: per triangle ------------------------------------------------------------------------------

// See rasterize.cpp for the math (2D homogeneous edge functions, canonical edge order, top-left rule).
struct TriangleSetup {
  Vec3d edge[3];          // e_k(p) = edge[k] . (px, py, 1), k = edge opposite vertex k, > 0 inside
  bool owns_zero[3];      // top-left rule: does a pixel centre with e_k == 0 belong here
  float z[3], w[3];       // per-vertex clip z and w, for the depth
  int x0, x1, y0, y1;     // inclusive pixel bounding box; empty when x0 > x1 or y0 > y1
  SD_HD bool Empty() const { return x0 > x1 || y0 > y1; }
};

SD_HD TriangleSetup SetUpTriangle(const float* clip_pos, const int32_t* tris, size_t t, int width, int height) {
  TriangleSetup s{};
  s.x0 = 0, s.x1 = -1, s.y0 = 0, s.y1 = -1;
  if (!TriangleDrawable(clip_pos, tris, t)) return s;
  Vec3d h[3];
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
  if (!(det != 0.0) || !Finite(det)) return s;  // degenerate in screen space (or NaN input)
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
    const double u = ClipToPixel(h[k].x, h[k].z, width);
    const double v = ClipToPixel(h[k].y, h[k].z, height);
    umin = Min(umin, u), umax = Max(umax, u), vmin = Min(vmin, v), vmax = Max(vmax, v);
  }
  constexpr double kSlack = 1e-4;
  if (!(umax >= -1.0 && vmax >= -1.0 && umin <= width + 1.0 && vmin <= height + 1.0)) return s;  // off screen
  s.x0 = MaxI(0, CeilToInt(Clamp(umin - 0.5 - kSlack, -1.0, width)));
  s.x1 = FloorToInt(Clamp(umax - 0.5 + kSlack, -1.0, width - 1));
  s.y0 = MaxI(0, CeilToInt(Clamp(vmin - 0.5 - kSlack, -1.0, height)));
  s.y1 = FloorToInt(Clamp(vmax - 0.5 + kSlack, -1.0, height - 1));
  return s;
}

// e is an oriented edge function (positive inside).
SD_HD bool Inside(double e, bool owns_zero) { return (e > 0) | ((e == 0) & owns_zero); }

// The row-constant part of an edge function, (g.y * py + g.z); the full value is g.x * px + row. Every
// triangle evaluates exactly these two steps, so shared edges stay exactly opposite.
SD_HD double EdgeRow(const Vec3d& g, double py) { return g.y * py + g.z; }

// One pixel centre against one set-up triangle: false when the centre is outside or its depth outside
// [-1, 1]; else the depth (as float, the value the depth test compares) and the edge values.
SD_HD bool CoverPixel(const TriangleSetup& s, double px, double r0, double r1, double r2, float* depth_f, double e[3]) {
  e[0] = s.edge[0].x * px + r0, e[1] = s.edge[1].x * px + r1, e[2] = s.edge[2].x * px + r2;
  // Bitwise &: one hard-to-predict branch per pixel instead of several.
  if (!(Inside(e[0], s.owns_zero[0]) & Inside(e[1], s.owns_zero[1]) & Inside(e[2], s.owns_zero[2]))) return false;
  // z/w = sum b_k z_k / sum b_k w_k; the normalisation of b cancels, so the depth test costs one division
  // and only winners pay for the barycentrics.
  const double depth = (e[0] * s.z[0] + e[1] * s.z[1] + e[2] * s.z[2]) / (e[0] * s.w[0] + e[1] * s.w[1] + e[2] * s.w[2]);
  // Per-pixel depth clipping to [-1, 1] (near..far), as a GPU's depth clip does.
  if (!(depth >= -1.0 && depth <= 1.0)) return false;
  *depth_f = static_cast<float>(depth);
  return true;
}

// The stored barycentrics (b0, b1) of a winning pixel.
SD_HD void Barycentrics(const double e[3], float* b0, float* b1) {
  const double inv_sum = 1.0 / (e[0] + e[1] + e[2]);
  *b0 = static_cast<float>(e[0] * inv_sum);
  *b1 = static_cast<float>(e[1] * inv_sum);
}

// ---- rasterize backward: per pixel ------------------------------------------------------------------------

// dL/d(x, y, z, w) of the triangle's three vertices at one pixel (12 floats); false when the pixel's edge
// sum is zero. Math in rasterize.cpp.
SD_HD bool PixelGradient(const float* clip_pos, const int32_t* tris, int32_t t, double px, double py, float grad_b0,
                         float grad_b1, float grad_d, float g[12]) {
  Vec3d h[3];
  double z[3];
  for (int k = 0; k < 3; ++k) {
    const int32_t v = tris[3 * static_cast<size_t>(t) + k];
    h[k] = Homogeneous2d(clip_pos, v);
    z[k] = clip_pos[4 * static_cast<size_t>(v) + 2];
  }
  const Vec3d p{px, py, 1.0};
  double e[3];
  for (int k = 0; k < 3; ++k) e[k] = Dot(Cross(h[(k + 1) % 3], h[(k + 2) % 3]), p);
  const double sum = e[0] + e[1] + e[2];
  if (sum == 0.0) return false;
  const double b[3] = {e[0] / sum, e[1] / sum, e[2] / sum};

  double dL_db[3] = {grad_b0, grad_b1, 0.0};
  double dL_dz[3] = {0, 0, 0}, dL_dw_direct[3] = {0, 0, 0};
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
  Vec3d dL_dh[3] = {{0, 0, 0}, {0, 0, 0}, {0, 0, 0}};  // (x, y, w) per vertex
  for (int j = 0; j < 3; ++j) {
    const double dL_de = (dL_db[j] - weighted) / sum;
    const int a = (j + 1) % 3, c = (j + 2) % 3;
    const Vec3d de_da = Cross(h[c], p), de_dc = Cross(p, h[a]);
    dL_dh[a] = {dL_dh[a].x + dL_de * de_da.x, dL_dh[a].y + dL_de * de_da.y, dL_dh[a].z + dL_de * de_da.z};
    dL_dh[c] = {dL_dh[c].x + dL_de * de_dc.x, dL_dh[c].y + dL_de * de_dc.y, dL_dh[c].z + dL_de * de_dc.z};
  }
  for (int k = 0; k < 3; ++k) {
    g[4 * k + 0] = static_cast<float>(dL_dh[k].x);
    g[4 * k + 1] = static_cast<float>(dL_dh[k].y);
    g[4 * k + 2] = static_cast<float>(dL_dz[k]);
    g[4 * k + 3] = static_cast<float>(dL_dh[k].z + dL_dw_direct[k]);
  }
  return true;
}

// ---- interpolate: per pixel -------------------------------------------------------------------------------

SD_HD void InterpolatePixel(const float* attr, size_t C, const int32_t* tris, int32_t t, float b0, float b1, float* o) {
  if (t < 0) {
    for (size_t c = 0; c < C; ++c) o[c] = 0.0f;
    return;
  }
  const float b2 = 1.0f - b0 - b1;
  const float* a0 = &attr[C * static_cast<size_t>(tris[3 * static_cast<size_t>(t)])];
  const float* a1 = &attr[C * static_cast<size_t>(tris[3 * static_cast<size_t>(t) + 1])];
  const float* a2 = &attr[C * static_cast<size_t>(tris[3 * static_cast<size_t>(t) + 2])];
  for (size_t c = 0; c < C; ++c) o[c] = b0 * a0[c] + b1 * a1[c] + b2 * a2[c];
}

// dL/db0 = g . (a0 - a2), dL/db1 = g . (a1 - a2) at one covered pixel.
SD_HD void InterpolateBaryGradient(const float* attr, size_t C, const int32_t* tris, int32_t t, const float* g,
                                   float* d0, float* d1) {
  const float* a0 = &attr[C * static_cast<size_t>(tris[3 * static_cast<size_t>(t)])];
  const float* a1 = &attr[C * static_cast<size_t>(tris[3 * static_cast<size_t>(t) + 1])];
  const float* a2 = &attr[C * static_cast<size_t>(tris[3 * static_cast<size_t>(t) + 2])];
  float s0 = 0.0f, s1 = 0.0f;
  for (size_t c = 0; c < C; ++c) {
    s0 += g[c] * (a0[c] - a2[c]);
    s1 += g[c] * (a1[c] - a2[c]);
  }
  *d0 = s0, *d1 = s1;
}

// ---- antialias: per vertex, per triangle, per pixel pair --------------------------------------------------
// See antialias.cpp for the method (pairs, owner, silhouette walk, blending axis, box-filter blend).

// Projected endpoint of a vertex: pixel coordinates and their derivatives with respect to the clip
// coordinates (u depends on x and w, v on y and w).
struct ScreenVertex {
  double u, v;
  double du_dx, du_dw, dv_dy, dv_dw;
};

SD_HD ScreenVertex Project(const float* clip_pos, int32_t vertex, int width, int height) {
  const float* c = &clip_pos[4 * static_cast<size_t>(vertex)];
  const double x = c[0], y = c[1], w = c[3];
  ScreenVertex s;
  s.u = ClipToPixel(x, w, width);
  s.v = ClipToPixel(y, w, height);
  s.du_dx = 0.5 * width / w;
  s.du_dw = -0.5 * width * x / (w * w);
  s.dv_dy = 0.5 * height / w;
  s.dv_dw = -0.5 * height * y / (w * w);
  return s;
}

// +1 / -1: winding of the triangle's projection on screen; 0 when it is not drawn (w <= 0) or degenerate.
SD_HD int ScreenFacing(const float* clip_pos, const int32_t* tris, size_t t) {
  if (!TriangleDrawable(clip_pos, tris, t)) return 0;
  double h[3][3];
  for (int k = 0; k < 3; ++k) {
    const float* c = &clip_pos[4 * static_cast<size_t>(tris[3 * t + k])];
    h[k][0] = c[0], h[k][1] = c[1], h[k][2] = c[3];
  }
  // det [h0 h1 h2] = w0 w1 w2 * (twice the NDC signed area); w > 0, so its sign is the screen winding.
  const double det = h[0][0] * (h[1][1] * h[2][2] - h[1][2] * h[2][1]) -
                     h[0][1] * (h[1][0] * h[2][2] - h[1][2] * h[2][0]) +
                     h[0][2] * (h[1][0] * h[2][1] - h[1][1] * h[2][0]);
  return det > 0 ? 1 : (det < 0 ? -1 : 0);
}

// Geometry of one pixel pair, in a frame where the pair runs along the first coordinate ("along") and the
// other coordinate ("across") is constant at the centres: for a horizontal pair along = u, across = v.
struct PairFrame {
  bool horizontal;
  double owner_along;  // owner pixel centre
  double direction;    // +1 when the other pixel is at larger along, -1 otherwise
  double across;       // the centres' common across coordinate
};

SD_HD PairFrame MakeFrame(int32_t owner, int32_t other, int width) {
  const int ox = owner % width, oy = owner / width, px = other % width, py = other / width;
  PairFrame f;
  f.horizontal = oy == py;
  f.owner_along = (f.horizontal ? ox : oy) + 0.5;
  f.direction = (f.horizontal ? px - ox : py - oy) > 0 ? 1.0 : -1.0;
  f.across = (f.horizontal ? oy : ox) + 0.5;
  return f;
}

// Where an edge crosses the pair segment: t (from the owner's centre) and dt/d(endpoint along, across).
struct Crossing {
  double t;
  double dt_dalong0, dt_dacross0, dt_dalong1, dt_dacross1;
};

// Crossing of the pair segment by the edge p0-p1 (any orientation); false when they do not cross.
SD_HD bool CrossPair(const PairFrame& f, const ScreenVertex& p0, const ScreenVertex& p1, Crossing* out) {
  const double along0 = f.horizontal ? p0.u : p0.v, across0 = f.horizontal ? p0.v : p0.u;
  const double along1 = f.horizontal ? p1.u : p1.v, across1 = f.horizontal ? p1.v : p1.u;
  const double d_across = across1 - across0, d_along = along1 - along0;
  if (d_across == 0) return false;
  const double s = (f.across - across0) / d_across;  // position along the edge
  if (!(s >= 0.0 && s <= 1.0)) return false;
  const double crossing = along0 + s * d_along;
  const double t = f.direction * (crossing - f.owner_along);
  if (!(t >= 0.0 && t <= 1.0)) return false;
  // crossing = along0 + (across - across0) d_along / d_across, so with slope = d_along / d_across:
  //   d/d along0 = 1 - s, d/d along1 = s, d/d across0 = -(1 - s) slope, d/d across1 = -s slope.
  const double slope = d_along / d_across;
  out->t = t;
  out->dt_dalong0 = f.direction * (1.0 - s);
  out->dt_dalong1 = f.direction * s;
  out->dt_dacross0 = -f.direction * (1.0 - s) * slope;
  out->dt_dacross1 = -f.direction * s * slope;
  return true;
}

// Blending axis: a horizontal pair takes edges at least as vertical as horizontal, a vertical pair strictly
// more horizontal ones, so each edge blends along exactly one axis.
SD_HD bool BlendsAlong(const PairFrame& f, const ScreenVertex& p0, const ScreenVertex& p1) {
  const double du = Abs(p1.u - p0.u), dv = Abs(p1.v - p0.v);
  return f.horizontal ? dv >= du : du > dv;
}

// Vertex indices of edge k of triangle t (edges v0v1, v1v2, v2v0, as in EdgeTopology).
SD_HD void EdgeVertices(const int32_t* tris, size_t t, int k, int32_t ev[2]) {
  ev[0] = tris[3 * t + k];
  ev[1] = tris[3 * t + (k + 1) % 3];
}

// What the pair search reads: raw views of the raster buffer, the mesh and the per-call tables.
struct AntialiasScene {
  int width, height;
  const int32_t* triangle;  // per pixel
  const float* depth;       // per pixel
  const int32_t* tris;
  const int32_t* neighbour;      // EdgeTopology, 3 per triangle
  const ScreenVertex* screen;    // per vertex
  const int8_t* facing;          // per triangle: ScreenFacing

  SD_HD bool IsSilhouette(size_t t, int k) const {
    const int32_t n = neighbour[3 * t + k];
    return n < 0 || facing[static_cast<size_t>(n)] != facing[t];
  }
};

// Shared by the forward and the backward pass so that both see the same pairs.
struct PairGeometry {
  int32_t owner_pixel, other_pixel;
  int32_t triangle, edge;
  Crossing crossing;
  ScreenVertex ends[2];
  int32_t end_vertices[2];
};

SD_HD PairGeometry MakePairGeometry(const AntialiasScene& sc, int32_t owner, int32_t other, int32_t t, int k,
                                    const Crossing& c) {
  PairGeometry g;
  g.owner_pixel = owner, g.other_pixel = other, g.triangle = t, g.edge = k, g.crossing = c;
  EdgeVertices(sc.tris, static_cast<size_t>(t), k, g.end_vertices);
  g.ends[0] = sc.screen[g.end_vertices[0]];
  g.ends[1] = sc.screen[g.end_vertices[1]];
  return g;
}

// The owner of a pair with different triangle ids: the pixel whose surface is in front.
SD_HD int32_t OwnerOf(const AntialiasScene& sc, int32_t a, int32_t b) {
  const int32_t ta = sc.triangle[a], tb = sc.triangle[b];
  if (ta < 0) return b;
  if (tb < 0) return a;
  if (sc.depth[a] != sc.depth[b]) return sc.depth[a] < sc.depth[b] ? a : b;
  return ta < tb ? a : b;
}

// The walk from the owner's centre through the mesh to the silhouette edge; bounded by kMaxWalk triangles.
constexpr int kMaxWalk = 16;

SD_HD bool FindSilhouette(const AntialiasScene& sc, int32_t owner, int32_t other, PairGeometry* g) {
  const PairFrame frame = MakeFrame(owner, other, sc.width);
  int32_t current = sc.triangle[owner];
  int entry_edge = -1;
  double entry_t = 0.0;
  for (int step = 0; step < kMaxWalk; ++step) {
    int exit_edge = -1;
    Crossing exit{};
    for (int k = 0; k < 3; ++k) {
      if (k == entry_edge) continue;
      int32_t ev[2];
      EdgeVertices(sc.tris, static_cast<size_t>(current), k, ev);
      Crossing c;
      if (!CrossPair(frame, sc.screen[ev[0]], sc.screen[ev[1]], &c) || c.t < entry_t) continue;
      if (exit_edge < 0 || c.t < exit.t) exit_edge = k, exit = c;
    }
    if (exit_edge < 0) return false;  // the segment ends inside this triangle: no outline between the pixels
    if (sc.IsSilhouette(static_cast<size_t>(current), exit_edge)) {
      *g = MakePairGeometry(sc, owner, other, current, exit_edge, exit);
      return BlendsAlong(frame, g->ends[0], g->ends[1]);
    }
    const int32_t next = sc.neighbour[3 * static_cast<size_t>(current) + exit_edge];
    int32_t ev[2];
    EdgeVertices(sc.tris, static_cast<size_t>(current), exit_edge, ev);
    entry_edge = -1;  // the neighbour's copy of the edge just crossed
    for (int k = 0; k < 3; ++k) {
      int32_t nv[2];
      EdgeVertices(sc.tris, static_cast<size_t>(next), k, nv);
      if ((nv[0] == ev[0] && nv[1] == ev[1]) || (nv[0] == ev[1] && nv[1] == ev[0])) entry_edge = k;
    }
    current = next;
    entry_t = exit.t;
  }
  return false;
}

SD_HD bool ExaminePair(const AntialiasScene& sc, int32_t a, int32_t b, PairGeometry* g) {
  if (sc.triangle[a] == sc.triangle[b]) return false;
  const int32_t owner = OwnerOf(sc, a, b);
  return FindSilhouette(sc, owner, owner == a ? b : a, g);
}

// A recorded pair's geometry, recomputed from the same inputs; false when the record does not match them.
SD_HD bool RecordedPair(const AntialiasScene& sc, int32_t pixel_a, int32_t pixel_b, int32_t triangle, int32_t edge,
                        PairGeometry* g) {
  const int32_t owner = OwnerOf(sc, pixel_a, pixel_b);
  const int32_t other = owner == pixel_a ? pixel_b : pixel_a;
  int32_t ev[2];
  EdgeVertices(sc.tris, static_cast<size_t>(triangle), edge, ev);
  Crossing c{};
  if (!CrossPair(MakeFrame(owner, other, sc.width), sc.screen[ev[0]], sc.screen[ev[1]], &c)) return false;
  *g = MakePairGeometry(sc, owner, other, triangle, edge, c);
  return true;
}

// Blend weight and which pixel receives it.
struct Blend {
  float alpha;
  int32_t receiver, source;
  double dalpha_dt;
};
SD_HD Blend BlendOf(const PairGeometry& g) {
  const double t = g.crossing.t;
  if (t >= 0.5) return {static_cast<float>(t - 0.5), g.other_pixel, g.owner_pixel, 1.0};
  return {static_cast<float>(0.5 - t), g.owner_pixel, g.other_pixel, -1.0};
}

// dL/d(clip x, y, w) of the pair's two edge endpoints from dL/dt (the crossing's position); writes 3 values
// per endpoint: (x, y, w).
SD_HD void CrossingClipGradient(const PairGeometry& g, int width, double dL_dt, double out[2][3]) {
  const bool horizontal = MakeFrame(g.owner_pixel, g.other_pixel, width).horizontal;
  const Crossing& cr = g.crossing;
  const double dt_dalong[2] = {cr.dt_dalong0, cr.dt_dalong1}, dt_dacross[2] = {cr.dt_dacross0, cr.dt_dacross1};
  for (int e = 0; e < 2; ++e) {
    const ScreenVertex& p = g.ends[e];
    const double dL_du = dL_dt * (horizontal ? dt_dalong[e] : dt_dacross[e]);
    const double dL_dv = dL_dt * (horizontal ? dt_dacross[e] : dt_dalong[e]);
    out[e][0] = dL_du * p.du_dx;
    out[e][1] = dL_dv * p.dv_dy;
    out[e][2] = dL_du * p.du_dw + dL_dv * p.dv_dw;
  }
}

// ---- vertex normals: per vertex (normals.h) ---------------------------------------------------------------

// geometry::VertexNormals' arithmetic, gathered per vertex instead of scattered per face: the sum over a
// vertex's faces, in ascending face order, of the face's (b - a) x (c - a) in double, which is the order in
// which the face loop adds them, so the sums agree bit for bit. `corners` lists the vertex's faces as
// 3 * face + k (k its corner), ascending.
SD_HD Vec3d Vec3dOf(const float* positions, int32_t v) {
  const float* p = &positions[3 * static_cast<size_t>(v)];
  return {p[0], p[1], p[2]};
}
SD_HD Vec3d Sub(const Vec3d& a, const Vec3d& b) { return {a.x - b.x, a.y - b.y, a.z - b.z}; }
SD_HD Vec3d Add(const Vec3d& a, const Vec3d& b) { return {a.x + b.x, a.y + b.y, a.z + b.z}; }

SD_HD Vec3d VertexNormalSum(const float* positions, const int32_t* tris, const int32_t* corners, int32_t begin,
                            int32_t end) {
  Vec3d sum{0, 0, 0};
  for (int32_t i = begin; i < end; ++i) {
    const int32_t* t = &tris[3 * static_cast<size_t>(corners[i] / 3)];
    const Vec3d a = Vec3dOf(positions, t[0]);
    sum = Add(sum, Cross(Sub(Vec3dOf(positions, t[1]), a), Sub(Vec3dOf(positions, t[2]), a)));
  }
  return sum;
}

// n = s / |s| as floats; the constant 0 where |s| = 0 (no faces, or all degenerate).
SD_HD void NormalFromSum(const Vec3d& s, float* normal) {
  const double len = Sqrt(s.x * s.x + s.y * s.y + s.z * s.z);
  if (len > 0) {
    normal[0] = static_cast<float>(s.x / len), normal[1] = static_cast<float>(s.y / len);
    normal[2] = static_cast<float>(s.z / len);
  } else {
    normal[0] = normal[1] = normal[2] = 0.0f;
  }
}

// dL/ds = (g - n (n . g)) / |s|: only the part of g orthogonal to n moves the normal; 0 where |s| = 0.
SD_HD Vec3d NormalSumGradient(const Vec3d& s, const float* grad_normal) {
  const double len = Sqrt(s.x * s.x + s.y * s.y + s.z * s.z);
  if (!(len > 0)) return {0, 0, 0};
  const Vec3d n{s.x / len, s.y / len, s.z / len};
  const Vec3d g{grad_normal[0], grad_normal[1], grad_normal[2]};
  const double ng = Dot(n, g);
  return {(g.x - n.x * ng) / len, (g.y - n.y * ng) / len, (g.z - n.z * ng) / len};
}

// A vertex's dL/dp: each face adds a x b + b x c + c x a to its vertices' sums, so with G the sum of dL/ds
// over its three vertices, dL/da = (b - c) x G, dL/db = (c - a) x G, dL/dc = (a - b) x G; summed over the
// vertex's faces in ascending order, as geometry::VertexNormalsBackward's face loop does. ds: 3 per vertex.
SD_HD Vec3d VertexPositionGradient(const float* positions, const int32_t* tris, const double* ds,
                                   const int32_t* corners, int32_t begin, int32_t end) {
  Vec3d sum{0, 0, 0};
  for (int32_t i = begin; i < end; ++i) {
    const int32_t* t = &tris[3 * static_cast<size_t>(corners[i] / 3)];
    const int k = corners[i] % 3;
    const double* d0 = &ds[3 * static_cast<size_t>(t[0])];
    const double* d1 = &ds[3 * static_cast<size_t>(t[1])];
    const double* d2 = &ds[3 * static_cast<size_t>(t[2])];
    const Vec3d G{d0[0] + d1[0] + d2[0], d0[1] + d1[1] + d2[1], d0[2] + d1[2] + d2[2]};
    const Vec3d p[3] = {Vec3dOf(positions, t[0]), Vec3dOf(positions, t[1]), Vec3dOf(positions, t[2])};
    sum = Add(sum, Cross(Sub(p[(k + 1) % 3], p[(k + 2) % 3]), G));
  }
  return sum;
}

}  // namespace sd::raster::shared
