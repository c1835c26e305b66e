#pragma once
// How an inserted object measures against the real objects of the same image: the statistics a detector could
// tell them apart by. Each object, real or inserted, is measured the same way over its projected 3D box (the
// near-plane-clipped outline of geometry/box_projection) in the final image:
//  - noise: the 20th percentile, over the 8x8 JPEG-grid blocks inside the outline, of each block's residual
//    sigma (synth/camera_look.h BlockNoiseSigma, green) over the image's own noise model at the block's level;
//    1 is the image's flat-region noise, more is grain or texture;
//  - edge rise: the median 10-90 % rise of the strong step edges inside the outline (EdgeRiseWidths);
//  - saturation: the 90th percentile of the outline's pixels' HSV saturation (camera_look.h OutlineSaturation).
#include <array>
#include <filesystem>
#include <functional>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/box3.h"
#include "core/image.h"
#include "datasets/log.h"
#include "synth/camera_look.h"
#include "synth/real_shadows.h"

namespace sd {

struct ObjectLook {
  std::string category;
  bool inserted = false;
  double noise_ratio = 0;  // NaN-free: 0 with no block inside the outline (noise_blocks 0)
  int noise_blocks = 0;
  double edge_rise_px = 0;  // 0 with no edge found (edges 0)
  int edges = 0;
  double saturation = 0;
  int pixels = 0;  // inside the outline and the image
};

// Measures `box_ego` (ego frame) in `image` of `camera`, against the image's `look` (its noise model).
ObjectLook MeasureObjectLook(const ImageU8& image, const CameraSensor& camera, const Box3& box_ego, const CameraLook& look);

// How many pixels the outline MeasureObjectLook measures over holds (the projected box, near-plane clipped; as a
// mask: ObjectOutlinesMask).
int OutlinePixels(const CameraSensor& camera, const Box3& box_ego);
// Its saturation alone (ObjectLook::saturation); 0 with no pixel inside the image.
double MeasureSaturation(const ImageU8& image, const CameraSensor& camera, const Box3& box_ego, int* pixels = nullptr);

// The projected outlines of `boxes_ego` in `camera`'s image as a mask (1 inside), skipping outlines of fewer
// than `min_pixels` pixels inside the image: where the real objects of an image are.
ImageF ObjectOutlinesMask(const CameraSensor& camera, const std::vector<Box3>& boxes_ego, int min_pixels);
// The pixels (x, y) of one box's outline, the same as its mask: for per-object work that should not touch the
// whole image.
std::vector<std::pair<int, int>> ObjectOutlinePixels(const CameraSensor& camera, const Box3& box_ego);

// Mean and spread of a statistic over objects, for the ratio inserted / real.
struct LookComparison {
  int real = 0, inserted = 0;
  double real_noise = 0, inserted_noise = 0;            // medians over objects with noise blocks
  double real_edge_rise = 0, inserted_edge_rise = 0;    // medians over objects with edges
  double real_saturation = 0, inserted_saturation = 0;  // medians
};
LookComparison CompareLooks(const std::vector<ObjectLook>& objects);

// The colour reference of the camera look's saturation cap (camera_look.h CapSaturation), for each of
// `categories` (canonical names), over the real objects of the category in `frames` of `log` and all their cameras
// (MeasureSaturation; projected outlines of at least 288 pixels), and how many views it rests on: the most
// saturated of them, since cars and trucks come in every paint; but for categories with a standard livery (cones,
// barriers, warning tripods, A-frame signs, portable traffic lights: HasStandardLivery) seen in three views or
// more, their median, since one near, sunlit cone would otherwise set the ceiling for all.
// Images are read only where such an object is seen. A planned sequence takes one reference over all its frames,
// so an object's colour does not change between frames that show a real one and frames that do not.
// `image` (optional): camera `camera` of frame `frame`'s photograph, where the caller has it decoded already.
using FrameImage = std::function<const ImageU8&(size_t frame, size_t camera)>;
bool HasStandardLivery(const std::string& canonical_category);
std::map<std::string, SaturationReference> RealSaturation(const Log& log, const std::vector<size_t>& frames,
                                                          const std::set<std::string>& categories,
                                                          const FrameImage& image = nullptr);

// Can a classifier tell inserted objects from real ones by these statistics? Features per object: log noise
// ratio, log edge rise, saturation (a missing measure takes the median of all objects'); an L2-regularised
// logistic regression on standardised features, classes weighted to equal mass, scored by balanced accuracy over
// stratified k-fold cross-validation (k = min(5, the smaller class)). 0.5 is chance: the inserts measure like the
// real objects; 1.0: every one is told apart. Deterministic (folds by order of appearance within each class).
struct TwoSampleTest {
  int real = 0, inserted = 0;
  int folds = 0;                  // 0: a class has fewer than two objects, no figure
  double balanced_accuracy = 0;   // mean of the two classes' recall over the held-out folds
  std::array<double, 3> weights{};  // the model fitted on all objects (standardised features), for reading
  nlohmann::json ToJson() const;
};
TwoSampleTest ClassifyRealVsInserted(const std::vector<ObjectLook>& objects);

// Cast shadows: how much an object's shadow darkens the road, inserts against the real objects of the same frame.
// Every object 0.5 m tall or more within 25 m, real or inserted, is judged in the camera that sees it nearest its
// image centre (real_shadows.h CheckSunAgainstShadows on the final images, with the sun the frame was lit by; the
// road another box hides is left out): the contrast of the road its shadow should cover against the same road
// mirrored through its footprint, 20th percentiles of linear luminance (ShadowCheckBox::CoreContrast). 1 is no
// visible shadow; a sunlit scene's real objects read 1.5-4. Objects whose mirrored road another box's shadow or
// footprint reaches are left out (that road is no reference). `inserted`: (category, box in the ego frame);
// `linear`: the frame's final images, linear, parallel to frame.cameras.
struct ShadowContrast {
  std::string frame, channel, category;
  bool inserted = false;
  double contrast = 0;
};
std::vector<ShadowContrast> MeasureShadowContrasts(const Frame& frame,
                                                   const std::vector<std::pair<std::string, Box3>>& inserted,
                                                   const LinearImages& linear, const Eigen::Vector3d& sun_dir_ego);
struct ShadowComparison {
  int real = 0, inserted = 0;
  double real_contrast = 0, inserted_contrast = 0;  // medians; 0 with none
};
ShadowComparison CompareShadows(const std::vector<ShadowContrast>& shadows);

// Contact darkening at an object's foot, inserts against the real objects of the same frame (real_shadows.h
// CheckContactDarkening on the final images, outside every box's shadow for `sun_dir_ego` when known): the
// median linear luminance of the road 0.6-1 m from its footprint over that of the road 3-20 cm from it. 1 is
// none: an object that does not darken the ground it stands on looks pasted onto it.
struct ContactDarkening {
  std::string frame, channel, category;
  bool inserted = false;
  double darkening = 0;
};
std::vector<ContactDarkening> MeasureContactDarkening(const Frame& frame,
                                                      const std::vector<std::pair<std::string, Box3>>& inserted,
                                                      const LinearImages& linear,
                                                      const std::optional<Eigen::Vector3d>& sun_dir_ego);
struct ContactComparison {
  std::string category;  // "" = all objects
  int real = 0, inserted = 0;
  double real_darkening = 0, inserted_darkening = 0;  // medians; 0 with none
};
// All objects first, then each category that has inserted objects.
std::vector<ContactComparison> CompareContacts(const std::vector<ContactDarkening>& contacts);

// `synthdrive eval realism`: every frame and camera of a synth output, its inserted objects (synth.json) and the
// real annotated objects of the original log (synth.json "log") measured in the output images, the noise model
// from the original image. InputError naming the file for a folder without synth.json, an original log that is
// gone, or an output image that is missing.
struct RealismRow {
  std::string frame, channel;
  ObjectLook look;
};
struct RealismSummary {
  std::string category;  // "" = all objects
  LookComparison comparison;
};
struct RealismReport {
  std::vector<RealismRow> rows;
  std::vector<RealismSummary> summaries;  // all objects first, then per category with inserted objects
  TwoSampleTest classifier;               // over all objects
  std::vector<ShadowContrast> shadows;    // frames that record their sun (synth.json sun_direction_ego)
  ShadowComparison shadow;
  std::vector<ContactDarkening> contacts;
  std::vector<ContactComparison> contact;  // CompareContacts(contacts)
  nlohmann::json ToJson() const;
};
RealismReport EvaluateRealism(const std::filesystem::path& synth_out);

}  // namespace sd
