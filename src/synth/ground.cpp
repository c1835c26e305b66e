#include "synth/ground.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <random>
#include <unordered_map>

#include <Eigen/Eigenvalues>

#include "core/error.h"
#include "core/log.h"

namespace sd {
namespace {

// Least-squares plane through points (PCA); normal oriented to +z.
GroundPlane FitPlane(const std::vector<Eigen::Vector3d>& pts, const std::vector<double>* weights = nullptr) {
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  double wsum = 0;
  for (size_t i = 0; i < pts.size(); ++i) {
    const double w = weights ? (*weights)[i] : 1.0;
    mean += w * pts[i];
    wsum += w;
  }
  mean /= wsum;
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (size_t i = 0; i < pts.size(); ++i) {
    const double w = weights ? (*weights)[i] : 1.0;
    const Eigen::Vector3d d = pts[i] - mean;
    cov += w * d * d.transpose();
  }
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(cov);
  Eigen::Vector3d n = es.eigenvectors().col(0);  // smallest eigenvalue
  if (n.z() < 0) n = -n;
  GroundPlane plane;
  plane.normal = n.normalized();
  plane.d = -plane.normal.dot(mean);
  return plane;
}

double Distance(const GroundPlane& p, const Eigen::Vector3d& x) { return p.normal.dot(x) + p.d; }

}  // namespace

int GroundModel::CellIndex(double x, double y) const {
  const int half = n_ / 2;
  const int ix = static_cast<int>(std::floor(x / options_.cell)) + half;
  const int iy = static_cast<int>(std::floor(y / options_.cell)) + half;
  if (ix < 0 || iy < 0 || ix >= n_ || iy >= n_) return -1;
  return iy * n_ + ix;
}

GroundModel GroundModel::Estimate(const std::vector<Eigen::Vector3d>& points_ego, const std::vector<Box3>& objects,
                                  const GroundOptions& options) {
  GroundModel g;
  g.options_ = options;
  g.n_ = 2 * static_cast<int>(std::ceil(options.max_range / options.cell));

  // 1. Candidate points: in range, outside annotated objects.
  std::vector<int> candidates;
  candidates.reserve(points_ego.size());
  for (size_t i = 0; i < points_ego.size(); ++i) {
    const auto& p = points_ego[i];
    if (p.head<2>().norm() > options.max_range || p.head<2>().norm() < 1.0) continue;
    bool inside = false;
    for (const auto& b : objects) {
      if ((b.center().head<2>() - p.head<2>()).norm() > 0.5 * b.size.norm() + 0.3) continue;
      if (b.Contains(p, 0.1)) { inside = true; break; }
    }
    if (!inside) candidates.push_back(static_cast<int>(i));
  }
  if (candidates.size() < 50) throw InputError("", Msg() << "LiDAR sweep has only " << candidates.size()
                                                         << " usable points; cannot estimate the ground");

  // 2. Seed plane from the lowest point per coarse cell.
  std::unordered_map<int64_t, int> lowest;
  for (int i : candidates) {
    const auto& p = points_ego[i];
    const int64_t key = (static_cast<int64_t>(std::floor(p.x() / options.seed_cell)) << 32) ^
                        (static_cast<int64_t>(std::floor(p.y() / options.seed_cell)) & 0xffffffff);
    auto it = lowest.find(key);
    if (it == lowest.end() || points_ego[it->second].z() > p.z()) lowest[key] = i;
  }
  std::vector<Eigen::Vector3d> seeds;
  for (const auto& [key, i] : lowest) seeds.push_back(points_ego[i]);
  std::sort(seeds.begin(), seeds.end(), [](const auto& a, const auto& b) {
    return std::make_tuple(a.x(), a.y(), a.z()) < std::make_tuple(b.x(), b.y(), b.z());
  });  // deterministic order for the seeded RANSAC
  std::mt19937 rng(options.seed);
  std::uniform_int_distribution<size_t> pick(0, seeds.size() - 1);
  GroundPlane best;
  size_t best_inliers = 0;
  const double cos_max_tilt = std::cos(20.0 * M_PI / 180.0);
  for (int it = 0; it < options.ransac_iterations; ++it) {
    const auto& a = seeds[pick(rng)];
    const auto& b = seeds[pick(rng)];
    const auto& c = seeds[pick(rng)];
    Eigen::Vector3d n = (b - a).cross(c - a);
    if (n.norm() < 1e-6) continue;
    n.normalize();
    if (n.z() < 0) n = -n;
    if (n.z() < cos_max_tilt) continue;
    GroundPlane plane{n, -n.dot(a)};
    size_t inliers = 0;
    for (const auto& s : seeds) inliers += std::abs(Distance(plane, s)) < options.inlier;
    // Prefer the lower plane on ties: under a flat roof of car tops the road must win.
    if (inliers > best_inliers) { best_inliers = inliers; best = plane; }
  }
  if (best_inliers < 10) throw InputError("", "no ground plane found in the LiDAR sweep");
  {
    std::vector<Eigen::Vector3d> in;
    for (const auto& s : seeds) if (std::abs(Distance(best, s)) < options.inlier) in.push_back(s);
    best = FitPlane(in);
  }
  g.seed_ = best;

  // 3. Height field: lowest near-plane point per fine cell, then median of the band above it.
  const int ncell = g.n_ * g.n_;
  std::vector<std::vector<int>> cell_all(ncell);
  for (int i : candidates) {
    const auto& p = points_ego[i];
    // Generous window around the seed plane: slopes and ramps drift from it over tens of metres.
    if (std::abs(Distance(g.seed_, p)) > 0.5 + 0.02 * p.head<2>().norm()) continue;
    const int c = g.CellIndex(p.x(), p.y());
    if (c >= 0) cell_all[c].push_back(i);
  }
  g.height_.assign(ncell, std::numeric_limits<float>::quiet_NaN());
  for (int c = 0; c < ncell; ++c) {
    auto& idx = cell_all[c];
    if (idx.size() < 2) continue;
    double zmin = std::numeric_limits<double>::max();
    for (int i : idx) zmin = std::min(zmin, points_ego[i].z());
    std::vector<double> zs;
    for (int i : idx) if (points_ego[i].z() < zmin + options.band) zs.push_back(points_ego[i].z());
    std::nth_element(zs.begin(), zs.begin() + zs.size() / 2, zs.end());
    g.height_[c] = static_cast<float>(zs[zs.size() / 2]);
  }

  // Ground points: within `inlier` of their cell's height (or of the seed plane where the cell is empty).
  g.cell_points_.assign(ncell, {});
  for (int i : candidates) {
    const auto& p = points_ego[i];
    const int c = g.CellIndex(p.x(), p.y());
    if (c < 0 || std::isnan(g.height_[c])) continue;
    if (std::abs(p.z() - g.height_[c]) < options.band + 0.02) {
      g.cell_points_[c].push_back(static_cast<int>(g.ground_points_.size()));
      g.ground_points_.push_back(p);
      g.ground_indices_.push_back(i);
    }
  }

  // 4. Drivable area: free-space walk per azimuth sector (file comment in ground.h).
  {
    std::vector<uint8_t> is_ground(points_ego.size(), 0);
    for (int i : g.ground_indices_) is_ground[i] = 1;
    struct Sample { float range, height; bool ground; };
    std::vector<std::vector<Sample>> sectors(options.sectors);
    for (size_t i = 0; i < points_ego.size(); ++i) {
      const auto& p = points_ego[i];
      const Eigen::Vector2d d = p.head<2>() - options.sensor_xy;
      const double r = d.norm();
      if (r < 1.0 || r > options.max_range) continue;
      // Returns from the ego vehicle's own body (and zero-range returns at the sensor) are not obstacles.
      if (p.x() > options.ego_body_min.x() && p.x() < options.ego_body_max.x() && p.y() > options.ego_body_min.y() &&
          p.y() < options.ego_body_max.y())
        continue;
      const double h = g.HeightAboveGround(p);
      const bool ground = is_ground[i];
      if (!ground && (h < 0.25 || h > 3.0)) continue;  // neither road nor obstacle
      const int s = static_cast<int>((std::atan2(d.y(), d.x()) + M_PI) / (2 * M_PI) * options.sectors) % options.sectors;
      sectors[s].push_back({static_cast<float>(r), static_cast<float>(p.z()), ground});
    }
    g.free_range_.assign(options.sectors, 0.0f);
    for (int s = 0; s < options.sectors; ++s) {
      auto& v = sectors[s];
      std::sort(v.begin(), v.end(), [](const Sample& a, const Sample& b) { return a.range < b.range; });
      float free = 0, prev_r = 0;
      float prev_h = static_cast<float>(g.seed_.HeightAt(options.sensor_xy.x(), options.sensor_xy.y()));
      for (const auto& smp : v) {
        if (!smp.ground) break;
        if (std::abs(smp.height - prev_h) > options.max_step + options.max_slope * (smp.range - prev_r)) break;
        free = smp.range;
        prev_r = smp.range;
        prev_h = smp.height;
      }
      g.free_range_[s] = free;
    }
  }

  SD_LOG(Debug, "ground: seed plane n=" << g.seed_.normal.transpose() << " d=" << g.seed_.d << ", "
                                       << g.ground_points_.size() << " ground points");
  return g;
}

GroundModel::Surface GroundModel::SurfaceAt(double x, double y, double radius) const {
  Surface s;
  const double r = radius > 0 ? std::max(radius, options_.local_radius) : options_.local_radius;
  const int span = static_cast<int>(std::ceil(r / options_.cell));
  const int c = CellIndex(x, y);
  std::vector<Eigen::Vector3d> pts;
  std::vector<double> w;
  for (const bool road_only : {true, false}) {
  pts.clear();
  w.clear();
  if (c >= 0) {
    const int cx = c % n_, cy = c / n_;
    for (int dy = -span; dy <= span; ++dy)
      for (int dx = -span; dx <= span; ++dx) {
        const int nx = cx + dx, ny = cy + dy;
        if (nx < 0 || ny < 0 || nx >= n_ || ny >= n_) continue;
        for (int i : cell_points_[ny * n_ + nx]) {
          const double d = (ground_points_[i].head<2>() - Eigen::Vector2d(x, y)).norm();
          if (d > r) continue;
          // On the road, the pavement behind a kerb is not the surface the object stands on.
          if (road_only && !IsDrivable(ground_points_[i].x(), ground_points_[i].y())) continue;
          pts.push_back(ground_points_[i]);
          w.push_back(1.0 - 0.5 * d / r);  // nearer points count more; all keep some weight
        }
      }
  }
  if (pts.size() >= 8) break;
  }
  if (pts.size() < 8) {
    s.height = seed_.HeightAt(x, y);
    s.normal = seed_.normal;
    return s;
  }
  GroundPlane local = FitPlane(pts, &w);
  // A local fit tilted beyond 15 deg is a wall or kerb edge leaking in; fall back to the seed normal.
  if (local.normal.z() < std::cos(15.0 * M_PI / 180.0)) local.normal = seed_.normal;
  // At range the support is often a single LiDAR ring: nearly collinear points fix no tilt across the
  // ring, and a free fit would extrapolate a wrong height to (x, y). Keep the seed normal then.
  {
    Eigen::Vector2d m = Eigen::Vector2d::Zero();
    for (const auto& p : pts) m += p.head<2>();
    m /= static_cast<double>(pts.size());
    Eigen::Matrix2d cov = Eigen::Matrix2d::Zero();
    for (const auto& p : pts) cov += (p.head<2>() - m) * (p.head<2>() - m).transpose();
    cov /= static_cast<double>(pts.size());
    if (Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d>(cov).eigenvalues()(0) < 0.3 * 0.3) local.normal = seed_.normal;
  }
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  double wsum = 0;
  for (size_t i = 0; i < pts.size(); ++i) { mean += w[i] * pts[i]; wsum += w[i]; }
  mean /= wsum;
  local.d = -local.normal.dot(mean);
  s.height = local.HeightAt(x, y);
  s.normal = local.normal;
  s.support = static_cast<int>(pts.size());
  return s;
}

double GroundModel::HeightAboveGround(const Eigen::Vector3d& p) const {
  const int c = CellIndex(p.x(), p.y());
  if (c >= 0 && !std::isnan(height_[c])) return p.z() - height_[c];
  return p.z() - seed_.HeightAt(p.x(), p.y());
}

bool GroundModel::IsObserved(double x, double y) const {
  const int c = CellIndex(x, y);
  return c >= 0 && !std::isnan(height_[c]);
}

bool GroundModel::IsDrivable(double x, double y) const {
  if (free_range_.empty()) return false;
  const Eigen::Vector2d d = Eigen::Vector2d(x, y) - options_.sensor_xy;
  const int n = static_cast<int>(free_range_.size());
  const int s = static_cast<int>((std::atan2(d.y(), d.x()) + M_PI) / (2 * M_PI) * n) % n;
  return d.norm() <= free_range_[s];
}

double GroundModel::DrivableFraction(const Box3& footprint) const {
  int total = 0, ok = 0;
  const double hl = 0.5 * footprint.size.x(), hw = 0.5 * footprint.size.y();
  // Samples every half cell, corners included.
  const int nu = std::max(2, static_cast<int>(std::ceil(2 * hl / (0.5 * options_.cell))) + 1);
  const int nv = std::max(2, static_cast<int>(std::ceil(2 * hw / (0.5 * options_.cell))) + 1);
  for (int i = 0; i < nu; ++i) {
    for (int j = 0; j < nv; ++j) {
      const double u = -hl + 2 * hl * i / (nu - 1), v = -hw + 2 * hw * j / (nv - 1);
      const Eigen::Vector3d p = footprint.T_frame_box * Eigen::Vector3d(u, v, 0);
      ++total;
      ok += IsDrivable(p.x(), p.y());
    }
  }
  return total ? static_cast<double>(ok) / total : 0.0;
}

}  // namespace sd
