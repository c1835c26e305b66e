#include "geometry/box_projection.h"

#include <gtest/gtest.h>

namespace sd::geometry {
namespace {

// 640 x 480, f = 500, looking along +z of the frame the boxes are given in.
PinholeCamera Camera() {
  PinholeCamera c;
  c.width = 640, c.height = 480;
  c.fx = c.fy = 500, c.cx = 320, c.cy = 240;
  return c;
}

Box3 BoxAt(const Eigen::Vector3d& center, const Eigen::Vector3d& size) {
  Box3 b;
  b.T_frame_box.translation = center;
  b.size = size;
  return b;
}

TEST(BoxProjection, ABoxInsideTheImageIsNotTruncated) {
  const auto b = ProjectBoxToImage(Camera(), Rigid3d(), BoxAt({0, 0, 10}, {1, 1, 1}), 0.1);
  ASSERT_TRUE(b.has_value());
  EXPECT_DOUBLE_EQ(b->truncation, 0.0);
  // The near face (z = 9.5) spans 500 * 0.5 / 9.5 px either side of the centre.
  EXPECT_NEAR(b->full.x1, 320 - 500 * 0.5 / 9.5, 1e-9);
  EXPECT_NEAR(b->full.x2, 320 + 500 * 0.5 / 9.5, 1e-9);
  EXPECT_EQ(b->full.x1, b->clipped.x1);
}

TEST(BoxProjection, TruncationIsTheShareOfTheRectangleOutsideTheImage) {
  // Centred on the right border: half of its rectangle lies outside.
  const double z = 10, u_edge = 640;
  const double x = (u_edge - 320) * z / 500;
  const auto b = ProjectBoxToImage(Camera(), Rigid3d(), BoxAt({x, 0, z}, {1, 1, 0.01}), 0.1);
  ASSERT_TRUE(b.has_value());
  EXPECT_NEAR(b->truncation, 0.5, 0.01);
  EXPECT_EQ(b->clipped.x2, 640);
}

TEST(BoxProjection, ABoxReachingBehindTheCameraIsClippedAtTheNearPlaneNotRefused) {
  // From 2 m behind to 4 m ahead, 1 m to the right: the corners behind would project mirrored.
  const auto b = ProjectBoxToImage(Camera(), Rigid3d(), BoxAt({1.5, 0, 1}, {1, 1, 6}), 0.5);
  ASSERT_TRUE(b.has_value());
  EXPECT_GT(b->truncation, 0.5);
  EXPECT_LT(b->truncation, 1.0);
  // The near-plane section (z = 0.5, x from 1 to 2 m) reaches u = 320 + 500 * 2 / 0.5 = 2320, past the image.
  EXPECT_NEAR(b->full.x2, 320 + 500 * 2 / 0.5, 1e-6);
  EXPECT_NEAR(b->full.x1, 320 + 500 * 1 / 4.0, 1e-6);  // the far face's inner edge
}

TEST(BoxProjection, BehindTheCameraOrOutsideTheImage) {
  EXPECT_FALSE(ProjectBoxToImage(Camera(), Rigid3d(), BoxAt({0, 0, -5}, {1, 1, 1}), 0.1).has_value());
  EXPECT_TRUE(ProjectBoxOutline(Camera(), Rigid3d(), BoxAt({0, 0, -5}, {1, 1, 1}), 0.1).empty());
  const auto aside = ProjectBoxToImage(Camera(), Rigid3d(), BoxAt({50, 0, 10}, {1, 1, 1}), 0.1);
  ASSERT_TRUE(aside.has_value());
  EXPECT_TRUE(aside->clipped.Empty());
  EXPECT_DOUBLE_EQ(aside->truncation, 1.0);
}

}  // namespace
}  // namespace sd::geometry
