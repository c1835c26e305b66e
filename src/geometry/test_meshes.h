#pragma once
// Small analytic meshes for the geometry tests (header-only; tests only, not part of the library).
// Shared by the geometry tests: extend rather than replace.
// All faces are counter-clockwise seen from outside (or from +z for the grid).
#include <cmath>
#include <cstdint>
#include <map>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "core/mesh.h"

namespace sd::geometry::testing {

// Only positions and faces are filled.
using TestMesh = ::sd::TriangleMesh;

// Icosahedron subdivided `subdivisions` times (each 1 -> 4 triangles, new vertices projected onto the
// sphere): 20 * 4^n faces, 10 * 4^n + 2 vertices. Closed, manifold, genus 0.
inline TestMesh Icosphere(int subdivisions, float radius = 1.0f,
                          const Eigen::Vector3f& center = Eigen::Vector3f::Zero()) {
  const double t = (1.0 + std::sqrt(5.0)) / 2.0;
  std::vector<Eigen::Vector3d> p = {{-1, t, 0}, {1, t, 0}, {-1, -t, 0}, {1, -t, 0}, {0, -1, t}, {0, 1, t},
                                    {0, -1, -t}, {0, 1, -t}, {t, 0, -1}, {t, 0, 1}, {-t, 0, -1}, {-t, 0, 1}};
  for (auto& q : p) q.normalize();
  std::vector<Eigen::Vector3i> f = {{0, 11, 5}, {0, 5, 1},  {0, 1, 7},   {0, 7, 10}, {0, 10, 11},
                                    {1, 5, 9},  {5, 11, 4}, {11, 10, 2}, {10, 7, 6}, {7, 1, 8},
                                    {3, 9, 4},  {3, 4, 2},  {3, 2, 6},   {3, 6, 8},  {3, 8, 9},
                                    {4, 9, 5},  {2, 4, 11}, {6, 2, 10},  {8, 6, 7},  {9, 8, 1}};
  for (int s = 0; s < subdivisions; ++s) {
    std::map<std::pair<int, int>, int> midpoint;
    auto mid = [&](int a, int b) {
      const auto key = std::make_pair(std::min(a, b), std::max(a, b));
      const auto it = midpoint.find(key);
      if (it != midpoint.end()) return it->second;
      p.push_back((p[a] + p[b]).normalized());
      const int id = static_cast<int>(p.size()) - 1;
      midpoint.emplace(key, id);
      return id;
    };
    std::vector<Eigen::Vector3i> next;
    next.reserve(f.size() * 4);
    for (const auto& tri : f) {
      const int ab = mid(tri[0], tri[1]), bc = mid(tri[1], tri[2]), ca = mid(tri[2], tri[0]);
      next.emplace_back(tri[0], ab, ca);
      next.emplace_back(tri[1], bc, ab);
      next.emplace_back(tri[2], ca, bc);
      next.emplace_back(ab, bc, ca);
    }
    f = std::move(next);
  }
  TestMesh m;
  for (const auto& q : p) m.positions.push_back((radius * q).cast<float>() + center);
  m.faces = std::move(f);
  return m;
}

// Flat grid of nx * ny quads (2 triangles each) over [0, size_x] x [0, size_y] at z = 0, normals +z.
// Vertex (i, j) has index j * (nx + 1) + i. Open: 2 (nx + ny) boundary edges.
inline TestMesh Grid(int nx, int ny, float size_x = 1.0f, float size_y = 1.0f) {
  TestMesh m;
  for (int j = 0; j <= ny; ++j) {
    for (int i = 0; i <= nx; ++i) m.positions.emplace_back(size_x * i / nx, size_y * j / ny, 0.0f);
  }
  auto id = [&](int i, int j) { return j * (nx + 1) + i; };
  for (int j = 0; j < ny; ++j) {
    for (int i = 0; i < nx; ++i) {
      m.faces.emplace_back(id(i, j), id(i + 1, j), id(i + 1, j + 1));
      m.faces.emplace_back(id(i, j), id(i + 1, j + 1), id(i, j + 1));
    }
  }
  return m;
}

// Axis-aligned cube [lo, hi]^3 with 8 shared vertices and 12 outward triangles (vertex i at bit pattern
// x = i & 1, y = i & 2, z = i & 4).
inline TestMesh Cube(const Eigen::Vector3f& lo = Eigen::Vector3f::Zero(),
                     const Eigen::Vector3f& hi = Eigen::Vector3f::Ones()) {
  TestMesh m;
  for (int i = 0; i < 8; ++i) {
    m.positions.emplace_back((i & 1) ? hi.x() : lo.x(), (i & 2) ? hi.y() : lo.y(), (i & 4) ? hi.z() : lo.z());
  }
  m.faces = {{0, 2, 1}, {1, 2, 3}, {4, 5, 6}, {5, 7, 6}, {0, 1, 4}, {1, 5, 4},
             {2, 6, 3}, {3, 6, 7}, {0, 4, 2}, {2, 4, 6}, {1, 3, 5}, {3, 7, 5}};
  return m;
}

}  // namespace sd::geometry::testing
