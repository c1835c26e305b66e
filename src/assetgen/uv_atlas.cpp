#include "assetgen/uv_atlas.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <numeric>
#include <unordered_map>
#include <utility>

#include <Eigen/Geometry>

#include "core/error.h"
#include "core/parallel.h"
#include "geometry/edge_adjacency.h"
#include "geometry/topology.h"
#include "raster/raster.h"

namespace sd {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr int kMinTextureSize = 64, kMaxTextureSize = 16384;

void CheckTextureSize(int size, const char* what) {
  if (size < kMinTextureSize || size > kMaxTextureSize)
    throw InputError({}, Msg() << what << ": texture size " << size << " outside [" << kMinTextureSize << ", "
                               << kMaxTextureSize << "]");
}

void CheckPadding(int padding, int size, const char* what) {
  // A gutter wider than an eighth of the atlas leaves no room for charts; it is a typo, not a choice.
  if (padding < 0 || padding > size / 8)
    throw InputError({}, Msg() << what << ": padding " << padding << " px outside [0, " << size / 8 << "]");
}

// ---------------------------------------------------------------------------------------------------------
// Charts

struct Chart {
  std::vector<int> faces;
  double cone_deg = 0;  // the normal-cone bound it was grown with (halved on every split)
  bool fixed = false;   // degenerate face: a one-texel triangle, independent of the texel density
  // Per face corner (3 per face, in `faces` order): chart-plane coordinates, world units (texels if fixed),
  // rotated to the minimum-area bounding rectangle and shifted to start at (0, 0).
  std::vector<Eigen::Vector2d> corner;
  double width = 0, height = 0;  // of that rectangle, width >= height
};

// Face adjacency across welded, manifold, consistently oriented edges: neighbour[3f + k] is the face across
// edge (k, k+1), or -1. Edges with more than two faces are cuts (a chart never grows across a non-manifold
// edge), and so are edges both faces run the same way: a duplicated face or a flipped neighbour, either of
// which would land on top of its neighbour in the chart's plane. Those are exactly the edges without twins.
std::vector<int> FaceAdjacency(int num_welded_vertices, const std::vector<Eigen::Vector3i>& welded_faces) {
  const geometry::EdgeAdjacency adjacency = geometry::BuildEdgeAdjacency(
      num_welded_vertices, welded_faces, geometry::DegenerateFaces::kKeepProperEdges);
  std::vector<int> neighbour(adjacency.twin.size(), -1);
  for (size_t h = 0; h < neighbour.size(); ++h) {
    if (adjacency.twin[h] >= 0) neighbour[h] = adjacency.twin[h] / 3;
  }
  return neighbour;
}

// Region growing from seeds in face order: a face joins while its normal is within `cone_deg` of the seed's.
// Measuring against the fixed seed normal (not a running mean) is what makes the planar projection safe:
// every face then has a positive cosine to the seed normal, so projecting along it flips no triangle and
// shrinks none below cos(cone) of its area.
std::vector<Chart> GrowCharts(const std::vector<int>& candidates, double cone_deg, const std::vector<int>& neighbour,
                              const std::vector<Eigen::Vector3d>& face_normal, std::vector<int>* label, int tag) {
  const double cos_max = std::cos(cone_deg * kPi / 180.0);
  // label == tag: free and allowed in this call (each call brings a fresh tag); 0: taken.
  for (int f : candidates) (*label)[f] = tag;
  std::vector<Chart> charts;
  std::vector<int> queue;
  for (int seed : candidates) {
    if ((*label)[seed] != tag) continue;
    Chart chart;
    chart.cone_deg = cone_deg;
    const Eigen::Vector3d n0 = face_normal[seed];
    constexpr int taken = 0;
    (*label)[seed] = taken;
    queue.assign(1, seed);
    for (size_t q = 0; q < queue.size(); ++q) {
      const int f = queue[q];
      chart.faces.push_back(f);
      for (int k = 0; k < 3; ++k) {
        const int g = neighbour[3 * f + k];
        if (g < 0 || (*label)[g] != tag || face_normal[g].dot(n0) < cos_max) continue;
        (*label)[g] = taken;
        queue.push_back(g);
      }
    }
    charts.push_back(std::move(chart));
  }
  return charts;
}

double Cross2(const Eigen::Vector2d& a, const Eigen::Vector2d& b) { return a.x() * b.y() - a.y() * b.x(); }

// Andrew's monotone chain; counter-clockwise, no collinear points.
std::vector<Eigen::Vector2d> ConvexHull(std::vector<Eigen::Vector2d> p) {
  std::sort(p.begin(), p.end(), [](const auto& a, const auto& b) { return a.x() < b.x() || (a.x() == b.x() && a.y() < b.y()); });
  if (p.size() < 3) return p;
  std::vector<Eigen::Vector2d> h(2 * p.size());
  size_t k = 0;
  for (size_t i = 0; i < p.size(); ++i) {
    while (k >= 2 && Cross2(h[k - 1] - h[k - 2], p[i] - h[k - 2]) <= 0) --k;
    h[k++] = p[i];
  }
  for (size_t i = p.size() - 1, t = k + 1; i > 0; --i) {
    while (k >= t && Cross2(h[k - 1] - h[k - 2], p[i - 1] - h[k - 2]) <= 0) --k;
    h[k++] = p[i - 1];
  }
  h.resize(k - 1);
  return h;
}

// Projects the chart onto its plane and turns it to its minimum-area bounding rectangle (one side of that
// rectangle lies along a hull edge), landscape, origin at the rectangle's corner. Rotations only: the
// projection's orientation survives.
void Flatten(Chart* chart, const TriangleMesh& mesh, const std::vector<Eigen::Vector3d>& face_normal,
             const std::vector<double>& face_area) {
  // Best-fit plane: the area-weighted mean normal, unless some face would lean further from it than from the
  // seed's normal (the one the cone guarantees); the plane is the one with the larger worst-case cosine.
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (int f : chart->faces) mean += face_area[f] * face_normal[f];
  const Eigen::Vector3d seed = face_normal[chart->faces.front()];
  Eigen::Vector3d n = seed;
  if (mean.norm() > 0) {
    mean.normalize();
    double worst_mean = 1, worst_seed = 1;
    for (int f : chart->faces) {
      worst_mean = std::min(worst_mean, face_normal[f].dot(mean));
      worst_seed = std::min(worst_seed, face_normal[f].dot(seed));
    }
    if (worst_mean >= worst_seed) n = mean;
  }
  const Eigen::Vector3d a = n.unitOrthogonal(), b = n.cross(a);  // (a, b, n) right-handed: CCW stays CCW
  chart->corner.resize(3 * chart->faces.size());
  for (size_t i = 0; i < chart->faces.size(); ++i) {
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector3d p = mesh.positions[mesh.faces[chart->faces[i]][k]].cast<double>();
      chart->corner[3 * i + k] = Eigen::Vector2d(p.dot(a), p.dot(b));
    }
  }
  const std::vector<Eigen::Vector2d> hull = ConvexHull(chart->corner);
  Eigen::Vector2d best_dir(1, 0);
  double best_area = std::numeric_limits<double>::max();
  for (size_t i = 0; i < hull.size(); ++i) {
    const Eigen::Vector2d e = hull[(i + 1) % hull.size()] - hull[i];
    if (e.norm() <= 0) continue;
    const Eigen::Vector2d d = e.normalized(), d_perp(-d.y(), d.x());
    double lo_u = 1e300, hi_u = -1e300, lo_v = 1e300, hi_v = -1e300;
    for (const auto& q : hull) {
      lo_u = std::min(lo_u, q.dot(d)), hi_u = std::max(hi_u, q.dot(d));
      lo_v = std::min(lo_v, q.dot(d_perp)), hi_v = std::max(hi_v, q.dot(d_perp));
    }
    const double area = (hi_u - lo_u) * (hi_v - lo_v);
    if (area < best_area) best_area = area, best_dir = d;
  }
  Eigen::Vector2d d = best_dir, d_perp(-d.y(), d.x());
  auto extent = [&](const Eigen::Vector2d& axis) {
    double lo = 1e300, hi = -1e300;
    for (const auto& q : chart->corner) lo = std::min(lo, q.dot(axis)), hi = std::max(hi, q.dot(axis));
    return hi - lo;
  };
  if (extent(d) < extent(d_perp)) {  // a quarter turn makes it landscape (shelves are then low)
    d = d_perp;
    d_perp = Eigen::Vector2d(-d.y(), d.x());
  }
  Eigen::Vector2d lo(1e300, 1e300), hi(-1e300, -1e300);
  for (auto& q : chart->corner) {
    q = Eigen::Vector2d(q.dot(d), q.dot(d_perp));
    lo = lo.cwiseMin(q), hi = hi.cwiseMax(q);
  }
  for (auto& q : chart->corner) q -= lo;
  chart->width = hi.x() - lo.x();
  chart->height = hi.y() - lo.y();
}

// True when two triangles' interiors overlap: no separating axis among their six edge normals. `eps`
// (world units) lets triangles that only touch along an edge or at a vertex count as separate.
bool TrianglesOverlap(const Eigen::Vector2d* A, const Eigen::Vector2d* B, double eps) {
  for (int t = 0; t < 2; ++t) {
    const Eigen::Vector2d* P = t == 0 ? A : B;
    for (int k = 0; k < 3; ++k) {
      const Eigen::Vector2d e = P[(k + 1) % 3] - P[k];
      const double len = e.norm();
      if (len <= 0) continue;
      const Eigen::Vector2d axis(-e.y() / len, e.x() / len);
      double lo_a = 1e300, hi_a = -1e300, lo_b = 1e300, hi_b = -1e300;
      for (int j = 0; j < 3; ++j) {
        lo_a = std::min(lo_a, A[j].dot(axis)), hi_a = std::max(hi_a, A[j].dot(axis));
        lo_b = std::min(lo_b, B[j].dot(axis)), hi_b = std::max(hi_b, B[j].dot(axis));
      }
      if (hi_a <= lo_b + eps || hi_b <= lo_a + eps) return false;
    }
  }
  return true;
}

// Whether a flattened chart overlaps itself. Positive orientation of every face (the cone bound) rules out
// folds across an edge, not a chart that winds round onto itself (a helicoid-like strip, a fan round a cone
// apex of more than 360 degrees), so pairs are tested exactly, bucketed by a uniform grid over the chart.
bool SelfOverlaps(const Chart& chart) {
  const size_t n = chart.faces.size();
  if (n < 2) return false;
  double area = 0;
  for (size_t i = 0; i < n; ++i) {
    const auto* c = &chart.corner[3 * i];
    area += 0.5 * std::abs(Cross2(c[1] - c[0], c[2] - c[0]));
  }
  const double extent = std::max(chart.width, chart.height);
  if (extent <= 0) return false;
  const double eps = 1e-7 * extent;
  // About two triangles per cell; at most 4n cells.
  double cell = std::sqrt(std::max(2.0 * area / static_cast<double>(n), 1e-30));
  cell = std::max(cell, std::sqrt(chart.width * chart.height / (4.0 * static_cast<double>(n))));
  cell = std::max(cell, extent / 1024.0);
  const int gx = std::max(1, static_cast<int>(std::ceil(chart.width / cell))),
            gy = std::max(1, static_cast<int>(std::ceil(chart.height / cell)));
  std::vector<std::vector<int>> grid(static_cast<size_t>(gx) * gy);
  for (size_t i = 0; i < n; ++i) {
    const auto* c = &chart.corner[3 * i];
    const Eigen::Vector2d lo = c[0].cwiseMin(c[1]).cwiseMin(c[2]), hi = c[0].cwiseMax(c[1]).cwiseMax(c[2]);
    const int x0 = std::clamp(static_cast<int>(lo.x() / cell), 0, gx - 1),
              x1 = std::clamp(static_cast<int>(hi.x() / cell), 0, gx - 1);
    const int y0 = std::clamp(static_cast<int>(lo.y() / cell), 0, gy - 1),
              y1 = std::clamp(static_cast<int>(hi.y() / cell), 0, gy - 1);
    for (int y = y0; y <= y1; ++y)
      for (int x = x0; x <= x1; ++x) grid[static_cast<size_t>(y) * gx + x].push_back(static_cast<int>(i));
  }
  for (const auto& bucket : grid) {
    for (size_t i = 0; i < bucket.size(); ++i) {
      for (size_t j = i + 1; j < bucket.size(); ++j) {
        if (TrianglesOverlap(&chart.corner[3 * bucket[i]], &chart.corner[3 * bucket[j]], eps)) return true;
      }
    }
  }
  return false;
}

// ---------------------------------------------------------------------------------------------------------
// Packing: a skyline packer (bottom-left: each rectangle, tallest first, goes where its top ends lowest,
// either way round) over chart bounding rectangles grown by the gutter.

struct Placement {
  int x = 0, y = 0;      // texel corner of the chart's padded rectangle
  bool turned = false;   // chart turned a quarter (x, y) -> (y, width - x): still a rotation, no flip
};

int PaddedSide(double side_world, double density, bool fixed, int padding) {
  const double texels = fixed ? side_world : side_world * density;
  return static_cast<int>(std::ceil(texels)) + 2 * padding;
}

// `rule` orders the rectangles: 0 tallest first, 1 largest area first, 2 longest side first.
bool Pack(const std::vector<Chart>& charts, double density, int size, int padding, int rule,
          std::vector<Placement>* out) {
  const size_t n = charts.size();
  std::vector<int> w(n), h(n);
  for (size_t i = 0; i < n; ++i) {
    w[i] = PaddedSide(charts[i].width, density, charts[i].fixed, padding);
    h[i] = PaddedSide(charts[i].height, density, charts[i].fixed, padding);
    if (std::min(w[i], h[i]) > size) return false;
  }
  std::vector<int> order(n);
  std::iota(order.begin(), order.end(), 0);
  auto key = [&](int i) -> int64_t {
    return rule == 0 ? h[i] : rule == 1 ? int64_t{w[i]} * h[i] : std::max(w[i], h[i]);
  };
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return key(a) > key(b); });
  out->assign(n, {});
  struct Segment {
    int x, y, width;
  };
  std::vector<Segment> sky = {{0, 0, size}};
  for (int i : order) {
    int best_top = std::numeric_limits<int>::max(), best_x = 0, best_seg = -1, best_w = 0, best_h = 0;
    bool best_turned = false;
    for (int turn = 0; turn < 2; ++turn) {
      const int rw = turn ? h[i] : w[i], rh = turn ? w[i] : h[i];
      if (rw > size || rh > size) continue;
      for (size_t s = 0; s < sky.size(); ++s) {
        if (sky[s].x + rw > size) break;
        // The rectangle rests on the highest segment it spans from sky[s].x.
        int y = 0, covered = 0;
        for (size_t t = s; t < sky.size() && covered < rw; ++t) {
          y = std::max(y, sky[t].y);
          covered += sky[t].width;
        }
        if (y + rh > size) continue;
        if (y + rh < best_top || (y + rh == best_top && sky[s].x < best_x)) {
          best_top = y + rh, best_x = sky[s].x, best_seg = static_cast<int>(s), best_w = rw, best_h = rh;
          best_turned = turn == 1;
        }
      }
    }
    if (best_seg < 0) return false;
    const int y = best_top - best_h;
    (*out)[i] = {best_x, y, best_turned};
    // New skyline: the rectangle's top over [x, x + w), what remains of the segments it covered after it.
    std::vector<Segment> next;
    next.reserve(sky.size() + 2);
    for (size_t s = 0; s < static_cast<size_t>(best_seg); ++s) next.push_back(sky[s]);
    next.push_back({best_x, best_top, best_w});
    const int end = best_x + best_w;
    for (size_t s = best_seg; s < sky.size(); ++s) {
      const int s_end = sky[s].x + sky[s].width;
      if (s_end <= end) continue;
      const int x0 = std::max(sky[s].x, end);
      next.push_back({x0, sky[s].y, s_end - x0});
    }
    // Merge neighbours at the same height.
    sky.clear();
    for (const Segment& g : next) {
      if (!sky.empty() && sky.back().y == g.y) sky.back().width += g.width;
      else sky.push_back(g);
    }
  }
  return true;
}

}  // namespace

TriangleMesh BuildUvAtlas(const TriangleMesh& mesh, const UvAtlasOptions& options, UvAtlasStats* stats) {
  if (mesh.NumFaces() == 0) throw InputError({}, "BuildUvAtlas: mesh has no faces");
  if (const std::string bad = mesh.Validate(); !bad.empty()) throw InputError({}, "BuildUvAtlas: " + bad);
  CheckTextureSize(options.texture_size, "BuildUvAtlas");
  CheckPadding(options.padding_px, options.texture_size, "BuildUvAtlas");
  if (!(options.max_normal_angle_deg > 0 && options.max_normal_angle_deg < 90))
    throw InputError({}, Msg() << "BuildUvAtlas: max_normal_angle_deg " << options.max_normal_angle_deg
                               << " outside (0, 90)");
  const size_t nf = mesh.NumFaces();
  const int size = options.texture_size, pad = options.padding_px;

  // Welded connectivity: loaders split vertices at old UV and normal seams, which must not cut charts.
  const Eigen::Vector3f diag = mesh.Bounds().Size();
  std::vector<Eigen::Vector3f> welded_positions = mesh.positions;
  std::vector<Eigen::Vector3i> dropped_faces = mesh.faces;  // WeldVertices drops faces; we keep all via the map
  const std::vector<int> weld = geometry::WeldVertices(&welded_positions, &dropped_faces, 1e-6f * diag.norm());
  std::vector<Eigen::Vector3i> welded_faces(nf);
  for (size_t f = 0; f < nf; ++f)
    for (int k = 0; k < 3; ++k) welded_faces[f][k] = weld[mesh.faces[f][k]];
  const std::vector<int> neighbour = FaceAdjacency(static_cast<int>(welded_positions.size()), welded_faces);

  std::vector<Eigen::Vector3d> face_normal(nf);
  std::vector<double> face_area(nf);
  // Slivers lower than 1e-5 of the bounding box diagonal have no usable plane, and would keep no UV area in
  // float UVs (a texel of a 16384 atlas is ~1e-4 of the diagonal): each gets its own one-texel chart.
  const double min_height = 1e-5 * static_cast<double>(diag.norm());
  std::vector<int> candidates;
  std::vector<Chart> charts;
  for (size_t f = 0; f < nf; ++f) {
    const Eigen::Vector3d p0 = mesh.positions[mesh.faces[f][0]].cast<double>(),
                          p1 = mesh.positions[mesh.faces[f][1]].cast<double>(),
                          p2 = mesh.positions[mesh.faces[f][2]].cast<double>();
    const Eigen::Vector3d c = (p1 - p0).cross(p2 - p0);
    face_area[f] = 0.5 * c.norm();
    const double longest = std::max({(p1 - p0).norm(), (p2 - p1).norm(), (p0 - p2).norm()});
    const Eigen::Vector3i& w = welded_faces[f];
    if (!(c.norm() > min_height * longest) || w[0] == w[1] || w[1] == w[2] || w[2] == w[0]) {
      Chart chart;
      chart.faces = {static_cast<int>(f)};
      chart.fixed = true;
      chart.corner = {{0, 0}, {1, 0}, {0, 1}};
      chart.width = chart.height = 1;
      charts.push_back(std::move(chart));
      face_normal[f] = Eigen::Vector3d::Zero();
      continue;
    }
    face_normal[f] = c / c.norm();
    candidates.push_back(static_cast<int>(f));
  }

  // Grow, flatten, and split (regrow with half the cone) every chart that overlaps itself. Below a degree
  // the faces are coplanar for all purposes and only overlapping geometry can still overlap: single faces.
  std::vector<int> label(nf, 0);
  int tag = 1;
  std::vector<Chart> pending = GrowCharts(candidates, options.max_normal_angle_deg, neighbour, face_normal, &label, tag);
  while (!pending.empty()) {
    Chart chart = std::move(pending.back());
    pending.pop_back();
    Flatten(&chart, mesh, face_normal, face_area);
    if (!SelfOverlaps(chart)) {
      charts.push_back(std::move(chart));
      continue;
    }
    const double cone = 0.5 * chart.cone_deg;
    if (cone < 1.0) {
      for (int f : chart.faces) {
        Chart single;
        single.faces = {f};
        single.cone_deg = cone;
        pending.push_back(std::move(single));
      }
      continue;
    }
    std::vector<Chart> parts = GrowCharts(chart.faces, cone, neighbour, face_normal, &label, ++tag);
    for (auto& p : parts) pending.push_back(std::move(p));
  }
  // Deterministic chart order whatever order the splitting finished in.
  std::sort(charts.begin(), charts.end(), [](const Chart& a, const Chart& b) { return a.faces.front() < b.faces.front(); });

  // One texel density for all charts: the largest that packs, by bisection. Its upper bound fills the atlas
  // exactly with chart rectangles and no gutters.
  double rect_area = 0;
  for (const auto& c : charts)
    if (!c.fixed) rect_area += c.width * c.height;
  std::vector<Placement> placement;
  if (!Pack(charts, 0.0, size, pad, 0, &placement))
    throw InputError({}, Msg() << "BuildUvAtlas: " << charts.size() << " charts with " << pad
                               << " px gutters do not fit a " << size << "^2 atlas (a larger texture or a smaller "
                                                                          "padding is needed)");
  // Orders suit different chart sets; each gets its own bisection, the densest wins. Beyond a few thousand
  // charts the (quadratic) skyline is run for one order only.
  const int rules = charts.size() > 2000 ? 1 : 3;
  double density = 0;
  std::vector<Placement> trial;
  for (int rule = 0; rule < rules; ++rule) {
    double lo = 0, hi = rect_area > 0 ? size / std::sqrt(rect_area) : 0;
    for (int it = 0; it < 24 && hi > 0; ++it) {  // density to 2^-24 of its bound
      const double mid = 0.5 * (lo + hi);
      if (mid <= density) {
        lo = mid;
        continue;
      }
      if (Pack(charts, mid, size, pad, rule, &trial)) {
        lo = mid;
        if (mid > density) density = mid, placement = trial;
      } else {
        hi = mid;
      }
    }
  }

  // Output: one vertex per (input vertex, chart); attributes other than UVs copied. Materials are kept as
  // they are, textures included, although those textures follow the old UVs: the caller replaces them with
  // the baked one (BakeTexture), and only the caller knows whether the old ones are still wanted.
  TriangleMesh out;
  out.faces.resize(nf);
  out.face_material = mesh.face_material;
  out.materials = mesh.materials;
  std::unordered_map<uint64_t, int> vertex_of;
  double uv_area = 0;
  for (size_t ci = 0; ci < charts.size(); ++ci) {
    const Chart& c = charts[ci];
    const double scale = c.fixed ? 1.0 : density;
    for (size_t i = 0; i < c.faces.size(); ++i) {
      const int f = c.faces[i];
      Eigen::Vector2d t[3];
      for (int k = 0; k < 3; ++k) {
        const int v = mesh.faces[f][k];
        Eigen::Vector2d q = scale * c.corner[3 * i + k];
        if (placement[ci].turned) q = Eigen::Vector2d(q.y(), scale * c.width - q.x());
        t[k] = Eigen::Vector2d(placement[ci].x + pad, placement[ci].y + pad) + q;
        const auto [it, inserted] = vertex_of.emplace((uint64_t{ci} << 32) | static_cast<uint32_t>(v),
                                                      static_cast<int>(out.positions.size()));
        if (inserted) {
          out.positions.push_back(mesh.positions[v]);
          out.uvs.push_back((t[k] / size).cast<float>());
          if (!mesh.normals.empty()) out.normals.push_back(mesh.normals[v]);
          if (!mesh.colors.empty()) out.colors.push_back(mesh.colors[v]);
        }
        out.faces[f][k] = it->second;
      }
      uv_area += 0.5 * std::abs(Cross2(t[1] - t[0], t[2] - t[0]));
    }
  }
  if (stats) {
    stats->charts = static_cast<int>(charts.size());
    stats->utilisation = static_cast<float>(uv_area / (static_cast<double>(size) * size));
  }
  return out;
}

// ---------------------------------------------------------------------------------------------------------
// Baking

namespace {

// One colour view prepared for per-texel lookups: the mesh rasterised at its camera, with the camera depth
// of the visible surface at each pixel centre.
struct BakeView {
  const ColorView* source = nullptr;
  Eigen::Matrix4f clip_from_world;
  Eigen::Matrix3f R_cam_world;
  Eigen::Vector3f t_cam_world, eye;
  int width = 0, height = 0;
  std::vector<int32_t> triangle;  // per pixel, -1 background
  std::vector<float> depth;       // per pixel, camera z of the visible surface, +inf background
  std::vector<Eigen::Vector3f> point;  // per pixel, the visible surface point (world), where covered
};

// Closest point of triangle (a, b, c) to p, as barycentrics of a and b; the distance through *dist.
Eigen::Vector2f ClosestBarycentrics(const Eigen::Vector2d& p, const Eigen::Vector2d& a, const Eigen::Vector2d& b,
                                    const Eigen::Vector2d& c, double* dist) {
  const double area = Cross2(b - a, c - a);
  if (std::abs(area) > 1e-12) {
    const double wa = Cross2(b - p, c - p) / area, wb = Cross2(c - p, a - p) / area;
    if (wa >= 0 && wb >= 0 && 1 - wa - wb >= 0) {
      *dist = 0;
      return {static_cast<float>(wa), static_cast<float>(wb)};
    }
  }
  const Eigen::Vector2d v[3] = {a, b, c};
  double best = 1e300;
  Eigen::Vector2f bary(1.0f / 3, 1.0f / 3);
  for (int k = 0; k < 3; ++k) {
    const Eigen::Vector2d e = v[(k + 1) % 3] - v[k];
    const double s = e.squaredNorm() > 0 ? std::clamp((p - v[k]).dot(e) / e.squaredNorm(), 0.0, 1.0) : 0.0;
    const double d = (v[k] + s * e - p).norm();
    if (d < best) {
      best = d;
      float w[3] = {0, 0, 0};
      w[k] = static_cast<float>(1 - s);
      w[(k + 1) % 3] = static_cast<float>(s);
      bary = {w[0], w[1]};
    }
  }
  *dist = best;
  return bary;
}

}  // namespace

ImageU8 BakeTexture(const TriangleMesh& mesh, const ColorViewSet& views, int texture_size, const BakeOptions& options,
                    TextureProvenance* provenance) {
  if (mesh.NumFaces() == 0) throw InputError({}, "BakeTexture: mesh has no faces");
  if (mesh.uvs.size() != mesh.NumVertices()) throw InputError({}, "BakeTexture: mesh has no UVs (run BuildUvAtlas)");
  if (const std::string bad = mesh.Validate(); !bad.empty()) throw InputError({}, "BakeTexture: " + bad);
  CheckTextureSize(texture_size, "BakeTexture");
  CheckPadding(options.padding_px, texture_size, "BakeTexture");
  if (views.empty()) throw InputError({}, "BakeTexture: no colour views");
  for (const ColorView& v : views) {
    const int w = v.view.camera.width, h = v.view.camera.height;
    if (w <= 0 || h <= 0 || v.color.width() != w || v.color.height() != h || v.color.channels() != 3)
      throw InputError({}, Msg() << "BakeTexture: view '" << v.view.name << "': colour image " << v.color.width() << "x"
                                 << v.color.height() << "x" << v.color.channels() << " does not match its " << w
                                 << "x" << h << " camera (3 channels)");
    if (!v.mask.empty() && (v.mask.width() != w || v.mask.height() != h || v.mask.channels() != 1))
      throw InputError({}, Msg() << "BakeTexture: view '" << v.view.name << "': mask size does not match its camera");
  }
  const size_t nf = mesh.NumFaces();
  const int size = texture_size;
  const std::span<const int32_t> tris(reinterpret_cast<const int32_t*>(mesh.faces.data()), 3 * nf);
  const std::span<const float> positions(reinterpret_cast<const float*>(mesh.positions.data()), 3 * mesh.NumVertices());

  std::vector<Eigen::Vector3f> face_normal(nf);
  for (size_t f = 0; f < nf; ++f) face_normal[f] = mesh.FaceNormal(f);

  // Per view: depth range from the mesh's bounding sphere (any object scale works), visible surface depth.
  const BoundingSphere sphere = BoundingSphereOf(mesh.positions);
  std::vector<BakeView> bake(views.size());
  for (size_t i = 0; i < views.size(); ++i) {
    BakeView& b = bake[i];
    const ViewCamera& vc = views[i].view;
    b.source = &views[i];
    b.width = vc.camera.width;
    b.height = vc.camera.height;
    const Rigid3d T_cam_world = vc.T_world_cam.Inverse();
    b.R_cam_world = T_cam_world.Rotation().cast<float>();
    b.t_cam_world = T_cam_world.translation.cast<float>();
    b.eye = vc.T_world_cam.translation.cast<float>();
    b.clip_from_world = ClipFromWorldAround(vc.camera, vc.T_world_cam, sphere);
    std::vector<float> clip(4 * mesh.NumVertices());
    raster::TransformToClip(positions, b.clip_from_world, clip);
    raster::RasterBuffer rast;
    raster::Rasterize({clip, tris, b.width, b.height}, &rast);
    b.triangle = std::move(rast.triangle.host());
    b.depth.assign(rast.NumPixels(), std::numeric_limits<float>::infinity());
    b.point.assign(rast.NumPixels(), Eigen::Vector3f::Zero());
    ParallelFor(0, rast.NumPixels(), [&](size_t p) {
      const int t = b.triangle[p];
      if (t < 0) return;
      const float b0 = rast.bary[2 * p], b1 = rast.bary[2 * p + 1];
      const Eigen::Vector3i& f = mesh.faces[t];
      const Eigen::Vector3f x = b0 * mesh.positions[f[0]] + b1 * mesh.positions[f[1]] + (1 - b0 - b1) * mesh.positions[f[2]];
      b.depth[p] = (b.R_cam_world * x + b.t_cam_world).z();
      b.point[p] = x;
    }, 1024);
  }

  // Texels of each triangle: centres inside it (the rasteriser, UV space as clip space with w = 1), then
  // every still-empty texel the triangle touches (centre within half a texel diagonal) takes the triangle's
  // closest point, so texels cut by a chart border and sub-texel triangles hold surface colour too.
  const size_t num_texels = static_cast<size_t>(size) * size;
  std::vector<float> uv_clip(4 * mesh.NumVertices());
  for (size_t v = 0; v < mesh.NumVertices(); ++v) {
    uv_clip[4 * v + 0] = 2 * mesh.uvs[v].x() - 1;
    uv_clip[4 * v + 1] = 2 * mesh.uvs[v].y() - 1;
    uv_clip[4 * v + 2] = 0;
    uv_clip[4 * v + 3] = 1;
  }
  raster::RasterBuffer uv_rast;
  raster::Rasterize({uv_clip, tris, size, size}, &uv_rast);
  std::vector<int32_t>& texel_tri = uv_rast.triangle.host();
  std::vector<float>& texel_bary = uv_rast.bary.host();
  {
    std::vector<float> border_dist(num_texels, std::numeric_limits<float>::infinity());
    const double reach = 0.5 * std::sqrt(2.0);
    for (size_t f = 0; f < nf; ++f) {
      Eigen::Vector2d t[3];
      for (int k = 0; k < 3; ++k) t[k] = mesh.uvs[mesh.faces[f][k]].cast<double>() * size;
      const Eigen::Vector2d lo = t[0].cwiseMin(t[1]).cwiseMin(t[2]), hi = t[0].cwiseMax(t[1]).cwiseMax(t[2]);
      const int x0 = std::max(0, static_cast<int>(std::floor(lo.x() - reach))),
                x1 = std::min(size - 1, static_cast<int>(std::floor(hi.x() + reach)));
      const int y0 = std::max(0, static_cast<int>(std::floor(lo.y() - reach))),
                y1 = std::min(size - 1, static_cast<int>(std::floor(hi.y() + reach)));
      for (int y = y0; y <= y1; ++y) {
        for (int x = x0; x <= x1; ++x) {
          const size_t p = static_cast<size_t>(y) * size + x;
          if (texel_tri[p] >= 0 && std::isinf(border_dist[p])) continue;  // centre covered by the rasteriser
          double d = 0;
          const Eigen::Vector2f bary = ClosestBarycentrics({x + 0.5, y + 0.5}, t[0], t[1], t[2], &d);
          if (d > reach || d >= border_dist[p]) continue;
          border_dist[p] = static_cast<float>(d);
          texel_tri[p] = static_cast<int32_t>(f);
          texel_bary[2 * p] = bary.x();
          texel_bary[2 * p + 1] = bary.y();
        }
      }
    }
  }

  // Per texel: the view that sees its surface point most head-on (the vertex-fusion rule) among those where
  // it is not occluded, colour by bilinear lookup over the taps that show the same surface.
  ImageF color(size, size, 3);
  // 0 = gutter, 1 = coloured from a real view, 2 = surface no view sees, 3 = coloured from a synthetic view
  std::vector<uint8_t> state(num_texels, 0);
  const float tolerance = options.fusion.depth_tolerance, min_cos = options.fusion.min_cosine;
  // A tap shows "the same surface" when its point lies on the texel's tangent plane (within the slack) and its
  // triangle faces within 60 degrees of the texel's: across a crease the neighbouring face's colour would
  // otherwise bleed in over one view pixel.
  constexpr float kSameSurfaceCos = 0.5f;
  ParallelFor(0, static_cast<size_t>(size), [&](size_t row) {
    for (int x = 0; x < size; ++x) {
      const size_t p = row * size + x;
      const int t = texel_tri[p];
      if (t < 0) continue;
      const Eigen::Vector3i& f = mesh.faces[t];
      const float b0 = texel_bary[2 * p], b1 = texel_bary[2 * p + 1];
      const Eigen::Vector3f X = b0 * mesh.positions[f[0]] + b1 * mesh.positions[f[1]] + (1 - b0 - b1) * mesh.positions[f[2]];
      const Eigen::Vector3f& n = face_normal[t];
      float best_cos = -1;
      Eigen::Vector3f best = Eigen::Vector3f::Zero();
      bool best_synthetic = false;
      for (const BakeView& v : bake) {
        const Eigen::Vector3f to_eye = v.eye - X;
        const float range = to_eye.norm();
        const float true_cosine = range > 0 ? n.dot(to_eye) / range : -1;
        if (true_cosine < min_cos) continue;
        // The rank (texture.h): a synthetic view's cosine counts kSyntheticViewWeight.
        const float cosine = v.source->synthetic ? kSyntheticViewWeight * true_cosine : true_cosine;
        if (cosine <= best_cos) continue;
        const Eigen::Vector4f c = v.clip_from_world * X.homogeneous();
        if (c.w() <= 0) continue;
        const float u = (c.x() / c.w() + 1) * 0.5f * v.width, w = (c.y() / c.w() + 1) * 0.5f * v.height;
        const int px = static_cast<int>(std::floor(u)), py = static_cast<int>(std::floor(w));
        if (px < 0 || py < 0 || px >= v.width || py >= v.height) continue;
        const float z = (v.R_cam_world * X + v.t_cam_world).z();
        const float slack = tolerance * range;
        // Same surface as the texel: on its tangent plane within the slack. Distance to the plane rather than
        // depth difference, because at grazing views the depth changes by more than the slack across a pixel.
        auto same_surface = [&](size_t q) {
          const int tap_tri = v.triangle[q];
          return tap_tri >= 0 && face_normal[tap_tri].dot(n) >= kSameSurfaceCos &&
                 std::abs(n.dot(v.point[q] - X)) <= slack;
        };
        const size_t nearest = static_cast<size_t>(py) * v.width + px;
        if (v.depth[nearest] < z - slack && !same_surface(nearest)) continue;  // occluded
        const float fx = u - 0.5f - std::floor(u - 0.5f), fy = w - 0.5f - std::floor(w - 0.5f);
        const int x0 = static_cast<int>(std::floor(u - 0.5f)), y0 = static_cast<int>(std::floor(w - 0.5f));
        Eigen::Vector3f sum = Eigen::Vector3f::Zero();
        float weight = 0;
        for (int dy = 0; dy < 2; ++dy) {
          for (int dx = 0; dx < 2; ++dx) {
            const int tx = x0 + dx, ty = y0 + dy;
            if (tx < 0 || ty < 0 || tx >= v.width || ty >= v.height) continue;
            const size_t q = static_cast<size_t>(ty) * v.width + tx;
            if (!same_surface(q)) continue;
            if (!v.source->mask.empty() && v.source->mask.at(tx, ty) < 0.5f) continue;
            const float wt = (dx ? fx : 1 - fx) * (dy ? fy : 1 - fy);
            if (wt <= 0) continue;
            sum += wt * Eigen::Vector3f(v.source->color.pixel(tx, ty));
            weight += wt;
          }
        }
        if (weight <= 1e-4f) continue;
        best_cos = cosine;
        best = sum / weight;
        best_synthetic = v.source->synthetic;
      }
      if (best_cos < 0) {
        state[p] = 2;
        continue;
      }
      state[p] = best_synthetic ? 3 : 1;
      for (int ch = 0; ch < 3; ++ch) color.at(x, static_cast<int>(row), ch) = best[ch];
    }
  }, 4);

  if (provenance) {
    size_t counts[4] = {0, 0, 0, 0};
    for (uint8_t s : state) ++counts[s];
    const double surface = static_cast<double>(counts[1] + counts[2] + counts[3]);
    *provenance = {};
    if (surface > 0) *provenance = {counts[1] / surface, counts[3] / surface, counts[2] / surface};
  }

  // Surface no view sees: the vertex fusion's propagated colours, interpolated over the triangle.
  if (std::find(state.begin(), state.end(), uint8_t{2}) != state.end()) {
    const std::vector<Eigen::Vector3f> vertex_color = FuseVertexColors(mesh, views, options.fusion).colors;
    ParallelFor(0, num_texels, [&](size_t p) {
      if (state[p] != 2) return;
      const Eigen::Vector3i& f = mesh.faces[texel_tri[p]];
      const float b0 = texel_bary[2 * p], b1 = texel_bary[2 * p + 1];
      const Eigen::Vector3f c = b0 * vertex_color[f[0]] + b1 * vertex_color[f[1]] + (1 - b0 - b1) * vertex_color[f[2]];
      for (int ch = 0; ch < 3; ++ch) color.data()[3 * p + ch] = c[ch];
      state[p] = 1;
    }, 4096);
  }

  // Gutters: `padding_px` rings of dilation, each empty texel taking the mean of its coloured 8-neighbours,
  // so bilinear lookups and the first mip levels near a chart border read the chart's own colours.
  std::vector<uint8_t> next = state;
  for (int ring = 0; ring < options.padding_px; ++ring) {
    ParallelFor(0, static_cast<size_t>(size), [&](size_t row) {
      const int y = static_cast<int>(row);
      for (int x = 0; x < size; ++x) {
        const size_t p = row * size + x;
        if (state[p]) continue;
        Eigen::Vector3f sum = Eigen::Vector3f::Zero();
        int count = 0;
        for (int dy = -1; dy <= 1; ++dy) {
          for (int dx = -1; dx <= 1; ++dx) {
            const int nx = x + dx, ny = y + dy;
            if (nx < 0 || ny < 0 || nx >= size || ny >= size || !state[static_cast<size_t>(ny) * size + nx]) continue;
            sum += Eigen::Vector3f(color.pixel(nx, ny));
            ++count;
          }
        }
        if (count == 0) continue;
        sum /= static_cast<float>(count);
        for (int ch = 0; ch < 3; ++ch) color.at(x, y, ch) = sum[ch];
        next[p] = 1;
      }
    }, 4);
    state = next;
  }
  return ToSrgb8(color);
}

}  // namespace sd
