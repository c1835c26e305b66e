#include "geometry/metrics.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <random>

#include <nanoflann.hpp>

#include "core/error.h"
#include "core/parallel.h"

namespace sd::geometry {
namespace {

// Uniform double in [0, 1) from the top 53 bits: std::uniform_real_distribution's output is not pinned by the
// standard, and the protocol promises the same samples on every platform for a given seed.
double Uniform01(std::mt19937_64& rng) { return static_cast<double>(rng() >> 11) * 0x1.0p-53; }

struct CloudAdaptor {
  const std::vector<Eigen::Vector3f>* points;
  size_t kdtree_get_point_count() const { return points->size(); }
  float kdtree_get_pt(size_t i, size_t dim) const { return (*points)[i][static_cast<int>(dim)]; }
  template <class Box>
  bool kdtree_get_bbox(Box&) const { return false; }
};
using KdTree = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<float, CloudAdaptor>, CloudAdaptor, 3>;

// Spreads the low 21 bits of v to every third bit (Morton code helper).
uint64_t SpreadBits(uint64_t v) {
  v &= 0x1fffff;
  v = (v | v << 32) & 0x1f00000000ffffull;
  v = (v | v << 16) & 0x1f0000ff0000ffull;
  v = (v | v << 8) & 0x100f00f00f00f00full;
  v = (v | v << 4) & 0x10c30c30c30c30c3ull;
  v = (v | v << 2) & 0x1249249249249249ull;
  return v;
}

// Reorders samples along a Z-order curve. Both the tree's points and the queries then sit near their spatial
// neighbours in memory; on random-order samples the nearest-neighbour passes are dominated by cache misses.
// The metrics are order-independent (means, fractions).
SurfaceSamples SpatiallySorted(const SurfaceSamples& s) {
  AlignedBox3f box;
  for (const auto& p : s.points) box.Extend(p);
  const Eigen::Vector3f scale = 1023.0f * box.Size().cwiseMax(1e-12f).cwiseInverse();
  std::vector<std::pair<uint64_t, uint32_t>> keys(s.points.size());
  for (size_t i = 0; i < s.points.size(); ++i) {
    const Eigen::Vector3f q = (s.points[i] - box.min).cwiseProduct(scale);
    keys[i] = {SpreadBits(uint64_t(q.x())) | SpreadBits(uint64_t(q.y())) << 1 | SpreadBits(uint64_t(q.z())) << 2,
               static_cast<uint32_t>(i)};
  }
  std::sort(keys.begin(), keys.end());
  SurfaceSamples out;
  out.points.reserve(keys.size());
  out.normals.reserve(keys.size());
  for (const auto& k : keys) {
    out.points.push_back(s.points[k.second]);
    out.normals.push_back(s.normals[k.second]);
  }
  return out;
}

struct Directed {
  double mean_distance = 0;
  double within_tau = 0;         // fraction of queries with a neighbour within tau
  double normal_agreement = 0;   // mean |n_query . n_neighbour|
};

// Nearest neighbour in `target` of every sample of `query`.
Directed NearestNeighbourStats(const SurfaceSamples& query, const SurfaceSamples& target, double tau) {
  CloudAdaptor adaptor{&target.points};
  const KdTree tree(3, adaptor, nanoflann::KDTreeSingleIndexAdaptorParams(10));
  const size_t n = query.points.size();
  std::vector<double> distance(n), agreement(n);
  ParallelForRange(0, n, 1024, [&](size_t begin, size_t end) {
    for (size_t i = begin; i < end; ++i) {
      uint32_t nearest = 0;
      float d2 = 0;
      tree.knnSearch(query.points[i].data(), 1, &nearest, &d2);
      distance[i] = std::sqrt(static_cast<double>(d2));
      agreement[i] = std::abs(static_cast<double>(query.normals[i].dot(target.normals[nearest])));
    }
  });
  // Serial sums keep the result independent of how the work was split.
  Directed out;
  size_t within = 0;
  for (size_t i = 0; i < n; ++i) {
    out.mean_distance += distance[i];
    out.normal_agreement += agreement[i];
    within += distance[i] <= tau ? 1 : 0;
  }
  out.mean_distance /= static_cast<double>(n);
  out.normal_agreement /= static_cast<double>(n);
  out.within_tau = static_cast<double>(within) / static_cast<double>(n);
  return out;
}

// --- Volume IoU -------------------------------------------------------------------------------------------

struct VoxelGrid {
  Eigen::Vector3d origin;  // corner of voxel (0, 0, 0)
  Eigen::Vector3d cell;    // voxel size per axis
  Eigen::Vector3i dims;
  size_t Index(int i, int j, int k) const { return (static_cast<size_t>(k) * dims.y() + j) * dims.x() + i; }
  size_t Count() const { return static_cast<size_t>(dims.x()) * dims.y() * dims.z(); }
};

// Fractional part of n * golden ratio: a deterministic, well spread sequence in [0, 1) for the ray jitter.
double Spread(uint64_t n) {
  const double x = static_cast<double>(n) * 0.6180339887498949;
  return x - std::floor(x);
}

// 2D orientation of q relative to the edge (a, b), evaluated with the endpoints in a canonical order so that
// the two triangles sharing an edge compute the bit-identical value with opposite signs. An exact zero is
// broken towards the canonical positive side, so a ray through a shared edge enters exactly one triangle
// (watertight ray/mesh test in the spirit of Woop et al. 2013).
double EdgeSide(const Eigen::Vector2d& a, const Eigen::Vector2d& b, const Eigen::Vector2d& q) {
  const bool swap = b.x() < a.x() || (b.x() == a.x() && b.y() < a.y());
  const Eigen::Vector2d& lo = swap ? b : a;
  const Eigen::Vector2d& hi = swap ? a : b;
  double e = (hi.x() - lo.x()) * (q.y() - lo.y()) - (hi.y() - lo.y()) * (q.x() - lo.x());
  if (e == 0) e = std::numeric_limits<double>::min();
  return swap ? -e : e;
}

// Adds 1 to `votes` of every voxel whose centre has odd crossing parity along a ray in +axis.
//
// The rays of one axis form a 2D lattice (one ray per voxel column); every triangle is binned into the lattice
// cells its projection's bounding box covers (the "2D uniform grid"), then each column intersects only its
// candidates, sorts the crossing coordinates and sweeps its voxels from the far end counting crossings ahead.
void VoteParity(const TriangleMesh& mesh, const VoxelGrid& grid, int axis, std::vector<uint8_t>& votes) {
  const int b_axis = (axis + 1) % 3, c_axis = (axis + 2) % 3;
  const int nb = grid.dims[b_axis], nc = grid.dims[c_axis], na = grid.dims[axis];
  // Ray lattice position of column (jb, jc), jittered by at most 1e-3 of a voxel so that rays do not pass
  // exactly through vertices or along edges of meshes aligned with the grid (boxes are common).
  auto ray_position = [&](int jb, int jc) {
    const uint64_t id = static_cast<uint64_t>(jc) * nb + jb + 1;
    return Eigen::Vector2d(grid.origin[b_axis] + grid.cell[b_axis] * (jb + 0.5 + 1e-3 * (Spread(id) - 0.5)),
                           grid.origin[c_axis] + grid.cell[c_axis] * (jc + 0.5 + 1e-3 * (Spread(id + 7919) - 0.5)));
  };
  // Along the ray a crossing exactly at a voxel centre would be ambiguous; the centres are shifted by the same
  // sub-voxel amount.
  const double centre_shift = 0.5 + 1.7e-4;

  // Bin the triangles (CSR): count, prefix sum, fill.
  const size_t num_columns = static_cast<size_t>(nb) * nc;
  std::vector<Eigen::Vector4i> column_range(mesh.NumFaces());  // jb0, jb1, jc0, jc1 inclusive; empty if jb0 > jb1
  std::vector<uint32_t> start(num_columns + 1, 0);
  for (size_t f = 0; f < mesh.NumFaces(); ++f) {
    double lo_b = std::numeric_limits<double>::max(), hi_b = -lo_b, lo_c = lo_b, hi_c = -lo_b;
    for (int v = 0; v < 3; ++v) {
      const Eigen::Vector3f& p = mesh.positions[mesh.faces[f][v]];
      lo_b = std::min(lo_b, double(p[b_axis])), hi_b = std::max(hi_b, double(p[b_axis]));
      lo_c = std::min(lo_c, double(p[c_axis])), hi_c = std::max(hi_c, double(p[c_axis]));
    }
    // Column j's ray sits at origin + cell * (j + 0.5 +- 5e-4); one column of slack on each side is harmless.
    auto first = [&](double lo, int ax, int n) {
      return std::clamp(static_cast<int>(std::floor((lo - grid.origin[ax]) / grid.cell[ax] - 0.5)), 0, n);
    };
    auto last = [&](double hi, int ax, int n) {
      return std::clamp(static_cast<int>(std::floor((hi - grid.origin[ax]) / grid.cell[ax] - 0.5)) + 1, -1, n - 1);
    };
    Eigen::Vector4i r(first(lo_b, b_axis, nb), last(hi_b, b_axis, nb), first(lo_c, c_axis, nc), last(hi_c, c_axis, nc));
    if (r[2] > r[3]) r[0] = r[1] + 1;
    column_range[f] = r;
    for (int jc = r[2]; jc <= r[3] && r[0] <= r[1]; ++jc)
      for (int jb = r[0]; jb <= r[1]; ++jb) ++start[static_cast<size_t>(jc) * nb + jb + 1];
  }
  for (size_t i = 0; i < num_columns; ++i) start[i + 1] += start[i];
  std::vector<uint32_t> tris(start.back());
  {
    std::vector<uint32_t> fill(start.begin(), start.end() - 1);
    for (size_t f = 0; f < mesh.NumFaces(); ++f) {
      const Eigen::Vector4i& r = column_range[f];
      for (int jc = r[2]; jc <= r[3] && r[0] <= r[1]; ++jc)
        for (int jb = r[0]; jb <= r[1]; ++jb) tris[fill[static_cast<size_t>(jc) * nb + jb]++] = static_cast<uint32_t>(f);
    }
  }

  ParallelForRange(0, num_columns, 64, [&](size_t begin, size_t end) {
    std::vector<double> hits;
    for (size_t column = begin; column < end; ++column) {
      const int jb = static_cast<int>(column % nb), jc = static_cast<int>(column / nb);
      const Eigen::Vector2d q = ray_position(jb, jc);
      hits.clear();
      for (uint32_t t = start[column]; t < start[column + 1]; ++t) {
        const Eigen::Vector3i& face = mesh.faces[tris[t]];
        Eigen::Vector2d p[3];
        double a[3];
        for (int v = 0; v < 3; ++v) {
          const Eigen::Vector3f& x = mesh.positions[face[v]];
          p[v] = Eigen::Vector2d(x[b_axis], x[c_axis]);
          a[v] = x[axis];
        }
        // Barycentric weights are the sub-triangle sides opposite each vertex.
        const double w0 = EdgeSide(p[1], p[2], q), w1 = EdgeSide(p[2], p[0], q), w2 = EdgeSide(p[0], p[1], q);
        const bool inside = (w0 > 0 && w1 > 0 && w2 > 0) || (w0 < 0 && w1 < 0 && w2 < 0);
        if (!inside) continue;
        hits.push_back((w0 * a[0] + w1 * a[1] + w2 * a[2]) / (w0 + w1 + w2));
      }
      if (hits.empty()) continue;
      std::sort(hits.begin(), hits.end());
      // Sweep voxels from the far end: `ahead` counts crossings beyond the current centre.
      size_t ahead = 0;
      for (int ja = na - 1; ja >= 0; --ja) {
        const double centre = grid.origin[axis] + grid.cell[axis] * (ja + centre_shift);
        while (ahead < hits.size() && hits[hits.size() - 1 - ahead] > centre) ++ahead;
        if (ahead % 2 == 1) {
          int ijk[3];
          ijk[axis] = ja, ijk[b_axis] = jb, ijk[c_axis] = jc;
          ++votes[grid.Index(ijk[0], ijk[1], ijk[2])];
        }
      }
    }
  });
}

// Inside by majority over the three axis-parallel rays.
std::vector<uint8_t> Occupancy(const TriangleMesh& mesh, const VoxelGrid& grid) {
  std::vector<uint8_t> votes(grid.Count(), 0);
  for (int axis = 0; axis < 3; ++axis) VoteParity(mesh, grid, axis, votes);
  for (uint8_t& v : votes) v = v >= 2 ? 1 : 0;
  return votes;
}

double VolumeIou(const TriangleMesh& pred, const TriangleMesh& gt, int resolution) {
  AlignedBox3f box = pred.Bounds();
  box.Extend(gt.Bounds().min);
  box.Extend(gt.Bounds().max);
  VoxelGrid grid;
  grid.dims = Eigen::Vector3i::Constant(resolution);
  // A flat mesh has no volume, but the grid still needs non-zero cells.
  const Eigen::Vector3d size = box.Size().cast<double>().cwiseMax(1e-6);
  grid.origin = box.min.cast<double>();
  grid.cell = size / resolution;
  const std::vector<uint8_t> a = Occupancy(pred, grid), b = Occupancy(gt, grid);
  size_t both = 0, either = 0;
  for (size_t i = 0; i < a.size(); ++i) both += a[i] & b[i], either += a[i] | b[i];
  return either == 0 ? 0.0 : static_cast<double>(both) / static_cast<double>(either);
}

void CheckMesh(const TriangleMesh& mesh, const char* which) {
  if (mesh.NumFaces() == 0) throw InputError("", Msg() << "CompareMeshes: the " << which << " mesh has no faces");
  const std::string problem = mesh.Validate();
  if (!problem.empty()) throw InputError("", Msg() << "CompareMeshes: the " << which << " mesh is invalid: " << problem);
  if (!(mesh.SurfaceArea() > 0)) throw InputError("", Msg() << "CompareMeshes: the " << which << " mesh has no area");
}

}  // namespace

SurfaceSamples SampleSurface(const TriangleMesh& mesh, int count, uint64_t seed) {
  SD_CHECK(count >= 0, << count);
  SurfaceSamples out;
  // Cumulative areas in double: a float sum over a million faces would bias the tail faces.
  std::vector<double> cumulative(mesh.NumFaces());
  double total = 0;
  for (size_t f = 0; f < mesh.NumFaces(); ++f) {
    const auto& face = mesh.faces[f];
    const Eigen::Vector3d a = mesh.positions[face[0]].cast<double>(), b = mesh.positions[face[1]].cast<double>(),
                          c = mesh.positions[face[2]].cast<double>();
    total += 0.5 * (b - a).cross(c - a).norm();
    cumulative[f] = total;
  }
  if (!(total > 0) || count == 0) return out;
  out.points.resize(count);
  out.normals.resize(count);
  std::mt19937_64 rng(seed);
  for (int s = 0; s < count; ++s) {
    const double pick = Uniform01(rng) * total;
    // upper_bound skips zero-area faces: their cumulative value equals their predecessor's.
    const size_t f = std::min<size_t>(std::upper_bound(cumulative.begin(), cumulative.end(), pick) - cumulative.begin(),
                                      mesh.NumFaces() - 1);
    const double r1 = std::sqrt(Uniform01(rng)), r2 = Uniform01(rng);
    const auto& face = mesh.faces[f];
    // Uniform on the triangle (Osada et al. 2002): (1 - sqrt(r1)) a + sqrt(r1) (1 - r2) b + sqrt(r1) r2 c.
    const Eigen::Vector3d p = (1 - r1) * mesh.positions[face[0]].cast<double>() +
                              r1 * (1 - r2) * mesh.positions[face[1]].cast<double>() +
                              r1 * r2 * mesh.positions[face[2]].cast<double>();
    out.points[s] = p.cast<float>();
    out.normals[s] = mesh.FaceNormal(f);
  }
  return out;
}

GeometryMetrics CompareMeshes(const TriangleMesh& pred, const TriangleMesh& gt, const GeometryMetricsOptions& options) {
  CheckMesh(pred, "predicted");
  CheckMesh(gt, "ground-truth");
  if (options.num_samples < 1) throw InputError("", Msg() << "CompareMeshes: num_samples must be >= 1, got " << options.num_samples);
  if (options.iou_resolution < 1) throw InputError("", Msg() << "CompareMeshes: iou_resolution must be >= 1, got " << options.iou_resolution);
  const AlignedBox3f gt_box = gt.Bounds();
  const float longest = gt_box.Size().maxCoeff();
  if (!(longest > 0)) throw InputError("", "CompareMeshes: the ground-truth mesh has zero extent");

  // Into the GT's normalised frame: p' = (p - c) / longest. Rigid3d carries only the translation, the
  // scale goes through Transform's scale argument, applied first: p' = s * p - s * c.
  const double scale = 1.0 / longest;
  const Rigid3d T_norm_mesh(Eigen::Quaterniond::Identity(), -scale * gt_box.Center().cast<double>());
  TriangleMesh p = pred, g = gt;
  p.Transform(T_norm_mesh, scale);
  g.Transform(T_norm_mesh, scale);

  // Independent streams for the two meshes, so identical meshes show the sampling-noise floor rather than an
  // artificial exact zero that near-identical meshes (re-indexed, re-triangulated) would never reach.
  const SurfaceSamples sp = SpatiallySorted(SampleSurface(p, options.num_samples, options.seed));
  const SurfaceSamples sg = SpatiallySorted(SampleSurface(g, options.num_samples, options.seed ^ 0x9E3779B97F4A7C15ull));

  const double tau = options.fscore_threshold;
  const Directed to_gt = NearestNeighbourStats(sp, sg, tau);
  const Directed to_pred = NearestNeighbourStats(sg, sp, tau);

  GeometryMetrics m;
  m.chamfer = 0.5 * (to_gt.mean_distance + to_pred.mean_distance);
  m.precision = to_gt.within_tau;
  m.recall = to_pred.within_tau;
  m.fscore = m.precision + m.recall > 0 ? 2 * m.precision * m.recall / (m.precision + m.recall) : 0.0;
  m.normal_consistency = 0.5 * (to_gt.normal_agreement + to_pred.normal_agreement);
  m.volume_iou = VolumeIou(p, g, options.iou_resolution);
  return m;
}

std::string DescribeProtocol(const GeometryMetricsOptions& o) {
  char tau[32];
  std::snprintf(tau, sizeof(tau), "%g", static_cast<double>(o.fscore_threshold));
  return Msg() << "Both meshes are translated by the centre of the ground truth's bounding box and scaled by 1 / its "
                  "longest side (GT in the unit cube, no alignment). Each mesh gets "
               << o.num_samples << " surface samples, uniform by area (mt19937_64, seed " << o.seed
               << ", an independent stream per mesh). Chamfer = (mean NN distance pred->GT + GT->pred) / 2, L2 not "
                  "squared, normalised units. F-score at tau = "
               << tau << ": harmonic mean of precision (pred samples within tau of the GT samples) and recall (the "
                         "converse). Volume IoU on a "
               << o.iou_resolution << "^3 grid spanning both meshes' joint bounds: a voxel centre is inside when at "
                                      "least 2 of the rays along +x, +y, +z cross the surface an odd number of times. "
                                      "Normal consistency = mean |n_pred . n_gt| of face normals at NN sample pairs, "
                                      "both directions averaged.";
}

}  // namespace sd::geometry
