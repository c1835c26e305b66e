#include "geometry/topology.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <span>
#include <unordered_map>

#include "core/error.h"
#include "core/union_find.h"
#include "geometry/edge_adjacency.h"

namespace sd::geometry {
namespace {

bool IsDegenerate(const Eigen::Vector3i& t) { return t[0] == t[1] || t[1] == t[2] || t[2] == t[0]; }

std::string Plural(int n, const char* what) {
  return std::to_string(n) + " " + what + (n == 1 ? "" : "s");
}

}  // namespace

std::string TopologyReport::Describe() const {
  std::string problems;
  auto add = [&](int n, const char* what) {
    if (n == 0) return;
    if (!problems.empty()) problems += ", ";
    problems += Plural(n, what);
  };
  add(boundary_edges, "boundary edge");
  add(nonmanifold_edges, "non-manifold edge");
  add(nonmanifold_vertices, "non-manifold vertex");
  add(inconsistent_edges, "inconsistently wound edge");
  add(degenerate_faces, "degenerate face");
  add(unreferenced_vertices, "unreferenced vertex");
  if (problems.empty()) problems = "watertight";
  return Msg() << num_vertices << " vertices, " << num_faces << " faces, " << num_edges << " edges, "
               << Plural(components, "component") << ", Euler " << euler_characteristic << ": " << problems;
}

TopologyReport AnalyzeTopology(int num_vertices, const std::vector<Eigen::Vector3i>& faces) {
  if (num_vertices < 0) throw InputError("", Msg() << "AnalyzeTopology: negative vertex count " << num_vertices);
  const int num_faces = static_cast<int>(faces.size());
  TopologyReport r;
  r.num_vertices = num_vertices;
  r.num_faces = num_faces;

  std::vector<char> referenced(num_vertices, 0);
  for (int f = 0; f < num_faces; ++f) {
    const Eigen::Vector3i& t = faces[f];
    if ((t.array() < 0).any() || (t.array() >= num_vertices).any()) {
      throw InputError("", Msg() << "AnalyzeTopology: face " << f << " indexes a vertex outside [0, " << num_vertices
                                 << ")");
    }
    for (int k = 0; k < 3; ++k) referenced[t[k]] = 1;
    if (IsDegenerate(t)) ++r.degenerate_faces;
  }
  // Degenerate faces have no well-defined edges or fans: counted, then left out of everything else.
  const EdgeAdjacency adjacency = BuildEdgeAdjacency(num_vertices, faces, DegenerateFaces::kSkip);

  // Corners (f, k) are united when their faces share an edge through that vertex; a vertex is manifold when
  // all its corners end up in one set, i.e. its faces form a single fan (open or closed).
  UnionFind corners(faces.size() * 3);
  UnionFind face_sets(faces.size());
  auto from = [&](int h) { return faces[h / 3][h % 3]; };
  auto corner_of = [&](int h, int v) { return from(h) == v ? h : 3 * (h / 3) + (h % 3 + 1) % 3; };
  r.num_edges = adjacency.NumEdges();
  for (int e = 0; e < adjacency.NumEdges(); ++e) {
    const std::span<const int> half_edges = adjacency.HalfEdgesOf(e);
    const size_t count = half_edges.size();
    if (count == 1) ++r.boundary_edges;
    if (count > 2) ++r.nonmanifold_edges;
    if (count == 2 && from(half_edges[0]) == from(half_edges[1])) ++r.inconsistent_edges;
    const int h0 = half_edges[0];
    const int a = adjacency.edges[e][0], b = adjacency.edges[e][1];
    for (size_t k = 1; k < count; ++k) {
      const int h = half_edges[k];
      face_sets.Unite(h0 / 3, h / 3);
      corners.Unite(corner_of(h0, a), corner_of(h, a));
      corners.Unite(corner_of(h0, b), corner_of(h, b));
    }
  }

  // Each corner set is one fan, and its root is one of its corners: count roots per vertex.
  std::vector<int> fans(num_vertices, 0);
  for (int f = 0; f < num_faces; ++f) {
    if (IsDegenerate(faces[f])) continue;
    for (int k = 0; k < 3; ++k) {
      if (corners.Find(3 * f + k) == 3 * f + k) ++fans[faces[f][k]];
    }
    if (face_sets.Find(f) == f) ++r.components;
  }
  for (int v = 0; v < num_vertices; ++v) {
    if (fans[v] > 1) ++r.nonmanifold_vertices;
    if (!referenced[v]) ++r.unreferenced_vertices;
  }
  r.euler_characteristic = (num_vertices - r.unreferenced_vertices) - r.num_edges + (num_faces - r.degenerate_faces);
  return r;
}

std::vector<int> WeldVertices(std::vector<Eigen::Vector3f>* positions, std::vector<Eigen::Vector3i>* faces,
                              float tolerance) {
  SD_CHECK(positions != nullptr && faces != nullptr);
  if (!(tolerance >= 0) || !std::isfinite(tolerance)) {
    throw InputError("", Msg() << "WeldVertices: tolerance must be finite and >= 0, got " << tolerance);
  }
  const int n = static_cast<int>(positions->size());
  for (size_t f = 0; f < faces->size(); ++f) {
    const Eigen::Vector3i& t = (*faces)[f];
    if ((t.array() < 0).any() || (t.array() >= n).any()) {
      throw InputError("", Msg() << "WeldVertices: face " << f << " indexes a vertex outside [0, " << n << ")");
    }
  }
  for (const Eigen::Vector3f& p : *positions) {
    if (!p.allFinite()) throw InputError("", "WeldVertices: non-finite vertex position");
  }

  // Spatial hash on a grid of cell size `tolerance`: a vertex within the tolerance of a kept one lies in one
  // of the 27 cells around it. Vertices are visited in order and join the first kept vertex in reach, so the
  // result is deterministic and keeps the first vertex's position. A zero tolerance welds exact duplicates
  // (one cell per distinct position; the bit pattern of +0 and -0 differ, so quantise instead).
  const float cell = tolerance > 0 ? tolerance : 1.0f;
  const float tol2 = tolerance * tolerance;
  // Clamped so that a tiny tolerance on far-away coordinates cannot overflow the int conversion.
  auto cell_of = [&](const Eigen::Vector3f& p) {
    const Eigen::Array3d c = (p.cast<double>() / cell).array().floor().cwiseMax(-1e9).cwiseMin(1e9);
    return Eigen::Vector3i(static_cast<int>(c.x()), static_cast<int>(c.y()), static_cast<int>(c.z()));
  };
  auto cell_key = [](const Eigen::Vector3i& c) {
    // 21 bits per axis; collisions only cost an extra distance test, never a wrong weld.
    const uint64_t mask = (uint64_t{1} << 21) - 1;
    return (static_cast<uint64_t>(c.x()) & mask) | ((static_cast<uint64_t>(c.y()) & mask) << 21) |
           ((static_cast<uint64_t>(c.z()) & mask) << 42);
  };
  std::unordered_multimap<uint64_t, int> grid;
  grid.reserve(positions->size());
  std::vector<int> remap(n, -1);
  std::vector<Eigen::Vector3f> welded;
  welded.reserve(positions->size());
  for (int v = 0; v < n; ++v) {
    const Eigen::Vector3f& p = (*positions)[v];
    const Eigen::Vector3i c = cell_of(p);
    int found = -1;
    for (int dz = -1; dz <= 1 && found < 0; ++dz) {
      for (int dy = -1; dy <= 1 && found < 0; ++dy) {
        for (int dx = -1; dx <= 1 && found < 0; ++dx) {
          const auto range = grid.equal_range(cell_key(c + Eigen::Vector3i(dx, dy, dz)));
          for (auto it = range.first; it != range.second; ++it) {
            if ((welded[it->second] - p).squaredNorm() <= tol2) {
              // Among candidates in reach, the earliest kept vertex wins (deterministic across hash orders).
              if (found < 0 || it->second < found) found = it->second;
            }
          }
        }
      }
    }
    if (found < 0) {
      found = static_cast<int>(welded.size());
      welded.push_back(p);
      grid.emplace(cell_key(c), found);
    }
    remap[v] = found;
  }

  std::vector<Eigen::Vector3i> kept;
  kept.reserve(faces->size());
  for (const Eigen::Vector3i& t : *faces) {
    const Eigen::Vector3i w(remap[t[0]], remap[t[1]], remap[t[2]]);
    if (!IsDegenerate(w)) kept.push_back(w);
  }
  *positions = std::move(welded);
  *faces = std::move(kept);
  return remap;
}

}  // namespace sd::geometry
