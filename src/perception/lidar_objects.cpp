#include "perception/lidar_objects.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <numeric>

#include "core/error.h"
#include "core/stats.h"
#include "core/union_find.h"

namespace sd::perception {
namespace {

// A vehicle seen from one side or one end: the LiDAR saw the faces nearest the sensor, the rest of the car lies
// behind them. The box grows to at least `min_vehicle_size` away from the sensor, the seen faces staying where
// they are. Which way the car's length runs is unknown when the seen side is short: a side shorter than 3 m is
// taken for the car's end (its length then runs away from the sensor), a longer one for its flank.
void CompleteVehicle(const DetectOptions& o, Box3* box) {
  const double min_length = o.min_vehicle_size.x(), min_width = o.min_vehicle_size.y();
  if (min_length <= 0 || min_width <= 0) return;
  const bool flank = box->size.x() >= 3.0;
  Eigen::Vector2d want = flank ? Eigen::Vector2d(min_length, min_width) : Eigen::Vector2d(min_width, min_length);
  const Eigen::Matrix3d R = box->T_frame_box.Rotation();
  Eigen::Vector3d c = box->center();
  for (int k = 0; k < 2; ++k) {
    const double grow = want[k] - box->size[k];
    if (grow <= 0) continue;
    Eigen::Vector3d axis = R.col(k);
    axis.z() = 0;
    axis.normalize();
    const double away = (c.head<2>() - o.sensor_xy).dot(axis.head<2>()) >= 0 ? 1.0 : -1.0;
    c += 0.5 * grow * away * axis;
    box->size[k] = want[k];
  }
  box->T_frame_box.translation = c;
  if (box->size.y() > box->size.x()) {  // keep length >= width: turn the box by 90 degrees
    std::swap(box->size.x(), box->size.y());
    double yaw = box->Yaw() + M_PI / 2;
    if (yaw >= M_PI) yaw -= M_PI;
    box->T_frame_box = Rigid3d::FromYaw(yaw, c);
  }
  if (box->Yaw() < 0) box->T_frame_box = Rigid3d::FromYaw(box->Yaw() + M_PI, c);
}

}  // namespace

const char* ToString(ObjectClass c) {
  switch (c) {
    case ObjectClass::kVehicle: return "vehicle";
    case ObjectClass::kPedestrian: return "pedestrian";
    case ObjectClass::kSmallObject: return "small_object";
    case ObjectClass::kOther: return "other";
  }
  return "other";
}

std::vector<int> ObstaclePoints(const std::vector<Eigen::Vector3d>& points_ego,
                                const std::vector<float>& height_above_ground, const DetectOptions& o) {
  SD_CHECK(points_ego.size() == height_above_ground.size(),
           << points_ego.size() << " points but " << height_above_ground.size() << " heights");
  const Eigen::Vector2d body_min = o.ego_body_min.array() - o.ego_margin, body_max = o.ego_body_max.array() + o.ego_margin;
  std::vector<int> out;
  for (size_t i = 0; i < points_ego.size(); ++i) {
    const Eigen::Vector3d& p = points_ego[i];
    const float h = height_above_ground[i];
    if (!p.allFinite() || !std::isfinite(h) || h < o.min_height || h > o.max_height) continue;
    const double r = (p.head<2>() - o.sensor_xy).norm();
    if (r < o.min_range || r > o.max_range) continue;
    if (p.x() >= body_min.x() && p.x() <= body_max.x() && p.y() >= body_min.y() && p.y() <= body_max.y()) continue;
    out.push_back(static_cast<int>(i));
  }
  return out;
}

std::vector<std::vector<int>> ClusterBev(const std::vector<Eigen::Vector3d>& points, double cell, double cluster_distance) {
  SD_CHECK(cell > 0 && cluster_distance >= cell, << "cell " << cell << ", cluster distance " << cluster_distance);
  if (points.empty()) return {};
  Eigen::Vector2d lo = points[0].head<2>(), hi = lo;
  for (const auto& p : points) lo = lo.cwiseMin(p.head<2>()), hi = hi.cwiseMax(p.head<2>());
  const int nx = static_cast<int>(std::floor((hi.x() - lo.x()) / cell)) + 1;
  const int ny = static_cast<int>(std::floor((hi.y() - lo.y()) / cell)) + 1;
  SD_CHECK(static_cast<double>(nx) * ny < 4e8, << "cluster grid " << nx << " x " << ny << " (points spread too far)");
  // Occupied cells, densely indexed.
  std::vector<int> cell_of(points.size());
  std::vector<int> occupied(static_cast<size_t>(nx) * ny, -1);
  std::vector<int> cells;  // grid index of each occupied cell
  for (size_t i = 0; i < points.size(); ++i) {
    const int ix = std::min(nx - 1, static_cast<int>((points[i].x() - lo.x()) / cell));
    const int iy = std::min(ny - 1, static_cast<int>((points[i].y() - lo.y()) / cell));
    const size_t g = static_cast<size_t>(iy) * nx + ix;
    if (occupied[g] < 0) {
      occupied[g] = static_cast<int>(cells.size());
      cells.push_back(static_cast<int>(g));
    }
    cell_of[i] = occupied[g];
  }
  // Cells join when their centres lie within cluster_distance: a fixed stencil of offsets.
  const int span = static_cast<int>(std::floor(cluster_distance / cell));
  std::vector<std::pair<int, int>> stencil;
  for (int dy = 0; dy <= span; ++dy)
    for (int dx = -span; dx <= span; ++dx) {
      if (dy == 0 && dx <= 0) continue;  // each unordered pair once
      if (std::hypot(dx, dy) * cell <= cluster_distance + 1e-9) stencil.emplace_back(dx, dy);
    }
  // Sorted by grid index, so the scan order (and every tie) is fixed.
  std::vector<int> order(cells.size());
  std::iota(order.begin(), order.end(), 0);
  std::sort(order.begin(), order.end(), [&](int a, int b) { return cells[a] < cells[b]; });
  std::vector<int> rank(cells.size());
  for (size_t k = 0; k < order.size(); ++k) rank[order[k]] = static_cast<int>(k);
  UnionFind uf(cells.size());
  for (int c : order) {
    const int ix = cells[c] % nx, iy = cells[c] / nx;
    for (const auto& [dx, dy] : stencil) {
      const int x = ix + dx, y = iy + dy;
      if (x < 0 || x >= nx || y >= ny) continue;
      const int other = occupied[static_cast<size_t>(y) * nx + x];
      if (other >= 0) uf.Unite(rank[c], rank[other]);
    }
  }
  // Components numbered by their root (= their lowest-ranked cell), points in input order.
  std::vector<int> label(cells.size(), -1);
  std::vector<std::vector<int>> clusters;
  for (size_t k = 0; k < order.size(); ++k) {
    const int root = uf.Find(static_cast<int>(k));
    if (label[root] < 0) {
      label[root] = static_cast<int>(clusters.size());
      clusters.emplace_back();
    }
  }
  for (size_t i = 0; i < points.size(); ++i) clusters[label[uf.Find(rank[cell_of[i]])]].push_back(static_cast<int>(i));
  return clusters;
}

std::vector<std::vector<int>> SplitCompactObjects(const std::vector<Eigen::Vector3d>& points,
                                                  const std::vector<float>& height_above_ground,
                                                  const std::vector<int>& cluster, const DetectOptions& o) {
  SD_CHECK(points.size() == height_above_ground.size(), << points.size() << " points but " << height_above_ground.size() << " heights");
  if (o.split_max_extent <= 0 || cluster.empty()) return {cluster};
  // The cluster's cells on a grid anchored at the ego origin, sorted: the cells, their tops and every scan below
  // are the same whatever the order of the returns.
  using Cell = std::pair<int, int>;
  const auto cell_of = [&](const Eigen::Vector3d& p) {
    return Cell(static_cast<int>(std::floor(p.x() / o.cell)), static_cast<int>(std::floor(p.y() / o.cell)));
  };
  std::vector<std::pair<Cell, int>> keyed;  // (cell, position in cluster), sorted
  keyed.reserve(cluster.size());
  for (size_t k = 0; k < cluster.size(); ++k) keyed.emplace_back(cell_of(points[cluster[k]]), static_cast<int>(k));
  std::sort(keyed.begin(), keyed.end());
  std::vector<Cell> cells;
  std::vector<size_t> first;  // cell c holds keyed[first[c], first[c + 1])
  std::vector<double> top, bottom;
  for (size_t k = 0; k < keyed.size(); ++k) {
    if (cells.empty() || cells.back() != keyed[k].first) {
      cells.push_back(keyed[k].first), first.push_back(k), top.push_back(-1e300), bottom.push_back(1e300);
    }
    const double h = height_above_ground[cluster[keyed[k].second]];
    top.back() = std::max(top.back(), h), bottom.back() = std::min(bottom.back(), h);
  }
  first.push_back(keyed.size());
  const size_t n = cells.size();
  // A dense index over the cells' bounding box (a cluster is at most max_extent long): constant-time lookups.
  int x0 = cells[0].first, x1 = x0, y0 = cells[0].second, y1 = y0;
  for (const Cell& c : cells) x0 = std::min(x0, c.first), x1 = std::max(x1, c.first), y0 = std::min(y0, c.second), y1 = std::max(y1, c.second);
  const int nx = x1 - x0 + 1, ny = y1 - y0 + 1;
  SD_CHECK(static_cast<double>(nx) * ny < 4e8, << "split grid " << nx << " x " << ny << " (cluster spread too far)");
  std::vector<int> index(static_cast<size_t>(nx) * ny, -1);
  for (size_t c = 0; c < n; ++c) index[static_cast<size_t>(cells[c].second - y0) * nx + (cells[c].first - x0)] = static_cast<int>(c);
  const auto find = [&](const Cell& c) {
    const int x = c.first - x0, y = c.second - y0;
    return x < 0 || y < 0 || x >= nx || y >= ny ? -1 : index[static_cast<size_t>(y) * nx + x];
  };
  std::vector<char> taller(n);
  for (size_t c = 0; c < n; ++c) taller[c] = top[c] > o.split_max_top;
  if (std::find(taller.begin(), taller.end(), 1) == taller.end()) return {cluster};  // nothing to stand against
  // Offsets to the cells whose centres lie within `dist` metres.
  const auto disc = [&](double dist) {
    std::vector<std::pair<int, int>> offsets;
    const int span = static_cast<int>(std::floor(dist / o.cell + 1e-9));
    for (int dx = -span; dx <= span; ++dx)
      for (int dy = -span; dy <= span; ++dy)
        if ((dx != 0 || dy != 0) && std::hypot(dx, dy) * o.cell <= dist + 1e-9) offsets.emplace_back(dx, dy);
    return offsets;
  };
  // Each low cell's distance to the nearest taller cell (centre to centre; capped just beyond the clearance
  // asked for). A cell touching a taller one (side or corner) stays with it: the taller object's own low edge
  // (a roller's step, the trunk lid under a rear window) as often as the side of a cone that touches it.
  const double reach = o.split_min_clearance + o.cell;
  const auto around = disc(reach);
  std::vector<double> clearance(n, 0);
  std::vector<char> candidate(n);
  for (size_t c = 0; c < n; ++c) {
    if (taller[c]) continue;
    clearance[c] = reach;
    for (const auto& [dx, dy] : around) {
      const int m = find(Cell(cells[c].first + dx, cells[c].second + dy));
      if (m >= 0 && taller[m]) clearance[c] = std::min(clearance[c], std::hypot(dx, dy) * o.cell);
    }
    candidate[c] = clearance[c] > 1.5 * o.cell;
  }
  // Components of candidate cells touching by side or corner, numbered by their lowest cell. Not the cluster
  // distance: it would join a cone to the hood of a car parked beside it.
  UnionFind uf(n);
  for (size_t c = 0; c < n; ++c) {
    if (!candidate[c]) continue;
    for (const auto& [dx, dy] : {std::pair{0, 1}, std::pair{1, -1}, std::pair{1, 0}, std::pair{1, 1}}) {
      const int m = find(Cell(cells[c].first + dx, cells[c].second + dy));
      if (m >= 0 && candidate[m]) uf.Unite(static_cast<int>(c), m);
    }
  }
  std::vector<int> label(n, -1);
  std::vector<std::vector<int>> components;
  for (size_t c = 0; c < n; ++c) {
    if (!candidate[c]) continue;
    const int root = uf.Find(static_cast<int>(c));
    if (label[root] < 0) label[root] = static_cast<int>(components.size()), components.emplace_back();
    components[label[root]].push_back(static_cast<int>(c));
  }
  Eigen::Vector2d lo = points[cluster[0]].head<2>(), hi = lo;  // the cluster's extent
  for (int i : cluster) lo = lo.cwiseMin(points[i].head<2>()), hi = hi.cwiseMax(points[i].head<2>());
  std::vector<int> object_of_cell(n, 0);
  int objects = 0;
  for (const std::vector<int>& comp : components) {
    int returns = 0;
    double comp_top = -1e300, comp_bottom = 1e300, farthest = 0;
    std::vector<Eigen::Vector2d> xy;
    for (int c : comp) {
      returns += static_cast<int>(first[c + 1] - first[c]);
      comp_top = std::max(comp_top, top[c]), comp_bottom = std::min(comp_bottom, bottom[c]);
      farthest = std::max(farthest, clearance[c]);
      for (size_t k = first[c]; k < first[c + 1]; ++k) xy.push_back(points[cluster[keyed[k].second]].head<2>());
    }
    if (returns < o.split_min_points || comp_top < o.split_min_top || comp_top - comp_bottom < o.split_min_span ||
        farthest < o.split_min_clearance - 1e-9)
      continue;
    const Rectangle r = FitLShape(xy, o.heading_step_deg, o.closeness_d0, o.max_fit_points);
    if (r.length > o.split_max_extent) continue;
    std::vector<int> against;  // the taller cells it stands against
    for (int c : comp)
      for (const auto& [dx, dy] : around) {
        const int m = find(Cell(cells[c].first + dx, cells[c].second + dy));
        if (m >= 0 && taller[m]) against.push_back(m);
      }
    std::sort(against.begin(), against.end());
    against.erase(std::unique(against.begin(), against.end()), against.end());
    std::vector<double> against_top;
    for (int m : against) against_top.push_back(top[m]);
    if (against_top.empty() || Median(against_top) < comp_top + o.split_min_rise) continue;
    // The line of sight from it to the sensor, in quarter cells until it leaves the cluster: a taller cell on
    // it means these returns were seen over or through the taller part (a pickup's bed, seats through a car's
    // windows), inside it rather than beside it.
    const Eigen::Vector2d to_sensor = o.sensor_xy - r.center;
    const double range = to_sensor.norm();
    bool behind_taller = false;
    for (double t = 0; t < range && !behind_taller; t += 0.25 * o.cell) {
      const Eigen::Vector2d p = r.center + to_sensor * (t / range);
      if ((p.array() < lo.array() - o.cell).any() || (p.array() > hi.array() + o.cell).any()) break;
      const int m = find(cell_of(Eigen::Vector3d(p.x(), p.y(), 0)));
      behind_taller = m >= 0 && taller[m];
    }
    if (behind_taller) continue;
    ++objects;
    for (int c : comp) object_of_cell[c] = objects;
  }
  if (objects == 0) return {cluster};
  std::vector<int> piece_at(cluster.size());
  for (size_t c = 0; c < n; ++c)
    for (size_t k = first[c]; k < first[c + 1]; ++k) piece_at[keyed[k].second] = object_of_cell[c];
  std::vector<std::vector<int>> out(objects + 1);
  for (size_t k = 0; k < cluster.size(); ++k) out[piece_at[k]].push_back(cluster[k]);
  return out;
}

Rectangle FitLShape(const std::vector<Eigen::Vector2d>& xy_all, double heading_step_deg, double d0, int max_points) {
  SD_CHECK(!xy_all.empty() && heading_step_deg > 0 && heading_step_deg <= 90, << xy_all.size() << " points, step " << heading_step_deg);
  // An even subsample for the score; the rectangle still spans every point.
  std::vector<Eigen::Vector2d> xy;
  const size_t stride = max_points > 0 && xy_all.size() > static_cast<size_t>(max_points)
                            ? (xy_all.size() + max_points - 1) / static_cast<size_t>(max_points) : 1;
  for (size_t i = 0; i < xy_all.size(); i += stride) xy.push_back(xy_all[i]);
  const int steps = std::max(1, static_cast<int>(std::lround(90.0 / heading_step_deg)));
  double best_score = -1, best_theta = 0;
  std::vector<double> c1(xy.size()), c2(xy.size());
  for (int s = 0; s < steps; ++s) {
    const double theta = (M_PI / 2) * s / steps;
    const Eigen::Vector2d e1(std::cos(theta), std::sin(theta)), e2(-std::sin(theta), std::cos(theta));
    double min1 = 1e300, max1 = -1e300, min2 = 1e300, max2 = -1e300;
    for (size_t i = 0; i < xy.size(); ++i) {
      c1[i] = xy[i].dot(e1), c2[i] = xy[i].dot(e2);
      min1 = std::min(min1, c1[i]), max1 = std::max(max1, c1[i]);
      min2 = std::min(min2, c2[i]), max2 = std::max(max2, c2[i]);
    }
    // Closeness (Zhang et al. 2017, Algorithm 4): each point's distance to the nearer edge along each axis;
    // the point belongs to whichever of the two is closer, and close points count most.
    double score = 0;
    for (size_t i = 0; i < xy.size(); ++i) {
      const double d1 = std::min(max1 - c1[i], c1[i] - min1), d2 = std::min(max2 - c2[i], c2[i] - min2);
      score += 1.0 / std::max(std::min(d1, d2), d0);
    }
    if (score > best_score + 1e-9 * std::abs(best_score)) best_score = score, best_theta = theta;
  }
  const Eigen::Vector2d e1(std::cos(best_theta), std::sin(best_theta)), e2(-std::sin(best_theta), std::cos(best_theta));
  double min1 = 1e300, max1 = -1e300, min2 = 1e300, max2 = -1e300;
  for (const auto& p : xy_all) {
    min1 = std::min(min1, p.dot(e1)), max1 = std::max(max1, p.dot(e1));
    min2 = std::min(min2, p.dot(e2)), max2 = std::max(max2, p.dot(e2));
  }
  Rectangle r;
  r.center = 0.5 * (min1 + max1) * e1 + 0.5 * (min2 + max2) * e2;
  r.length = max1 - min1, r.width = max2 - min2, r.heading = best_theta;
  if (r.width > r.length) {  // length along the longer side; heading stays in [0, pi)
    std::swap(r.length, r.width);
    r.heading += M_PI / 2;
  }
  return r;
}

ObjectClass ClassifyBySize(double length, double width, double height) {
  // Thresholds from the canonical sizes (datasets/categories.cpp) with room for partial views: a pedestrian is
  // at most 1.3 m across and 1.2-2.3 m tall; a cone, bollard or tripod under 0.9 m across and 1.2 m tall; a
  // vehicle shows a side wider than a pedestrian (over 1.3 m: a car's end is 1.7-2 m, partly seen) and stands
  // 0.9 m or more.
  if (length <= 1.3 && height >= 1.2 && height <= 2.3) return ObjectClass::kPedestrian;
  // Cones, bollards, tripods, and barrier segments (a piece of a cut run, see DetectObjects): low and either
  // small or thin. A car is 1.4 m tall or more, so even its end-on partial view does not read as one.
  if (height < 1.3 && (length <= 0.9 || (width <= 0.8 && length <= 3.0))) return ObjectClass::kSmallObject;
  if (length > 1.3 && length <= 20.0 && height >= 0.9 && height <= 4.6) return ObjectClass::kVehicle;
  return ObjectClass::kOther;
}

std::vector<DetectedObject> DetectObjects(const std::vector<Eigen::Vector3d>& points_ego,
                                          const std::vector<float>& height_above_ground, const DetectOptions& o) {
  const std::vector<int> obstacle = ObstaclePoints(points_ego, height_above_ground, o);
  std::vector<Eigen::Vector3d> pts;
  std::vector<float> heights;
  pts.reserve(obstacle.size());
  heights.reserve(obstacle.size());
  for (int i : obstacle) pts.push_back(points_ego[i]), heights.push_back(height_above_ground[i]);
  // A set of returns (a cluster or a piece of one): its footprint, its highest z and the road's z under each.
  struct Returns {
    std::vector<Eigen::Vector2d> xy;
    double top = -1e300;
    std::vector<double> ground;
  };
  const auto gather = [&](const std::vector<int>& members) {
    Returns r;
    r.xy.reserve(members.size());
    r.ground.reserve(members.size());
    for (int k : members) {
      r.xy.push_back(pts[k].head<2>());
      r.top = std::max(r.top, pts[k].z());
      r.ground.push_back(pts[k].z() - heights[k]);
    }
    return r;
  };
  std::vector<DetectedObject> out;
  // Steps 3-4 for one cluster, given its returns and its rectangle.
  const auto box_cluster = [&](const std::vector<int>& cluster, const Returns& whole, const Rectangle& r) {
    std::vector<std::vector<int>> pieces = {cluster};
    bool structure = false;
    if (r.length > o.max_extent) {
      // Structure (walls, hedges, buildings, and whatever touches them): no object box, but its returns binned on
      // a grid of `structure_tile` metres (axis-aligned in ego xy) and each bin boxed, as keep-out, so an object
      // parked against a wall is still kept clear of; or nothing when structure_tile is 0.
      if (o.structure_tile <= 0) return;
      structure = true;
      std::map<std::pair<int, int>, std::vector<int>> tiles;  // ordered: deterministic
      for (int idx : cluster)
        tiles[{static_cast<int>(std::floor(pts[idx].x() / o.structure_tile)), static_cast<int>(std::floor(pts[idx].y() / o.structure_tile))}]
            .push_back(idx);
      pieces.clear();
      for (auto& [key, members] : tiles) pieces.push_back(std::move(members));
    }
    // A long, thin, low run (a line of barriers, a fence, a low wall) is cut along its length into pieces of
    // about `run_piece` metres, each boxed alone: one rectangle over a curved or angled run would cover road
    // the run does not, and barriers standing end to end cannot be told apart by distance.
    const double run_height = whole.top - Median(whole.ground);
    if (!structure && r.length > o.run_min_length && r.width < o.run_max_width && run_height < o.run_max_height) {
      const int k = std::max(2, static_cast<int>(std::lround(r.length / o.run_piece)));
      const Eigen::Vector2d axis(std::cos(r.heading), std::sin(r.heading));
      pieces.assign(k, {});
      for (int idx : cluster) {
        const double t = (pts[idx].head<2>() - r.center).dot(axis) / r.length + 0.5;  // 0..1 along the run
        pieces[std::clamp(static_cast<int>(t * k), 0, k - 1)].push_back(idx);
      }
    }
    for (const std::vector<int>& piece : pieces) {
      if (static_cast<int>(piece.size()) < o.min_points) continue;
      const Returns part = gather(piece);
      const Rectangle pr = pieces.size() == 1 && !structure ? r : FitLShape(part.xy, o.heading_step_deg, o.closeness_d0, o.max_fit_points);
      DetectedObject d;
      d.ground_z = Median(part.ground);
      // A single ring on a thin object is a line: give the box a few centimetres so it has a footprint.
      const double length = std::max(pr.length, 0.1), width = std::max(pr.width, 0.1);
      const double height = std::max(part.top - d.ground_z, o.min_height);
      d.box.T_frame_box = Rigid3d::FromYaw(pr.heading, Eigen::Vector3d(pr.center.x(), pr.center.y(), d.ground_z + 0.5 * height));
      d.box.size = Eigen::Vector3d(length, width, height);
      d.object_class = structure ? ObjectClass::kOther : ClassifyBySize(length, width, height);
      d.structure = structure;
      d.num_points = static_cast<int>(piece.size());
      d.seen_center = d.box.center();
      if (d.object_class == ObjectClass::kVehicle) CompleteVehicle(o, &d.box);
      out.push_back(d);
    }
  };
  const auto fit = [&](const Returns& returns) { return FitLShape(returns.xy, o.heading_step_deg, o.closeness_d0, o.max_fit_points); };
  for (const std::vector<int>& cluster : ClusterBev(pts, o.cell, o.cluster_distance)) {
    if (static_cast<int>(cluster.size()) < o.min_points) continue;
    const Returns whole = gather(cluster);
    const Rectangle r = fit(whole);
    // Step 2b, on objects only: structure is tiled whatever stands against it.
    const std::vector<std::vector<int>> parts = r.length > o.max_extent ? std::vector<std::vector<int>>{cluster}
                                                                          : SplitCompactObjects(pts, heights, cluster, o);
    if (parts.size() == 1) {
      box_cluster(cluster, whole, r);
      continue;
    }
    // What is left is clustered again: a cone standing between two vehicles had joined them.
    std::vector<Eigen::Vector3d> rest_pts;
    for (int k : parts[0]) rest_pts.push_back(pts[k]);
    std::vector<std::vector<int>> objects;
    for (const std::vector<int>& sub : ClusterBev(rest_pts, o.cell, o.cluster_distance)) {
      objects.emplace_back();
      for (int k : sub) objects.back().push_back(parts[0][k]);
    }
    objects.insert(objects.end(), parts.begin() + 1, parts.end());
    for (const std::vector<int>& object : objects) {
      if (static_cast<int>(object.size()) < o.min_points) continue;
      const Returns returns = gather(object);
      box_cluster(object, returns, fit(returns));
    }
  }
  std::sort(out.begin(), out.end(), [&](const DetectedObject& a, const DetectedObject& b) {
    const double ra = (a.box.center().head<2>() - o.sensor_xy).norm(), rb = (b.box.center().head<2>() - o.sensor_xy).norm();
    if (ra != rb) return ra < rb;
    if (a.box.center().x() != b.box.center().x()) return a.box.center().x() < b.box.center().x();
    return a.box.center().y() < b.box.center().y();
  });
  return out;
}

}  // namespace sd::perception
