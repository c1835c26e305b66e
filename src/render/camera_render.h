#pragma once
// Rendering inserted objects into a real camera image by ray tracing.
//
// The scene (RayScene) holds the inserted objects and one "receiver" mesh: the real road surface near
// them. Rays that hit an object produce colour, coverage and depth; rays that hit the receiver produce a
// shadow ratio — how much of the light the road received is now blocked by the objects — which the
// compositor multiplies into the real photo (the real road keeps its own texture and exposure).
//
// Radiometry (linear RGB, arbitrary but consistent units): a Lambertian surface with albedo a and normal n
// receives E = sun_irradiance * max(0, n.l) * V_sun + sky_radiance * pi * AO, where V_sun is the sun's
// visibility (shadow ray) and AO the unoccluded fraction of the cosine-weighted sky hemisphere (above
// the horizon). Radiance L = a * E / pi. Callers calibrate sun/sky from the real image (synth/lighting).
#include <vector>

#include <Eigen/Core>

#include "core/camera.h"
#include "core/image.h"
#include "core/rigid3.h"
#include "render/ray_scene.h"

namespace sd {

struct Lighting {
  Eigen::Vector3f sun_direction = Eigen::Vector3f(0, 0, 1);  // unit, scene frame, pointing towards the sun
  Eigen::Vector3f sun_irradiance = Eigen::Vector3f::Constant(3.0f);  // linear RGB, on a surface facing the sun
  Eigen::Vector3f sky_radiance = Eigen::Vector3f::Constant(0.3f);    // linear RGB, uniform sky
  // The sky is the upper hemisphere around +z of the scene frame.
};

struct CameraRenderOptions {
  int samples_per_pixel = 4;   // stratified sub-pixel samples (anti-aliased edges); perfect square preferred
  int ao_samples = 16;         // hemisphere rays for sky visibility per shaded sample
  int receiver_mesh = -1;      // mesh id of the road receiver (shadows only, never drawn); -1 = none
  // Pixel rectangle to render [x0, x1) x [y0, y1); outside it the result is "no object, no shadow".
  // Default (all zero) = the whole image.
  int x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  uint32_t seed = 1;           // sampling is deterministic given the seed
};

struct CameraRender {
  ImageF color;      // 3 channels, linear radiance of objects, premultiplied by coverage
  ImageF coverage;   // 1 channel, 0..1 fraction of sub-samples that hit an object
  ImageF depth;      // 1 channel, nearest object depth along the camera z axis (metres); +inf where none
  Image<int> object; // 1 channel, mesh id of the object hit by most sub-samples; -1 where none
  ImageF shadow;     // 1 channel, multiplier for the real image where the receiver is seen (1 = unchanged)
};

// Renders `scene` seen by a camera with intrinsics `camera` at pose T_scene_cam (OpenCV camera frame).
CameraRender RenderCamera(const RayScene& scene, const PinholeCamera& camera, const Rigid3d& T_scene_cam,
                          const Lighting& lighting, const CameraRenderOptions& options = {});

}  // namespace sd
