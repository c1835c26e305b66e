#pragma once
// Light for inserted objects: sun direction and the sun/sky intensities that make them sit in the photo.
//
// Sun direction: from the scenario when given; else from the solar ephemeris (NOAA's low-precision
// algorithm, ~0.5 deg) at the frame's UTC time when the log's location is known, turned into the ego
// frame through the ego pose (nuScenes' global frame is x east, y north); else a default high afternoon sun.
//
// Intensities are calibrated per camera from the real road next to the objects: the road is taken as a
// grey Lambertian surface of albedo `road_albedo`, so its linear pixel colour L gives the horizontal
// irradiance E = pi * L / albedo — colour included, which matches white balance and exposure to the
// camera. E is split into sun and sky by `direct_fraction`.
//
// synth/environment.h goes further: an HDR environment map stitched from all cameras (exposure/white-balance
// gains per camera, fitted sky, sun from the images or this ephemeris, sun intensity from real shadows).
#include <optional>
#include <vector>

#include <Eigen/Core>

#include "core/image.h"
#include "datasets/log.h"
#include "render/camera_render.h"
#include "synth/scenario.h"

namespace sd {

struct SolarPosition {
  double azimuth_deg = 0;    // clockwise from north
  double elevation_deg = 0;  // above the horizon (no refraction)
};
SolarPosition ComputeSolarPosition(double unix_seconds, double latitude_deg, double longitude_deg);

// Unit vector towards the sun in the ego frame, and a note saying where it came from.
Eigen::Vector3d SunDirectionEgo(const Frame& frame, const std::optional<GeoLocation>& location,
                                const std::optional<SunSpec>& override_sun, std::string* source = nullptr);

struct LightingOptions {
  double road_albedo = 0.15;      // asphalt is 0.05-0.2
  double direct_fraction = 0.65;  // share of horizontal irradiance from the sun (clear sky ~0.7-0.85)
};

// Per-channel median of the linear image under those of `road_points_ego` (ego frame) that project into it;
// `samples` receives how many did (0: the median is zero).
Eigen::Vector3f MedianRoadColour(const ImageF& linear_image, const CameraSensor& camera,
                                 const std::vector<Eigen::Vector3d>& road_points_ego, int* samples);

// `road_points_ego`: ground points near the objects, ego frame. Falls back to a neutral mid-grey exposure
// when fewer than 20 of them project into the image.
Lighting CalibrateLighting(const ImageF& linear_image, const CameraSensor& camera,
                           const std::vector<Eigen::Vector3d>& road_points_ego, const Eigen::Vector3d& sun_dir_ego,
                           const LightingOptions& options = {});

}  // namespace sd
