#pragma once
// Topology checks for triangle meshes: what refinement and remeshing must keep true.
#include <string>
#include <vector>

#include <Eigen/Core>

namespace sd::geometry {

struct TopologyReport {
  int num_vertices = 0, num_faces = 0, num_edges = 0;
  int boundary_edges = 0;        // edges with one face
  int nonmanifold_edges = 0;     // edges with more than two faces
  int nonmanifold_vertices = 0;  // vertices whose faces do not form one fan
  int inconsistent_edges = 0;    // interior edges traversed in the same direction by both faces (bad winding)
  int degenerate_faces = 0;      // repeated vertex indices
  int unreferenced_vertices = 0;
  int components = 0;            // face-connected components
  int euler_characteristic = 0;  // V - E + F (2 for a closed genus-0 surface)

  bool IsManifold() const { return nonmanifold_edges == 0 && nonmanifold_vertices == 0 && degenerate_faces == 0; }
  bool IsWatertight() const { return IsManifold() && boundary_edges == 0 && inconsistent_edges == 0; }
  std::string Describe() const;  // one line, e.g. "12 boundary edges, 2 non-manifold edges"
};

TopologyReport AnalyzeTopology(int num_vertices, const std::vector<Eigen::Vector3i>& faces);

// Welds vertices closer than `tolerance` (and drops faces that become degenerate). Loaders split vertices at
// UV / normal seams; geometry work needs the welded surface. Returns the old -> new vertex map.
std::vector<int> WeldVertices(std::vector<Eigen::Vector3f>* positions, std::vector<Eigen::Vector3i>* faces,
                              float tolerance);

}  // namespace sd::geometry
