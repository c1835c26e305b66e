#include "synth/lighting.h"

#include <algorithm>
#include <cmath>

#include "core/log.h"

namespace sd {
namespace {
constexpr double kDeg = M_PI / 180.0;
}

SolarPosition ComputeSolarPosition(double unix_seconds, double latitude_deg, double longitude_deg) {
  // NOAA General Solar Position (Spencer's series): declination and equation of time from the fractional year.
  const double days = unix_seconds / 86400.0;
  // Days since 1 January 12:00 UTC of the current tropical year (the sun's path repeats every tropical year).
  const double year_fraction_days = std::fmod(std::fmod(days - 10957.5 /* 2000-01-01 12:00 */, 365.2422) + 365.2422, 365.2422);
  const double utc_hours = std::fmod(unix_seconds / 3600.0, 24.0);
  const double gamma = 2 * M_PI / 365.0 * year_fraction_days;
  const double eqtime = 229.18 * (0.000075 + 0.001868 * std::cos(gamma) - 0.032077 * std::sin(gamma) -
                                  0.014615 * std::cos(2 * gamma) - 0.040849 * std::sin(2 * gamma));
  const double decl = 0.006918 - 0.399912 * std::cos(gamma) + 0.070257 * std::sin(gamma) - 0.006758 * std::cos(2 * gamma) +
                      0.000907 * std::sin(2 * gamma) - 0.002697 * std::cos(3 * gamma) + 0.00148 * std::sin(3 * gamma);
  const double true_solar_minutes = std::fmod(utc_hours * 60.0 + eqtime + 4.0 * longitude_deg + 1440.0, 1440.0);
  const double hour_angle = (true_solar_minutes / 4.0 - 180.0) * kDeg;
  const double lat = latitude_deg * kDeg;
  const double cos_zenith = std::clamp(std::sin(lat) * std::sin(decl) + std::cos(lat) * std::cos(decl) * std::cos(hour_angle), -1.0, 1.0);
  const double zenith = std::acos(cos_zenith);
  // Azimuth clockwise from north.
  double az = std::atan2(std::sin(hour_angle), std::cos(hour_angle) * std::sin(lat) - std::tan(decl) * std::cos(lat));
  az = std::fmod(az / kDeg + 180.0 + 360.0, 360.0);
  return {az, 90.0 - zenith / kDeg};
}

Eigen::Vector3d SunDirectionEgo(const Frame& frame, const std::optional<GeoLocation>& location,
                                const std::optional<SunSpec>& override_sun, std::string* source) {
  auto from_ego_angles = [](double az_deg, double el_deg) {
    return Eigen::Vector3d(std::cos(el_deg * kDeg) * std::cos(az_deg * kDeg), std::cos(el_deg * kDeg) * std::sin(az_deg * kDeg),
                           std::sin(el_deg * kDeg));
  };
  if (override_sun) {
    if (source) *source = "scenario";
    return from_ego_angles(override_sun->azimuth_deg, override_sun->elevation_deg);
  }
  if (location && frame.timestamp > 1e9) {
    const SolarPosition sp = ComputeSolarPosition(frame.timestamp, location->latitude_deg, location->longitude_deg);
    if (sp.elevation_deg > 5) {
      const double el = sp.elevation_deg * kDeg, az = sp.azimuth_deg * kDeg;
      const Eigen::Vector3d world(std::sin(az) * std::cos(el), std::cos(az) * std::cos(el), std::sin(el));  // x east, y north
      if (source) *source = Msg() << "ephemeris (" << location->name << ", azimuth " << sp.azimuth_deg << " deg, elevation "
                                  << sp.elevation_deg << " deg)";
      return (frame.T_world_ego.rotation.conjugate() * world).normalized();
    }
  }
  if (source) *source = "default (no location or time: sun 45 deg up, behind-left)";
  return from_ego_angles(150.0, 45.0);
}

Eigen::Vector3f MedianRoadColour(const ImageF& linear_image, const CameraSensor& camera,
                                 const std::vector<Eigen::Vector3d>& road_points_ego, int* samples) {
  const Rigid3d T_cam_ego = camera.T_ego_cam.Inverse();
  std::vector<float> ch[3];
  for (const auto& p : road_points_ego) {
    const auto uv = camera.intrinsics.Project(T_cam_ego * p, 1.0);
    if (!uv || !camera.intrinsics.InImage(*uv)) continue;
    float rgb[4];
    SampleBilinear(linear_image, uv->x(), uv->y(), rgb);
    for (int c = 0; c < 3; ++c) ch[c].push_back(rgb[c]);
  }
  *samples = static_cast<int>(ch[0].size());
  Eigen::Vector3f median = Eigen::Vector3f::Zero();
  if (ch[0].empty()) return median;
  for (int c = 0; c < 3; ++c) {
    std::nth_element(ch[c].begin(), ch[c].begin() + ch[c].size() / 2, ch[c].end());
    median[c] = ch[c][ch[c].size() / 2];
  }
  return median;
}

Lighting CalibrateLighting(const ImageF& linear_image, const CameraSensor& camera,
                           const std::vector<Eigen::Vector3d>& road_points_ego, const Eigen::Vector3d& sun_dir_ego,
                           const LightingOptions& options) {
  int samples = 0;
  Eigen::Vector3f road = MedianRoadColour(linear_image, camera, road_points_ego, &samples);
  if (samples < 20) {
    road = Eigen::Vector3f::Constant(0.08f);  // neutral mid exposure when the road is not visible
    SD_LOG(Debug, camera.channel << ": road not visible near the objects; neutral exposure");
  }
  const Eigen::Vector3f E = road * static_cast<float>(M_PI / options.road_albedo);  // horizontal irradiance
  Lighting l;
  l.sun_direction = sun_dir_ego.cast<float>().normalized();
  const float sin_el = std::max(0.2f, l.sun_direction.z());
  l.sun_irradiance = E * static_cast<float>(options.direct_fraction) / sin_el;
  l.sky_radiance = E * static_cast<float>((1.0 - options.direct_fraction) / M_PI);
  return l;
}

}  // namespace sd
