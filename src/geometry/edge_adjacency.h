#pragma once
// The undirected edges of a triangle mesh and the faces on each: the one connectivity build behind the
// topology report, the uniform Laplacian, the remesher's half-edge twins and the UV atlas's face adjacency.
//
// Half-edge h = 3 f + k runs from corner k to corner k + 1 of face f: faces[f][k] -> faces[f][(k + 1) % 3].
#include <span>
#include <vector>

#include <Eigen/Core>

namespace sd::geometry {

// Which half-edges of a face with a repeated vertex index take part.
enum class DegenerateFaces {
  kKeepProperEdges,  // those between two distinct vertices: (a, a, b) puts a -> b and b -> a on edge a-b
  kSkip,             // none
};

struct EdgeAdjacency {
  // Unique undirected edges (lo, hi), lo < hi, ascending in (lo, hi).
  std::vector<Eigen::Vector2i> edges;
  // Edge e's half-edges are half_edges[offset[e] .. offset[e + 1]), ascending. Their count is the number of
  // faces on the edge: 1 on the boundary, 2 inside, more at a non-manifold edge. offset has NumEdges() + 1
  // entries.
  std::vector<int> offset;
  std::vector<int> half_edges;
  // 3 per face: the twin of half-edge h, i.e. the other half-edge of its edge when that edge has exactly two
  // and they run opposite ways; -1 on the boundary, at non-manifold and inconsistently wound edges, and for
  // half-edges left out by DegenerateFaces.
  std::vector<int> twin;

  int NumEdges() const { return static_cast<int>(edges.size()); }
  int NumFacesOn(int e) const { return offset[e + 1] - offset[e]; }
  std::span<const int> HalfEdgesOf(int e) const {
    return {half_edges.data() + offset[e], static_cast<size_t>(NumFacesOn(e))};
  }
};

// Faces must index [0, num_vertices): a contract (checked), so callers validate their input first. Time is
// linear in the number of faces while vertex valences stay bounded.
EdgeAdjacency BuildEdgeAdjacency(int num_vertices, const std::vector<Eigen::Vector3i>& faces,
                                 DegenerateFaces degenerate);

}  // namespace sd::geometry
