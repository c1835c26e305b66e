#include "core/box3.h"

#include <gtest/gtest.h>

#include <cmath>

namespace sd {
namespace {

constexpr double kPi = 3.14159265358979323846;

Box3 MakeBox(double x, double y, double z, double yaw, double l, double w, double h) {
  return Box3{Rigid3d::FromYaw(yaw, {x, y, z}), {l, w, h}};
}

TEST(Box3, CornersOrder) {
  const Box3 b = MakeBox(0, 0, 0, 0, 4, 2, 1);
  const auto c = b.Corners();
  const Eigen::Vector3d expected[8] = {{2, 1, -0.5}, {-2, 1, -0.5}, {-2, -1, -0.5}, {2, -1, -0.5},
                                       {2, 1, 0.5},  {-2, 1, 0.5},  {-2, -1, 0.5},  {2, -1, 0.5}};
  for (int i = 0; i < 8; ++i) EXPECT_TRUE(c[i].isApprox(expected[i])) << i << ": " << c[i].transpose();
  // Rotated 90 degrees and moved: the front-left corner (+x, +y) points along +y, left is -x.
  const auto r = MakeBox(10, 20, 1, kPi / 2, 4, 2, 1).Corners();
  EXPECT_TRUE(r[0].isApprox(Eigen::Vector3d(9, 22, 0.5), 1e-12)) << r[0].transpose();
  EXPECT_TRUE(r[6].isApprox(Eigen::Vector3d(11, 18, 1.5), 1e-12)) << r[6].transpose();
}

TEST(Box3, ContainsWithMargin) {
  const Box3 b = MakeBox(5, 0, 1, kPi / 4, 4, 2, 2);
  const Eigen::Vector3d fwd(std::cos(kPi / 4), std::sin(kPi / 4), 0);
  const Eigen::Vector3d c = b.center();
  EXPECT_TRUE(b.Contains(c));
  EXPECT_TRUE(b.Contains(c + 1.99 * fwd));
  EXPECT_FALSE(b.Contains(c + 2.01 * fwd));
  EXPECT_TRUE(b.Contains(c + 2.2 * fwd, 0.25));
  EXPECT_FALSE(b.Contains(c + 2.3 * fwd, 0.25));
  EXPECT_FALSE(b.Contains(c + Eigen::Vector3d(0, 0, 1.1)));
  EXPECT_TRUE(b.Contains(c + Eigen::Vector3d(0, 0, 1.1), 0.2));
  // A point inside the axis-aligned hull but outside the rotated box.
  EXPECT_FALSE(b.Contains(c + Eigen::Vector3d(1.9, -1.9, 0)));
}

TEST(Box3, TransformedKeepsCorners) {
  const Box3 b = MakeBox(1, 2, 0.5, 0.3, 4, 2, 1);
  const Rigid3d T = Rigid3d::FromYaw(-1.1, {3, -4, 0.2});
  const auto moved = b.Transformed(T).Corners();
  const auto orig = b.Corners();
  for (int i = 0; i < 8; ++i) EXPECT_TRUE(moved[i].isApprox(T * orig[i], 1e-12));
}

TEST(Box3, OverlapAxisAligned) {
  const Box3 a = MakeBox(0, 0, 0, 0, 2, 2, 2);
  EXPECT_TRUE(BoxesOverlap(a, MakeBox(1.5, 0, 0, 0, 2, 2, 2)));
  // Gap of 0.5 along x; `margin` is a clearance (each box grows by half), so 0.4 keeps them apart, 0.6 not.
  const Box3 b = MakeBox(2.5, 0, 0, 0, 2, 2, 2);
  EXPECT_FALSE(BoxesOverlap(a, b));
  EXPECT_FALSE(BoxesOverlap(a, b, 0.4));
  EXPECT_TRUE(BoxesOverlap(a, b, 0.6));
}

TEST(Box3, OverlapRotatedSeparatedByEdgeNormal) {
  // A: axis-aligned 2x2 square; B: the same square turned 45 degrees, centred at (c, c). Their axis-aligned
  // hulls overlap for c < 2.41, but along the diagonal (B's edge normal) the gap opens at c > 1 + 1/sqrt(2).
  const Box3 a = MakeBox(0, 0, 0, 0, 2, 2, 2);
  EXPECT_TRUE(BoxesOverlap(a, MakeBox(1.6, 1.6, 0, kPi / 4, 2, 2, 2)));
  const Box3 b = MakeBox(1.8, 1.8, 0, kPi / 4, 2, 2, 2);
  EXPECT_FALSE(BoxesOverlap(a, b));
  EXPECT_FALSE(BoxesOverlap(b, a));
  // Projected gap along the diagonal: 1.8 * sqrt(2) - sqrt(2) - 1 = 0.1314. Growing each box by m / 2 widens
  // A's projection by (m / 2) * sqrt(2) and B's by m / 2, so they touch at m = 2 * gap / (sqrt(2) + 1).
  const double gap = 1.8 * std::sqrt(2.0) - std::sqrt(2.0) - 1.0;
  const double m_touch = 2 * gap / (std::sqrt(2.0) + 1.0);
  EXPECT_FALSE(BoxesOverlap(a, b, 0.95 * m_touch));
  EXPECT_TRUE(BoxesOverlap(a, b, 1.05 * m_touch));
}

TEST(Box3, OverlapNeedsZOverlap) {
  const Box3 a = MakeBox(0, 0, 0, 0, 2, 2, 2);
  const Box3 above = MakeBox(0.5, 0, 2.5, 0.7, 2, 2, 2);  // footprints overlap, 0.5 m gap in z
  EXPECT_FALSE(BoxesOverlap(a, above));
  EXPECT_FALSE(BoxesOverlap(a, above, 0.4));
  EXPECT_TRUE(BoxesOverlap(a, above, 0.6));
  EXPECT_TRUE(BoxesOverlap(a, MakeBox(0.5, 0, 1.5, 0.7, 2, 2, 2)));
}

TEST(Box2, IoU) {
  EXPECT_NEAR(IoU({0, 0, 2, 2}, {1, 0, 3, 2}), 1.0 / 3.0, 1e-12);
  EXPECT_NEAR(IoU({0, 0, 2, 2}, {0, 0, 2, 2}), 1.0, 1e-12);
  EXPECT_NEAR(IoU({0, 0, 2, 2}, {0.5, 0.5, 1.5, 1.5}), 0.25, 1e-12);
  EXPECT_EQ(IoU({0, 0, 1, 1}, {2, 2, 3, 3}), 0.0);
  EXPECT_EQ(IoU({0, 0, 1, 1}, {1, 0, 2, 1}), 0.0);  // touching edges: [x1, x2) intervals
  EXPECT_EQ(IoU({1, 1, 0, 0}, {1, 1, 0, 0}), 0.0);  // empty boxes
  EXPECT_TRUE((Box2{3, 3, 2, 5}).Empty());
  EXPECT_EQ((Box2{0, 0, 2, 3}).Area(), 6.0);
}

}  // namespace
}  // namespace sd
