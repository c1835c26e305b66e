#include "synth/object_light.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"
#include "synth/lighting.h"

namespace sd {
namespace {

float Luma(const Eigen::Vector3f& rgb) { return 0.2126f * rgb[0] + 0.7152f * rgb[1] + 0.0722f * rgb[2]; }

}  // namespace

ObjectLight LightAtObjects(const EnvironmentMap& map, size_t camera_index, const CameraSensor& camera,
                           const ImageF& linear_image, const std::vector<Eigen::Vector3d>& road_points_ego,
                           const ObjectLightOptions& options) {
  SD_CHECK(options.road_albedo > 0 && options.shade_sky_visibility >= 0 && options.shade_sky_visibility < 1,
           << "albedo " << options.road_albedo << ", shade sky visibility " << options.shade_sky_visibility);
  ObjectLight out;
  out.lighting = RendererLighting(map, camera_index);
  out.shading = MakeEnvironmentLight(map);
  const Eigen::Vector3f road = MedianRoadColour(linear_image, camera, road_points_ego, &out.road_samples);
  if (out.road_samples < options.min_road_samples) {
    out.road_samples = 0;
    return out;
  }
  const double v = options.shade_sky_visibility;
  const double sin_el = std::max(0.0f, out.lighting.sun_direction.z());
  const double Y_sun = Luma(out.lighting.sun_irradiance) * sin_el;       // on the road, full sun
  const double Y_sky = M_PI * Luma(out.lighting.sky_radiance);           // on the road, whole sky
  const double Y_road = M_PI * Luma(road) / options.road_albedo;         // what the photo's road receives
  if (Y_sky <= 0 && Y_sun <= 0) return out;                              // a black map: nothing to scale
  double s = 1.0;
  const double slope = Y_sun + (1 - v) * Y_sky;                          // d(irradiance) / ds
  if (slope > 0) s = std::clamp((Y_road - v * Y_sky) / slope, 0.0, 1.0);
  const double sky_share = s + (1 - s) * v;
  const double predicted = s * Y_sun + sky_share * Y_sky;
  out.sun_visibility = s;
  out.scale = predicted > 0 ? Y_road / predicted : 1.0;
  out.lighting.sun_irradiance *= static_cast<float>(s * out.scale);
  out.lighting.sky_radiance *= static_cast<float>(sky_share * out.scale);
  out.shading.sun_irradiance *= static_cast<float>(s);
  return out;
}

}  // namespace sd
