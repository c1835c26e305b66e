#include "core/camera.h"

#include <gtest/gtest.h>

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
