// LightAtObjects on a synthetic map and a synthetic photograph whose road radiance is known: the sun's
// visibility and the scale that make a grey road of the assumed albedo look as the photo shows it.
#include "synth/object_light.h"

#include <cmath>

#include <gtest/gtest.h>

#include "datasets/log.h"

namespace sd {
namespace {

float Luma(const Eigen::Vector3f& v) { return 0.2126f * v[0] + 0.7152f * v[1] + 0.0722f * v[2]; }

class ObjectLightTest : public ::testing::Test {
 protected:
  void SetUp() override {
    // A uniform, slightly blue sky over the upper hemisphere, black below; sun 40 deg up; one camera whose
    // exposure is half the reference's (gain 2) and whose white balance is neutral.
    const int W = 128;
    map_.radiance = ImageF(W, W / 2, 3);
    map_.coverage = ImageF(W, W / 2, 1, 1.0f);
    for (int v = 0; v < W / 2; ++v)
      for (int u = 0; u < W; ++u) {
        const bool sky = LatLongDirection(u + 0.5, v + 0.5, W, W / 2).z() > 0;
        const Eigen::Vector3f L = sky ? Eigen::Vector3f(0.20f, 0.24f, 0.30f) : Eigen::Vector3f::Zero();
        for (int c = 0; c < 3; ++c) map_.radiance.at(u, v, c) = L[c];
      }
    const double el = 40 * M_PI / 180;
    map_.sun_direction = Eigen::Vector3d(std::cos(el), 0, std::sin(el));
    map_.sun_irradiance = Eigen::Vector3f::Constant(2.0f);
    map_.sun_source = "ephemeris";
    CameraGain g;
    g.channel = "CAM_FRONT";
    g.exposure = 2.0f;
    map_.gains = {g};

    // Camera 1.5 m up looking along ego +x (OpenCV axes: x right = -y ego, y down = -z ego, z forward = +x ego).
    cam_.channel = "CAM_FRONT";
    cam_.intrinsics.width = 320;
    cam_.intrinsics.height = 240;
    cam_.intrinsics.fx = cam_.intrinsics.fy = 200;
    cam_.intrinsics.cx = 160;
    cam_.intrinsics.cy = 120;
    Eigen::Matrix3d R;
    R << 0, 0, 1, -1, 0, 0, 0, -1, 0;
    cam_.T_ego_cam = Rigid3d(R, Eigen::Vector3d(0, 0, 1.5));
    for (double x = 6; x <= 12; x += 0.5)
      for (double y = -2; y <= 2; y += 0.5) road_.push_back(Eigen::Vector3d(x, y, 0));

    base_ = RendererLighting(map_, 0);
    Y_sun_ = Luma(base_.sun_irradiance) * base_.sun_direction.z();
    Y_sky_ = M_PI * Luma(base_.sky_radiance);
  }

  // A photograph whose road (grey, albedo 0.15) receives `irradiance` (camera units, luminance).
  ImageF Photo(double irradiance) const {
    return ImageF(cam_.intrinsics.width, cam_.intrinsics.height, 3, static_cast<float>(0.15 / M_PI * irradiance));
  }

  EnvironmentMap map_;
  CameraSensor cam_;
  std::vector<Eigen::Vector3d> road_;
  Lighting base_;
  double Y_sun_ = 0, Y_sky_ = 0;
};

TEST_F(ObjectLightTest, RoadInFullSunKeepsTheMapsLight) {
  ASSERT_GT(Y_sun_, 0);
  ASSERT_GT(Y_sky_, 0);
  const ObjectLight l = LightAtObjects(map_, 0, cam_, Photo(Y_sun_ + Y_sky_), road_);
  EXPECT_GT(l.road_samples, 100);
  EXPECT_NEAR(l.sun_visibility, 1.0, 1e-3);
  EXPECT_NEAR(l.scale, 1.0, 1e-3);
  EXPECT_TRUE(l.lighting.sun_irradiance.isApprox(base_.sun_irradiance, 1e-3f));
  EXPECT_TRUE(l.lighting.sky_radiance.isApprox(base_.sky_radiance, 1e-3f));
  // The sky keeps its colour (the map's white balance), and the map's units are the camera's times the gain.
  EXPECT_GT(l.lighting.sky_radiance.z(), l.lighting.sky_radiance.x());
  EXPECT_NEAR(l.lighting.sun_irradiance.x() * 2.0f, 2.0f, 1e-4f);
}

TEST_F(ObjectLightTest, RoadInABuildingsShadeTurnsTheSunOff) {
  const ObjectLight l = LightAtObjects(map_, 0, cam_, Photo(0.6 * Y_sky_), road_);
  EXPECT_NEAR(l.sun_visibility, 0.0, 1e-3);
  EXPECT_NEAR(l.scale, 1.0, 1e-3);
  EXPECT_LT(l.lighting.sun_irradiance.norm(), 1e-6f);
  EXPECT_TRUE(l.lighting.sky_radiance.isApprox(0.6f * base_.sky_radiance, 1e-3f));
  EXPECT_LT(l.shading.sun_irradiance.norm(), 1e-6f) << "no hard sun shadow inside the shade";
}

TEST_F(ObjectLightTest, PenumbraDimsTheSunInProportion) {
  const double s = 0.3;
  const ObjectLight l = LightAtObjects(map_, 0, cam_, Photo(s * Y_sun_ + (s + (1 - s) * 0.6) * Y_sky_), road_);
  EXPECT_NEAR(l.sun_visibility, s, 1e-3);
  EXPECT_NEAR(l.scale, 1.0, 1e-3);
  EXPECT_TRUE(l.shading.sun_irradiance.isApprox(static_cast<float>(s) * map_.sun_irradiance, 1e-3f));
}

TEST_F(ObjectLightTest, RoadBrighterThanFullSunScalesTheLight) {
  // A clipped sky makes the map a lower bound: the road says how much brighter the light really is.
  const ObjectLight l = LightAtObjects(map_, 0, cam_, Photo(1.8 * (Y_sun_ + Y_sky_)), road_);
  EXPECT_NEAR(l.sun_visibility, 1.0, 1e-6);
  EXPECT_NEAR(l.scale, 1.8, 1e-3);
  EXPECT_TRUE(l.lighting.sun_irradiance.isApprox(1.8f * base_.sun_irradiance, 1e-3f));
  // The receiver's shading is a ratio: the scale does not enter it.
  EXPECT_TRUE(l.shading.sun_irradiance.isApprox(map_.sun_irradiance, 1e-6f));
}

TEST_F(ObjectLightTest, RoadDarkerThanShadeScalesDown) {
  const ObjectLight l = LightAtObjects(map_, 0, cam_, Photo(0.3 * Y_sky_), road_);
  EXPECT_NEAR(l.sun_visibility, 0.0, 1e-6);
  EXPECT_NEAR(l.scale, 0.5, 1e-3);
}

TEST_F(ObjectLightTest, NoRoadInViewKeepsTheMapsLight) {
  std::vector<Eigen::Vector3d> behind;
  for (const auto& p : road_) behind.push_back(Eigen::Vector3d(-p.x(), p.y(), p.z()));
  const ObjectLight l = LightAtObjects(map_, 0, cam_, Photo(10 * Y_sky_), behind);
  EXPECT_EQ(l.road_samples, 0);
  EXPECT_EQ(l.sun_visibility, 1.0);
  EXPECT_EQ(l.scale, 1.0);
  EXPECT_TRUE(l.lighting.sun_irradiance.isApprox(base_.sun_irradiance));
}

TEST_F(ObjectLightTest, AGivenSunVerdictKeepsItsSunAndFitsTheScale) {
  // The road is in full sun in this view, but the verdict for the spot (made from every camera) says shade: the
  // sun stays off, and the scale alone makes the road's brightness.
  const ObjectLight l = LightAtObjects(map_, 0, cam_, Photo(Y_sun_ + Y_sky_), road_, {}, 0.0);
  EXPECT_EQ(l.sun_visibility, 0.0);
  EXPECT_NEAR(l.scale, (Y_sun_ + Y_sky_) / (0.6 * Y_sky_), 1e-3);
  EXPECT_LT(l.lighting.sun_irradiance.norm(), 1e-6f);
  // A verdict and no road in view: the verdict, at the map's level.
  std::vector<Eigen::Vector3d> behind;
  for (const auto& p : road_) behind.push_back(Eigen::Vector3d(-p.x(), p.y(), p.z()));
  const ObjectLight unseen = LightAtObjects(map_, 0, cam_, Photo(Y_sky_), behind, {}, 0.25);
  EXPECT_EQ(unseen.road_samples, 0);
  EXPECT_EQ(unseen.sun_visibility, 0.25);
  EXPECT_EQ(unseen.scale, 1.0);
}

TEST_F(ObjectLightTest, OneSunVerdictFromCamerasOfDifferentExposure) {
  // Two cameras on the same road, the second exposed half as long (gain 2): in map units both show the same
  // road, so the pooled verdict is the single camera's.
  Frame frame;
  CameraSensor second = cam_;
  second.channel = "CAM_FRONT_2";
  frame.cameras = {cam_, second};
  CameraGain g2 = map_.gains[0];
  g2.channel = second.channel;
  g2.exposure = 4.0f;  // twice the first camera's 2
  map_.gains.push_back(g2);
  const double s = 0.4;
  const double Y = s * Y_sun_ + (s + (1 - s) * 0.6) * Y_sky_;  // camera 0 units
  const auto photo8 = [&](double irradiance) {
    const float L = static_cast<float>(0.15 / M_PI * irradiance);
    return ImageU8(cam_.intrinsics.width, cam_.intrinsics.height, 3, static_cast<uint8_t>(std::lround(255 * LinearToSrgb(L))));
  };
  const ImageU8 first = photo8(Y), darker = photo8(Y / 2);
  const SunVerdict one = SunVisibilityAt(map_, frame, {&first, nullptr}, road_);
  const SunVerdict both = SunVisibilityAt(map_, frame, {&first, &darker}, road_);
  EXPECT_GT(one.road_samples, 100);
  EXPECT_EQ(both.road_samples, 2 * one.road_samples);
  EXPECT_NEAR(one.sun_visibility, s, 0.02);  // 8-bit quantisation of the photo
  EXPECT_NEAR(both.sun_visibility, s, 0.02);
  EXPECT_EQ(SunVisibilityAt(map_, frame, {nullptr, nullptr}, road_).road_samples, 0);
}

}  // namespace
}  // namespace sd
