#include "synth/placement.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <unordered_map>

#include "core/error.h"
#include "core/log.h"

namespace sd {
namespace {

// Hash grid over the above-ground LiDAR points for footprint queries.
class ObstacleGrid {
 public:
  ObstacleGrid(const std::vector<Eigen::Vector3d>& points, const GroundModel& ground, double cell) : cell_(cell) {
    for (const auto& p : points) {
      const double h = ground.HeightAboveGround(p);
      if (h < 0.25 || h > 3.0) continue;  // ground and overhanging branches/signs are not obstacles
      cells_[Key(p.x(), p.y())].push_back(p);
    }
  }
  int CountInside(const Box3& footprint, double margin) const {
    int n = 0;
    const double r = 0.5 * footprint.size.head<2>().norm() + margin;
    const int span = static_cast<int>(std::ceil(r / cell_));
    const auto& c = footprint.center();
    const int64_t cx = static_cast<int64_t>(std::floor(c.x() / cell_)), cy = static_cast<int64_t>(std::floor(c.y() / cell_));
    const Rigid3d T_box_ego = footprint.T_frame_box.Inverse();
    for (int64_t dy = -span; dy <= span; ++dy)
      for (int64_t dx = -span; dx <= span; ++dx) {
        auto it = cells_.find(Pack(cx + dx, cy + dy));
        if (it == cells_.end()) continue;
        for (const auto& p : it->second) {
          const Eigen::Vector3d local = T_box_ego * p;
          if (std::abs(local.x()) <= 0.5 * footprint.size.x() + margin && std::abs(local.y()) <= 0.5 * footprint.size.y() + margin) ++n;
        }
      }
    return n;
  }

 private:
  static int64_t Pack(int64_t x, int64_t y) { return (x << 32) ^ (y & 0xffffffff); }
  int64_t Key(double x, double y) const {
    return Pack(static_cast<int64_t>(std::floor(x / cell_)), static_cast<int64_t>(std::floor(y / cell_)));
  }
  double cell_;
  std::unordered_map<int64_t, std::vector<Eigen::Vector3d>> cells_;
};

bool SeenByACamera(const Eigen::Vector3d& p_ego, const std::vector<const CameraSensor*>& cameras) {
  for (const CameraSensor* cam : cameras) {
    const auto uv = cam->intrinsics.Project(cam->T_ego_cam.Inverse() * p_ego, 1.0);
    if (uv && cam->intrinsics.InImage(*uv)) return true;
  }
  return cameras.empty();
}

std::vector<const Asset*> CandidatesFor(const ObjectRequest& req, const std::vector<Asset>& assets) {
  std::vector<const Asset*> out;
  for (const auto& a : assets)
    if ((!req.asset_id.empty() && a.info.id == req.asset_id) || (!req.category.empty() && a.info.category == req.category))
      out.push_back(&a);
  return out;
}

}  // namespace

std::string PlacementStats::Summary() const {
  return Msg() << candidates << " candidates tried: " << off_road << " off the drivable area, " << blocked_by_points
               << " blocked by unlabelled LiDAR points, " << overlaps_real << " overlapping annotated objects, "
               << overlaps_placed << " overlapping inserted objects, " << not_visible << " not seen by any camera";
}

std::vector<PlacedObject> PlaceObjects(const Scenario& scenario, const std::vector<Asset>& assets,
                                       const PlacementInput& input, PlacementStats* stats_out) {
  SD_CHECK(input.ground != nullptr);
  const GroundModel& ground = *input.ground;
  const ObstacleGrid obstacles(input.points_ego, ground, 1.0);
  std::mt19937 rng(scenario.seed);
  std::uniform_real_distribution<double> unit(0.0, 1.0);
  PlacementStats stats;
  std::vector<PlacedObject> placed;

  for (size_t ri = 0; ri < scenario.objects.size(); ++ri) {
    const ObjectRequest& req = scenario.objects[ri];
    const auto pool = CandidatesFor(req, assets);
    if (pool.empty())
      throw InputError("", "scenario object " + std::to_string(ri) + " asks for " +
                               (req.asset_id.empty() ? "category '" + req.category + "'" : "asset '" + req.asset_id + "'") +
                               " but no --asset provides it");
    for (int k = 0; k < req.count; ++k) {
      const Asset* asset = pool[static_cast<size_t>(unit(rng) * pool.size()) % pool.size()];
      const Eigen::Vector3d extent = asset->info.extent;
      bool done = false;
      PlacementStats local;
      for (int attempt = 0; attempt < input.max_candidates_per_object && !done; ++attempt) {
        ++local.candidates;
        const double x = req.distance_min + unit(rng) * (req.distance_max - req.distance_min);
        const double y = req.lateral_min + unit(rng) * (req.lateral_max - req.lateral_min);
        double yaw = 0;
        switch (req.yaw_mode) {
          case ObjectRequest::Yaw::kAligned: yaw = (unit(rng) - 0.5) * (20.0 * M_PI / 180.0); break;
          case ObjectRequest::Yaw::kRandom: yaw = (unit(rng) * 2 - 1) * M_PI; break;
          case ObjectRequest::Yaw::kFixed: yaw = req.yaw_deg * M_PI / 180.0; break;
        }
        const GroundModel::Surface surface = ground.SurfaceAt(x, y, 0.5 * extent.head<2>().norm() + 0.5);
        // Up axis along the local ground normal, heading `yaw` projected into the tilted plane.
        const Eigen::Vector3d up = surface.normal;
        Eigen::Vector3d fwd(std::cos(yaw), std::sin(yaw), 0);
        fwd = (fwd - fwd.dot(up) * up).normalized();
        Eigen::Matrix3d R;
        R.col(0) = fwd;
        R.col(1) = up.cross(fwd);
        R.col(2) = up;
        const Rigid3d T_ego_asset(R, Eigen::Vector3d(x, y, surface.height));
        // The asset origin is the centre of its ground contact, so the box centre is half its height up.
        const Box3 box{Rigid3d(R, T_ego_asset * Eigen::Vector3d(0, 0, 0.5 * extent.z())), extent};

        if (ground.DrivableFraction(box) < 0.9) { ++local.off_road; continue; }
        if (obstacles.CountInside(box, scenario.margin_m) > 2) { ++local.blocked_by_points; continue; }
        bool hit = false;
        for (const auto& rb : input.real_boxes)
          if (BoxesOverlap(box, rb, scenario.margin_m)) { hit = true; break; }
        if (hit) { ++local.overlaps_real; continue; }
        for (const auto& p : placed)
          if (BoxesOverlap(box, p.box, scenario.margin_m)) { hit = true; break; }
        if (hit) { ++local.overlaps_placed; continue; }
        if (!SeenByACamera(box.center(), input.cameras)) { ++local.not_visible; continue; }

        placed.push_back(PlacedObject{asset, static_cast<int>(ri), T_ego_asset, box, surface.height});
        done = true;
      }
      stats.candidates += local.candidates;
      stats.off_road += local.off_road;
      stats.blocked_by_points += local.blocked_by_points;
      stats.overlaps_real += local.overlaps_real;
      stats.overlaps_placed += local.overlaps_placed;
      stats.not_visible += local.not_visible;
      if (!done)
        throw InputError("", Msg() << "impossible scenario: no free space for object " << ri << " #" << k + 1 << " ("
                                   << asset->info.id << ", " << extent.x() << "x" << extent.y() << " m) at "
                                   << req.distance_min << ".." << req.distance_max << " m ahead, " << req.lateral_min
                                   << ".." << req.lateral_max << " m lateral: " << local.Summary());
      SD_LOG(Debug, "placed " << asset->info.id << " at " << placed.back().box.center().transpose());
    }
  }
  if (stats_out) *stats_out = stats;
  return placed;
}

}  // namespace sd
