#include "render/lidar_cast.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"

namespace sd {

std::vector<LidarReturn> CastLidarRays(const RayScene& scene, const Eigen::Vector3f& origin,
                                       const std::vector<Eigen::Vector3f>& dirs, float max_range) {
  return CastLidarRays(scene, std::vector<Eigen::Vector3f>(dirs.size(), origin), dirs, max_range);
}

std::vector<LidarReturn> CastLidarRays(const RayScene& scene, const std::vector<Eigen::Vector3f>& origins,
                                       const std::vector<Eigen::Vector3f>& dirs, float max_range) {
  SD_CHECK(origins.size() == dirs.size(), << origins.size() << " origins for " << dirs.size() << " directions");
  const std::vector<RayHit> hits = scene.IntersectMany(origins, dirs);
  std::vector<LidarReturn> out(dirs.size());
  for (size_t i = 0; i < dirs.size(); ++i) {
    const RayHit& h = hits[i];
    if (!h.Hit() || !(h.t <= max_range)) continue;
    LidarReturn& r = out[i];
    r.hit = true;
    r.range = h.t;
    r.mesh = h.mesh;
    r.face = h.face;
    r.point = scene.HitPoint(h);
    Eigen::Vector3f n = scene.GeometricNormal(h);
    const float c = n.dot(dirs[i]);
    if (c > 0) n = -n;
    r.normal = n;
    r.cos_incidence = std::min(1.0f, std::abs(c));
  }
  return out;
}

}  // namespace sd
