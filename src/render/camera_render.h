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
#include <array>
#include <cstdint>
#include <optional>
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
  // Hemisphere rays for sky visibility per shaded sub-sample. (Sharing one set of 16 among a pixel's 4 sub-samples
  // was tried: twice the grain, visible as speckle in the concave parts of a car at full resolution.)
  int ao_samples = 16;
  // > 0: the sky is estimated once per surface a pixel shows (one mesh, normals alike), not once per sub-sample,
  // and denoised. Every sub-sample still traces its own `ao_samples` sky rays (from its own hit point) and its own
  // sun ray, all of a pixel's rays in packets; each surface's open-sky share is then averaged over the same
  // surface in the pixels within this radius (a joint bilateral filter guided by the hit points, the shading
  // normals and the pixel footprint), and multiplies the surface's albedo-weighted sky. With a quarter of the rays, less error than
  // the rays alone over a surface and a little more within 2 pixels of an edge: DenoisedSkyAgainstAConvergedRender
  // in camera_render_test.cpp, bench_sky_filter in bench/RESULTS.md.
  // 0: every sub-sample is shaded by its own rays alone (the reference path). The receiver's shadow (when
  // receiver_shadow) is shaded the same way in both.
  int sky_filter_radius = 0;
  int receiver_mesh = -1;      // mesh id of the road receiver (shadows only, never drawn); -1 = none
  bool receiver_shadow = true; // false: the receiver only blocks rays (shadow stays 1): for callers that shade it themselves
  // Per-mesh light (indexed by mesh id; empty: `lighting` for every mesh): objects standing in the sun and in a
  // shade within one view. The receiver's shadow uses `lighting`.
  std::vector<Lighting> mesh_lighting;
  // Pixel rectangle to render [x0, x1) x [y0, y1); outside it the result is "no object, no shadow".
  // Default (all zero) = the whole image.
  int x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  // When not empty, the rectangles {x0, y0, x1, y1} to render instead (their union; the one above is ignored):
  // each object's own, so the space between objects far apart costs nothing.
  std::vector<std::array<int, 4>> rects;
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
// All five images have the camera's full size; pixels outside the rectangle hold the "nothing" values
// (colour 0, coverage 0, depth +inf, object -1, shadow 1).
//
// Sampling: sub-pixel positions are stratified on a ceil(sqrt(spp)) grid with hash jitter seeded by
// (seed, pixel), so a pixel's result does not depend on threads or on the rectangle. AO directions are
// cosine-weighted around the shading normal: a correlated multi-jittered pattern shifted per shaded sub-sample
// (core/sampling.h).
// Object samples (any mesh other than receiver_mesh): L = a * E / pi with a = BaseColor().rgb (alpha is
// ignored), normals flipped to face the camera (double-sided), the sun visibility traced with one shadow
// ray and AO = fraction of the ao_samples directions that point above the horizon (z > 0) and are
// unoccluded by any mesh but the receiver. The receiver stands in for the real road: it never hides an object
// from the camera (primary rays find objects through it) nor shades one (a patch laid on a kerb's slope would
// otherwise rise over a neighbouring object). Shadow and AO rays start at the hit point offset along
// the geometric normal by 2e-5 * (1 + max |coordinate|) metres.
// Receiver samples: ratio = Y(E_with_objects) / Y(E_without_objects), where Y is Rec. 709 luminance of the
// irradiance formula above and visibility there ignores the receiver itself (the real photo already holds
// the road's own shading; only the shadow the inserted objects add is wanted). One ratio (not per RGB)
// because `shadow` is a single-channel multiplier; where the light without objects is zero the ratio is 1.
// The same AO directions serve numerator and denominator so that their noise is correlated.
CameraRender RenderCamera(const RayScene& scene, const PinholeCamera& camera, const Rigid3d& T_scene_cam,
                          const Lighting& lighting, const CameraRenderOptions& options = {});

// Pixel rectangle {x0, y0, x1, y1} (half-open, clamped to the image) covering the projections of those
// `points_scene` that lie in front of the camera (z > 1 mm), grown by `pad` pixels on each side. Use it to
// restrict RenderCamera to the region of objects and their shadows (pass the corners of the objects' boxes
// and of their shadows on the ground). Points behind the camera are ignored, so a box that straddles the
// image plane should be clipped by the caller or rendered whole. Empty when no point is in front of the
// camera or the rectangle misses the image.
std::optional<std::array<int, 4>> ProjectedRect(const PinholeCamera& camera, const Rigid3d& T_cam_scene,
                                                const std::vector<Eigen::Vector3d>& points_scene, int pad);

// Row y of a union of pixel rectangles {x0, y0, x1, y1} (half-open): its merged [x0, x1) spans, left to right,
// clamped to [0, width). For stages that compute around each object rather than over their common bounds.
std::vector<std::pair<int, int>> RowSpans(const std::vector<std::array<int, 4>>& rects, int y, int width);
// The rows [first, last) the non-empty rectangles cover, clamped to [0, height); first >= last when none.
std::pair<int, int> RowRange(const std::vector<std::array<int, 4>>& rects, int height);

}  // namespace sd
