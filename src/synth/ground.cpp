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

// One return of a free-space sector: its range from the sensor and its height above the seed plane.
struct SectorReturn {
  float range, height;
  bool ground;
};

// The road profile of a sector so far: the height that the accepted returns of the last `window` metres predict
// at `range`, a least-squares line whose grade is shrunk towards the seed plane's by a prior of `prior_span`
// metres (returns spanning less than that fix a grade poorly, and extrapolating a noisy grade over the next ring
// gap would invent kerbs) and bounded by `max_grade`.
double PredictRoadHeight(const std::vector<SectorReturn>& accepted, double range, double window, double max_grade) {
  constexpr double kPriorSpan = 1.0;
  const double from = accepted.back().range - window;
  double n = 0, sr = 0, sh = 0;
  for (auto it = accepted.rbegin(); it != accepted.rend() && it->range >= from; ++it) {
    n += 1;
    sr += it->range;
    sh += it->height;
  }
  const double mr = sr / n, mh = sh / n;
  double srr = 0, srh = 0;
  for (auto it = accepted.rbegin(); it != accepted.rend() && it->range >= from; ++it) {
    srr += (it->range - mr) * (it->range - mr);
    srh += (it->range - mr) * (it->height - mh);
  }
  const double grade = std::clamp(srh / (srr + n * kPriorSpan * kPriorSpan / 12.0), -max_grade, max_grade);
  return mh + grade * (range - mr);
}

// The free range of one sector (ground.h, step 4), its returns sorted by range. Before a return joins the road,
// the returns from it to `kerb_lookahead` metres beyond (at most 9: three rings of a spinning LiDAR) are compared
// with the road profile: when their median departs by more than a kerb (`kerb_step`) and by more than a change of
// grade of `max_bend` since the last road return could explain, a kerb begins there and the road ends at the last
// return accepted. The median is what makes a 4 cm kerb stand out of a centimetre of noise, of rings biased by
// their calibration and of returns on the kerb's face; comparing with the profile of the last metres, not with
// the previous return alone, is what catches a kerb seen across a ring gap, which return by return reads as a
// gentle slope; the bend allowance is what lets a street tip over a crest. A return departing on its own (noise,
// a pothole edge) is passed over without joining the profile.
// `open_ended` (optional): set when the walk ran out of returns rather than meeting a kerb or an obstacle.
float WalkSector(const std::vector<SectorReturn>& v, const GroundOptions& o, double kerb_step,
                 std::vector<float>* accepted_departures, bool* open_ended = nullptr) {
  if (open_ended) *open_ended = false;
  constexpr size_t kMaxLookahead = 9;
  std::vector<SectorReturn> accepted;
  std::vector<double> departures, distances;
  float free = 0;
  for (size_t i = 0; i < v.size(); ++i) {
    const SectorReturn& smp = v[i];
    if (!smp.ground) return free;
    if (accepted.empty()) {
      // The first return after the ego body: the road the ego stands on, near the seed plane (which a cambered
      // road leaves by a few per cent).
      if (std::abs(smp.height) > o.max_step + o.max_grade * smp.range) return free;
      accepted.push_back(smp);
      free = smp.range;
      continue;
    }
    const double last = accepted.back().range;
    const auto departure = [&](const SectorReturn& r) {
      return r.height - PredictRoadHeight(accepted, r.range, o.profile_window, o.max_grade);
    };
    const auto tolerance = [&](double distance) { return std::max(kerb_step, o.max_bend * distance); };
    departures.clear();
    distances.clear();
    for (size_t j = i; j < v.size() && v[j].ground && v[j].range <= smp.range + o.kerb_lookahead &&
                       departures.size() < kMaxLookahead; ++j) {
      departures.push_back(departure(v[j]));
      distances.push_back(v[j].range - last);
    }
    const size_t mid = departures.size() / 2;
    std::nth_element(departures.begin(), departures.begin() + mid, departures.end());
    std::nth_element(distances.begin(), distances.begin() + mid, distances.end());
    if (std::abs(departures[mid]) > tolerance(distances[mid])) return free;
    const double own = departure(smp);
    if (std::abs(own) <= tolerance(smp.range - last)) {
      if (accepted_departures && accepted.size() >= 3) accepted_departures->push_back(static_cast<float>(std::abs(own)));
      accepted.push_back(smp);
      free = smp.range;
    }
  }
  if (open_ended) *open_ended = true;
  return free;
}

}  // namespace

int GroundModel::CellIndex(double x, double y) const {
  const int half = n_ / 2;
  const int ix = static_cast<int>(std::floor(x / options_.cell)) + half;
  const int iy = static_cast<int>(std::floor(y / options_.cell)) + half;
  if (ix < 0 || iy < 0 || ix >= n_ || iy >= n_) return -1;
  return iy * n_ + ix;
}

GroundModel GroundModel::Estimate(const std::vector<Eigen::Vector3d>& points_ego, const std::vector<Box3>& objects,
                                  const GroundOptions& options, const std::vector<uint8_t>& other_sensor) {
  SD_CHECK(other_sensor.empty() || other_sensor.size() == points_ego.size());
  const auto own = [&](size_t i) { return other_sensor.empty() || other_sensor[i] == 0; };
  GroundModel g;
  g.options_ = options;
  g.n_ = 2 * static_cast<int>(std::ceil(options.max_range / options.cell));

  // 1. Candidate points: in range, outside annotated objects.
  std::vector<int> candidates;
  candidates.reserve(points_ego.size());
  for (size_t i = 0; i < points_ego.size(); ++i) {
    const auto& p = points_ego[i];
    if (p.head<2>().norm() > options.max_range || p.head<2>().norm() < 1.0 || !own(i)) continue;
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
    std::vector<std::vector<SectorReturn>> sectors(options.sectors);
    for (size_t i = 0; i < points_ego.size(); ++i) {
      const auto& p = points_ego[i];
      const Eigen::Vector2d d = p.head<2>() - options.sensor_xy;
      const double r = d.norm();
      if (r < 1.0 || r > options.max_range || !own(i)) continue;
      // Returns from the ego vehicle's own body (and zero-range returns at the sensor) are not obstacles.
      if (p.x() > options.ego_body_min.x() && p.x() < options.ego_body_max.x() && p.y() > options.ego_body_min.y() &&
          p.y() < options.ego_body_max.y())
        continue;
      const double h = g.HeightAboveGround(p);
      const bool ground = is_ground[i];
      if (!ground && (h < 0.25 || h > 3.0)) continue;  // neither road nor obstacle
      const int s = static_cast<int>((std::atan2(d.y(), d.x()) + M_PI) / (2 * M_PI) * options.sectors) % options.sectors;
      sectors[s].push_back({static_cast<float>(r), static_cast<float>(p.z() - g.seed_.HeightAt(p.x(), p.y())), ground});
    }
    // The kerb threshold is the sensor's own: a LiDAR whose rings disagree by centimetres (KITTI's HDL-64)
    // would find a kerb at every ring. A first walk measures how far accepted road returns depart from their
    // profile (robust sigma); the threshold is 4 sigma when that exceeds `kerb_step`.
    for (auto& v : sectors)
      std::sort(v.begin(), v.end(), [](const SectorReturn& a, const SectorReturn& b) { return a.range < b.range; });
    std::vector<float> departures;
    for (const auto& v : sectors) WalkSector(v, options, options.kerb_step, &departures);
    g.road_roughness_ = 0;
    if (departures.size() >= 50) {
      std::nth_element(departures.begin(), departures.begin() + departures.size() / 2, departures.end());
      g.road_roughness_ = 1.4826 * departures[departures.size() / 2];
    }
    g.kerb_step_ = std::max(options.kerb_step, 4.0 * g.road_roughness_);
    g.free_range_.assign(options.sectors, 0.0f);
    for (int s = 0; s < options.sectors; ++s) {
      bool open_ended = false;
      g.free_range_[s] = WalkSector(sectors[s], options, g.kerb_step_, nullptr, &open_ended);
      // Beyond a camera's last road return the road goes on until something stands on it: its stereo stops for
      // want of parallax, not because the road does.
      if (options.open_sectors_reach_obstacles && open_ended && !sectors[s].empty()) {
        float reach = static_cast<float>(options.max_range);
        for (const SectorReturn& r : sectors[s])
          if (!r.ground && r.range > g.free_range_[s]) {
            reach = r.range;
            break;
          }
        g.free_range_[s] = reach;
      }
    }
    // A sector without a single return says nothing; between two that reach out, it takes the nearer reach
    // (a camera's stereo has no parallax towards its direction of travel, the ego's own lane ahead).
    if (options.bridge_empty_sectors > 0) {
      const std::vector<float> walked = g.free_range_;
      const int n = options.sectors, k = options.bridge_empty_sectors;
      const auto reach = [&](int s, int step) -> std::optional<float> {
        for (int i = 1; i <= k; ++i) {
          const int t = ((s + step * i) % n + n) % n;
          if (!sectors[t].empty()) return walked[t];
        }
        return std::nullopt;
      };
      for (int s = 0; s < n; ++s) {
        if (!sectors[s].empty()) continue;
        const auto left = reach(s, -1), right = reach(s, +1);
        if (left && right) g.free_range_[s] = std::min(*left, *right);
      }
    }
  }

  SD_LOG(Debug, "ground: seed plane n=" << g.seed_.normal.transpose() << " d=" << g.seed_.d << ", "
                                       << g.ground_points_.size() << " ground points, road roughness "
                                       << g.road_roughness_ << " m, kerb step " << g.kerb_step_ << " m");
  return g;
}

GroundModel GroundModel::Plane(const GroundPlane& plane, const GroundOptions& options) {
  SD_CHECK(plane.normal.z() > 0 && std::abs(plane.normal.norm() - 1.0) < 1e-6, << "plane normal " << plane.normal.transpose());
  GroundModel g;
  g.options_ = options;
  g.seed_ = plane;
  g.n_ = 2 * static_cast<int>(std::ceil(options.max_range / options.cell));
  g.height_.assign(static_cast<size_t>(g.n_) * g.n_, std::numeric_limits<float>::quiet_NaN());
  g.cell_points_.assign(static_cast<size_t>(g.n_) * g.n_, {});
  g.free_range_.assign(static_cast<size_t>(options.sectors), static_cast<float>(options.max_range));
  g.kerb_step_ = options.kerb_step;
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
