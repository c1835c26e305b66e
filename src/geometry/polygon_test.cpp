#include "geometry/polygon.h"

#include <gtest/gtest.h>

#include <random>

namespace sd::geometry {
namespace {

TEST(Polygon, HullOfASquareWithInteriorAndCollinearPoints) {
  std::vector<Eigen::Vector2d> pts = {{0, 0}, {2, 0}, {2, 2}, {0, 2}, {1, 1}, {1, 0}, {2, 1}, {0, 0}, {0.5, 1.5}};
  const auto hull = ConvexHull2D(pts);
  ASSERT_EQ(hull.size(), 4u);  // collinear edge midpoints, interior points and the duplicate are dropped
  double area = 0;
  for (size_t i = 0; i < hull.size(); ++i) {
    const auto& a = hull[i];
    const auto& b = hull[(i + 1) % hull.size()];
    area += a.x() * b.y() - b.x() * a.y();
  }
  EXPECT_DOUBLE_EQ(0.5 * area, 4.0);  // positive: counter-clockwise
  EXPECT_TRUE(InsideConvexPolygon(hull, {1, 1}));
  EXPECT_TRUE(InsideConvexPolygon(hull, {2, 1}));  // boundary
  EXPECT_FALSE(InsideConvexPolygon(hull, {2.01, 1}));
  EXPECT_EQ(ConvexHull2D({{1, 1}, {1, 1}}).size(), 1u);
  EXPECT_FALSE(InsideConvexPolygon({{0, 0}, {1, 1}}, {0.5, 0.5}));
}

TEST(Polygon, RandomPointsAreInsideTheirHull) {
  std::mt19937 rng(3);
  std::normal_distribution<double> g;
  std::vector<Eigen::Vector2d> pts(500);
  for (auto& p : pts) p = {g(rng), 0.3 * g(rng)};
  const auto hull = ConvexHull2D(pts);
  for (const auto& p : pts) EXPECT_TRUE(InsideConvexPolygon(hull, p));
  // Every hull vertex is an input point, and no point lies beyond any hull edge's line.
  for (const auto& v : hull) EXPECT_NE(std::find(pts.begin(), pts.end(), v), pts.end());
  EXPECT_FALSE(InsideConvexPolygon(hull, {10, 0}));
}

TEST(ConvexPolygonsOverlap, OverlapTouchAndSeparation) {
  const std::vector<Eigen::Vector2d> square = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
  auto shifted = [&](double dx, double dy) {
    std::vector<Eigen::Vector2d> s = square;
    for (auto& p : s) p += Eigen::Vector2d(dx, dy);
    return s;
  };
  EXPECT_TRUE(ConvexPolygonsOverlap(square, shifted(0.5, 0.5)));
  EXPECT_TRUE(ConvexPolygonsOverlap(square, shifted(0, 0)));
  EXPECT_FALSE(ConvexPolygonsOverlap(square, shifted(1, 0)));   // sharing an edge only
  EXPECT_FALSE(ConvexPolygonsOverlap(square, shifted(1.5, 0.2)));
  // A diamond whose bounding box overlaps the square's but which lies beyond its corner: only a diagonal axis
  // (one of the diamond's edge normals) separates them.
  const std::vector<Eigen::Vector2d> diamond = {{1.6, 1.0}, {2.2, 1.6}, {1.6, 2.2}, {1.0, 1.6}};
  EXPECT_FALSE(ConvexPolygonsOverlap(square, diamond));
  // Clockwise input works too, and degenerate polygons never overlap.
  std::vector<Eigen::Vector2d> clockwise(square.rbegin(), square.rend());
  EXPECT_TRUE(ConvexPolygonsOverlap(clockwise, shifted(0.5, -0.5)));
  EXPECT_FALSE(ConvexPolygonsOverlap(square, {{0.5, 0.5}, {0.6, 0.6}}));
}

}  // namespace
}  // namespace sd::geometry
