#pragma once
// Tiny analytic meshes shared by the render tests (header-only, tests only).
#include <memory>

#include "core/mesh.h"

namespace sd::testmesh {

// Rectangle centred at `c` spanned by the unit axes `a` and `b` (half-sizes ha, hb); faces are CCW seen
// from the side a x b points to. UV (0,0) at c - ha*a - hb*b, (1,1) at the opposite corner.
inline std::shared_ptr<TriangleMesh> Quad(const Eigen::Vector3f& c, const Eigen::Vector3f& a, const Eigen::Vector3f& b,
                                          float ha, float hb) {
  auto m = std::make_shared<TriangleMesh>();
  m->positions = {c - ha * a - hb * b, c + ha * a - hb * b, c + ha * a + hb * b, c - ha * a + hb * b};
  m->uvs = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
  m->faces = {{0, 1, 2}, {0, 2, 3}};
  return m;
}

// Axis-aligned box [lo, hi] as 12 outward-facing triangles (closed, shared edges and vertices).
inline std::shared_ptr<TriangleMesh> Box(const Eigen::Vector3f& lo, const Eigen::Vector3f& hi) {
  auto m = std::make_shared<TriangleMesh>();
  for (int i = 0; i < 8; ++i) {
    m->positions.emplace_back((i & 1) ? hi.x() : lo.x(), (i & 2) ? hi.y() : lo.y(), (i & 4) ? hi.z() : lo.z());
  }
  // Each quad (CCW from outside) split along its first diagonal.
  const int quads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (const auto& q : quads) {
    m->faces.emplace_back(q[0], q[1], q[2]);
    m->faces.emplace_back(q[0], q[2], q[3]);
  }
  return m;
}

}  // namespace sd::testmesh
