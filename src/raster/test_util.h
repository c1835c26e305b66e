#pragma once
// Small fixtures shared by the raster tests: a closed sphere mesh, random cameras looking at the origin,
// and a world -> clip helper.
#include <cmath>
#include <cstdint>
#include <numbers>
#include <random>
#include <vector>

#include <Eigen/Geometry>

#include "raster/raster.h"

namespace sd::raster::testing {

struct Mesh {
  std::vector<float> positions;  // 3 per vertex
  std::vector<int32_t> tris;     // 3 per triangle
  int NumVertices() const { return static_cast<int>(positions.size() / 3); }
};

// Closed UV sphere (poles are single vertices): 2 * slices * (stacks - 1) triangles, consistently wound.
// `bumpiness` > 0 scales each vertex radially by a random factor in [1 - bumpiness, 1 + bumpiness], which
// creates folds (front/back-facing neighbours) and so silhouette edges inside the outline too.
inline Mesh Sphere(int stacks, int slices, float radius, float bumpiness = 0.0f, uint32_t seed = 1) {
  Mesh m;
  std::mt19937 rng(seed);
  std::uniform_real_distribution<float> bump(1.0f - bumpiness, 1.0f + bumpiness);
  auto add = [&](double theta, double phi) {
    const float r = radius * (bumpiness > 0 ? bump(rng) : 1.0f);
    m.positions.push_back(static_cast<float>(r * std::sin(theta) * std::cos(phi)));
    m.positions.push_back(static_cast<float>(r * std::cos(theta)));
    m.positions.push_back(static_cast<float>(r * std::sin(theta) * std::sin(phi)));
  };
  add(0, 0);  // north pole: vertex 0
  for (int s = 1; s < stacks; ++s)
    for (int k = 0; k < slices; ++k) add(std::numbers::pi * s / stacks, 2 * std::numbers::pi * k / slices);
  add(std::numbers::pi, 0);  // south pole: last vertex
  const int32_t south = m.NumVertices() - 1;
  auto ring = [&](int s, int k) { return static_cast<int32_t>(1 + (s - 1) * slices + (k % slices)); };
  for (int k = 0; k < slices; ++k) m.tris.insert(m.tris.end(), {0, ring(1, k + 1), ring(1, k)});
  for (int s = 1; s + 1 < stacks; ++s)
    for (int k = 0; k < slices; ++k) {
      m.tris.insert(m.tris.end(), {ring(s, k), ring(s, k + 1), ring(s + 1, k)});
      m.tris.insert(m.tris.end(), {ring(s, k + 1), ring(s + 1, k + 1), ring(s + 1, k)});
    }
  for (int k = 0; k < slices; ++k) m.tris.insert(m.tris.end(), {south, ring(stacks - 1, k), ring(stacks - 1, k + 1)});
  return m;
}

// Camera at `distance` from the origin in a random direction, looking at the origin.
inline Rigid3d LookAtOrigin(std::mt19937& rng, double distance) {
  std::normal_distribution<double> n(0, 1);
  const Eigen::Vector3d eye = Eigen::Vector3d(n(rng), n(rng), n(rng)).normalized() * distance;
  const Eigen::Vector3d forward = (-eye).normalized();
  Eigen::Vector3d right = forward.cross(Eigen::Vector3d(n(rng), n(rng), n(rng))).normalized();
  const Eigen::Vector3d down = forward.cross(right);
  Eigen::Matrix3d R_world_cam;
  R_world_cam << right, down, forward;  // columns: camera x, y, z in world
  const Eigen::Matrix3d R_cam_world = R_world_cam.transpose();
  return Rigid3d(R_cam_world, -R_cam_world * eye);
}

inline PinholeCamera SquareCamera(int size, double fov_scale = 1.2) {
  PinholeCamera cam;
  cam.width = cam.height = size;
  cam.fx = cam.fy = fov_scale * size;
  cam.cx = cam.cy = size / 2.0;
  return cam;
}

inline std::vector<float> ToClip(const std::vector<float>& positions, const Eigen::Matrix4f& M) {
  std::vector<float> clip(positions.size() / 3 * 4);
  TransformToClip(positions, M, clip);
  return clip;
}

}  // namespace sd::raster::testing
