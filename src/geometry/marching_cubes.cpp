#include "geometry/marching_cubes.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/error.h"
#include "core/parallel.h"

// Marching cubes without a 256-case table: each cell's polygons are built from its six faces.
//
// On every cube face the iso-contour is a set of segments joining the crossed face edges; which edges pair up
// depends only on the face's four corner values, and on an ambiguous face (inside corners on a diagonal) it
// is settled by the asymptotic decider (Nielson & Hamann 1991), again from those four values alone. The two
// cells sharing a face therefore draw the same segments (in opposite directions), so the surface is
// watertight and every edge has exactly two faces whatever the field. The segments of a cell chain into
// closed loops (every crossing vertex lies on two faces of the cell), and each loop is triangulated.
//
// Winding: segments are directed so that, seen from outside the cell, the inside region of the face lies on
// their left; the fan over such a loop faces the inside, so triangles are emitted reversed (outward CCW).

namespace sd::geometry {
namespace {

// Corner c of a cell sits at offset (c & 1, (c >> 1) & 1, (c >> 2) & 1).
// Faces: corners counter-clockwise seen from outside the cell.
constexpr int kFaceCorners[6][4] = {{0, 4, 6, 2}, {1, 3, 7, 5}, {0, 1, 5, 4},
                                    {2, 6, 7, 3}, {0, 2, 3, 1}, {4, 5, 7, 6}};

struct CubeTables {
  int edge_of[8][8];            // cube edge id (0..11) joining two corners, -1 if not an edge
  int edge_corner[12];          // the lower corner of each edge (its grid-edge origin)
  int edge_axis[12];
  bool share_face[12][12];      // two edges lie on a common face of the cell

  CubeTables() {
    for (auto& row : edge_of)
      for (int& e : row) e = -1;
    int n = 0;
    for (int c = 0; c < 8; ++c) {
      for (int axis = 0; axis < 3; ++axis) {
        if (c & (1 << axis)) continue;
        const int d = c | (1 << axis);
        edge_of[c][d] = edge_of[d][c] = n;
        edge_corner[n] = c;
        edge_axis[n] = axis;
        ++n;
      }
    }
    for (auto& row : share_face)
      for (bool& s : row) s = false;
    for (const auto& face : kFaceCorners) {
      for (int a = 0; a < 4; ++a) {
        for (int b = 0; b < 4; ++b) {
          share_face[edge_of[face[a]][face[(a + 1) % 4]]][edge_of[face[b]][face[(b + 1) % 4]]] = true;
        }
      }
    }
  }
};

const CubeTables& Tables() {
  static const CubeTables tables;
  return tables;
}

// A loop fanned from its centre, kept as its vertex ids: the centre's position is the mean of theirs, computed
// once all edge vertices exist (those of the slab's top layer belong to the next task, see MarchingCubes).
struct CentreLoop {
  int n = 0;
  int ids[12];
};

// The triangles of one z-slab of cells. Vertex ids >= 0 index the shared edge vertices; a loop that needs a
// centre vertex (see TriangulateLoop) refers to it as -(1 + index into `centres`).
struct Slab {
  std::vector<Eigen::Vector3i> faces;
  std::vector<CentreLoop> centres;
};

// Fan-triangulates a loop from a vertex none of whose diagonals joins two vertices on one cube face. Such a
// diagonal would lie in the face, where the neighbouring cell may draw the same edge (an edge with four
// triangles); it can only arise when the loop passes through both segments of an ambiguous face. When
// every start has one (rare loops of 6+ vertices), the loop is fanned from an added centre vertex instead.
void TriangulateLoop(const int* loop_edges, const int* loop_ids, int n, Slab& slab) {
  const CubeTables& t = Tables();
  // Emitted as (apex, b, a) for the loop step a -> b: reversed, see the winding note at the top.
  if (n == 3) {
    slab.faces.emplace_back(loop_ids[0], loop_ids[2], loop_ids[1]);
    return;
  }
  for (int s = 0; s < n; ++s) {
    bool ok = true;
    for (int j = 2; j < n - 1 && ok; ++j) ok = !t.share_face[loop_edges[s]][loop_edges[(s + j) % n]];
    if (!ok) continue;
    for (int j = 1; j < n - 1; ++j) {
      slab.faces.emplace_back(loop_ids[s], loop_ids[(s + j + 1) % n], loop_ids[(s + j) % n]);
    }
    return;
  }
  CentreLoop& centre = slab.centres.emplace_back();
  centre.n = n;
  std::copy(loop_ids, loop_ids + n, centre.ids);
  const int c = -static_cast<int>(slab.centres.size());
  for (int i = 0; i < n; ++i) slab.faces.emplace_back(c, loop_ids[(i + 1) % n], loop_ids[i]);
}

}  // namespace

TriangleMesh MarchingCubes(const ScalarGrid& grid, float iso) {
  const int nx = grid.dims.x(), ny = grid.dims.y(), nz = grid.dims.z();
  SD_CHECK(nx >= 0 && ny >= 0 && nz >= 0, << grid.dims.transpose());
  SD_CHECK(grid.values.size() == size_t(nx) * ny * nz, << grid.values.size() << " values for " << grid.dims.transpose());
  TriangleMesh mesh;
  if (nx < 2 || ny < 2 || nz < 2) return mesh;
  const CubeTables& t = Tables();
  // NaN compares false: an undefined sample counts as outside.
  auto inside = [&](size_t index) { return grid.values[index] > iso; };

  // 1. One vertex per crossed grid edge, numbered layer by layer (k), then by node (j, i) and axis, so the ids are
  //    deterministic: first count each layer's crossings.
  const size_t layer = size_t(nx) * ny;
  const size_t stride[3] = {1, size_t(nx), layer};
  const int dims[3] = {nx, ny, nz};
  auto crosses = [&](size_t node, int axis, int i, int j, int k) {
    const int ijk[3] = {i, j, k};
    if (ijk[axis] + 1 >= dims[axis]) return false;
    return inside(node) != inside(node + stride[axis]);
  };
  std::vector<size_t> layer_count(nz + 1, 0);
  ParallelFor(0, size_t(nz), [&](size_t k) {
    size_t count = 0;
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i) {
        const size_t node = grid.Index(i, j, int(k));
        for (int axis = 0; axis < 3; ++axis) count += crosses(node, axis, i, j, int(k)) ? 1 : 0;
      }
    layer_count[k + 1] = count;
  });
  for (int k = 0; k < nz; ++k) layer_count[k + 1] += layer_count[k];
  if (layer_count[nz] > size_t(std::numeric_limits<int>::max() / 2))
    throw InputError("", Msg() << "MarchingCubes: " << layer_count[nz] << " surface vertices exceed the index range");
  mesh.positions.resize(layer_count[nz]);

  // Numbers the crossed edges leaving the nodes of layer k: ids[3 * (node in layer) + axis] is the vertex on the
  // edge from that node towards +axis, or -1. Writes the vertices too when `write`: two tasks number a layer
  // where their slab ranges meet, and only one of them may write it.
  auto number_layer = [&](int k, std::vector<int>& ids, bool write) {
    int id = static_cast<int>(layer_count[k]);
    for (int j = 0; j < ny; ++j)
      for (int i = 0; i < nx; ++i) {
        const size_t node = grid.Index(i, j, k);
        int* node_ids = &ids[3 * (size_t(j) * nx + i)];
        for (int axis = 0; axis < 3; ++axis) {
          node_ids[axis] = -1;
          if (!crosses(node, axis, i, j, k)) continue;
          node_ids[axis] = id++;
          if (!write) continue;
          const float v0 = grid.values[node], v1 = grid.values[node + stride[axis]];
          float s = (iso - v0) / (v1 - v0);
          if (!std::isfinite(s)) s = 0.5f;  // a NaN endpoint: no better guess than the middle
          // Strictly inside the edge: a sample exactly at the iso value would otherwise put the vertices of all its
          // crossed edges at one point, a surface pinched there, which any welding by position (refinement's, the
          // texture's) fuses into non-manifold edges. A hundredth of a voxel is far below the surface's accuracy
          // and far above welding tolerances (1e-6 of the diagonal: under 0.004 voxel at 2048^3).
          constexpr float kInset = 0.01f;
          s = std::clamp(s, kInset, 1.0f - kInset);
          Eigen::Vector3f offset(static_cast<float>(i), static_cast<float>(j), static_cast<float>(k));
          offset[axis] += s;
          mesh.positions[node_ids[axis]] = grid.origin + grid.voxel_size * offset;
        }
      }
  };

  // 2. Cells, slab by slab. A cell needs the edge ids of the layers below and above it only, so each task walks
  //    its range of slabs upwards holding two layers of ids (12 bytes per node of a layer) rather than the whole
  //    grid's. Neighbouring tasks both number the layer where they meet; the one above writes its vertices (the
  //    last task also writes the grid's top layer). The grain bounds that repeated numbering.
  std::vector<Slab> slabs(nz - 1);
  auto polygonise_slab = [&](size_t k, const std::vector<int>& bottom, const std::vector<int>& top) {
    Slab& slab = slabs[k];
    for (int j = 0; j + 1 < ny; ++j) {
      for (int i = 0; i + 1 < nx; ++i) {
        float value[8];
        int mask = 0;
        for (int c = 0; c < 8; ++c) {
          const size_t node = grid.Index(i + (c & 1), j + ((c >> 1) & 1), int(k) + ((c >> 2) & 1));
          value[c] = grid.values[node];
          mask |= inside(node) ? 1 << c : 0;
        }
        if (mask == 0 || mask == 255) continue;

        // Face segments, directed crossing edge -> crossing edge (`next`).
        int next[12];
        for (int& n : next) n = -1;
        for (const auto& face : kFaceCorners) {
          int leave[2], enter[2], nl = 0, ne = 0;
          for (int a = 0; a < 4; ++a) {
            const bool in0 = mask >> face[a] & 1, in1 = mask >> face[(a + 1) % 4] & 1;
            if (in0 && !in1) leave[nl++] = a;
            if (!in0 && in1) enter[ne++] = a;
          }
          auto edge = [&](int a) { return t.edge_of[face[a]][face[(a + 1) % 4]]; };
          if (nl == 1) {
            next[edge(leave[0])] = edge(enter[0]);
          } else if (nl == 2) {
            // Inside corners on a diagonal. The bilinear interpolant's saddle is inside iff
            // (a - iso)(c - iso) > (b - iso)(d - iso) with a, c the inside diagonal; products commute exactly,
            // so both cells sharing the face decide alike.
            const int in_a = (mask >> face[0] & 1) ? 0 : 1;
            const float p_in = (value[face[in_a]] - iso) * (value[face[in_a + 2]] - iso);
            const float p_out = (value[face[1 - in_a]] - iso) * (value[face[3 - in_a]] - iso);
            const bool connected = p_in > p_out;
            for (int l = 0; l < 2; ++l) {
              // Walking the face counter-clockwise, a leaving crossing is followed by an entering one; the
              // inside region is cut around each inside corner (separated) or kept as a band (connected).
              const int a = leave[l];
              const int partner = connected ? (a + 1) % 4 : (a + 3) % 4;
              next[edge(a)] = edge(partner);
            }
          }
        }

        bool used[12] = {};
        for (int start = 0; start < 12; ++start) {
          if (next[start] < 0 || used[start]) continue;
          int loop_edges[12], loop_ids[12], n = 0;
          for (int e = start; !used[e]; e = next[e]) {
            SD_CHECK(next[e] >= 0 && n < 12, << "open contour in cell " << i << "," << j << "," << k);
            used[e] = true;
            loop_edges[n] = e;
            const int c = t.edge_corner[e];
            const std::vector<int>& ids = (c & 4) ? top : bottom;
            loop_ids[n++] = ids[3 * (size_t(j + ((c >> 1) & 1)) * nx + i + (c & 1)) + t.edge_axis[e]];
          }
          TriangulateLoop(loop_edges, loop_ids, n, slab);
        }
      }
    }
  };
  constexpr size_t kSlabsPerTask = 8;
  ParallelForRange(0, size_t(nz - 1), kSlabsPerTask, [&](size_t k_begin, size_t k_end) {
    std::vector<int> bottom(3 * layer), top(3 * layer);
    number_layer(int(k_begin), bottom, true);
    for (size_t k = k_begin; k < k_end; ++k) {
      number_layer(int(k) + 1, top, k + 1 < k_end || k + 2 == size_t(nz));
      polygonise_slab(k, bottom, top);
      std::swap(bottom, top);
    }
  });

  // 3. Concatenate in slab order; centre vertices go after the edge vertices.
  size_t num_faces = 0, num_centres = 0;
  for (const Slab& s : slabs) {
    num_faces += s.faces.size();
    num_centres += s.centres.size();
  }
  mesh.faces.reserve(num_faces);
  mesh.positions.reserve(mesh.positions.size() + num_centres);
  for (const Slab& s : slabs) {
    const int base = static_cast<int>(mesh.positions.size());
    for (const CentreLoop& loop : s.centres) {
      Eigen::Vector3f centre = Eigen::Vector3f::Zero();
      for (int i = 0; i < loop.n; ++i) centre += mesh.positions[loop.ids[i]];
      mesh.positions.push_back(centre / float(loop.n));
    }
    for (Eigen::Vector3i f : s.faces) {
      for (int v = 0; v < 3; ++v)
        if (f[v] < 0) f[v] = base + (-f[v] - 1);
      mesh.faces.push_back(f);
    }
  }
  return mesh;
}

}  // namespace sd::geometry
