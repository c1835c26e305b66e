#include "geometry/topology.h"

#include <gtest/gtest.h>

#include "core/error.h"
#include "geometry/test_meshes.h"

namespace sd::geometry {
namespace {

TopologyReport Analyze(const TriangleMesh& m) {
  return AnalyzeTopology(static_cast<int>(m.positions.size()), m.faces);
}

TEST(AnalyzeTopology, IcosphereIsWatertightGenusZero) {
  const TriangleMesh sphere = testing::Icosphere(2);
  const TopologyReport r = Analyze(sphere);
  EXPECT_TRUE(r.IsWatertight()) << r.Describe();
  EXPECT_EQ(r.num_faces, 320);
  EXPECT_EQ(r.num_vertices, 162);
  EXPECT_EQ(r.num_edges, 480);
  EXPECT_EQ(r.components, 1);
  EXPECT_EQ(r.euler_characteristic, 2);
  EXPECT_NE(r.Describe().find("watertight"), std::string::npos) << r.Describe();
}

TEST(AnalyzeTopology, GridHasItsBoundary) {
  const TriangleMesh grid = testing::Grid(5, 3);
  const TopologyReport r = Analyze(grid);
  EXPECT_TRUE(r.IsManifold()) << r.Describe();
  EXPECT_FALSE(r.IsWatertight());
  EXPECT_EQ(r.boundary_edges, 2 * (5 + 3));
  EXPECT_EQ(r.euler_characteristic, 1);  // a disc
  EXPECT_EQ(r.inconsistent_edges, 0);
  EXPECT_NE(r.Describe().find("16 boundary edges"), std::string::npos) << r.Describe();
}

TEST(AnalyzeTopology, TwoCubesSharingAnEdgeHaveANonManifoldEdge) {
  // Cube B = cube A shifted by (1, 1, 0): they touch along the edge x = y = 1. Vertices 3 and 7 of A are
  // vertices 0 and 4 of B.
  TriangleMesh a = testing::Cube();
  const TriangleMesh b = testing::Cube(Eigen::Vector3f(1, 1, 0), Eigen::Vector3f(2, 2, 1));
  std::vector<int> remap(8);
  for (int i = 0; i < 8; ++i) {
    if (i == 0 || i == 4) {
      remap[i] = i == 0 ? 3 : 7;
      continue;
    }
    remap[i] = static_cast<int>(a.positions.size());
    a.positions.push_back(b.positions[i]);
  }
  for (const auto& f : b.faces) a.faces.emplace_back(remap[f[0]], remap[f[1]], remap[f[2]]);
  ASSERT_EQ(a.positions.size(), 14u);
  const TopologyReport r = Analyze(a);
  EXPECT_EQ(r.nonmanifold_edges, 1) << r.Describe();
  EXPECT_FALSE(r.IsManifold());
  EXPECT_EQ(r.boundary_edges, 0);
  EXPECT_EQ(r.components, 1);
}

TEST(AnalyzeTopology, BowtieVertexIsNonManifold) {
  // Two triangles that share only vertex 0.
  const std::vector<Eigen::Vector3i> faces = {{0, 1, 2}, {0, 3, 4}};
  const TopologyReport r = AnalyzeTopology(5, faces);
  EXPECT_EQ(r.nonmanifold_vertices, 1) << r.Describe();
  EXPECT_EQ(r.nonmanifold_edges, 0);
  EXPECT_EQ(r.components, 2);
  EXPECT_FALSE(r.IsManifold());

  // Closing the gap with a triangle (0, 2, 3) makes it one fan again.
  const TopologyReport fan = AnalyzeTopology(5, {{0, 1, 2}, {0, 2, 3}, {0, 3, 4}});
  EXPECT_EQ(fan.nonmanifold_vertices, 0) << fan.Describe();
}

TEST(AnalyzeTopology, CountsWindingDegenerateAndUnreferenced) {
  const TopologyReport r = AnalyzeTopology(6, {{0, 1, 2}, {0, 1, 3}, {2, 2, 4}});
  EXPECT_EQ(r.inconsistent_edges, 1);  // edge 0-1 traversed 0 -> 1 by both faces
  EXPECT_EQ(r.degenerate_faces, 1);
  EXPECT_EQ(r.unreferenced_vertices, 1);  // vertex 5
  EXPECT_THROW(AnalyzeTopology(3, {{0, 1, 3}}), InputError);
}

TEST(WeldVertices, SplitVertexCubeWeldsWatertight) {
  // One vertex per face corner, as a loader splitting at every seam would produce, with 1e-6 noise.
  const TriangleMesh cube = testing::Cube();
  std::vector<Eigen::Vector3f> positions;
  std::vector<Eigen::Vector3i> faces;
  for (size_t f = 0; f < cube.faces.size(); ++f) {
    Eigen::Vector3i t;
    for (int k = 0; k < 3; ++k) {
      t[k] = static_cast<int>(positions.size());
      positions.push_back(cube.positions[cube.faces[f][k]] + Eigen::Vector3f::Constant(1e-6f * ((f + k) % 3)));
    }
    faces.push_back(t);
  }
  ASSERT_FALSE(AnalyzeTopology(static_cast<int>(positions.size()), faces).IsWatertight());
  const std::vector<int> remap = WeldVertices(&positions, &faces, 1e-4f);
  EXPECT_EQ(positions.size(), 8u);
  EXPECT_EQ(faces.size(), 12u);
  EXPECT_EQ(remap.size(), 36u);
  const TopologyReport r = AnalyzeTopology(static_cast<int>(positions.size()), faces);
  EXPECT_TRUE(r.IsWatertight()) << r.Describe();
  EXPECT_EQ(r.euler_characteristic, 2);
}

TEST(WeldVertices, DropsCollapsedFacesAndKeepsDistantVertices) {
  std::vector<Eigen::Vector3f> p = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {0.005f, 0, 0}};
  std::vector<Eigen::Vector3i> f = {{0, 1, 2}, {0, 3, 2}};
  auto remap = WeldVertices(&p, &f, 0.001f);
  EXPECT_EQ(p.size(), 4u);  // 0.005 apart: outside the tolerance
  remap = WeldVertices(&p, &f, 0.01f);
  EXPECT_EQ(p.size(), 3u);
  EXPECT_EQ(f.size(), 1u);  // (0, 3, 2) became (0, 0, 2)
  EXPECT_EQ(remap[3], 0);
  EXPECT_THROW(WeldVertices(&p, &f, -1.0f), InputError);
}

}  // namespace
}  // namespace sd::geometry
