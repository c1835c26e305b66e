#pragma once
// The real shadows of a frame's annotated objects, read from its camera images: where a box's shadow falls for a
// sun direction (ShadowHull), whether the road there is darker than the same road mirrored through the box's
// footprint (CheckSunAgainstShadows), and the sun direction whose shadows best explain the images
// (EstimateSunFromShadows). The environment map checks and estimates its sun with them (environment.h); the
// realism figures measure inserted objects' shadows against the real ones with them (realism.h).
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/box3.h"
#include "core/image.h"
#include "datasets/log.h"

namespace sd {

// A frame's camera images read as linear light, parallel to frame.cameras: float images (ToLinear), or the 8-bit
// sRGB images themselves read through the sRGB table and scaled by a gain per camera at each sample (the
// environment map's exposure and white balance). The checks below read a few thousand ground cells of a rig, so
// the second form spares the float copies (17 MB per 1600x900 camera) with the same values, bit for bit. A view:
// the images (and the vector) must outlive it.
class LinearImages {
 public:
  LinearImages(const std::vector<ImageF>& linear);  // NOLINT(google-explicit-constructor): float images pass as they are
  // `gains` empty: 1 for every camera; otherwise one per image.
  explicit LinearImages(const std::vector<ImageU8>& srgb, std::vector<Eigen::Vector3f> gains = {});
  size_t size() const { return linear_ ? linear_->size() : srgb_->size(); }
  // SampleBilinear of image k (core/image.h): its channels' linear values at (u, v).
  void SampleBilinear(size_t k, double u, double v, float* out) const;

 private:
  const std::vector<ImageF>* linear_ = nullptr;
  const std::vector<ImageU8>* srgb_ = nullptr;
  std::vector<Eigen::Vector3f> gains_;
};

// Ground polygon (ego frame, z = box bottom, convex, counter-clockwise) covered by the box's footprint and its
// shadow for a sun direction; `mirrored` reflects the shadow through the footprint (the "no shadow" control).
std::vector<Eigen::Vector2d> ShadowHull(const Box3& box, const Eigen::Vector3d& sun_dir_ego, bool mirrored = false);

struct ShadowCheckOptions {
  double min_height_m = 0.8;     // objects shorter than this cast too small a shadow to judge
  double max_distance_m = 25;
  double cell_m = 0.1;           // ground sampling step
  double footprint_margin_m = 0.15;  // ground this close to the footprint is left out (the object's own base)
  int min_cells = 25;            // visible cells needed on each side
};

struct ShadowCheckBox {
  size_t annotation = 0;
  std::string channel;
  double shadow_luminance = 0, mirrored_luminance = 0;  // mean linear Y in the predicted / mirrored region
  double Ratio() const { return shadow_luminance > 0 ? mirrored_luminance / shadow_luminance : 0; }
  // The 20th percentiles of the same two regions: the shadow's core, which a thin object's shadow (a cone's, a
  // fraction of its box's shadow hull) still fills, against the same statistic of the road it would darken.
  double shadow_core_luminance = 0, mirrored_core_luminance = 0;
  double CoreContrast() const { return shadow_core_luminance > 0 ? mirrored_core_luminance / shadow_core_luminance : 0; }
};
struct ShadowCheck {
  std::vector<ShadowCheckBox> boxes;  // the objects that could be judged
  double agreement = 0;        // share of them whose predicted shadow is darker than the mirrored region
  double mean_log_ratio = 0;   // mean of log(mirrored / shadow) clamped to [-1, 1]: > 0 when the sun explains the dark side
};
// `linear`: the frame's camera images, linear (ToLinear), parallel to frame.cameras. Each annotated box is
// judged in the camera that sees it closest to its image centre; ground cells hidden behind any annotated
// box (ray-box test from the camera) are left out.
ShadowCheck CheckSunAgainstShadows(const Frame& frame, const LinearImages& linear, const Eigen::Vector3d& sun_dir_ego,
                                   const ShadowCheckOptions& options = {});
// The sun direction (5 deg azimuth x 10 deg elevation grid, elevation 20..80) whose shadows best explain the
// images: the largest mean_log_ratio x sqrt(objects judged). With `elevation_deg`, only the azimuth is searched
// (shadow length is the weak cue; a known elevation, e.g. the ephemeris', makes it an azimuth check). Empty
// when no box can be judged.
std::optional<Eigen::Vector3d> EstimateSunFromShadows(const Frame& frame, const LinearImages& linear,
                                                      const ShadowCheckOptions& options = {}, ShadowCheck* best = nullptr,
                                                      std::optional<double> elevation_deg = std::nullopt);

// Contact darkening: the road right beside a box's footprint against the road a little farther out, both outside
// every box's sun shadow. The object hides part of the sky (and of the bright surroundings) from the ground at its
// foot; that darker rim is how a viewer reads an object as standing on the road rather than pasted over it. Each
// box 0.3 m tall or more within 25 m is judged in the camera that sees it nearest its image centre; ground
// hidden behind a box, inside another box's footprint or in any box's shadow (`sun_dir_ego`, when known) is
// left out.
struct ContactCheckOptions {
  double min_height_m = 0.3;
  double max_distance_m = 25;
  double cell_m = 0.03;
  double near_from_m = 0.03, near_to_m = 0.2;  // the band beside the footprint (from its edge)
  double far_from_m = 0.6, far_to_m = 1.0;     // the reference road around it
  int min_cells = 12;                          // visible cells needed in each band
};
struct ContactCheckBox {
  size_t annotation = 0;
  std::string channel;
  double near_luminance = 0, far_luminance = 0;  // medians of linear Y
  double Darkening() const { return near_luminance > 0 ? far_luminance / near_luminance : 0; }  // 1 = none
};
std::vector<ContactCheckBox> CheckContactDarkening(const Frame& frame, const LinearImages& linear,
                                                   const std::optional<Eigen::Vector3d>& sun_dir_ego,
                                                   const ContactCheckOptions& options = {});

}  // namespace sd
