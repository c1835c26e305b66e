#include "geometry/edge_adjacency.h"

#include <gtest/gtest.h>

#include <vector>

#include "geometry/test_meshes.h"

namespace sd::geometry {
namespace {

std::vector<int> HalfEdges(const EdgeAdjacency& adjacency, int e) {
  const auto span = adjacency.HalfEdgesOf(e);
  return {span.begin(), span.end()};
}

TEST(BuildEdgeAdjacency, IcosphereEdgesAreSortedUniqueWithOppositeTwins) {
  const TriangleMesh sphere = testing::Icosphere(2);
  const EdgeAdjacency adjacency =
      BuildEdgeAdjacency(static_cast<int>(sphere.positions.size()), sphere.faces, DegenerateFaces::kSkip);
  ASSERT_EQ(adjacency.NumEdges(), 480);  // 3 F / 2
  ASSERT_EQ(adjacency.offset.size(), 481u);
  for (int e = 0; e < adjacency.NumEdges(); ++e) {
    const Eigen::Vector2i& edge = adjacency.edges[e];
    EXPECT_LT(edge[0], edge[1]);
    if (e > 0) {
      const Eigen::Vector2i& prev = adjacency.edges[e - 1];
      EXPECT_TRUE(prev[0] < edge[0] || (prev[0] == edge[0] && prev[1] < edge[1])) << "edge " << e;
    }
    ASSERT_EQ(adjacency.NumFacesOn(e), 2);
    const std::vector<int> h = HalfEdges(adjacency, e);
    EXPECT_LT(h[0], h[1]);
  }
  ASSERT_EQ(adjacency.twin.size(), 3 * sphere.faces.size());
  auto from = [&](int h) { return sphere.faces[h / 3][h % 3]; };
  auto to = [&](int h) { return sphere.faces[h / 3][(h % 3 + 1) % 3]; };
  for (int h = 0; h < static_cast<int>(adjacency.twin.size()); ++h) {
    const int g = adjacency.twin[h];
    ASSERT_GE(g, 0);
    EXPECT_EQ(adjacency.twin[g], h);
    EXPECT_EQ(from(g), to(h));
    EXPECT_EQ(to(g), from(h));
  }
}

TEST(BuildEdgeAdjacency, GridBoundaryEdgesHaveOneFaceAndNoTwin) {
  const TriangleMesh grid = testing::Grid(4, 3);
  const EdgeAdjacency adjacency =
      BuildEdgeAdjacency(static_cast<int>(grid.positions.size()), grid.faces, DegenerateFaces::kSkip);
  int boundary = 0;
  for (int e = 0; e < adjacency.NumEdges(); ++e) {
    if (adjacency.NumFacesOn(e) != 1) continue;
    ++boundary;
    EXPECT_EQ(adjacency.twin[adjacency.HalfEdgesOf(e)[0]], -1);
  }
  EXPECT_EQ(boundary, 2 * (4 + 3));
}

TEST(BuildEdgeAdjacency, NonManifoldAndInconsistentEdgesHaveNoTwins) {
  // Three faces on edge 0-1; faces 3 and 4 both run 2 -> 3.
  const std::vector<Eigen::Vector3i> faces = {{0, 1, 2}, {1, 0, 3}, {0, 1, 4}, {2, 3, 5}, {2, 3, 6}};
  const EdgeAdjacency adjacency = BuildEdgeAdjacency(7, faces, DegenerateFaces::kSkip);
  ASSERT_EQ(adjacency.edges[0], Eigen::Vector2i(0, 1));
  EXPECT_EQ(HalfEdges(adjacency, 0), (std::vector<int>{0, 3, 6}));
  for (int h : HalfEdges(adjacency, 0)) EXPECT_EQ(adjacency.twin[h], -1);
  int e23 = -1;
  for (int e = 0; e < adjacency.NumEdges(); ++e) {
    if (adjacency.edges[e] == Eigen::Vector2i(2, 3)) e23 = e;
  }
  ASSERT_GE(e23, 0);
  EXPECT_EQ(HalfEdges(adjacency, e23), (std::vector<int>{9, 12}));
  EXPECT_EQ(adjacency.twin[9], -1);
  EXPECT_EQ(adjacency.twin[12], -1);
}

TEST(BuildEdgeAdjacency, DegenerateFacesKeepTheirProperEdgesOrNone) {
  // Face 1 repeats vertex 1: its half-edges 1 -> 2 and 2 -> 1 lie on edge 1-2 with face 0's 1 -> 2.
  const std::vector<Eigen::Vector3i> faces = {{0, 1, 2}, {1, 1, 2}};
  const EdgeAdjacency kept = BuildEdgeAdjacency(3, faces, DegenerateFaces::kKeepProperEdges);
  ASSERT_EQ(kept.NumEdges(), 3);
  EXPECT_EQ(kept.edges[2], Eigen::Vector2i(1, 2));
  EXPECT_EQ(HalfEdges(kept, 2), (std::vector<int>{1, 4, 5}));
  const EdgeAdjacency skipped = BuildEdgeAdjacency(3, faces, DegenerateFaces::kSkip);
  ASSERT_EQ(skipped.NumEdges(), 3);
  EXPECT_EQ(HalfEdges(skipped, 2), (std::vector<int>{1}));
  EXPECT_EQ(skipped.twin.size(), 6u);
  EXPECT_EQ(skipped.twin[4], -1);
}

TEST(BuildEdgeAdjacency, EmptyMesh) {
  const EdgeAdjacency adjacency = BuildEdgeAdjacency(3, {}, DegenerateFaces::kSkip);
  EXPECT_EQ(adjacency.NumEdges(), 0);
  EXPECT_EQ(adjacency.offset, std::vector<int>{0});
  EXPECT_TRUE(adjacency.twin.empty());
}

}  // namespace
}  // namespace sd::geometry
