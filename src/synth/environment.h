#pragma once
// Image-based light for inserted objects: an HDR environment map stitched from a frame's surround cameras.
//
// Why: the road calibration in synth/lighting.h gives one sun and one uniform sky per camera. Real light is
// directional (a bright sky on one side, a dark building on the other) and the six cameras of a rig expose
// and white-balance independently, so objects seen by two cameras must be lit in one consistent unit.
//
// Map: lat-long, `width` x `width/2`, 3 channels of linear radiance in the ego frame (x forward, y left,
// z up). Column u has azimuth phi = pi - 2*pi*(u + 0.5)/width (counter-clockwise from ego +x, so the
// centre column looks forward and the left half of the image is the car's left); row v has elevation
// pi/2 - pi*(v + 0.5)/height (row 0 = zenith). Units are the linear pixel values of the reference camera
// (CAM_FRONT when present): camera k's linear pixel times `gains[k].Gain()` is map radiance. The sun is
// NOT in `radiance` (it is far brighter than one pixel can carry usefully); it is `sun_direction` +
// `sun_irradiance` (on a surface facing it, map units) + `sun_angular_radius_rad`.
//
// Build: images are linearised with the sRGB curve (the camera's tone curve is unknown; sRGB is the usual
// stand-in), area-averaged to the map's angular resolution, projected through each camera's intrinsics
// (distortion included) and rotation (the rig is treated as one point: the environment is far away),
// blended with weights that fall from 1 at the image centre to 0 at its border. Exposure and white balance:
// in every overlap of two cameras the median per-channel log ratio of their pixels (saturated and very dark
// ones left out) is one equation log g_i - log g_j = median(log I_j - log I_i); least squares over all
// overlaps with the reference camera fixed at gain 1. Sky no camera sees (above the cameras' vertical FOV)
// comes from a sky model fitted to the seen sky: per channel a non-negative mix of the CIE standard clear
// (type 12) and overcast (type 1) sky luminance distributions for the sun's position. Ground no camera
// sees (under the car) gets the median colour of the seen road band.
// Sun: the centroid of a small, round, saturated blob above the horizon, ringed by bright glare (a white sign
// is not), when a camera sees one, else the
// ephemeris direction passed in. Its intensity comes from the contrast of the road in and next to the real
// shadows of annotated objects: lit road / shadowed road = (E_sun sin(el) + E_sky) / (k E_sky) with E_sky the
// map's sky irradiance on the road and k the sky fraction a shadowed spot still sees; albedo cancels.
#include <array>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/box3.h"
#include "core/image.h"
#include "datasets/log.h"
#include "render/camera_render.h"
#include "render/ray_scene.h"

namespace sd {

// Lat-long pixel <-> ego direction (continuous pixel coordinates, centres at +0.5).
Eigen::Vector3d LatLongDirection(double u, double v, int width, int height);
Eigen::Vector2d LatLongPixel(const Eigen::Vector3d& dir_ego, int width, int height);

// CIE sky: a fitted non-negative mix of the standard clear and overcast relative luminance distributions.
struct SkyModel {
  Eigen::Vector3d sun_direction = Eigen::Vector3d(0, 0, 1);  // ego frame, unit
  Eigen::Vector3f clear = Eigen::Vector3f::Zero();     // per-channel zenith radiance of the clear component
  Eigen::Vector3f overcast = Eigen::Vector3f::Zero();  // per-channel zenith radiance of the overcast component
  Eigen::Vector3f Radiance(const Eigen::Vector3d& dir_ego) const;  // 0 below the horizon
};
// Relative luminance (1 at the zenith) of CIE standard sky type 12 (clear) or 1 (overcast).
double CieClearSky(const Eigen::Vector3d& dir, const Eigen::Vector3d& sun_dir);
double CieOvercastSky(const Eigen::Vector3d& dir);

struct CameraGain {
  std::string channel;
  float exposure = 1;                                    // luminance gain
  Eigen::Vector3f white_balance = Eigen::Vector3f::Ones();  // per-channel gain / exposure (Rec. 709 Y = 1)
  Eigen::Vector3f Gain() const { return exposure * white_balance; }
};

struct EnvironmentOptions {
  int width = 512;                       // map columns (rows = width / 2)
  bool estimate_gains = true;            // false: every gain is 1 (the "before" of the seam error)
  std::string reference_channel = "CAM_FRONT";  // gain 1; the first camera when absent
  std::optional<Eigen::Vector3d> ephemeris_sun_ego;  // fallback sun (SunDirectionEgo); default: straight up
  bool detect_sun_in_images = true;
  double sun_angular_radius_deg = 0.27;
  double shadow_sky_visibility = 0.8;    // k above: share of the sky a spot in a car's shadow still sees
  double default_direct_fraction = 0.65; // sun share of road irradiance when no real shadow can be measured
  int saturated_level = 250;             // 8-bit value from which a channel counts as clipped
  double min_overlap_elevation_deg = -8;  // overlaps below this (the near road: parallax) do not set gains
};

// Irradiance as order-2 spherical harmonics (Ramamoorthi & Hanrahan 2001): 9 RGB coefficients of the
// radiance, convolved with the clamped cosine on evaluation. Error < ~3% of the mean for smooth skies.
struct ShIrradiance {
  std::array<Eigen::Vector3f, 9> L{};  // radiance coefficients L_lm, order (0,0) (1,-1) (1,0) (1,1) (2,-2) (2,-1) (2,0) (2,1) (2,2)
  Eigen::Vector3f Irradiance(const Eigen::Vector3d& normal) const;  // E(n), unoccluded
};
ShIrradiance ProjectToSh(const ImageF& latlong_radiance);

struct EnvironmentMap {
  ImageF radiance;   // width x height x 3, linear, map units (see top), no sun
  ImageF coverage;   // width x height x 1, sum of camera blend weights (0 = sky model or ground fill)
  SkyModel sky;
  Eigen::Vector3d sun_direction = Eigen::Vector3d(0, 0, 1);
  std::string sun_source;              // "image (CAM_...)" or "ephemeris"
  Eigen::Vector3f sun_irradiance = Eigen::Vector3f::Zero();
  double sun_angular_radius_rad = 0;
  double sun_road_contrast = 0;        // measured lit/shadow road ratio (0 = none measured, default split used)
  // The sun checked against the real shadows of annotated objects (CheckSunAgainstShadows): how many objects
  // could be judged, and the share of them whose predicted shadow is darker than its mirror image.
  int shadow_objects = 0;
  double shadow_agreement = 0;
  std::vector<CameraGain> gains;       // parallel to frame.cameras
  // Median relative luminance difference |Y_i - Y_j| / mean(Y_i, Y_j) over all overlap pixels, with unit
  // gains and with the estimated gains; overlap_pixels = how many map pixels entered it.
  double seam_error_before = 0, seam_error_after = 0;
  int overlap_pixels = 0;
  // ProjectToSh(radiance), kept by BuildEnvironmentMap (every light made from the map needs it); empty in a map
  // put together by hand, whose readers then project it themselves (MapSh).
  std::optional<ShIrradiance> sh;
  // The luminance of `radiance`, kept by BuildEnvironmentMap likewise (the receiver's sky weights read it); empty
  // in a map put together by hand, whose lights then make their own (MakeEnvironmentLight).
  std::shared_ptr<const ImageF> luminance;

  int width() const { return radiance.width(); }
  int height() const { return radiance.height(); }
  Eigen::Vector3f Lookup(const Eigen::Vector3d& dir_ego) const;  // bilinear, no sun
  // Horizontal irradiance the upper hemisphere of `radiance` gives a surface facing up (no sun, no occlusion).
  Eigen::Vector3f SkyIrradianceUp() const;
};

// map.sh, or the projection of map.radiance where the map has none.
ShIrradiance MapSh(const EnvironmentMap& map);

// `images`: 8-bit sRGB, parallel to frame.cameras (same sizes as the calibrations). Throws InputError when a
// size disagrees.
EnvironmentMap BuildEnvironmentMap(const Frame& frame, const std::vector<ImageU8>& images,
                                   const EnvironmentOptions& options = {});

// Sun from the images alone: unit ego direction of a small (0.15-4 deg equivalent radius), round, saturated
// blob above 3 deg elevation whose surrounding ring averages >= 190 (8-bit luma), if any; the largest wins.
std::optional<Eigen::Vector3d> DetectSunInImages(const Frame& frame, const std::vector<ImageU8>& images,
                                                 int saturated_level = 250, std::string* channel = nullptr);

// ---- Lighting inserted objects from the map ----

// Everything a shading point needs, in map units (divide by a camera's gain for its pixels).
struct EnvironmentLight {
  ShIrradiance sh;
  const ImageF* radiance = nullptr;    // lat-long map for directional sky occlusion on the receiver (may be null)
  // The luminance of `radiance` (EnvironmentMap::luminance, MakeEnvironmentLight): what the receiver's sky weights
  // read. Null: they read `radiance` and take its luminance per sample (the same weights, to float rounding).
  std::shared_ptr<const ImageF> radiance_luminance;
  Eigen::Vector3d sun_direction = Eigen::Vector3d(0, 0, 1);
  Eigen::Vector3f sun_irradiance = Eigen::Vector3f::Zero();
  double sun_angular_radius_rad = 0.0047;
};
EnvironmentLight MakeEnvironmentLight(const EnvironmentMap& map);

struct EnvShadingOptions {
  int sun_rays = 16;      // shadow rays over the sun disk (soft shadows), a shifted pattern (core/sampling.h)
  int sky_rays = 32;      // cosine-weighted hemisphere rays (ambient occlusion)
  uint32_t seed = 1;
  int skip_mesh = -1;     // mesh never counted as an occluder (-1 none)
  float ray_offset = 1e-3f;  // metres along the normal before tracing
};
// Fraction of the sun disk visible from p (rays over the disk from the shifted pattern of core/sampling.h).
double SunVisibility(const RayScene& scene, const Eigen::Vector3d& p, const Eigen::Vector3d& normal,
                     const EnvironmentLight& light, const EnvShadingOptions& options = {});
// Unoccluded share of the cosine-weighted hemisphere around `normal` that lies above the horizon.
double AmbientOcclusion(const RayScene& scene, const Eigen::Vector3d& p, const Eigen::Vector3d& normal,
                        const EnvShadingOptions& options = {});
// Irradiance on an inserted object's surface: sun disk x max(0, n.l) x visibility + SH(n) x AO.
Eigen::Vector3f ObjectIrradiance(const RayScene& scene, const Eigen::Vector3d& p, const Eigen::Vector3d& normal,
                                 const EnvironmentLight& light, const EnvShadingOptions& options = {});
// Multiplier for the real road photo at receiver point p: Y(E with the inserted objects) / Y(E without), the
// sun as a disk (soft shadow) and the sky weighted by the map's radiance in each blocked direction (AO that
// knows where the bright sky is). `options.skip_mesh` must be the receiver itself. 1 when nothing blocks.
float ReceiverShadowRatio(const RayScene& scene, const Eigen::Vector3d& p, const Eigen::Vector3d& normal,
                          const EnvironmentLight& light, const EnvShadingOptions& options = {});

// Drop-in for CameraRender::shadow (render/camera_render.h) with soft shadows and radiance-weighted AO: for each
// pixel of the rectangle [x0, x1) x [y0, y1) (all zero = whole image) a ray through the pixel centre; where it
// first hits `receiver_mesh`, the ratio ReceiverShadowRatio estimates there (per-pixel seed from options.seed);
// elsewhere 1. Its economy over calling ReceiverShadowRatio per pixel (bench_road_shade): the sun's disk is traced
// only within the widest penumbra of the edges of its centre's hard shadow; elsewhere the disk is wholly seen or
// wholly hidden, as its centre is.
ImageF ReceiverShadowImage(const RayScene& scene, const PinholeCamera& camera, const Rigid3d& T_scene_cam, int receiver_mesh,
                           const EnvironmentLight& light, const EnvShadingOptions& options = {}, int x0 = 0, int y0 = 0,
                           int x1 = 0, int y1 = 0);
// The same with a light per receiver face: the receiver of several objects is made of their patches, each under
// the light where its object stands (sun or shade). `light_of_face[f]` (non-null) for every face f of
// `receiver_mesh`. Only the pixels of `rects` ({x0, y0, x1, y1}, their union; empty = the whole image) are
// shaded: each object's own rectangle, so the road between objects far apart costs nothing.
ImageF ReceiverShadowImage(const RayScene& scene, const PinholeCamera& camera, const Rigid3d& T_scene_cam, int receiver_mesh,
                           const std::vector<const EnvironmentLight*>& light_of_face, const EnvShadingOptions& options = {},
                           const std::vector<std::array<int, 4>>& rects = {});

// The existing renderer's (render/camera_render.h) two-term light for camera k, from the map: the same sun,
// and the uniform sky that gives the map's SH irradiance on an upward surface; both in camera k's pixel units.
Lighting RendererLighting(const EnvironmentMap& map, size_t camera_index);

}  // namespace sd
