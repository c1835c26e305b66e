// BuildEdgeTopology / Antialias / AntialiasBackward: analytic anti-aliasing of silhouette edges after
// Laine et al. 2020, "Modular primitives for high-performance differentiable rendering", section 4.3.
//
// The choices made here (the paper leaves the details open):
//  - Pairs. Every horizontally or vertically adjacent pixel pair (a left of / above b) whose triangle ids
//    differ is examined. The "owner" is the pixel whose surface is in front: the covered one when the other
//    is background, else the smaller depth (ties to the lower triangle index, as in Rasterize).
//  - Silhouette edge: a mesh boundary edge, or one whose two triangles face opposite ways on screen (signs of
//    the projected 2D signed areas differ; a neighbour that is not drawn, w <= 0, counts as facing away).
//  - Search (FindSilhouette): walk the segment between the two pixel centres from the owner's centre, through
//    the owner's triangle and on across non-silhouette edges into the neighbours (same facing: the same
//    visible surface), until it leaves by a silhouette edge; t in [0, 1] is that crossing's distance from the
//    owner's centre, in pixels. Looking at the owner's triangle alone is not enough: near an outline triangles
//    are seen edge-on, and the pixel next to the background is usually covered by a triangle several slivers
//    away from the silhouette edge (on a 10k-triangle sphere the owner's own triangle held the edge for ~1% of
//    outline pixels). The record keeps the triangle and edge found.
//  - Axis: a horizontal pair only blends across edges at least as vertical as horizontal (|dv| >= |du|), a
//    vertical pair only across the others, so an edge's coverage is counted along one axis, not twice.
//  - Blend: a 1D box filter across the pixel pair. The owner's surface covers [0, t] of the unit segment from
//    the owner's centre towards the other; each pixel's footprint extends half a pixel either side of its
//    centre. So
//      t >= 1/2: the surface spills (t - 1/2) into the other pixel:  out_other += (t - 1/2) (c_owner - c_other);
//      t <  1/2: it misses (1/2 - t) of the owner's pixel:           out_owner += (1/2 - t) (c_other - c_owner).
//    alpha = |t - 1/2| is continuous at t = 1/2 and d(coverage)/dt = +1 on both sides, so moving an edge
//    outwards always raises the owner colour's share: a mask loss pulls the outline the right way, with a
//    gradient of 1 per pixel row crossed (the derivative of a box-filtered edge). A vertical edge at u = e
//    gives a row whose mask sums to exactly e (tested).
//  - Deltas are computed from the input colours (not chained when a pixel is in several pairs) and summed
//    serially in pair order, so the result is deterministic.
// Known limits: a walk longer than kMaxWalk triangles gives up; a silhouette edge that crosses a pair but
// blends along the other axis is not seen by that pair, so where a triangulated outline zigzags a few outline
// pixels (2-4% on a finely tessellated sphere) stay unblended. Such pairs give no gradient; forward and
// backward always agree.
#include <algorithm>
#include <array>
#include <cmath>
#include <vector>

#include "core/parallel.h"
#include "raster/internal.h"
#include "raster/raster.h"

namespace sd::raster {
namespace {

// Vertex indices of edge k of triangle t (edges v0v1, v1v2, v2v0, as in EdgeTopology).
inline std::array<int32_t, 2> EdgeVertices(std::span<const int32_t> tris, size_t t, int k) {
  return {tris[3 * t + k], tris[3 * t + (k + 1) % 3]};
}

// +1 / -1: winding of the triangle's projection on screen; 0 when it is not drawn (w <= 0) or degenerate.
int ScreenFacing(std::span<const float> clip_pos, std::span<const int32_t> tris, size_t t) {
  if (!internal::TriangleDrawable(clip_pos, tris, t)) return 0;
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

// Projected endpoint of a vertex: pixel coordinates and their derivatives with respect to the clip
// coordinates (u depends on x and w, v on y and w).
struct ScreenVertex {
  double u, v;
  double du_dx, du_dw, dv_dy, dv_dw;
};

ScreenVertex Project(std::span<const float> clip_pos, int32_t vertex, int width, int height) {
  const float* c = &clip_pos[4 * static_cast<size_t>(vertex)];
  const double x = c[0], y = c[1], w = c[3];
  ScreenVertex s;
  s.u = internal::ClipToPixel(x, w, width);
  s.v = internal::ClipToPixel(y, w, height);
  s.du_dx = 0.5 * width / w;
  s.du_dw = -0.5 * width * x / (w * w);
  s.dv_dy = 0.5 * height / w;
  s.dv_dw = -0.5 * height * y / (w * w);
  return s;
}

// Geometry of one pixel pair, in a frame where the pair runs along the first coordinate ("along") and the
// other coordinate ("across") is constant at the centres: for a horizontal pair along = u, across = v.
struct PairFrame {
  bool horizontal;
  double owner_along;  // owner pixel centre
  double direction;    // +1 when the other pixel is at larger along, -1 otherwise
  double across;       // the centres' common across coordinate
};

// Where an edge crosses the pair segment: t (from the owner's centre) and dt/d(endpoint along, across).
struct Crossing {
  double t;
  double dt_dalong0, dt_dacross0, dt_dalong1, dt_dacross1;
};

// Crossing of the pair segment by the edge p0-p1 (any orientation); false when they do not cross.
bool CrossPair(const PairFrame& f, const ScreenVertex& p0, const ScreenVertex& p1, Crossing* out) {
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

// Blending axis (see the file comment): a horizontal pair takes edges at least as vertical as horizontal, a
// vertical pair strictly more horizontal ones, so each edge blends along exactly one axis.
bool BlendsAlong(const PairFrame& f, const ScreenVertex& p0, const ScreenVertex& p1) {
  const double du = std::abs(p1.u - p0.u), dv = std::abs(p1.v - p0.v);
  return f.horizontal ? dv >= du : du > dv;
}

// Shared by the forward and the backward pass so that both see the same pairs.
struct PairGeometry {
  int32_t owner_pixel, other_pixel;
  int32_t triangle, edge;
  Crossing crossing;
  std::array<ScreenVertex, 2> ends;
  std::array<int32_t, 2> end_vertices;
};

PairFrame MakeFrame(int32_t owner, int32_t other, int width) {
  const int ox = owner % width, oy = owner / width, px = other % width, py = other / width;
  PairFrame f;
  f.horizontal = oy == py;
  f.owner_along = (f.horizontal ? ox : oy) + 0.5;
  f.direction = (f.horizontal ? px - ox : py - oy) > 0 ? 1.0 : -1.0;
  f.across = (f.horizontal ? oy : ox) + 0.5;
  return f;
}

// Per-call geometry shared by all pairs: each vertex projected once, each triangle's facing once.
struct Scene {
  const RasterBuffer& rast;
  std::span<const int32_t> tris;
  const EdgeTopology& topology;
  std::vector<ScreenVertex> screen;  // per vertex
  std::vector<int8_t> facing;        // per triangle: ScreenFacing

  Scene(const RasterBuffer& r, std::span<const float> clip_pos, std::span<const int32_t> t, const EdgeTopology& top)
      : rast(r), tris(t), topology(top), screen(internal::NumVertices(clip_pos)), facing(t.size() / 3) {
    ParallelForRange(0, screen.size(), 1024, [&](size_t begin, size_t end) {
      for (size_t v = begin; v < end; ++v) screen[v] = Project(clip_pos, static_cast<int32_t>(v), r.width, r.height);
    });
    ParallelForRange(0, facing.size(), 1024, [&](size_t begin, size_t end) {
      for (size_t f = begin; f < end; ++f) facing[f] = static_cast<int8_t>(ScreenFacing(clip_pos, t, f));
    });
  }

  bool IsSilhouette(size_t t, int k) const {
    const int32_t n = topology.neighbour[3 * t + k];
    return n < 0 || facing[static_cast<size_t>(n)] != facing[t];
  }
  PairGeometry Edge(int32_t owner, int32_t other, int32_t t, int k, const Crossing& c) const {
    const std::array<int32_t, 2> ev = EdgeVertices(tris, static_cast<size_t>(t), k);
    return PairGeometry{owner, other, t, k, c, {screen[ev[0]], screen[ev[1]]}, ev};
  }
};

// The owner of a pair with different triangle ids: the pixel whose surface is in front.
int32_t OwnerOf(const RasterBuffer& rast, int32_t a, int32_t b) {
  const int32_t ta = rast.triangle[a], tb = rast.triangle[b];
  if (ta < 0) return b;
  if (tb < 0) return a;
  if (rast.depth[a] != rast.depth[b]) return rast.depth[a] < rast.depth[b] ? a : b;
  return ta < tb ? a : b;
}

// Walks the pair segment from the owner's centre through the mesh: in the current triangle, the segment
// leaves by the crossed edge nearest beyond the entry point; a silhouette edge ends the walk, any other edge
// leads into the neighbour across it (which faces the same way: the same visible surface). Near an outline
// triangles are seen edge-on, so the pixel next to the background is often covered by a triangle several
// slivers away from the silhouette edge; the walk finds that edge where a look at the owner's triangle
// alone would not. Bounded by kMaxWalk triangles.
constexpr int kMaxWalk = 16;

bool FindSilhouette(const Scene& sc, int32_t owner, int32_t other, PairGeometry* g) {
  const PairFrame frame = MakeFrame(owner, other, sc.rast.width);
  int32_t current = sc.rast.triangle[owner];
  int entry_edge = -1;
  double entry_t = 0.0;
  for (int step = 0; step < kMaxWalk; ++step) {
    int exit_edge = -1;
    Crossing exit{};
    for (int k = 0; k < 3; ++k) {
      if (k == entry_edge) continue;
      const std::array<int32_t, 2> ev = EdgeVertices(sc.tris, static_cast<size_t>(current), k);
      Crossing c;
      if (!CrossPair(frame, sc.screen[ev[0]], sc.screen[ev[1]], &c) || c.t < entry_t) continue;
      if (exit_edge < 0 || c.t < exit.t) exit_edge = k, exit = c;
    }
    if (exit_edge < 0) return false;  // the segment ends inside this triangle: no outline between the pixels
    if (sc.IsSilhouette(static_cast<size_t>(current), exit_edge)) {
      *g = sc.Edge(owner, other, current, exit_edge, exit);
      return BlendsAlong(frame, g->ends[0], g->ends[1]);
    }
    const int32_t next = sc.topology.neighbour[3 * static_cast<size_t>(current) + exit_edge];
    const std::array<int32_t, 2> ev = EdgeVertices(sc.tris, static_cast<size_t>(current), exit_edge);
    entry_edge = -1;  // the neighbour's copy of the edge just crossed
    for (int k = 0; k < 3; ++k) {
      const std::array<int32_t, 2> nv = EdgeVertices(sc.tris, static_cast<size_t>(next), k);
      if ((nv[0] == ev[0] && nv[1] == ev[1]) || (nv[0] == ev[1] && nv[1] == ev[0])) entry_edge = k;
    }
    current = next;
    entry_t = exit.t;
  }
  return false;
}

bool ExaminePair(const Scene& sc, int32_t a, int32_t b, PairGeometry* g) {
  if (sc.rast.triangle[a] == sc.rast.triangle[b]) return false;
  const int32_t owner = OwnerOf(sc.rast, a, b);
  return FindSilhouette(sc, owner, owner == a ? b : a, g);
}

// A recorded pair's geometry, recomputed from the same inputs (for blending and for the backward pass).
PairGeometry RecordedPair(const Scene& sc, const AntialiasRecord::PixelPair& pair) {
  const int32_t owner = OwnerOf(sc.rast, pair.pixel_a, pair.pixel_b);
  const int32_t other = owner == pair.pixel_a ? pair.pixel_b : pair.pixel_a;
  const std::array<int32_t, 2> ev = EdgeVertices(sc.tris, static_cast<size_t>(pair.triangle), pair.edge);
  Crossing c{};
  const bool crosses = CrossPair(MakeFrame(owner, other, sc.rast.width), sc.screen[ev[0]], sc.screen[ev[1]], &c);
  SD_CHECK(crosses, << "AntialiasRecord does not match the geometry it is used with");
  return sc.Edge(owner, other, pair.triangle, pair.edge, c);
}

// Blend weight and which pixel receives it (see the file comment).
struct Blend {
  float alpha;
  int32_t receiver, source;
  double dalpha_dt;
};
Blend BlendOf(const PairGeometry& g) {
  const double t = g.crossing.t;
  if (t >= 0.5) return {static_cast<float>(t - 0.5), g.other_pixel, g.owner_pixel, 1.0};
  return {static_cast<float>(0.5 - t), g.owner_pixel, g.other_pixel, -1.0};
}

void CheckAntialiasArgs(std::span<const float> color, int channels, const RasterBuffer& rast,
                        std::span<const float> clip_pos, std::span<const int32_t> tris, const EdgeTopology& topology) {
  internal::CheckRaster(rast);
  internal::CheckTriangles(clip_pos, tris);
  SD_CHECK(channels > 0 && color.size() == static_cast<size_t>(channels) * rast.NumPixels(),
           << "color: " << color.size() << " floats for " << channels << " channels");
  SD_CHECK(topology.neighbour.size() == tris.size(), << "topology built for another mesh");
}

}  // namespace

EdgeTopology BuildEdgeTopology(std::span<const int32_t> tris, int num_vertices) {
  SD_CHECK(tris.size() % 3 == 0 && num_vertices >= 0);
  const size_t num_edges = tris.size();
  // Sort half-edges by their undirected vertex pair; runs of exactly two are manifold edges.
  struct HalfEdge {
    int32_t lo, hi;
    uint32_t slot;  // 3 * triangle + edge
  };
  std::vector<HalfEdge> half(num_edges);
  for (size_t t = 0; t < num_edges / 3; ++t)
    for (int k = 0; k < 3; ++k) {
      const std::array<int32_t, 2> ev = EdgeVertices(tris, t, k);
      SD_CHECK(ev[0] >= 0 && ev[0] < num_vertices && ev[1] >= 0 && ev[1] < num_vertices, << "triangle " << t);
      half[3 * t + k] = {std::min(ev[0], ev[1]), std::max(ev[0], ev[1]), static_cast<uint32_t>(3 * t + k)};
    }
  std::sort(half.begin(), half.end(), [](const HalfEdge& x, const HalfEdge& y) {
    return x.lo != y.lo ? x.lo < y.lo : (x.hi != y.hi ? x.hi < y.hi : x.slot < y.slot);
  });
  EdgeTopology topology;
  topology.neighbour.assign(num_edges, -1);
  for (size_t i = 0; i < half.size();) {
    size_t j = i + 1;
    while (j < half.size() && half[j].lo == half[i].lo && half[j].hi == half[i].hi) ++j;
    if (j - i == 2 && half[i].lo != half[i].hi) {
      topology.neighbour[half[i].slot] = static_cast<int32_t>(half[i + 1].slot / 3);
      topology.neighbour[half[i + 1].slot] = static_cast<int32_t>(half[i].slot / 3);
    }
    i = j;
  }
  return topology;
}

void Antialias(std::span<const float> color, int channels, const RasterBuffer& rast, std::span<const float> clip_pos,
               std::span<const int32_t> tris, const EdgeTopology& topology, std::span<float> out,
               AntialiasRecord* record, bool color_gradient) {
  CheckAntialiasArgs(color, channels, rast, clip_pos, tris, topology);
  SD_CHECK(out.size() == color.size(), << "out: " << out.size());
  SD_CHECK(out.data() != color.data(), << "Antialias cannot work in place");
  SD_CHECK(record != nullptr);
  const Scene sc(rast, clip_pos, tris, topology);
  const int width = rast.width, height = rast.height;

  const size_t C = static_cast<size_t>(channels);
  auto same_color = [&](int32_t a, int32_t b) {
    for (size_t c = 0; c < C; ++c)
      if (color[C * a + c] != color[C * b + c]) return false;
    return true;
  };
  // Pairs whose first pixel is in row j, found per row in parallel and concatenated in row order.
  std::vector<std::vector<AntialiasRecord::PixelPair>> rows(height);
  ParallelFor(0, static_cast<size_t>(height), [&](size_t j) {
    for (int i = 0; i < width; ++i) {
      const int32_t a = static_cast<int32_t>(j * width + i);
      for (const int32_t b : {i + 1 < width ? a + 1 : -1, static_cast<int>(j) + 1 < height ? a + width : -1}) {
        PairGeometry g;
        if (b < 0 || rast.triangle[a] == rast.triangle[b]) continue;
        if (!color_gradient && same_color(a, b)) continue;
        if (!ExaminePair(sc, a, b, &g)) continue;
        rows[j].push_back({a, b, g.triangle, g.edge, BlendOf(g).alpha});
      }
    }
  });
  record->pairs.clear();
  for (const auto& row : rows) record->pairs.insert(record->pairs.end(), row.begin(), row.end());

  std::copy(color.begin(), color.end(), out.begin());
  for (const AntialiasRecord::PixelPair& pair : record->pairs) {
    const Blend blend = BlendOf(RecordedPair(sc, pair));
    for (size_t c = 0; c < C; ++c)
      out[C * blend.receiver + c] += blend.alpha * (color[C * blend.source + c] - color[C * blend.receiver + c]);
  }
}

void AntialiasBackward(std::span<const float> color, int channels, const RasterBuffer& rast,
                       std::span<const float> clip_pos, std::span<const int32_t> tris, const EdgeTopology& topology,
                       const AntialiasRecord& record, std::span<const float> grad_out, std::span<float> grad_color,
                       std::span<float> grad_clip) {
  CheckAntialiasArgs(color, channels, rast, clip_pos, tris, topology);
  SD_CHECK(grad_out.size() == color.size(), << "grad_out: " << grad_out.size());
  SD_CHECK(grad_color.size() == color.size(), << "grad_color: " << grad_color.size());
  SD_CHECK(grad_clip.size() == clip_pos.size(), << "grad_clip: " << grad_clip.size());
  const Scene sc(rast, clip_pos, tris, topology);
  const size_t C = static_cast<size_t>(channels);

  for (size_t n = 0; n < grad_out.size(); ++n) grad_color[n] += grad_out[n];  // out = color + deltas
  std::vector<double> dL_dclip(grad_clip.size(), 0.0);
  for (const AntialiasRecord::PixelPair& pair : record.pairs) {
    const PairGeometry g = RecordedPair(sc, pair);
    const Blend blend = BlendOf(g);
    // out_r = c_r + alpha (c_s - c_r).
    double dL_dalpha = 0;
    for (size_t c = 0; c < C; ++c) {
      const float g_r = grad_out[C * blend.receiver + c];
      dL_dalpha += static_cast<double>(g_r) * (color[C * blend.source + c] - color[C * blend.receiver + c]);
      grad_color[C * blend.source + c] += blend.alpha * g_r;
      grad_color[C * blend.receiver + c] -= blend.alpha * g_r;
    }
    const double dL_dt = dL_dalpha * blend.dalpha_dt;
    if (dL_dt == 0) continue;
    const bool horizontal = MakeFrame(g.owner_pixel, g.other_pixel, rast.width).horizontal;
    const Crossing& cr = g.crossing;
    const double dt_dalong[2] = {cr.dt_dalong0, cr.dt_dalong1}, dt_dacross[2] = {cr.dt_dacross0, cr.dt_dacross1};
    for (int e = 0; e < 2; ++e) {
      const ScreenVertex& p = g.ends[e];
      const double dL_du = dL_dt * (horizontal ? dt_dalong[e] : dt_dacross[e]);
      const double dL_dv = dL_dt * (horizontal ? dt_dacross[e] : dt_dalong[e]);
      double* d = &dL_dclip[4 * static_cast<size_t>(g.end_vertices[e])];
      d[0] += dL_du * p.du_dx;
      d[1] += dL_dv * p.dv_dy;
      d[3] += dL_du * p.du_dw + dL_dv * p.dv_dw;
    }
  }
  for (size_t n = 0; n < dL_dclip.size(); ++n) grad_clip[n] += static_cast<float>(dL_dclip[n]);
}

}  // namespace sd::raster
