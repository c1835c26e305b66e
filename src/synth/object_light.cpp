#include "synth/object_light.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"
#include "synth/lighting.h"

namespace sd {
namespace {

float Luma(const Eigen::Vector3f& rgb) { return LinearLuminance(rgb.data()); }

// Road irradiance terms (luminance, on a horizontal surface) and the sun visibility that explains `Y_road`.
struct RoadTerms {
  double Y_sun = 0, Y_sky = 0;  // full sun; whole sky
  double SunVisibility(double Y_road, double v) const {
    const double slope = Y_sun + (1 - v) * Y_sky;  // d(irradiance) / ds
    return slope > 0 ? std::clamp((Y_road - v * Y_sky) / slope, 0.0, 1.0) : 1.0;
  }
  double Predicted(double s, double v) const { return s * Y_sun + (s + (1 - s) * v) * Y_sky; }
};

void CheckOptions(const ObjectLightOptions& options) {
  SD_CHECK(options.road_albedo > 0 && options.shade_sky_visibility >= 0 && options.shade_sky_visibility < 1,
           << "albedo " << options.road_albedo << ", shade sky visibility " << options.shade_sky_visibility);
}

}  // namespace

ObjectLight LightAtObjects(const EnvironmentMap& map, size_t camera_index, const CameraSensor& camera,
                           const ImageF& linear_image, const std::vector<Eigen::Vector3d>& road_points_ego,
                           const ObjectLightOptions& options, std::optional<double> sun_visibility) {
  CheckOptions(options);
  ObjectLight out;
  out.lighting = RendererLighting(map, camera_index);
  out.shading = MakeEnvironmentLight(map);
  const Eigen::Vector3f road = MedianRoadColour(linear_image, camera, road_points_ego, &out.road_samples);
  const bool seen = out.road_samples >= options.min_road_samples;
  if (!seen) out.road_samples = 0;
  if (!seen && !sun_visibility) return out;
  const double v = options.shade_sky_visibility;
  const double sin_el = std::max(0.0f, out.lighting.sun_direction.z());
  const RoadTerms terms{Luma(out.lighting.sun_irradiance) * sin_el, M_PI * Luma(out.lighting.sky_radiance)};
  if (terms.Y_sky <= 0 && terms.Y_sun <= 0) return out;                  // a black map: nothing to scale
  const double Y_road = M_PI * Luma(road) / options.road_albedo;         // what the photo's road receives
  const double s = sun_visibility ? std::clamp(*sun_visibility, 0.0, 1.0) : terms.SunVisibility(Y_road, v);
  const double sky_share = s + (1 - s) * v;
  const double predicted = terms.Predicted(s, v);
  out.sun_visibility = s;
  out.scale = seen && predicted > 0 ? Y_road / predicted : 1.0;
  out.lighting.sun_irradiance *= static_cast<float>(s * out.scale);
  out.lighting.sky_radiance *= static_cast<float>(sky_share * out.scale);
  out.shading.sun_irradiance *= static_cast<float>(s);
  return out;
}

SunVerdict SunVisibilityAt(const EnvironmentMap& map, const Frame& frame, const std::vector<const ImageU8*>& images,
                           const std::vector<Eigen::Vector3d>& road_points_ego, const ObjectLightOptions& options) {
  CheckOptions(options);
  SD_CHECK(images.size() == frame.cameras.size() && map.gains.size() == frame.cameras.size(),
           << images.size() << " images, " << map.gains.size() << " gains, " << frame.cameras.size() << " cameras");
  std::vector<double> Y;  // road irradiance per sample, map units
  for (size_t k = 0; k < frame.cameras.size(); ++k) {
    if (!images[k]) continue;
    const CameraSensor& cam = frame.cameras[k];
    const Rigid3d T_cam_ego = cam.T_ego_cam.Inverse();
    const Eigen::Vector3f gain = map.gains[k].Gain();
    for (const auto& p : road_points_ego) {
      const auto uv = cam.intrinsics.Project(T_cam_ego * p, 1.0);
      if (!uv || !cam.intrinsics.InImage(*uv)) continue;
      float rgb[4];
      SampleBilinear(*images[k], uv->x(), uv->y(), rgb);
      Eigen::Vector3f linear;
      for (int c = 0; c < 3; ++c) linear[c] = SrgbToLinear(rgb[c] / 255.0f) * gain[c];
      Y.push_back(M_PI * Luma(linear) / options.road_albedo);
    }
  }
  SunVerdict out;
  if (static_cast<int>(Y.size()) < options.min_road_samples) return out;
  std::nth_element(Y.begin(), Y.begin() + Y.size() / 2, Y.end());
  const double sin_el = std::max(0.0, map.sun_direction.normalized().z());
  const RoadTerms terms{Luma(map.sun_irradiance) * sin_el, Luma(MapSh(map).Irradiance(Eigen::Vector3d::UnitZ()))};
  out.road_samples = static_cast<int>(Y.size());
  out.sun_visibility = terms.SunVisibility(Y[Y.size() / 2], options.shade_sky_visibility);
  return out;
}

}  // namespace sd
