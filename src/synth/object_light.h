#pragma once
// The light falling on inserted objects in one camera's view: the frame's environment map (synth/environment.h)
// for where light comes from, the real road next to the objects for how much of it arrives there.
//
// The map knows the sun's direction, how road irradiance splits between sun and sky (E_sun sin(el) / E_sky,
// measured at real shadows or the default split) and each camera's exposure and white balance. It cannot know
// two things: the absolute level where the sky clips (its sky is then a lower bound), and whether the sun
// reaches the spot the objects stand on (the shade of a building or a tree the sweep does not reach). Both
// come from the real road next to the objects in this camera, taken as a grey Lambertian surface of albedo
// `road_albedo` (the assumption synth/lighting.h's CalibrateLighting makes): the light is chosen so that this
// road under it has the luminance the photo shows,
//   Y_road = rho / pi * scale * (s * E_sun sin(el) + (s + (1 - s) v) * E_sky),
// by the sun's visibility s in [0, 1] first (full sun, penumbra, shade; a shaded spot still sees the share v
// = `shade_sky_visibility` of the sky), and by the overall `scale` only where no s explains the road (brighter
// than full sun: clipped sky; darker than shade). Objects get the same s and sky share; their cast shadows are
// drawn with the sun dimmed by s (no hard sun shadow inside a building's shade).
//
// Per object: the pipeline decides each object's sun visibility once, from the road next to it as every camera
// shows it (SunVisibilityAt, in map units), so an object seen by two cameras is in the sun in both or in neither;
// each camera then fits only the scale to its own view of that road (LightAtObjects with the verdict).
#include <optional>
#include <vector>

#include <Eigen/Core>

#include "core/image.h"
#include "datasets/log.h"
#include "render/camera_render.h"
#include "synth/environment.h"

namespace sd {

struct ObjectLightOptions {
  double road_albedo = 0.15;          // as LightingOptions::road_albedo
  double shade_sky_visibility = 0.6;  // sky share seen from a spot in a building's or tree's shade
  int min_road_samples = 20;          // fewer road pixels in view: the map's light as it is
};

struct ObjectLight {
  Lighting lighting;         // for RenderCamera, in this camera's linear pixel units
  EnvironmentLight shading;  // for ReceiverShadowImage: the map's light with the sun dimmed by sun_visibility
  double sun_visibility = 1;
  double scale = 1;
  int road_samples = 0;      // road pixels the verdict rests on (0: none in view, map light unchanged)
};

// `map` must outlive the result (`shading` points into it). `linear_image`: camera `camera_index` of the
// frame (map.gains is parallel to frame.cameras), linearised; `road_points_ego`: ground points near the
// objects, ego frame. `sun_visibility`: a verdict made for all cameras (SunVisibilityAt); then only the scale
// is fitted to this camera's road (1 where it sees too little of it).
ObjectLight LightAtObjects(const EnvironmentMap& map, size_t camera_index, const CameraSensor& camera,
                           const ImageF& linear_image, const std::vector<Eigen::Vector3d>& road_points_ego,
                           const ObjectLightOptions& options = {}, std::optional<double> sun_visibility = std::nullopt);

// The sun's visibility at a spot, decided once for every camera: the road next to it as each camera shows it,
// brought to map units by the camera's gain, pooled (median). Per camera, a view that sees only the sunlit part
// of that road and a view that sees only its shaded part would light the same object differently.
struct SunVerdict {
  double sun_visibility = 1;
  int road_samples = 0;  // pooled road pixels; 0: fewer than min_road_samples, no verdict
};
// `images`: the frame's photographs (sRGB), parallel to frame.cameras and map.gains; null entries are skipped.
SunVerdict SunVisibilityAt(const EnvironmentMap& map, const Frame& frame, const std::vector<const ImageU8*>& images,
                           const std::vector<Eigen::Vector3d>& road_points_ego, const ObjectLightOptions& options = {});

}  // namespace sd
