#pragma once
// Scalar fields on regular grids and their iso-surface (marching cubes).
#include <vector>

#include <Eigen/Core>

#include "core/mesh.h"

namespace sd::geometry {

// Samples at the grid nodes origin + voxel_size * (i, j, k), x fastest.
struct ScalarGrid {
  Eigen::Vector3i dims = Eigen::Vector3i::Zero();  // node counts
  Eigen::Vector3f origin = Eigen::Vector3f::Zero();
  float voxel_size = 1.0f;
  std::vector<float> values;

  size_t Index(int i, int j, int k) const {
    return (static_cast<size_t>(k) * dims.y() + j) * dims.x() + i;
  }
  float& at(int i, int j, int k) { return values[Index(i, j, k)]; }
  float at(int i, int j, int k) const { return values[Index(i, j, k)]; }
  Eigen::Vector3f NodePosition(int i, int j, int k) const {
    return origin + voxel_size * Eigen::Vector3f(float(i), float(j), float(k));
  }
};

// Iso-surface at `iso`, "inside" where value > iso; faces counter-clockwise seen from outside, vertices
// shared between faces (a closed field gives a watertight manifold mesh: the ambiguous cases are resolved
// consistently). Fields must be <= iso on the grid border for the result to be closed.
// One vertex per crossed grid edge (linear interpolation, kept a hundredth of a voxel from the edge's ends so that
// no two vertices coincide and the mesh is manifold by position as well as by index), plus, rarely, a centre
// vertex for a cell whose contour loop cannot be fanned without an edge in a cell face. Ambiguous faces use the
// asymptotic decider. NaN samples count as outside. Positions and faces only (no normals). Parallel over z-slabs; memory beyond the
// grid and the mesh: two xy-layers of edge ids (12 bytes per node of a layer) per worker thread, and the faces
// once more while they are gathered.
TriangleMesh MarchingCubes(const ScalarGrid& grid, float iso);

}  // namespace sd::geometry
