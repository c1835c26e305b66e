#pragma once
// LiDAR ray casting against a RayScene: a thin batch API over RayScene::IntersectMany that adds what a
// LiDAR model needs per return (range, surface normal, incidence angle). Beam patterns, drop-out and
// intensity models live in synth/.
#include <vector>

#include <Eigen/Core>

#include "render/ray_scene.h"

namespace sd {

struct LidarReturn {
  bool hit = false;
  float range = 0.0f;   // metres along the unit ray from `origin`; 0 where no hit
  int mesh = -1;        // RayScene mesh id; -1 where no hit
  int face = -1;        // triangle index in that mesh; -1 where no hit
  Eigen::Vector3f point = Eigen::Vector3f::Zero();   // hit point, scene frame; zero where no hit
  Eigen::Vector3f normal = Eigen::Vector3f::Zero();  // unit geometric normal, flipped to face the sensor
  float cos_incidence = 0.0f;  // |cos| of the angle between the ray and the surface normal, 0..1
};

// Casts one ray per entry of `dirs` (unit length, scene frame) from `origin`; returns are in the same order.
// Hits farther than `max_range` are misses. Parallel; deterministic.
std::vector<LidarReturn> CastLidarRays(const RayScene& scene, const Eigen::Vector3f& origin,
                                       const std::vector<Eigen::Vector3f>& dirs, float max_range);
// The same with one origin per ray (a spinning sensor on a moving vehicle fires each beam from another place).
std::vector<LidarReturn> CastLidarRays(const RayScene& scene, const std::vector<Eigen::Vector3f>& origins,
                                       const std::vector<Eigen::Vector3f>& dirs, float max_range);

}  // namespace sd
