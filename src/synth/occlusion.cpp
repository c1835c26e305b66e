#include "synth/occlusion.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/parallel.h"

namespace sd {

std::vector<ProjectedPoint> ProjectPoints(const std::vector<Eigen::Vector3d>& points_ego, const std::vector<uint8_t>& is_ground,
                                          const PinholeCamera& camera, const Rigid3d& T_cam_ego) {
  std::vector<ProjectedPoint> out;
  for (size_t i = 0; i < points_ego.size(); ++i) {
    const Eigen::Vector3d p = T_cam_ego * points_ego[i];
    const auto uv = camera.Project(p, 0.5);
    if (!uv || !camera.InImage(*uv)) continue;
    out.push_back({static_cast<float>(uv->x()), static_cast<float>(uv->y()), static_cast<float>(p.z()),
                   !is_ground.empty() && is_ground[i] != 0});
  }
  return out;
}

ImageF ComputeVisibility(const std::vector<ProjectedPoint>& points, const ImageF& object_depth, const OcclusionOptions& options) {
  const int W = object_depth.width(), H = object_depth.height();
  ImageF vis(W, H, 1, 1.0f);
  // Bucket points by column for the strip searches; each column sorted by v.
  std::vector<std::vector<const ProjectedPoint*>> columns(W);
  for (const auto& p : points) {
    const int x = std::clamp(static_cast<int>(p.u), 0, W - 1);
    columns[x].push_back(&p);
  }
  for (auto& col : columns) std::sort(col.begin(), col.end(), [](auto* a, auto* b) { return a->v < b->v; });

  ParallelFor(0, static_cast<size_t>(H), [&](size_t yi) {
    const int y = static_cast<int>(yi);
    const float vc = y + 0.5f;
    for (int x = 0; x < W; ++x) {
      const float d = object_depth.at(x, y);
      if (!std::isfinite(d)) continue;
      const float tol = static_cast<float>(std::max(options.tol_abs, options.tol_rel * d));
      // Nearest point above (v <= vc) and below (v > vc) in the strip.
      const ProjectedPoint* above = nullptr;
      const ProjectedPoint* below = nullptr;
      for (int cx = std::max(0, x - options.column_half_width); cx <= std::min(W - 1, x + options.column_half_width); ++cx) {
        const auto& col = columns[cx];
        auto it = std::lower_bound(col.begin(), col.end(), vc, [](const ProjectedPoint* p, float v) { return p->v <= v; });
        if (it != col.end() && (*it)->v - vc <= options.max_gap && (!below || (*it)->v < below->v)) below = *it;
        if (it != col.begin()) {
          const ProjectedPoint* a = *(it - 1);
          if (vc - a->v <= options.max_gap && (!above || a->v > above->v)) above = a;
        }
      }
      auto occludes = [&](const ProjectedPoint* p) { return p && !p->ground && p->depth < d - tol; };
      bool hidden = false;
      if (above && below) {
        hidden = (vc - above->v <= below->v - vc) ? occludes(above) : occludes(below);
        if (occludes(above) && occludes(below)) hidden = true;
      } else if (above || below) {
        const ProjectedPoint* p = above ? above : below;
        hidden = occludes(p) && std::abs(p->v - vc) <= 0.5f * options.max_gap;
      }
      if (hidden) vis.at(x, y) = 0.0f;
    }
  });
  return vis;
}

}  // namespace sd
