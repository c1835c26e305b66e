#pragma once
// A spinning LiDAR's measurable behaviour, fitted from one real sweep, so that objects inserted into that
// sweep are sampled the way the real sensor samples the rest of the scene (docs/lidar.md).
//
// Frames and units: the sweep in its sensor frame (x, y, z metres; spin axis = z), angles in radians,
// azimuth = atan2(y, x), elevation = atan2(z - z_offset, hypot(x, y)), times in seconds from the sweep start.
//
//  - Beam pattern: one LidarBeam per laser. Lasers come from the sweep's ring feature ("ring", nuScenes;
//    "laser_number", AV2) where present; otherwise (KITTI) from the record order: the scan lines are stored one
//    after another, each one full turn, so laser k holds the records of the k-th turn of the unwrapped azimuth.
//    Per laser, (hypot(x, y), z) of every return of a raw (not de-skewed) sweep lies on a cone
//    z = tan(elevation) * hypot + z_offset; where the sweep's lasers do (KITTI: apex offsets 0.12-0.2 m) the
//    cone is fitted, which removes the bias the offset puts on near returns. Motion-compensated sweeps
//    (nuScenes, AV2) are not exact cones: elevation = median angle, z_offset = 0.
//  - Range noise: sigma(r) = noise_sigma0 + noise_sigma_slope * r, from ground returns' residuals to local
//    planes (1.5 m cells), converted to range by the incidence angle; only cos(incidence) >= 0.2 is used.
//  - Dropout: per range bin, the fraction of firing slots that returned nothing between two consecutive
//    ground returns of the same laser (a gap in a ring on flat ground: the beam should have hit).
//  - Intensity: I = reflectivity(category) * cos(incidence)^intensity_exponent, the exponent fitted on ground
//    returns (log-log least squares; 1 = Lambertian), reflectivities as medians of I / cos^n over the ground
//    and over the points of annotated boxes (incidence from the nearest box face).
//  - Timing: where the records carry a per-point time ("time", "timestamp", "offset_ns"), spin rate and direction
//    come from it; otherwise from the options, and the firing time of a direction is derived from its azimuth.
#include <algorithm>
#include <cmath>
#include <map>
#include <string>
#include <utility>
#include <vector>

#include "core/box3.h"
#include "core/pointcloud.h"

namespace sd {

struct LidarBeam {
  int laser = 0;               // the sweep's own laser id (ring feature) or the inferred scan-line index
  double elevation = 0;        // radians
  double z_offset = 0;         // metres: cone apex on the spin axis
  double azimuth_step = 0;     // radians between consecutive firings of this laser
  int firing_position = -1;    // rank of the laser's first record in the sweep (firing order), -1 unknown
  int returns = 0;             // real returns of this laser in the sweep
};

struct LidarModel {
  std::vector<LidarBeam> beams;  // ascending elevation
  bool rings_from_feature = false;
  double azimuth_step = 0;       // median over beams, radians
  int firings_per_revolution = 0;  // records per laser on a complete firing grid, else round(2 pi / step)

  // Timing.
  double spin_hz = 10;
  int spin_direction = -1;       // +1: azimuth grows with time (counter-clockwise seen from above), -1: clockwise
  double start_azimuth = M_PI;   // azimuth of the first firing of the sweep
  bool timing_from_data = false; // spin rate/direction measured from a per-point time feature

  // Range noise: 1-sigma range error in metres at range r.
  double noise_sigma0 = 0, noise_sigma_slope = 0;
  int noise_samples = 0;

  // Dropout: probability that a beam that meets a surface returns nothing, per range bin [edge_k, edge_k+1).
  std::vector<double> dropout_range_edges;  // size = dropout_probability.size() + 1
  std::vector<double> dropout_probability;
  std::vector<int> dropout_slots;           // slots seen per bin (support)

  // Intensity.
  int intensity_feature = -1;     // index in the sweep's records, -1 when the sweep has none
  double intensity_exponent = 1;  // cos^n
  double intensity_rms_log = 0;   // rms of the log-log fit residual (fitted n)
  double intensity_rms_log_lambertian = 0;  // same with n = 1
  double ground_reflectivity = 0;
  std::map<std::string, double> category_reflectivity;  // canonical category name -> reflectivity
  float intensity_max = 0;

  double SweepPeriod() const { return spin_hz > 0 ? 1.0 / spin_hz : 0.1; }
  // Seconds after the sweep start at which the beam at `azimuth` fires, in [0, SweepPeriod()).
  double FiringTime(double azimuth) const;
  double RangeSigma(double range) const { return std::max(0.0, noise_sigma0 + noise_sigma_slope * range); }
  double DropoutProbability(double range) const;
  // Intensity of a return on `category` (canonical or dataset name) at |cos incidence| `cos_incidence`;
  // unknown categories use ground_reflectivity x the category's relative reflectivity. Clamped to [0, max].
  float Intensity(const std::string& category, double cos_incidence) const;
  std::string Summary() const;
};

struct LidarFitOptions {
  // Annotated boxes in the SENSOR frame, with the dataset's category names (for per-category reflectivity).
  std::vector<std::pair<std::string, Box3>> annotated;
  double spin_hz = 0;           // 0: from a time feature, else 20 Hz for a complete 32-laser firing-ordered
                                // sweep (HDL-32E firing cycle 46.08 us), else 10 Hz
  int spin_direction = 0;       // 0: from the time feature or the record order of one laser; else forced
  double start_azimuth = NAN;   // NaN: the first record's azimuth (firing-ordered sweeps) or pi
  double min_range = 1.0;       // records closer than this are "no return" markers (nuScenes) or the ego body
};

// InputError when the sweep has too few points to fit (fewer than 1000) or no laser with 100 returns.
LidarModel FitLidarModel(const PointCloud& sweep, const LidarFitOptions& options = {});

}  // namespace sd
