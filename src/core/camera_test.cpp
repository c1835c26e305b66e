#include "core/camera.h"

#include <gtest/gtest.h>

#include <cmath>

#include <Eigen/Geometry>

namespace sd {
namespace {

PinholeCamera NuScenesLike() {
  Eigen::Matrix3d K;
  K << 1266.4, 0, 816.3, 0, 1266.4, 491.5, 0, 0, 1;  // CAM_FRONT-like intrinsics
  return PinholeCamera::FromK(K, 1600, 900);
}

void ExpectRoundTrip(const PinholeCamera& cam) {
  for (int j = 0; j <= 8; ++j)
    for (int i = 0; i <= 8; ++i) {
      const Eigen::Vector2d uv(cam.width * i / 8.0, cam.height * j / 8.0);
      const Eigen::Vector3d ray = cam.RayDirection(uv);
      EXPECT_NEAR(ray.norm(), 1.0, 1e-12);
      for (double depth : {0.5, 10.0, 80.0}) {
        const auto back = cam.Project(ray * depth / ray.z());
        ASSERT_TRUE(back.has_value());
        EXPECT_NEAR((*back - uv).norm(), 0.0, 1e-6) << uv.transpose();
      }
      // And the other way: point -> pixel -> ray is parallel to the point.
      const Eigen::Vector3d p = ray * 7.0;
      EXPECT_NEAR(cam.RayDirection(*cam.Project(p)).cross(p.normalized()).norm(), 0.0, 1e-9);
    }
}

TEST(Camera, ProjectRayRoundTripPinhole) { ExpectRoundTrip(NuScenesLike()); }

TEST(Camera, ProjectRayRoundTripDistorted) {
  PinholeCamera cam = NuScenesLike();
  cam.distortion = {-0.12, 0.03, 1e-3, -5e-4, 0.0};  // moderate barrel, as for automotive lenses
  ExpectRoundTrip(cam);
  // Distortion moves off-axis points (barrel: towards the centre) and leaves the principal point alone.
  const Eigen::Vector3d p(0.5, 0.3, 1.0);
  const Eigen::Vector2d d = *cam.Project(p), u = *NuScenesLike().Project(p);
  EXPECT_LT((d - Eigen::Vector2d(cam.cx, cam.cy)).norm(), (u - Eigen::Vector2d(cam.cx, cam.cy)).norm());
  EXPECT_TRUE(cam.Project({0, 0, 3})->isApprox(Eigen::Vector2d(cam.cx, cam.cy)));
}

PinholeCamera StronglyDistorted() {
  PinholeCamera cam = NuScenesLike();
  cam.distortion = {-0.3, 0.1, 1e-3, -1e-3, 0.0};
  return cam;
}

TEST(Camera, DistortJacobianMatchesCentralDifferences) {
  const PinholeCamera cam = StronglyDistorted();
  const double h = 1e-6;
  for (const Eigen::Vector2d& xy : {Eigen::Vector2d(0, 0), Eigen::Vector2d(0.3, -0.2), Eigen::Vector2d(-0.9, 0.6)}) {
    Eigen::Matrix2d numeric;
    for (int k = 0; k < 2; ++k) {
      const Eigen::Vector2d e = h * Eigen::Vector2d::Unit(k);
      numeric.col(k) = (cam.Distort(xy + e) - cam.Distort(xy - e)) / (2 * h);
    }
    EXPECT_LT((cam.DistortJacobian(xy) - numeric).norm(), 1e-8 * numeric.norm()) << xy.transpose();
  }
  EXPECT_EQ(NuScenesLike().DistortJacobian({0.3, -0.2}), Eigen::Matrix2d::Identity());
}

TEST(Camera, UndistortInvertsDistortOverAStronglyDistortedImage) {
  const PinholeCamera cam = StronglyDistorted();
  for (int v = 0; v <= cam.height; v += 10)
    for (int u = 0; u <= cam.width; u += 10) {
      const Eigen::Vector2d xy_distorted((u - cam.cx) / cam.fx, (v - cam.cy) / cam.fy);
      const auto xy = cam.TryUndistort(xy_distorted);
      ASSERT_TRUE(xy.has_value()) << u << " " << v;
      EXPECT_LT((cam.Distort(*xy) - xy_distorted).norm(), 1e-12) << u << " " << v;
      EXPECT_EQ(cam.Undistort(xy_distorted), *xy);
    }
}

TEST(Camera, UndistortReportsPointsPastTheFold) {
  // Pure barrel k1 = -0.3: the radius maps as f(r) = r (1 - 0.3 r^2), which rises to its maximum
  // 2 / (3 sqrt(0.9)) = 0.7027 at the fold r = 1 / sqrt(0.9) and falls beyond it. A distorted radius of 0.8 is
  // reached by no point inside the fold, so no real image has it.
  PinholeCamera cam = NuScenesLike();
  cam.distortion = {-0.3, 0, 0, 0, 0};
  const Eigen::Vector2d direction = Eigen::Vector2d(0.6, -0.8);
  const Eigen::Vector2d xy_distorted = 0.8 * direction;
  const double fold = 1 / std::sqrt(0.9);
  for (double r = 0; r <= fold; r += 1e-4) EXPECT_LE(cam.Distort(r * direction).norm(), 0.7028) << r;
  EXPECT_GT(cam.DistortJacobian(0.99 * fold * direction).determinant(), 0.0);
  EXPECT_LT(cam.DistortJacobian(1.01 * fold * direction).determinant(), 0.0);
  EXPECT_FALSE(cam.TryUndistort(xy_distorted).has_value());
  // Undistort still answers: its best step inside the fold, here the start.
  const Eigen::Vector2d best = cam.Undistort(xy_distorted);
  EXPECT_GT(cam.DistortJacobian(best).determinant(), 0.0);
  EXPECT_TRUE(best.allFinite());
  // A radius inside the image of the fold still inverts.
  EXPECT_TRUE(cam.TryUndistort(0.7 * direction).has_value());
}

TEST(Camera, UndistortWithoutDistortionIsTheIdentity) {
  const PinholeCamera cam = NuScenesLike();
  for (const Eigen::Vector2d& xy : {Eigen::Vector2d(0.1, -0.7), Eigen::Vector2d(5, -9), Eigen::Vector2d(1e-300, 0)}) {
    EXPECT_EQ(cam.Undistort(xy), xy);
    EXPECT_EQ(*cam.TryUndistort(xy), xy);
    EXPECT_EQ(cam.Distort(xy), xy);
  }
  const Eigen::Vector2d uv(3.5, 899.5);
  EXPECT_EQ(cam.RayDirection(uv), Eigen::Vector3d((uv.x() - cam.cx) / cam.fx, (uv.y() - cam.cy) / cam.fy, 1).normalized());
}

TEST(Camera, PixelCentreConvention) {
  // A 4x2 camera with the principal point at the image centre (2, 1): the optical axis hits the corner
  // shared by pixels (1, 0) and (2, 1); the centre of pixel (0, 0) is (0.5, 0.5).
  PinholeCamera cam;
  cam.width = 4;
  cam.height = 2;
  cam.fx = cam.fy = 2;
  cam.cx = 2;
  cam.cy = 1;
  EXPECT_TRUE(cam.Project({0, 0, 1})->isApprox(Eigen::Vector2d(2, 1)));
  const Eigen::Vector3d r00 = cam.RayDirection({0.5, 0.5});
  EXPECT_TRUE(r00.isApprox(Eigen::Vector3d(-0.75, -0.25, 1).normalized()));  // up-left of the axis: x<0, y<0
  EXPECT_TRUE(cam.InImage({0, 0}));
  EXPECT_TRUE(cam.InImage({3.999, 1.999}));
  EXPECT_FALSE(cam.InImage({4, 1}));
  EXPECT_FALSE(cam.InImage({1, 2}));
  EXPECT_FALSE(cam.InImage({-1e-9, 1}));
  EXPECT_TRUE(cam.K().isApprox((Eigen::Matrix3d() << 2, 0, 2, 0, 2, 1, 0, 0, 1).finished()));
}

TEST(Camera, BehindTheCameraIsEmpty) {
  const PinholeCamera cam = NuScenesLike();
  EXPECT_FALSE(cam.Project({0, 0, -1}).has_value());
  EXPECT_FALSE(cam.Project({1, 1, 0}).has_value());
  EXPECT_FALSE(cam.Project({0, 0, 0.5}, 1.0).has_value());
  EXPECT_TRUE(cam.Project({0, 0, 1.5}, 1.0).has_value());
}

}  // namespace
}  // namespace sd
