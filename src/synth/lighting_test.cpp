#include "synth/lighting.h"

#include <cmath>

#include <gtest/gtest.h>

namespace sd {
namespace {

// Reference values from spherical astronomy, independent of the NOAA series: at solar noon the sun stands
// due south (north of the tropics) at elevation 90 - latitude + declination.
TEST(Solar, GreenwichNoonAtSummerSolstice) {
  const double t = 1592740800.0;  // 2020-06-21 12:00:00 UTC; declination +23.44 deg
  const SolarPosition sp = ComputeSolarPosition(t, 51.4769, 0.0);
  EXPECT_NEAR(sp.elevation_deg, 90.0 - 51.4769 + 23.44, 0.4);
  EXPECT_NEAR(sp.azimuth_deg, 180.0, 2.0);
}

TEST(Solar, EquatorAtEquinoxNoonIsOverhead) {
  const double t = 1616241600.0;  // 2021-03-20 12:00 UTC (equinox 09:37 UTC)
  const SolarPosition sp = ComputeSolarPosition(t, 0.0, 0.0);
  EXPECT_NEAR(sp.elevation_deg, 90.0, 2.5);  // equation of time (-7.5 min) shifts the hour angle ~1.9 deg
}

TEST(Solar, SunsetAndMorningAzimuth) {
  // 2020-06-21 06:00 UTC at Greenwich (hour angle -90 deg): sin(el) = sin(lat) sin(decl) -> 18.1 deg,
  // cos(az) = (sin(decl) - sin(el) sin(lat)) / (cos(el) cos(lat)) -> 74.8 deg east of north.
  const SolarPosition sp = ComputeSolarPosition(1592719200.0, 51.4769, 0.0);
  EXPECT_NEAR(sp.azimuth_deg, 74.8, 1.5);
  EXPECT_NEAR(sp.elevation_deg, 18.1, 1.0);
  // Midnight: below the horizon.
  EXPECT_LT(ComputeSolarPosition(1592697600.0, 51.4769, 0.0).elevation_deg, 0.0);
}

TEST(Lighting, EphemerisDirectionTurnsWithTheEgoHeading) {
  Frame f;
  f.timestamp = 1592740800.0;
  GeoLocation loc{51.4769, 0.0, "greenwich"};
  // World x east, y north. Ego facing north: the southern noon sun is behind the car (ego -x).
  f.T_world_ego = Rigid3d::FromYaw(M_PI / 2, Eigen::Vector3d::Zero());
  const Eigen::Vector3d d = SunDirectionEgo(f, loc, std::nullopt);
  EXPECT_LT(d.x(), -0.4);
  EXPECT_NEAR(d.y(), 0.0, 0.05);
  EXPECT_NEAR(std::asin(d.z()) * 180 / M_PI, 90.0 - 51.4769 + 23.44, 0.5);
  // An explicit sun wins.
  const Eigen::Vector3d o = SunDirectionEgo(f, loc, SunSpec{90.0, 30.0});
  EXPECT_NEAR(o.y(), std::cos(M_PI / 6), 1e-9);
  EXPECT_NEAR(o.z(), 0.5, 1e-9);
}

TEST(Lighting, RoadCalibrationInvertsTheLambertianModel) {
  // A uniform grey "road" image of linear radiance 0.05 seen by a camera looking down.
  ImageF img(64, 48, 3, 0.05f);
  CameraSensor cam;
  cam.intrinsics.width = 64;
  cam.intrinsics.height = 48;
  cam.intrinsics.fx = cam.intrinsics.fy = 50;
  cam.intrinsics.cx = 32;
  cam.intrinsics.cy = 24;
  // Camera 10 m above the origin looking straight down (camera z = ego -z).
  Eigen::Matrix3d R;
  R << 1, 0, 0, 0, -1, 0, 0, 0, -1;
  cam.T_ego_cam = Rigid3d(R, Eigen::Vector3d(0, 0, 10));
  std::vector<Eigen::Vector3d> road;
  for (int i = -3; i <= 3; ++i)
    for (int j = -3; j <= 3; ++j) road.emplace_back(i, j, 0);
  LightingOptions opt;
  const Eigen::Vector3d sun(0, 0, 1);
  const Lighting l = CalibrateLighting(img, cam, road, sun, opt);
  // Horizontal irradiance rebuilt from the sun and sky must give back the road radiance: a*E/pi = L.
  const float E = l.sun_irradiance.x() * 1.0f + l.sky_radiance.x() * static_cast<float>(M_PI);
  EXPECT_NEAR(opt.road_albedo * E / M_PI, 0.05, 1e-5);
  EXPECT_NEAR(l.sun_irradiance.x() / E, opt.direct_fraction, 1e-5);
}

}  // namespace
}  // namespace sd
