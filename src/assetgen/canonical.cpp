#include "assetgen/canonical.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <map>
#include <unordered_map>
#include <utility>
#include <vector>

#include <Eigen/Eigenvalues>
#include <Eigen/Geometry>
#include <nanoflann.hpp>

#include "core/error.h"
#include "core/log.h"
#include "core/parallel.h"
#include "geometry/metrics.h"
#include "geometry/polygon.h"

namespace sd {
namespace {

Eigen::Vector3d ParseAxis(const std::string& s) {
  if (s.size() == 2 && (s[0] == '+' || s[0] == '-')) {
    const double sign = s[0] == '+' ? 1 : -1;
    if (s[1] == 'x') return sign * Eigen::Vector3d::UnitX();
    if (s[1] == 'y') return sign * Eigen::Vector3d::UnitY();
    if (s[1] == 'z') return sign * Eigen::Vector3d::UnitZ();
  }
  throw InputError("", "unknown axis '" + s + "' (use +x, -x, +y, -y, +z or -z; Canonicalize also takes auto)");
}

}  // namespace

Eigen::Matrix3d AxesToCanonical(const std::string& up, const std::string& front) {
  const Eigen::Vector3d u = ParseAxis(up), f = ParseAxis(front);
  if (std::abs(u.dot(f)) > 0.5) throw InputError("", "up axis " + up + " and front axis " + front + " must differ");
  // Rows are the source directions that become canonical x (front), y (left = up x front), z (up).
  Eigen::Matrix3d R;
  R.row(0) = f.transpose();
  R.row(1) = u.cross(f).transpose();
  R.row(2) = u.transpose();
  return R;
}

// --- Automatic frame estimation -----------------------------------------------------------------------------

namespace {

uint64_t EdgeKey(int a, int b) {
  return (static_cast<uint64_t>(static_cast<uint32_t>(a)) << 32) | static_cast<uint32_t>(b);
}

struct HullFace {
  std::array<int, 3> v{};
  Eigen::Vector3d n = Eigen::Vector3d::Zero();  // unit outward, zero for a degenerate face
  double d = 0;                                 // plane: n . x = d
  double area = 0;
  std::vector<int> outside;                     // points above this face, waiting to be added
  bool alive = true;
};

// 3D convex hull by quickhull: faces are CCW seen from outside. `edges` maps a directed edge (a, b) to the
// live face that has it, so the neighbour across (a, b) is edges[(b, a)]. Points closer than `eps` to a face
// count as inside it, which merges (near-)coplanar points into one facet. Empty when the points span no volume.
struct ConvexHull {
  std::vector<HullFace> faces;  // live ones have alive == true
  std::unordered_map<uint64_t, int> edges;
};

ConvexHull BuildConvexHull(const std::vector<Eigen::Vector3d>& p, double eps) {
  ConvexHull hull;
  const int n = static_cast<int>(p.size());
  if (n < 4) return hull;
  // Initial tetrahedron from the axis extremes.
  std::array<int, 6> ext{};
  for (int k = 0; k < 3; ++k) {
    for (int i = 0; i < n; ++i) {
      if (p[i][k] < p[ext[2 * k]][k]) ext[2 * k] = i;
      if (p[i][k] > p[ext[2 * k + 1]][k]) ext[2 * k + 1] = i;
    }
  }
  int i0 = ext[0], i1 = ext[1];
  double best = -1;
  for (int a = 0; a < 6; ++a) {
    for (int b = a + 1; b < 6; ++b) {
      const double d2 = (p[ext[a]] - p[ext[b]]).squaredNorm();
      if (d2 > best) best = d2, i0 = ext[a], i1 = ext[b];
    }
  }
  if (best <= eps * eps) return hull;
  const Eigen::Vector3d dir = (p[i1] - p[i0]).normalized();
  int i2 = -1;
  best = eps;
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3d q = p[i] - p[i0];
    const double dist = (q - q.dot(dir) * dir).norm();
    if (dist > best) best = dist, i2 = i;
  }
  if (i2 < 0) return hull;
  const Eigen::Vector3d pn = (p[i1] - p[i0]).cross(p[i2] - p[i0]).normalized();
  int i3 = -1;
  best = eps;
  for (int i = 0; i < n; ++i) {
    const double dist = std::abs(pn.dot(p[i] - p[i0]));
    if (dist > best) best = dist, i3 = i;
  }
  if (i3 < 0) return hull;

  std::vector<int> visible_stamp;
  auto add_face = [&](int a, int b, int c) {
    HullFace f;
    f.v = {a, b, c};
    const Eigen::Vector3d cr = (p[b] - p[a]).cross(p[c] - p[a]);
    f.area = 0.5 * cr.norm();
    if (f.area > 0) f.n = cr / (2 * f.area);
    f.d = f.n.dot(p[a]);
    const int id = static_cast<int>(hull.faces.size());
    hull.faces.push_back(std::move(f));
    visible_stamp.push_back(-1);
    hull.edges[EdgeKey(a, b)] = id;
    hull.edges[EdgeKey(b, c)] = id;
    hull.edges[EdgeKey(c, a)] = id;
    return id;
  };
  auto dist = [&](const HullFace& f, int i) { return f.n.dot(p[i]) - f.d; };
  // Orient the tetrahedron outwards.
  if (pn.dot(p[i3] - p[i0]) > 0) std::swap(i1, i2);  // now i3 is below the plane (i0, i1, i2)
  add_face(i0, i1, i2);
  add_face(i0, i3, i1);
  add_face(i1, i3, i2);
  add_face(i2, i3, i0);

  auto assign = [&](int i, const std::vector<int>& candidates) {
    int best_face = -1;
    double best_dist = eps;
    for (int f : candidates) {
      const double dd = dist(hull.faces[f], i);
      if (dd > best_dist) best_dist = dd, best_face = f;
    }
    if (best_face >= 0) hull.faces[best_face].outside.push_back(i);
  };
  {
    const std::vector<int> all = {0, 1, 2, 3};
    for (int i = 0; i < n; ++i)
      if (i != i0 && i != i1 && i != i2 && i != i3) assign(i, all);
  }
  std::vector<int> stack = {0, 1, 2, 3};
  int stamp = 0;
  while (!stack.empty()) {
    const int f0 = stack.back();
    stack.pop_back();
    if (!hull.faces[f0].alive || hull.faces[f0].outside.empty()) continue;
    int apex = hull.faces[f0].outside[0];
    for (int i : hull.faces[f0].outside)
      if (dist(hull.faces[f0], i) > dist(hull.faces[f0], apex)) apex = i;
    // Faces seen from the apex, grown from f0 across edges.
    ++stamp;
    std::vector<int> visible = {f0};
    visible_stamp[f0] = stamp;
    for (size_t k = 0; k < visible.size(); ++k) {
      const HullFace& g = hull.faces[visible[k]];
      for (int e = 0; e < 3; ++e) {
        const auto it = hull.edges.find(EdgeKey(g.v[(e + 1) % 3], g.v[e]));
        if (it == hull.edges.end()) continue;
        const int h = it->second;
        if (visible_stamp[h] == stamp || !hull.faces[h].alive) continue;
        if (dist(hull.faces[h], apex) > eps) {
          visible_stamp[h] = stamp;
          visible.push_back(h);
        }
      }
    }
    std::vector<std::pair<int, int>> horizon;
    std::vector<int> orphans;
    for (int g : visible) {
      const HullFace& f = hull.faces[g];
      for (int e = 0; e < 3; ++e) {
        const int a = f.v[e], b = f.v[(e + 1) % 3];
        const auto it = hull.edges.find(EdgeKey(b, a));
        if (it == hull.edges.end() || visible_stamp[it->second] != stamp) horizon.emplace_back(a, b);
      }
      for (int i : f.outside)
        if (i != apex) orphans.push_back(i);
    }
    for (int g : visible) {
      HullFace& f = hull.faces[g];
      f.alive = false;
      f.outside.clear();
      f.outside.shrink_to_fit();
      for (int e = 0; e < 3; ++e) {
        const auto it = hull.edges.find(EdgeKey(f.v[e], f.v[(e + 1) % 3]));
        if (it != hull.edges.end() && it->second == g) hull.edges.erase(it);
      }
    }
    std::vector<int> created;
    created.reserve(horizon.size());
    for (const auto& [a, b] : horizon) created.push_back(add_face(a, b, apex));
    for (int i : orphans) assign(i, created);
    for (int f : created)
      if (!hull.faces[f].outside.empty()) stack.push_back(f);
  }
  return hull;
}

// Two unit vectors completing `n` to a right-handed orthonormal basis (deterministic).
std::pair<Eigen::Vector3d, Eigen::Vector3d> Basis(const Eigen::Vector3d& n) {
  const Eigen::Vector3d a = std::abs(n.x()) < 0.6 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
  const Eigen::Vector3d t1 = (a - a.dot(n) * n).normalized();
  return {t1, n.cross(t1)};
}

// Centre of mass: the volume centroid when the mesh (welded by exact position) is closed, else the area
// centroid; in the coordinates of `p` (the positions relative to the bounding-box centre).
Eigen::Vector3d CentreOfMass(const TriangleMesh& mesh, const std::vector<Eigen::Vector3d>& p, bool* closed) {
  // Weld exactly coincident positions so that UV seams do not open a closed surface.
  std::vector<int> id(p.size());
  std::map<std::array<float, 3>, int> exact;
  for (size_t i = 0; i < mesh.positions.size(); ++i) {
    const auto& q = mesh.positions[i];
    id[i] = exact.emplace(std::array<float, 3>{q.x(), q.y(), q.z()}, static_cast<int>(i)).first->second;
  }
  std::vector<uint64_t> directed;
  directed.reserve(3 * mesh.faces.size());
  double volume = 0, area = 0;
  Eigen::Vector3d vol_sum = Eigen::Vector3d::Zero(), area_sum = Eigen::Vector3d::Zero();
  for (const auto& f : mesh.faces) {
    const Eigen::Vector3d &a = p[f[0]], &b = p[f[1]], &c = p[f[2]];
    const double v = a.dot(b.cross(c)) / 6.0;
    volume += v;
    vol_sum += v * (a + b + c) / 4.0;
    const double ar = 0.5 * (b - a).cross(c - a).norm();
    area += ar;
    area_sum += ar * (a + b + c) / 3.0;
    for (int e = 0; e < 3; ++e) directed.push_back(EdgeKey(id[f[e]], id[f[(e + 1) % 3]]));
  }
  std::sort(directed.begin(), directed.end());
  bool is_closed = std::adjacent_find(directed.begin(), directed.end()) == directed.end();  // each directed edge once
  for (size_t i = 0; is_closed && i < directed.size(); ++i) {
    const uint64_t rev = (directed[i] << 32) | (directed[i] >> 32);
    is_closed = std::binary_search(directed.begin(), directed.end(), rev);
  }
  // A closed surface of negligible volume (a folded sheet) has no meaningful volume centroid.
  const AlignedBox3f box = mesh.Bounds();
  const double box_volume = box.Size().cast<double>().prod();
  is_closed = is_closed && std::abs(volume) > 1e-6 * box_volume && std::abs(volume) > 0;
  *closed = is_closed;
  if (is_closed) return vol_sum / volume;
  SD_CHECK(area > 0, << "mesh without area reached CentreOfMass");
  return area_sum / area;
}

struct Support {
  Eigen::Vector3d normal;  // outward normal of the support plane (up = -normal)
  double area = 0;         // support polygon area
  double com_height = 0;   // centre of mass above the support plane
  double margin = 0;       // distance of the centre of mass's projection inside the polygon (< 0: outside)
};

// The hull's facets (near-coplanar triangle groups), each with its support polygon and stability.
std::vector<Support> SupportCandidates(const ConvexHull& hull, const std::vector<Eigen::Vector3d>& p,
                                       const Eigen::Vector3d& com) {
  // Hull triangles whose normals lie within kFacetAngle of a seed's are one facet: scanned or tessellated
  // bottoms are not exactly planar, and wheel contacts of a car give a few slightly tilted triangles.
  constexpr double kFacetAngleDeg = 3.0;
  const double cos_tol = std::cos(kFacetAngleDeg * M_PI / 180.0);
  std::vector<int> order;
  for (size_t i = 0; i < hull.faces.size(); ++i)
    if (hull.faces[i].alive && hull.faces[i].area > 0) order.push_back(static_cast<int>(i));
  std::stable_sort(order.begin(), order.end(), [&](int a, int b) { return hull.faces[a].area > hull.faces[b].area; });
  std::vector<int> group(hull.faces.size(), -1);
  std::vector<Support> out;
  for (int seed : order) {
    if (group[seed] >= 0) continue;
    const int gid = static_cast<int>(out.size());
    const Eigen::Vector3d seed_n = hull.faces[seed].n;
    std::vector<int> members = {seed};
    group[seed] = gid;
    for (size_t k = 0; k < members.size(); ++k) {
      const HullFace& f = hull.faces[members[k]];
      for (int e = 0; e < 3; ++e) {
        const auto it = hull.edges.find(EdgeKey(f.v[(e + 1) % 3], f.v[e]));
        if (it == hull.edges.end()) continue;
        const int h = it->second;
        if (group[h] >= 0 || !hull.faces[h].alive || hull.faces[h].area <= 0) continue;
        if (hull.faces[h].n.dot(seed_n) < cos_tol) continue;
        group[h] = gid;
        members.push_back(h);
      }
    }
    Eigen::Vector3d n = Eigen::Vector3d::Zero();
    for (int m : members) n += hull.faces[m].area * hull.faces[m].n;
    n.normalize();
    std::vector<int> verts;
    for (int m : members) verts.insert(verts.end(), hull.faces[m].v.begin(), hull.faces[m].v.end());
    std::sort(verts.begin(), verts.end());
    verts.erase(std::unique(verts.begin(), verts.end()), verts.end());
    double plane = -std::numeric_limits<double>::max();
    for (int v : verts) plane = std::max(plane, n.dot(p[v]));
    const auto [t1, t2] = Basis(n);
    std::vector<Eigen::Vector2d> flat;
    for (int v : verts) flat.emplace_back(t1.dot(p[v]), t2.dot(p[v]));
    const std::vector<Eigen::Vector2d> poly = geometry::ConvexHull2D(std::move(flat));
    Support s;
    s.normal = n;
    s.com_height = plane - n.dot(com);
    const Eigen::Vector2d q(t1.dot(com), t2.dot(com));
    s.margin = poly.size() >= 3 ? std::numeric_limits<double>::max() : -1;
    for (size_t i = 0; i < poly.size() && poly.size() >= 3; ++i) {
      const Eigen::Vector2d& a = poly[i];
      const Eigen::Vector2d& b = poly[(i + 1) % poly.size()];
      s.area += 0.5 * (a.x() * b.y() - a.y() * b.x());
      const Eigen::Vector2d e = b - a;
      const double len = e.norm();
      if (len > 0) s.margin = std::min(s.margin, (e.x() * (q - a).y() - e.y() * (q - a).x()) / len);
    }
    out.push_back(s);
  }
  return out;
}

struct FrontEstimate {
  Eigen::Vector3d front;
  double symmetry_error = 0;
  std::string method;
};

using Cloud = std::vector<Eigen::Vector3d>;
struct CloudAdaptor {
  const Cloud* points;
  size_t kdtree_get_point_count() const { return points->size(); }
  double kdtree_get_pt(size_t i, size_t dim) const { return (*points)[i][static_cast<int>(dim)]; }
  template <class Box>
  bool kdtree_get_bbox(Box&) const { return false; }
};
using KdTree = nanoflann::KDTreeSingleIndexAdaptor<nanoflann::L2_Simple_Adaptor<double, CloudAdaptor>, CloudAdaptor, 3>;

// Mean distance from each query point, passed through `map`, to its nearest neighbour in the tree.
template <class Map>
double MeanNearest(const KdTree& tree, const Cloud& query, size_t stride, const Map& map) {
  const size_t n = (query.size() + stride - 1) / stride;
  std::vector<double> d(n);
  ParallelForRange(0, n, 256, [&](size_t begin, size_t end) {
    for (size_t i = begin; i < end; ++i) {
      const Eigen::Vector3d q = map(query[i * stride]);
      uint32_t idx = 0;
      double d2 = 0;
      tree.knnSearch(q.data(), 1, &idx, &d2);
      d[i] = std::sqrt(d2);
    }
  });
  double sum = 0;  // serial: the result does not depend on the split
  for (double x : d) sum += x;
  return sum / static_cast<double>(n);
}

// Mirror symmetry about vertical planes through the area centroid. The residual of a plane is the mean
// distance from mirrored surface samples to the nearest sample, as a fraction of the bounding radius; an exactly
// symmetric surface scores the sampling-noise floor (two independent sample sets are that far apart).
class Symmetry {
 public:
  struct Plane {
    double theta = 0, residual = 1;  // normal = cos(theta) e1 + sin(theta) e2 of Basis(up)
  };

  Symmetry(const TriangleMesh& mesh, const std::vector<Eigen::Vector3d>& vertices, const Eigen::Vector3d& centroid,
           double radius, const Eigen::Vector3d& origin)
      : samples_(ToCloud(geometry::SampleSurface(mesh, kSamples, 11), origin)),
        vertices_(vertices),
        centroid_(centroid),
        radius_(radius),
        samples_adaptor_{&samples_},
        vertices_adaptor_{&vertices_},
        samples_tree_(3, samples_adaptor_, nanoflann::KDTreeSingleIndexAdaptorParams(10)),
        vertices_tree_(3, vertices_adaptor_, nanoflann::KDTreeSingleIndexAdaptorParams(10)) {
    const Cloud other = ToCloud(geometry::SampleSurface(mesh, kSamples, 12), origin);
    noise_ = MeanNearest(samples_tree_, other, 1, [](const Eigen::Vector3d& q) { return q; }) / radius_;
  }
  Symmetry(const Symmetry&) = delete;
  Symmetry& operator=(const Symmetry&) = delete;

  double noise() const { return noise_; }
  const Cloud& samples() const { return samples_; }
  // Convincingly symmetric: mirrored samples land about as close to the surface as independent samples do
  // (kSymmetryRatio x the noise floor), plus kSymmetrySlack of the bounding radius for modelling details
  // (door mirrors, steering wheels, scan noise).
  bool Convincing(double residual) const { return residual <= kSymmetryRatio * noise_ + kSymmetrySlack; }
  static Eigen::Vector3d Normal(const Eigen::Vector3d& up, double theta) {
    const auto [e1, e2] = Basis(up);
    return std::cos(theta) * e1 + std::sin(theta) * e2;
  }
  double Residual(const Eigen::Vector3d& up, double theta, size_t stride) const {
    return Mirrored(samples_tree_, samples_, up, theta, stride);
  }
  // Coarse scan over plane normals in [0, 180) degrees: the local minima, best first.
  std::vector<Plane> Scan(const Eigen::Vector3d& up) const {
    std::vector<double> coarse(kSteps);
    for (int i = 0; i < kSteps; ++i) coarse[i] = Residual(up, i * kStep, 3);
    std::vector<Plane> planes;
    for (int i = 0; i < kSteps; ++i) {
      const double prev = coarse[(i + kSteps - 1) % kSteps], next = coarse[(i + 1) % kSteps];
      if (coarse[i] <= prev && coarse[i] < next) planes.push_back({i * kStep, coarse[i]});
    }
    std::sort(planes.begin(), planes.end(), [](const Plane& a, const Plane& b) { return a.residual < b.residual; });
    return planes;
  }
  // Golden-section refinement on all samples, then a polish on the mesh vertices: modelled (CAD) meshes
  // mirror vertex onto vertex, which pins the plane far below the sampling noise.
  Plane Refine(const Eigen::Vector3d& up, const Plane& coarse) const {
    const size_t vstride = std::max<size_t>(1, vertices_.size() / 4000);
    const double theta = Golden([&](double t) { return Residual(up, t, 1); }, coarse.theta, kStep, 14);
    const double polished = Golden([&](double t) { return Mirrored(vertices_tree_, vertices_, up, t, vstride); },
                                   theta, 0.5 * M_PI / 180.0, 40);
    return {polished, Residual(up, polished, 1)};
  }

 private:
  static constexpr int kSamples = 3000, kSteps = 90;
  static constexpr double kStep = M_PI / kSteps;
  static constexpr double kSymmetryRatio = 1.5, kSymmetrySlack = 0.01;

  static Cloud ToCloud(const geometry::SurfaceSamples& s, const Eigen::Vector3d& origin) {
    Cloud c;
    c.reserve(s.points.size());
    for (const auto& q : s.points) c.push_back(q.cast<double>() - origin);
    return c;
  }
  double Mirrored(const KdTree& tree, const Cloud& cloud, const Eigen::Vector3d& up, double theta,
                  size_t stride) const {
    const Eigen::Vector3d m = Normal(up, theta);
    return MeanNearest(tree, cloud, stride, [&](const Eigen::Vector3d& q) {
             return (q - 2.0 * (q - centroid_).dot(m) * m).eval();
           }) / radius_;
  }
  template <class F>
  static double Golden(const F& f, double centre, double half_width, int iterations) {
    const double golden = (std::sqrt(5.0) - 1) / 2;
    double a = centre - half_width, b = centre + half_width;
    double x1 = b - golden * (b - a), x2 = a + golden * (b - a);
    double f1 = f(x1), f2 = f(x2);
    for (int it = 0; it < iterations; ++it) {
      if (f1 < f2) {
        b = x2, x2 = x1, f2 = f1;
        x1 = b - golden * (b - a), f1 = f(x1);
      } else {
        a = x1, x1 = x2, f1 = f2;
        x2 = a + golden * (b - a), f2 = f(x2);
      }
    }
    return f1 < f2 ? x1 : x2;
  }

  Cloud samples_, vertices_;
  Eigen::Vector3d centroid_;
  double radius_;
  double noise_ = 0;
  CloudAdaptor samples_adaptor_, vertices_adaptor_;
  KdTree samples_tree_, vertices_tree_;
};

// Front (unit, perpendicular to `up`) from vertical mirror symmetry; see the header and docs/canonical.md.
FrontEstimate EstimateFront(const Symmetry& symmetry, const Eigen::Vector3d& up,
                            const std::vector<Eigen::Vector3d>& hull_points) {
  std::vector<Symmetry::Plane> planes = symmetry.Scan(up);
  if (planes.size() > 3) planes.resize(3);
  for (auto& pl : planes) pl = symmetry.Refine(up, pl);
  std::sort(planes.begin(), planes.end(), [](const auto& a, const auto& b) { return a.residual < b.residual; });

  auto extent_along = [&](const Eigen::Vector3d& d) {
    double lo = std::numeric_limits<double>::max(), hi = -lo;
    for (const auto& q : hull_points) lo = std::min(lo, q.dot(d)), hi = std::max(hi, q.dot(d));
    return std::make_pair(lo, hi);
  };
  FrontEstimate est;
  std::vector<Symmetry::Plane> symmetric;
  for (const auto& pl : planes)
    if (symmetry.Convincing(pl.residual)) symmetric.push_back(pl);
  if (!symmetric.empty()) {
    // Several symmetric planes (boxes, cones on a square base): take the frame with the tightest footprint
    // rectangle, then the one whose front runs along the longer side.
    double best_area = std::numeric_limits<double>::max();
    for (const auto& pl : symmetric) {
      const Eigen::Vector3d m = Symmetry::Normal(up, pl.theta), f = up.cross(m);
      const auto [flo, fhi] = extent_along(f);
      const auto [mlo, mhi] = extent_along(m);
      best_area = std::min(best_area, (fhi - flo) * (mhi - mlo));
    }
    double best_length = -1;
    for (const auto& pl : symmetric) {
      const Eigen::Vector3d m = Symmetry::Normal(up, pl.theta), f = up.cross(m);
      const auto [flo, fhi] = extent_along(f);
      const auto [mlo, mhi] = extent_along(m);
      if ((fhi - flo) * (mhi - mlo) > 1.02 * best_area || fhi - flo <= best_length) continue;
      best_length = fhi - flo;
      est.front = f;
      est.symmetry_error = pl.residual;
    }
    est.method = "mirror-symmetry";
  } else {
    // No convincing mirror plane: the longest horizontal principal axis of the hull's footprint.
    const auto [e1, e2] = Basis(up);
    Eigen::Matrix2d cov = Eigen::Matrix2d::Zero();
    Eigen::Vector2d mean = Eigen::Vector2d::Zero();
    for (const auto& q : hull_points) mean += Eigen::Vector2d(q.dot(e1), q.dot(e2));
    mean /= static_cast<double>(hull_points.size());
    for (const auto& q : hull_points) {
      const Eigen::Vector2d d = Eigen::Vector2d(q.dot(e1), q.dot(e2)) - mean;
      cov += d * d.transpose();
    }
    const Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d> eig(cov);
    const Eigen::Vector2d axis = eig.eigenvectors().col(1);
    est.front = (axis.x() * e1 + axis.y() * e2).normalized();
    est.symmetry_error = planes.empty() ? 1.0 : planes.front().residual;
    est.method = "horizontal-pca (no mirror plane)";
  }
  // Sign: the taller end is the back (a car's cabin sits behind its middle, a truck's box behind its cab).
  // Measured as the mean horizontal offset, along front, of the surface samples in the top 30% of the height
  // from the footprint centre.
  double zlo = std::numeric_limits<double>::max(), zhi = -zlo;
  for (const auto& q : hull_points) zlo = std::min(zlo, q.dot(up)), zhi = std::max(zhi, q.dot(up));
  const auto [flo, fhi] = extent_along(est.front);
  double offset = 0;
  int count = 0;
  for (const auto& q : symmetry.samples()) {
    if (q.dot(up) < zlo + 0.7 * (zhi - zlo)) continue;
    offset += q.dot(est.front) - 0.5 * (flo + fhi);
    ++count;
  }
  offset = count > 0 ? offset / count : 0;
  if (offset > 0) est.front = -est.front;
  est.method +=
      std::abs(offset) < 0.01 * (fhi - flo) ? ", sign ambiguous (top is centred)" : ", taller end is the back";
  return est;
}

}  // namespace

namespace {

// The estimate, with up either known (`known_up`, unit) or found from the support facet.
FrameEstimate EstimateFrame(const TriangleMesh& mesh, const std::optional<Eigen::Vector3d>& known_up) {
  if (mesh.positions.empty() || mesh.faces.empty()) throw InputError("", "mesh has no triangles");
  if (const std::string bad = mesh.Validate(); !bad.empty()) throw InputError("", "invalid mesh: " + bad);
  // Work relative to the bounding-box centre: keeps plane offsets well conditioned for meshes far from 0.
  const AlignedBox3f box = mesh.Bounds();
  const Eigen::Vector3d origin = box.Center().cast<double>();
  std::vector<Eigen::Vector3d> p(mesh.positions.size());
  for (size_t i = 0; i < p.size(); ++i) p[i] = mesh.positions[i].cast<double>() - origin;
  if (!(mesh.SurfaceArea() > 0)) throw InputError("", "mesh has no area; cannot estimate its frame");
  const double diag = box.Size().cast<double>().norm();
  const ConvexHull hull = BuildConvexHull(p, 1e-9 * diag);
  if (hull.faces.empty())
    throw InputError("", "mesh is flat (its convex hull has no volume): give its up and front axes explicitly");

  std::vector<Eigen::Vector3d> hull_points;
  {
    std::vector<int> ids;
    for (const HullFace& f : hull.faces)
      if (f.alive) ids.insert(ids.end(), f.v.begin(), f.v.end());
    std::sort(ids.begin(), ids.end());
    ids.erase(std::unique(ids.begin(), ids.end()), ids.end());
    for (int i : ids) hull_points.push_back(p[i]);
  }
  Eigen::Vector3d area_centroid = Eigen::Vector3d::Zero();
  double area = 0;
  for (const auto& f : mesh.faces) {
    const double a = 0.5 * (p[f[1]] - p[f[0]]).cross(p[f[2]] - p[f[0]]).norm();
    area_centroid += a * (p[f[0]] + p[f[1]] + p[f[2]]) / 3.0;
    area += a;
  }
  area_centroid /= area;
  double radius = 0;
  for (const auto& q : hull_points) radius = std::max(radius, (q - area_centroid).norm());
  const Symmetry symmetry(mesh, p, area_centroid, radius, origin);

  FrameEstimate est;
  if (known_up) {
    est.up = *known_up;
    est.up_method = "given";
  } else {
    bool closed = false;
    const Eigen::Vector3d com = CentreOfMass(mesh, p, &closed);
    const std::vector<Support> supports = SupportCandidates(hull, p, com);
    std::vector<const Support*> stable;
    for (const Support& s : supports)
      if (s.margin > 1e-9 * diag) stable.push_back(&s);
    std::stable_sort(stable.begin(), stable.end(),
                     [](const Support* a, const Support* b) { return a->area > b->area; });
    // The largest stable facet wins, except that a facet within kAreaTie of its area with a lower centre of
    // mass wins (more stable: a higher energy barrier against tipping). Boxes standing on their top or bottom
    // tie exactly and keep whichever the hull lists first (see docs/canonical.md).
    constexpr double kAreaTie = 0.10;
    const Support* chosen = stable.empty() ? nullptr : stable[0];
    for (const Support* s : stable)
      if (s->area >= (1 - kAreaTie) * stable[0]->area && s->com_height < chosen->com_height - 1e-9 * diag) chosen = s;
    const std::string com_kind = closed ? "volume centroid" : "area centroid";
    if (chosen != nullptr) {
      est.up_method =
          "hull support facet: largest stable (" + com_kind + "), lowest centre of mass within 10% of its area";
    } else {
      // Cannot happen for an exact hull (some face is always stable); the facet merging can break it for
      // nearly round objects. Take the facet the centre of mass is closest to being inside.
      for (const Support& s : supports)
        if (chosen == nullptr || s.margin > chosen->margin) chosen = &s;
      est.up_method = "hull support facet: least unstable (" + com_kind + "; no stable facet)";
    }
    SD_CHECK(chosen != nullptr, << "convex hull without facets");
    est.up = -chosen->normal;
    est.support_area = chosen->area;
  }

  const FrontEstimate front = EstimateFront(symmetry, est.up, hull_points);
  est.front = front.front;
  est.symmetry_error = front.symmetry_error;
  est.front_method = front.method;
  est.rotation.row(0) = est.front.transpose();
  est.rotation.row(1) = est.up.cross(est.front).transpose();
  est.rotation.row(2) = est.up.transpose();
  return est;
}

}  // namespace

FrameEstimate EstimateCanonicalFrame(const TriangleMesh& mesh) { return EstimateFrame(mesh, std::nullopt); }

CanonicalizeResult Canonicalize(const TriangleMesh& mesh, const CanonicalizeOptions& options) {
  if (mesh.positions.empty() || mesh.faces.empty()) throw InputError("", "mesh has no triangles");
  CanonicalizeResult r;
  const bool up_auto = options.up == "auto", front_auto = !options.front_direction && options.front == "auto";
  if (!up_auto && !front_auto && !options.front_direction) {
    r.rotation = AxesToCanonical(options.up, options.front);
  } else if (!up_auto && options.front_direction) {
    // Up named, front a free direction: no estimation needed.
    const Eigen::Vector3d u = ParseAxis(options.up), f = *options.front_direction;
    const Eigen::Vector3d h = f - f.dot(u) * u;
    if (!(h.norm() > 0.5 * f.norm()) || !h.allFinite())
      throw InputError("", "the front direction is within 30 degrees of the up axis " + options.up);
    r.rotation.row(0) = h.normalized().transpose();
    r.rotation.row(1) = u.cross(h.normalized()).transpose();
    r.rotation.row(2) = u.transpose();
  } else {
    const std::optional<Eigen::Vector3d> named_up =
        up_auto ? std::nullopt : std::optional<Eigen::Vector3d>(ParseAxis(options.up));
    FrameEstimate est = EstimateFrame(mesh, named_up);
    if (!front_auto) {
      // Up estimated, front named: the named axis, made horizontal.
      const Eigen::Vector3d f =
          options.front_direction ? options.front_direction->normalized() : ParseAxis(options.front);
      const Eigen::Vector3d h = f - f.dot(est.up) * est.up;
      if (h.norm() < 0.5)
        throw InputError("", "front axis " + options.front +
                                 " is within 30 degrees of the estimated up; give --up too");
      est.front = h.normalized();
      est.symmetry_error = 0;
      est.front_method = options.front_direction ? "given direction (made horizontal)"
                                                 : "given " + options.front + " (made horizontal)";
      est.rotation.row(0) = est.front.transpose();
      est.rotation.row(1) = est.up.cross(est.front).transpose();
      est.rotation.row(2) = est.up.transpose();
    }
    SD_LOG(Info, "estimated frame: up (" << est.up.transpose() << ") by " << est.up_method << "; front ("
                                         << est.front.transpose() << ") by " << est.front_method
                                         << ", symmetry residual " << est.symmetry_error);
    r.rotation = est.rotation;
    r.frame = est;
  }
  r.mesh = mesh;
  const Eigen::Matrix3f R = r.rotation.cast<float>();
  for (auto& p : r.mesh.positions) p = R * p;
  for (auto& n : r.mesh.normals) n = R * n;
  const AlignedBox3f b = r.mesh.Bounds();
  const Eigen::Vector3d size = b.Size().cast<double>();

  if (options.scale < 0 || !std::isfinite(options.scale))
    throw InputError("", Msg() << "impossible scale " << options.scale << " (must be positive)");
  if (options.target_height && !(*options.target_height > 0))
    throw InputError("", Msg() << "impossible target height " << *options.target_height << " m");
  if (options.scale > 0) {
    r.scale = options.scale;
  } else if (options.target_size) {
    // Uniform scale minimising the squared relative error over the three dimensions.
    const Eigen::Vector3d& t = *options.target_size;
    double num = 0, den = 0;
    for (int k = 0; k < 3; ++k) {
      if (size[k] <= 0 || t[k] <= 0) continue;
      num += size[k] / t[k];
      den += (size[k] / t[k]) * (size[k] / t[k]);
    }
    if (den <= 0) throw InputError("", "target size and mesh size give no scale");
    r.scale = num / den;
  } else if (options.target_height) {
    if (size.z() <= 0) throw InputError("", "mesh is flat along its up axis; cannot scale to a height");
    r.scale = *options.target_height / size.z();
  } else {
    throw InputError("", "no metric scale: give a scale, a target height or a target size");
  }
  if (!(r.scale > 0) || !std::isfinite(r.scale)) throw InputError("", Msg() << "impossible scale " << r.scale);

  // Origin at the centre of the ground contact: bbox centre in x/y, lowest point at z = 0.
  const Eigen::Vector3f offset(-b.Center().x(), -b.Center().y(), -b.min.z());
  const float s = static_cast<float>(r.scale);
  for (auto& p : r.mesh.positions) p = s * (p + offset);
  r.extent = r.scale * size;
  return r;
}

}  // namespace sd
