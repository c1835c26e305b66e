#include "synth/road_surface.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <deque>
#include <exception>
#include <limits>
#include <random>

#include <Eigen/Eigenvalues>

#include "core/error.h"
#include "core/log.h"
#include "core/parallel.h"
#include "datasets/readers.h"

namespace sd {

namespace {

constexpr float kNaN = std::numeric_limits<float>::quiet_NaN();

// xy relative to a reference point (float keeps millimetres within 100 km of it, not at UTM magnitudes).
struct KeptPoint {
  float x, y, z;
  int32_t sweep, index;
};

// Median of v (reordered); v non-empty.
float Median(std::vector<float>& v) {
  const size_t mid = v.size() / 2;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(mid), v.end());
  return v[mid];
}

// z = a x + b y + c fitted to `pts` (least squares, centred for conditioning); nullopt when degenerate.
std::optional<Eigen::Vector3d> FitHeightPlane(const std::vector<Eigen::Vector3d>& pts) {
  if (pts.size() < 3) return std::nullopt;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& p : pts) mean += p;
  mean /= static_cast<double>(pts.size());
  Eigen::Matrix2d A = Eigen::Matrix2d::Zero();
  Eigen::Vector2d b = Eigen::Vector2d::Zero();
  for (const auto& p : pts) {
    const Eigen::Vector2d d = (p - mean).head<2>();
    A += d * d.transpose();
    b += d * (p.z() - mean.z());
  }
  if (std::abs(A.determinant()) < 1e-9) return std::nullopt;
  const Eigen::Vector2d g = A.ldlt().solve(b);
  return Eigen::Vector3d(g.x(), g.y(), mean.z() - g.x() * mean.x() - g.y() * mean.y());
}

// RANSAC plane z = a x + b y + c through the given candidate points, normal within 20 deg of +z, refined
// by least squares on its inliers. nullopt when fewer than 10 inliers.
std::optional<Eigen::Vector3d> SeedPlane(const std::vector<Eigen::Vector3d>& cand, const RoadSurfaceOptions& o) {
  if (cand.size() < 10) return std::nullopt;
  std::mt19937 rng(o.seed);
  std::uniform_int_distribution<size_t> pick(0, cand.size() - 1);
  const double min_nz = std::cos(20.0 * 3.14159265358979 / 180.0);
  size_t best_count = 0;
  Eigen::Vector4d best = Eigen::Vector4d::Zero();
  for (int it = 0; it < o.ransac_iterations; ++it) {
    const Eigen::Vector3d& a = cand[pick(rng)];
    const Eigen::Vector3d& b = cand[pick(rng)];
    const Eigen::Vector3d& c = cand[pick(rng)];
    Eigen::Vector3d n = (b - a).cross(c - a);
    if (n.norm() < 1e-6) continue;
    n.normalize();
    if (n.z() < 0) n = -n;
    if (n.z() < min_nz) continue;
    const double d = -n.dot(a);
    size_t count = 0;
    for (const auto& p : cand) count += std::abs(n.dot(p) + d) < o.seed_inlier;
    if (count > best_count) {
      best_count = count;
      best << n, d;
    }
  }
  if (best_count < 10) return std::nullopt;
  std::vector<Eigen::Vector3d> inliers;
  for (const auto& p : cand)
    if (std::abs(best.head<3>().dot(p) + best[3]) < o.seed_inlier) inliers.push_back(p);
  if (auto fit = FitHeightPlane(inliers)) return fit;
  return Eigen::Vector3d(-best.x() / best.z(), -best.y() / best.z(), -best[3] / best.z());
}

}  // namespace

int RoadSurface::CellIndex(const Eigen::Vector2d& xy) const {
  const double fx = (xy.x() - origin_.x()) / options_.cell, fy = (xy.y() - origin_.y()) / options_.cell;
  if (!(fx >= 0 && fy >= 0 && fx < nx_ && fy < ny_)) return -1;
  return static_cast<int>(fy) * nx_ + static_cast<int>(fx);
}

RoadSurface RoadSurface::Build(const std::vector<SweepInWorld>& sweeps, const RoadSurfaceOptions& o) {
  SD_CHECK(o.cell > 0 && o.band > 0 && o.grow_distance >= 0, << "bad RoadSurfaceOptions");
  RoadSurface s;
  s.options_ = o;
  s.ground_indices_.resize(sweeps.size());

  // 1. Drop ego-body, far and annotated-object points.
  const Eigen::Vector2d ref = sweeps.empty() ? Eigen::Vector2d::Zero() : sweeps.front().sensor_origin.head<2>().eval();
  std::vector<std::vector<KeptPoint>> kept(sweeps.size());
  {
    Progress progress("road surface: filtering sweeps", sweeps.size());
    ParallelForRethrow(0, sweeps.size(), [&](size_t k) {
      const SweepInWorld& sw = sweeps[k];
      const Eigen::Vector2d sensor = sw.sensor_origin.head<2>();
      std::vector<double> reach(sw.objects.size());
      for (size_t b = 0; b < sw.objects.size(); ++b)
        reach[b] = 0.5 * sw.objects[b].size.head<2>().norm() + o.box_margin;
      for (size_t i = 0; i < sw.points.size(); ++i) {
        const Eigen::Vector3d& p = sw.points[i];
        const double r = (p.head<2>() - sensor).norm();
        if (r < o.min_range || r > o.max_range || !p.allFinite()) continue;
        bool in_object = false;
        for (size_t b = 0; b < sw.objects.size() && !in_object; ++b)
          in_object = (p.head<2>() - sw.objects[b].center().head<2>()).norm() <= reach[b] &&
                      sw.objects[b].Contains(p, o.box_margin);
        if (in_object) continue;
        kept[k].push_back({static_cast<float>(p.x() - ref.x()), static_cast<float>(p.y() - ref.y()),
                           static_cast<float>(p.z()), static_cast<int32_t>(k), static_cast<int32_t>(i)});
      }
      progress.Advance();
    });
  }

  // Grid extent: the kept points and the ego positions (whose footprint gets filled).
  Eigen::AlignedBox2d extent;
  for (const auto& sweep_points : kept)
    for (const KeptPoint& p : sweep_points) extent.extend(ref + Eigen::Vector2d(p.x, p.y));
  for (const SweepInWorld& sw : sweeps) {
    extent.extend(sw.sensor_origin.head<2>() - Eigen::Vector2d::Constant(o.ego_fill_radius));
    extent.extend(sw.sensor_origin.head<2>() + Eigen::Vector2d::Constant(o.ego_fill_radius));
  }
  if (extent.isEmpty()) throw InputError({}, "road surface: no sweeps");
  s.origin_ = (extent.min().array() / o.cell).floor().matrix() * o.cell - Eigen::Vector2d::Constant(o.cell);
  s.nx_ = static_cast<int>(std::ceil((extent.max().x() - s.origin_.x()) / o.cell)) + 2;
  s.ny_ = static_cast<int>(std::ceil((extent.max().y() - s.origin_.y()) / o.cell)) + 2;
  if (static_cast<double>(s.nx_) * s.ny_ > 2e8)
    throw InputError({}, Msg() << "road surface: the sequence spans " << s.nx_ * o.cell << " x " << s.ny_ * o.cell
                               << " m, too large for a " << o.cell << " m grid; build it over fewer frames");
  const int nx = s.nx_, ny = s.ny_;
  const size_t ncell = static_cast<size_t>(nx) * ny;
  Progress progress("road surface: height field", 7);

  // 2. Bucket the points by cell (counting sort), heights ascending within each cell.
  std::vector<KeptPoint> pts;
  for (auto& v : kept) {
    pts.insert(pts.end(), v.begin(), v.end());
    std::vector<KeptPoint>().swap(v);
  }
  std::vector<uint32_t> start(ncell + 1, 0);
  std::vector<int> cell_of(pts.size());
  for (size_t i = 0; i < pts.size(); ++i) {
    cell_of[i] = s.CellIndex(ref + Eigen::Vector2d(pts[i].x, pts[i].y));
    SD_CHECK(cell_of[i] >= 0, << "point outside the grid extent");
    ++start[static_cast<size_t>(cell_of[i]) + 1];
  }
  for (size_t c = 0; c < ncell; ++c) start[c + 1] += start[c];
  std::vector<KeptPoint> sorted(pts.size());
  {
    std::vector<uint32_t> fill(start.begin(), start.end() - 1);
    for (size_t i = 0; i < pts.size(); ++i) sorted[fill[static_cast<size_t>(cell_of[i])]++] = pts[i];
  }
  std::vector<KeptPoint>().swap(pts);
  std::vector<int>().swap(cell_of);
  std::vector<float> candidate(ncell, kNaN);
  ParallelFor(0, static_cast<size_t>(ny), [&](size_t iy) {
    std::vector<float> band;
    for (size_t c = iy * nx; c < (iy + 1) * nx; ++c) {
      const auto b = sorted.begin() + start[c], e = sorted.begin() + start[c + 1];
      if (b == e) continue;
      std::sort(b, e, [](const KeptPoint& p, const KeptPoint& q) { return p.z < q.z; });
      const size_t n = static_cast<size_t>(e - b);
      size_t low = 0;  // robust lowest: has a neighbour within `band` above it
      while (low + 1 < n && (b + low + 1)->z - (b + low)->z > o.band) ++low;
      if (low + 1 == n && n > 1) low = 0;  // no pair at all: vertical scatter, keep the lowest
      band.clear();
      for (size_t k = low; k < n && (b + k)->z <= (b + low)->z + o.band; ++k) band.push_back((b + k)->z);
      candidate[c] = Median(band);
    }
  });
  progress.Advance();

  // 3. Seeds: per sweep, the cells near the sensor that lie on its RANSAC ground plane.
  std::vector<uint8_t> accepted(ncell, 0);
  std::deque<int> queue;
  // Per sweep, the seed plane's gradient (dz/dx, dz/dy): the local road grade where heights are compared
  // across unobserved cells.
  std::vector<std::optional<Eigen::Vector2d>> grade(sweeps.size());
  {
    for (size_t k = 0; k < sweeps.size(); ++k) {
      const Eigen::Vector2d sensor = sweeps[k].sensor_origin.head<2>();
      const int r_cells = static_cast<int>(std::ceil(o.seed_radius / o.cell));
      const int cx = static_cast<int>((sensor.x() - s.origin_.x()) / o.cell);
      const int cy = static_cast<int>((sensor.y() - s.origin_.y()) / o.cell);
      // Lowest candidate of each seed cell (seed_cell metres) within the radius.
      const int group = std::max(1, static_cast<int>(std::lround(o.seed_cell / o.cell)));
      std::vector<Eigen::Vector3d> cand;
      for (int gy = cy - r_cells; gy <= cy + r_cells; gy += group)
        for (int gx = cx - r_cells; gx <= cx + r_cells; gx += group) {
          float best = kNaN;
          int best_c = -1;
          for (int y = gy; y < gy + group; ++y)
            for (int x = gx; x < gx + group; ++x) {
              if (x < 0 || y < 0 || x >= nx || y >= ny) continue;
              const int c = y * nx + x;
              if (!std::isnan(candidate[c]) && (best_c < 0 || candidate[c] < best)) best = candidate[c], best_c = c;
            }
          if (best_c < 0) continue;
          const Eigen::Vector2d xy = s.CellCentre(best_c % nx, best_c / nx);
          if ((xy - sensor).norm() <= o.seed_radius) cand.emplace_back(xy.x(), xy.y(), best);
        }
      const auto plane = SeedPlane(cand, o);
      if (!plane) continue;
      grade[k] = plane->head<2>();
      for (int y = std::max(0, cy - r_cells); y <= std::min(ny - 1, cy + r_cells); ++y)
        for (int x = std::max(0, cx - r_cells); x <= std::min(nx - 1, cx + r_cells); ++x) {
          const int c = y * nx + x;
          const Eigen::Vector2d xy = s.CellCentre(x, y);
          if (std::isnan(candidate[c]) || accepted[c] || (xy - sensor).norm() > o.seed_radius) continue;
          const double plane_z = plane->x() * xy.x() + plane->y() * xy.y() + plane->z();
          if (std::abs(candidate[c] - plane_z) <= o.seed_inlier) {
            accepted[c] = 1;
            queue.push_back(c);
          }
        }
    }
  }
  if (queue.empty())
    throw InputError({}, "road surface: no ground plane found near any sensor position (are the sweeps in the "
                         "world frame?)");

  // 4. Region growing. Offsets within grow_distance, nearest first, each with the cells its segment crosses.
  struct Jump {
    int dx, dy;
    double dist;
    std::vector<std::array<int, 2>> between;
  };
  std::vector<Jump> jumps;
  {
    const int r = std::max(1, static_cast<int>(std::floor(o.grow_distance / o.cell)));
    for (int dy = -r; dy <= r; ++dy)
      for (int dx = -r; dx <= r; ++dx) {
        const double d = std::hypot(dx, dy);
        if (d == 0 || (d > r && std::max(std::abs(dx), std::abs(dy)) > 1)) continue;
        Jump j{dx, dy, d * o.cell, {}};
        const int steps = static_cast<int>(std::ceil(2 * d));
        for (int k = 1; k < steps; ++k) {
          const int bx = static_cast<int>(std::lround(dx * static_cast<double>(k) / steps));
          const int by = static_cast<int>(std::lround(dy * static_cast<double>(k) / steps));
          if ((bx == 0 && by == 0) || (bx == dx && by == dy)) continue;
          if (j.between.empty() || j.between.back() != std::array<int, 2>{bx, by}) j.between.push_back({bx, by});
        }
        jumps.push_back(std::move(j));
      }
    std::sort(jumps.begin(), jumps.end(), [](const Jump& a, const Jump& b) { return a.dist < b.dist; });
  }
  while (!queue.empty()) {
    const int a = queue.front();
    queue.pop_front();
    const int ax = a % nx, ay = a / nx;
    for (const Jump& j : jumps) {
      const int x = ax + j.dx, y = ay + j.dy;
      if (x < 0 || y < 0 || x >= nx || y >= ny) continue;
      const int b = y * nx + x;
      if (accepted[b] || std::isnan(candidate[b])) continue;
      if (std::abs(candidate[b] - candidate[a]) > o.ground_max_step + o.ground_max_slope * j.dist) continue;
      bool empty_between = true;
      for (const auto& m : j.between)
        if (!std::isnan(candidate[static_cast<size_t>((ay + m[1]) * nx + ax + m[0])])) {
          empty_between = false;
          break;
        }
      if (!empty_between) continue;
      accepted[b] = 1;
      queue.push_back(b);
    }
  }
  progress.Advance();

  // 5. Ground points and observed heights.
  s.height_.assign(ncell, kNaN);
  s.observed_.assign(ncell, 0);
  {
    std::vector<float> zs;
    for (size_t c = 0; c < ncell; ++c) {
      if (!accepted[c]) continue;
      zs.clear();
      for (uint32_t k = start[c]; k < start[c + 1]; ++k) {
        const KeptPoint& p = sorted[k];
        if (std::abs(p.z - candidate[c]) <= o.inlier) {
          zs.push_back(p.z);
          s.ground_indices_[static_cast<size_t>(p.sweep)].push_back(p.index);
        }
      }
      if (zs.empty()) continue;
      s.height_[c] = Median(zs);
      s.observed_[c] = 1;
      s.stats_.ground_points += zs.size();
    }
    for (auto& v : s.ground_indices_) std::sort(v.begin(), v.end());
  }
  progress.Advance();

  // 6. Holes: targets, then membrane fill with the observed cells fixed.
  std::vector<float> dist(ncell, std::numeric_limits<float>::infinity());  // to observed ground, metres
  {
    for (size_t c = 0; c < ncell; ++c)
      if (s.observed_[c]) dist[c] = 0;
    // Two-pass chamfer distance (1, sqrt 2) on the grid.
    const float d1 = static_cast<float>(o.cell), d2 = static_cast<float>(o.cell * std::sqrt(2.0));
    auto relax = [&](int c, int x, int y, int dx, int dy, float w) {
      const int xx = x + dx, yy = y + dy;
      if (xx < 0 || yy < 0 || xx >= nx || yy >= ny) return;
      dist[c] = std::min(dist[c], dist[yy * nx + xx] + w);
    };
    for (int y = 0; y < ny; ++y)
      for (int x = 0; x < nx; ++x) {
        const int c = y * nx + x;
        relax(c, x, y, -1, 0, d1), relax(c, x, y, 0, -1, d1), relax(c, x, y, -1, -1, d2), relax(c, x, y, 1, -1, d2);
      }
    for (int y = ny - 1; y >= 0; --y)
      for (int x = nx - 1; x >= 0; --x) {
        const int c = y * nx + x;
        relax(c, x, y, 1, 0, d1), relax(c, x, y, 0, 1, d1), relax(c, x, y, 1, 1, d2), relax(c, x, y, -1, 1, d2);
      }
  }
  // The road grade near xy: the seed-plane gradient of the nearest sweep that has one, tabulated on blocks of
  // kGradeBlock cells (long sequences have hundreds of sweeps).
  constexpr int kGradeBlock = 16;
  const int gbx = (nx + kGradeBlock - 1) / kGradeBlock, gby = (ny + kGradeBlock - 1) / kGradeBlock;
  std::vector<Eigen::Vector2d> grade_table(static_cast<size_t>(gbx) * gby, Eigen::Vector2d::Zero());
  for (int by = 0; by < gby; ++by)
    for (int bx = 0; bx < gbx; ++bx) {
      const Eigen::Vector2d xy = s.origin_ + o.cell * kGradeBlock * Eigen::Vector2d(bx + 0.5, by + 0.5);
      double best = std::numeric_limits<double>::infinity();
      for (size_t k = 0; k < sweeps.size(); ++k) {
        const double d = (sweeps[k].sensor_origin.head<2>() - xy).squaredNorm();
        if (grade[k] && d < best) best = d, grade_table[static_cast<size_t>(by * gbx + bx)] = *grade[k];
      }
    }
  auto grade_at = [&](const Eigen::Vector2d& xy) {
    const int c = s.CellIndex(xy);
    if (c < 0) return Eigen::Vector2d::Zero().eval();
    return grade_table[static_cast<size_t>((c / nx / kGradeBlock) * gbx + (c % nx) / kGradeBlock)];
  };
  std::vector<uint8_t> gap_step(ncell, 0);  // a filled gap that hides a kerb (never drivable)
  // target: 1 = object / ego footprint, 2 = enclosed gap; both get the membrane fill.
  std::vector<uint8_t> target(ncell, 0);
  // Object footprints: the height of the road seen in front of the object (NaN elsewhere).
  std::vector<float> near_side(ncell, kNaN);
  auto mark_footprint = [&](const Box3& box, double margin, const Eigen::Vector2d& sensor) {
    const Rigid3d T_box_world = box.T_frame_box.Inverse();
    const double hx = 0.5 * box.size.x() + margin, hy = 0.5 * box.size.y() + margin;
    const double reach = std::hypot(hx, hy);
    const Eigen::Vector2d c0 = box.center().head<2>();
    const int x0 = std::max(0, static_cast<int>((c0.x() - reach - s.origin_.x()) / o.cell));
    const int x1 = std::min(nx - 1, static_cast<int>((c0.x() + reach - s.origin_.x()) / o.cell));
    const int y0 = std::max(0, static_cast<int>((c0.y() - reach - s.origin_.y()) / o.cell));
    const int y1 = std::min(ny - 1, static_cast<int>((c0.y() + reach - s.origin_.y()) / o.cell));
    // The membrane may carry a different surface into a footprint (a lawn or wall base seen beyond the
    // object, in its shadow), so we also estimate the road the sensor sees in front of the object: walk from
    // each footprint cell towards the sensor to the first observed cell.
    std::vector<int> cells;
    std::vector<Eigen::Vector3d> hits;
    const Eigen::Vector2d g = grade_at(c0);
    for (int y = y0; y <= y1; ++y)
      for (int x = x0; x <= x1; ++x) {
        const Eigen::Vector2d xy = s.CellCentre(x, y);
        const Eigen::Vector3d q = T_box_world * Eigen::Vector3d(xy.x(), xy.y(), box.center().z());
        const int c = y * nx + x;
        if (!(std::abs(q.x()) <= hx && std::abs(q.y()) <= hy && !s.observed_[c] && dist[c] <= o.object_fill_distance))
          continue;
        cells.push_back(c);
        const Eigen::Vector2d to_sensor = sensor - xy;
        const double len = std::min(to_sensor.norm(), 2 * reach + o.object_fill_distance);
        if (len <= 0) continue;
        const Eigen::Vector2d dir = to_sensor.normalized();
        for (double t = 0.5 * o.cell; t <= len; t += 0.5 * o.cell) {
          const int h = s.CellIndex(xy + t * dir);
          if (h >= 0 && s.observed_[static_cast<size_t>(h)]) {
            const Eigen::Vector2d hxy = s.CellCentre(h % nx, h / nx);
            hits.emplace_back(hxy.x(), hxy.y(), s.height_[static_cast<size_t>(h)]);
            break;
          }
        }
      }
    if (hits.empty()) {
      for (int c : cells) target[static_cast<size_t>(c)] = std::max<uint8_t>(target[static_cast<size_t>(c)], 1);
      return;  // nothing seen in front: the membrane alone
    }
    // A plane through the observed road around those hits (2D patch: both grade components), restricted to
    // heights near the hits' median so a kerb or sidewalk behind them does not tilt it; where the patch is a
    // thin line (a single LiDAR ring), the median hit height carried along the seed plane's grade.
    std::vector<float> zs(hits.size());
    for (size_t k = 0; k < hits.size(); ++k) zs[k] = static_cast<float>(hits[k].z());
    const double hit_median = Median(zs);
    std::vector<int> patch_cells;
    const int pr = static_cast<int>(std::ceil(1.2 / o.cell));
    for (const auto& hp : hits) {
      const int hc = s.CellIndex(hp.head<2>());
      for (int dy = -pr; dy <= pr; ++dy)
        for (int dx = -pr; dx <= pr; ++dx) {
          const int x = hc % nx + dx, y = hc / nx + dy;
          if (x < 0 || y < 0 || x >= nx || y >= ny) continue;
          const int c = y * nx + x;
          const size_t cc = static_cast<size_t>(c);
          if (s.observed_[cc] && std::abs(s.height_[cc] - hit_median) <= o.kerb_height) patch_cells.push_back(c);
        }
    }
    std::sort(patch_cells.begin(), patch_cells.end());
    patch_cells.erase(std::unique(patch_cells.begin(), patch_cells.end()), patch_cells.end());
    std::vector<Eigen::Vector3d> patch;
    Eigen::Vector2d mean = Eigen::Vector2d::Zero();
    for (int c : patch_cells) {
      const Eigen::Vector2d xy = s.CellCentre(c % nx, c / nx);
      patch.emplace_back(xy.x(), xy.y(), s.height_[static_cast<size_t>(c)]);
      mean += xy;
    }
    if (!patch.empty()) mean /= static_cast<double>(patch.size());
    std::optional<Eigen::Vector3d> plane;
    if (patch.size() >= 6) {
      Eigen::Matrix2d cov = Eigen::Matrix2d::Zero();
      for (const auto& p : patch) cov += (p.head<2>() - mean) * (p.head<2>() - mean).transpose();
      cov /= static_cast<double>(patch.size());
      const double thinnest = Eigen::SelfAdjointEigenSolver<Eigen::Matrix2d>(cov).eigenvalues().minCoeff();
      if (thinnest > 0.3 * 0.3) plane = FitHeightPlane(patch);
      if (plane && plane->head<2>().norm() > 0.3) plane.reset();  // steeper than any road: not trusted
    }
    for (int c : cells) {
      const Eigen::Vector2d xy = s.CellCentre(c % nx, c / nx);
      near_side[static_cast<size_t>(c)] = static_cast<float>(
          plane ? plane->x() * xy.x() + plane->y() * xy.y() + plane->z()
                : hit_median + g.dot(xy - (patch.empty() ? hits.front().head<2>() : mean)));
      target[static_cast<size_t>(c)] = std::max<uint8_t>(target[static_cast<size_t>(c)], 1);
    }
  };
  for (const SweepInWorld& sw : sweeps) {
    for (const Box3& box : sw.objects) mark_footprint(box, o.box_margin, sw.sensor_origin.head<2>());
    const int cx = s.CellIndex(sw.sensor_origin.head<2>());
    const int r = static_cast<int>(std::ceil(o.ego_fill_radius / o.cell));
    if (cx < 0) continue;
    for (int y = std::max(0, cx / nx - r); y <= std::min(ny - 1, cx / nx + r); ++y)
      for (int x = std::max(0, cx % nx - r); x <= std::min(nx - 1, cx % nx + r); ++x) {
        const int c = y * nx + x;
        if ((s.CellCentre(x, y) - sw.sensor_origin.head<2>()).norm() <= o.ego_fill_radius && !s.observed_[c] &&
            dist[c] <= o.object_fill_distance)
          target[c] = 1;
      }
  }
  {
    const int reach = static_cast<int>(std::floor(o.max_fill_distance / o.cell));
    constexpr double kGradeTolerance = 0.02;  // local grade and camber changes the seed plane does not follow
    const int dirs[4][2] = {{1, 0}, {0, 1}, {1, 1}, {1, -1}};
    ParallelRows(0, ny, [&](int y) {
      for (int x = 0; x < nx; ++x) {
        const int c = y * nx + x;
        if (s.observed_[c] || target[c] || dist[c] > o.max_fill_distance) continue;
        int enclosed = 0;
        bool step = false;
        for (const auto& d : dirs) {
          int ends[2] = {-1, -1};
          for (int side = 0; side < 2; ++side) {
            const int sign = side == 0 ? 1 : -1;
            for (int k = 1; k <= reach && ends[side] < 0; ++k) {
              const int xx = x + sign * k * d[0], yy2 = y + sign * k * d[1];
              if (xx < 0 || yy2 < 0 || xx >= nx || yy2 >= ny) break;
              if (o.cell * k * std::hypot(d[0], d[1]) > o.max_fill_distance) break;
              if (s.observed_[yy2 * nx + xx]) ends[side] = yy2 * nx + xx;
            }
          }
          if (ends[0] < 0 || ends[1] < 0) continue;
          ++enclosed;
          // A gap whose two sides differ by more than the road grade explains hides a kerb.
          const Eigen::Vector2d p0 = s.CellCentre(ends[0] % nx, ends[0] / nx), p1 = s.CellCentre(ends[1] % nx, ends[1] / nx);
          const double dh = s.height_[ends[0]] - s.height_[ends[1]] - grade_at(p1).dot(p0 - p1);
          step = step || std::abs(dh) > o.kerb_height + kGradeTolerance * (p0 - p1).norm();
        }
        if (enclosed >= 1) target[c] = 2;
        gap_step[c] = step;
      }
    });
  }
  {
    // Initial values: the nearest observed (or object-footprint) height (BFS), then SOR Gauss-Seidel on the
    // Laplace equation over the membrane targets; non-target unobserved neighbours are left out (a free
    // boundary), observed and object-footprint cells stay fixed.
    std::deque<int> bfs;
    for (size_t c = 0; c < ncell; ++c)
      if (s.observed_[c]) bfs.push_back(static_cast<int>(c));
    std::vector<float> init(s.height_);
    while (!bfs.empty()) {
      const int a = bfs.front();
      bfs.pop_front();
      const int ax = a % nx, ay = a / nx;
      const int nb[4][2] = {{1, 0}, {-1, 0}, {0, 1}, {0, -1}};
      for (const auto& d : nb) {
        const int x = ax + d[0], y = ay + d[1];
        if (x < 0 || y < 0 || x >= nx || y >= ny) continue;
        const int b = y * nx + x;
        if (!target[b] || !std::isnan(init[b])) continue;
        init[b] = init[a];
        bfs.push_back(b);
      }
    }
    std::vector<int> cells;
    for (size_t c = 0; c < ncell; ++c)
      if (target[c]) {
        if (std::isnan(init[c]) && !std::isnan(near_side[c])) init[c] = near_side[c];
        if (std::isnan(init[c])) {
          target[c] = 0;  // a target island touching no observed ground through targets
          continue;
        }
        s.height_[c] = init[c];
        cells.push_back(static_cast<int>(c));
      }
    const double omega = 1.8;
    constexpr float kForeignSurface = 0.25f;  // metres: more than a kerb, less than a lawn bank or wall base
    for (int it = 0; it < o.fill_iterations; ++it) {
      double change = 0;
      for (int c : cells) {
        const int x = c % nx, y = c / nx;
        double sum = 0;
        int n = 0;
        const int nb[4][2] = {{1, 0}, {-1, 0}, {0, 1}, {0, -1}};
        for (const auto& d : nb) {
          const int xx = x + d[0], yy = y + d[1];
          if (xx < 0 || yy < 0 || xx >= nx || yy >= ny) continue;
          const int b = yy * nx + xx;
          if (std::isnan(s.height_[b])) continue;
          sum += s.height_[b];
          ++n;
        }
        if (n == 0) continue;
        const double updated = s.height_[c] + omega * (sum / n - s.height_[c]);
        change = std::max(change, std::abs(updated - s.height_[c]));
        s.height_[c] = static_cast<float>(updated);
      }
      if (change < 1e-5) break;
    }
    // Where the membrane and the road in front of an object disagree grossly, the membrane came from another
    // surface: the road in front wins.
    for (int c : cells) {
      const size_t cc = static_cast<size_t>(c);
      if (!std::isnan(near_side[cc]) && std::abs(s.height_[cc] - near_side[cc]) > kForeignSurface) s.height_[cc] = near_side[cc];
    }
    s.stats_.filled_cells = cells.size();
  }
  progress.Advance();

  // 7. Normals from the 3x3 least-squares plane (central differences where it is sparse), and
  // 8. kerb cells: the 3x3 heights depart from that plane by more than kerb_height / 3.
  s.normal_.assign(ncell, Eigen::Vector3f::UnitZ());
  std::vector<uint8_t> kerb(ncell, 0);
  auto valid = [&](int x, int y) { return x >= 0 && y >= 0 && x < nx && y < ny && !std::isnan(s.height_[y * nx + x]); };
  auto h = [&](int x, int y) { return static_cast<double>(s.height_[y * nx + x]); };
  ParallelRows(0, ny, [&](int y) {
    std::vector<Eigen::Vector3d> window;
    for (int x = 0; x < nx; ++x) {
      if (!valid(x, y)) continue;
      const size_t c = static_cast<size_t>(y * nx + x);
      window.clear();
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx)
          if (valid(x + dx, y + dy)) window.emplace_back(dx, dy, h(x + dx, y + dy));
      const auto plane = window.size() >= 5 ? FitHeightPlane(window) : std::nullopt;
      if (plane) {
        s.normal_[c] = Eigen::Vector3d(-plane->x() / o.cell, -plane->y() / o.cell, 1).normalized().cast<float>();
        double worst = 0;
        for (const auto& p : window)
          worst = std::max(worst, std::abs(p.z() - (plane->x() * p.x() + plane->y() * p.y() + plane->z())));
        kerb[c] = worst > o.kerb_height / 3;
        continue;
      }
      auto slope = [&](int dx, int dy) {
        const bool fwd = valid(x + dx, y + dy), back = valid(x - dx, y - dy);
        if (fwd && back) return (h(x + dx, y + dy) - h(x - dx, y - dy)) / (2 * o.cell);
        if (fwd) return (h(x + dx, y + dy) - h(x, y)) / o.cell;
        if (back) return (h(x, y) - h(x - dx, y - dy)) / o.cell;
        return 0.0;
      };
      s.normal_[c] = Eigen::Vector3d(-slope(1, 0), -slope(0, 1), 1).normalized().cast<float>();
    }
  });
  progress.Advance();

  // Drivable: the region reachable from the ego trajectory without entering a kerb cell.
  s.drivable_.assign(ncell, 0);
  {
    std::deque<int> bfs;
    for (const SweepInWorld& sw : sweeps) {
      const int c = s.CellIndex(sw.sensor_origin.head<2>());
      if (c >= 0 && !std::isnan(s.height_[c]) && !kerb[c] && !gap_step[c] && !s.drivable_[c]) {
        s.drivable_[c] = 1;
        bfs.push_back(c);
      }
    }
    while (!bfs.empty()) {
      const int a = bfs.front();
      bfs.pop_front();
      const int ax = a % nx, ay = a / nx;
      const int nb[4][2] = {{1, 0}, {-1, 0}, {0, 1}, {0, -1}};
      for (const auto& d : nb) {
        const int x = ax + d[0], y = ay + d[1];
        if (!valid(x, y)) continue;
        const int b = y * nx + x;
        if (s.drivable_[b] || kerb[b] || gap_step[b] || std::abs(s.height_[b] - s.height_[a]) > o.kerb_height) continue;
        s.drivable_[b] = 1;
        bfs.push_back(b);
      }
    }
  }
  for (size_t c = 0; c < ncell; ++c) {
    s.stats_.observed_cells += s.observed_[c];
    s.stats_.drivable_cells += s.drivable_[c];
  }
  progress.Advance();

  // Residual of the ground points to the interpolated surface.
  {
    std::vector<float> res;
    res.reserve(s.stats_.ground_points);
    for (size_t k = 0; k < sweeps.size(); ++k)
      for (int i : s.ground_indices_[k]) {
        const Eigen::Vector3d& p = sweeps[k].points[static_cast<size_t>(i)];
        if (const auto sp = s.At(p.head<2>())) res.push_back(static_cast<float>(std::abs(p.z() - sp->height)));
      }
    if (!res.empty()) s.stats_.median_abs_residual = Median(res);
  }
  progress.Advance();
  SD_LOG(Info, "road surface: " << s.stats_.observed_cells << " observed cells, " << s.stats_.filled_cells
                                << " filled, " << s.stats_.drivable_cells << " drivable; median ground residual "
                                << s.stats_.median_abs_residual * 100 << " cm");
  return s;
}

std::optional<SurfacePoint> RoadSurface::At(const Eigen::Vector2d& xy) const {
  const int c = CellIndex(xy);
  if (c < 0 || std::isnan(height_[static_cast<size_t>(c)])) return std::nullopt;
  SurfacePoint sp;
  sp.normal = normal_[static_cast<size_t>(c)].cast<double>();
  sp.observed = observed_[static_cast<size_t>(c)] != 0;
  sp.height = height_[static_cast<size_t>(c)];
  // Bilinear between the four cell centres around xy when all are on the surface.
  const double fx = (xy.x() - origin_.x()) / options_.cell - 0.5, fy = (xy.y() - origin_.y()) / options_.cell - 0.5;
  const int x0 = static_cast<int>(std::floor(fx)), y0 = static_cast<int>(std::floor(fy));
  if (x0 >= 0 && y0 >= 0 && x0 + 1 < nx_ && y0 + 1 < ny_) {
    const size_t c00 = static_cast<size_t>(y0 * nx_ + x0), c01 = c00 + static_cast<size_t>(nx_);
    const float h00 = height_[c00], h10 = height_[c00 + 1], h01 = height_[c01], h11 = height_[c01 + 1];
    if (!std::isnan(h00) && !std::isnan(h10) && !std::isnan(h01) && !std::isnan(h11)) {
      const double u = fx - x0, v = fy - y0;
      sp.height = (1 - v) * ((1 - u) * h00 + u * h10) + v * ((1 - u) * h01 + u * h11);
    }
  }
  return sp;
}

bool RoadSurface::IsDrivable(const Eigen::Vector2d& xy) const {
  const int c = CellIndex(xy);
  return c >= 0 && drivable_[static_cast<size_t>(c)] != 0;
}

Eigen::Affine2d RoadSurface::Sim2ToAffine(double scale, const Eigen::Matrix2d& R, const Eigen::Vector2d& t) {
  Eigen::Affine2d T = Eigen::Affine2d::Identity();
  T.linear() = scale * R;
  T.translation() = scale * t;
  return T;
}

size_t RoadSurface::IntersectDrivableRaster(const std::vector<uint8_t>& raster, int width, int height,
                                            const Eigen::Affine2d& T_pixel_world) {
  SD_CHECK(raster.size() == static_cast<size_t>(width) * static_cast<size_t>(height), << "raster size mismatch");
  size_t removed = 0;
  for (int y = 0; y < ny_; ++y)
    for (int x = 0; x < nx_; ++x) {
      const size_t c = static_cast<size_t>(y * nx_ + x);
      if (!drivable_[c]) continue;
      const Eigen::Vector2d p = T_pixel_world * CellCentre(x, y);
      const long col = std::lround(std::floor(p.x())), row = std::lround(std::floor(p.y()));
      const bool ok = col >= 0 && row >= 0 && col < width && row < height &&
                      raster[static_cast<size_t>(row) * static_cast<size_t>(width) + static_cast<size_t>(col)] != 0;
      if (!ok) {
        drivable_[c] = 0;
        ++removed;
      }
    }
  stats_.drivable_cells -= removed;
  return removed;
}

std::vector<SweepInWorld> SweepsFromLog(const Log& log, size_t first, size_t last, const SweepsFromLogOptions& options) {
  last = std::min(last, log.frames.size());
  std::vector<SweepInWorld> out;
  Progress progress("reading sweeps", last > first ? last - first : 0);
  for (size_t i = first; i < last; ++i) {
    const Frame& f = log.frames[i];
    progress.Advance();
    if (!f.lidar) continue;
    const PointCloud pc = ReadLidar(*f.lidar);
    const Rigid3d T_world_lidar = f.T_world_ego * f.lidar->T_ego_lidar;
    SweepInWorld sw;
    sw.sensor_origin = T_world_lidar.translation;
    sw.points.reserve(pc.size());
    for (size_t k = 0; k < pc.size(); ++k) {
      const Eigen::Vector3d p = pc.xyz(k).cast<double>();
      if (p.head<2>().norm() > options.max_range) continue;
      sw.points.push_back(T_world_lidar * p);
    }
    for (const Annotation& a : f.annotations) sw.objects.push_back(a.box.Transformed(f.T_world_ego));
    out.push_back(std::move(sw));
  }
  return out;
}

}  // namespace sd
