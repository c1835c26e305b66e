#pragma once
// Keep-out tracks for logs without labels: obstacles detected and tracked from each frame's own LiDAR sweep
// (perception/lidar_objects.h, perception/tracker.h) on the road this module already estimates (GroundModel, one
// sweep), written into the Log as Annotations so placement (synth/placement.h) and sequence planning
// (synth/sequence_plan.h) keep inserted objects clear of them exactly as they do of annotated tracks.
// docs/detection.md gives the method, the parameters and the figures measured against hidden annotations.
//
// What a detected Annotation holds: `detected` = true; category "detected.vehicle" | "detected.pedestrian" |
// "detected.small_object" | "detected.other" (no canonical category knows these names on purpose: a guessed
// class is never a real object's reference for the colour cap, LiDAR intensity or realism); box in the ego frame,
// geometric centre; instance_token "detected:<sequence>-<track>" (one per track, so planning interpolates a
// moving track between frames); token "detected:<frame token>:<k>"; velocity in the ego frame (m/s);
// num_lidar_pts = the cluster's obstacle returns. The frame's has_annotations becomes true.
// Never labels: the writers (datasets/writers.h) write only a FrameEdit's added objects besides the input's own
// records, and COCO's real boxes skip detected ones.
#include <cstddef>
#include <limits>
#include <string>
#include <vector>

#include "datasets/log.h"
#include "perception/lidar_objects.h"
#include "perception/tracker.h"
#include "synth/ground.h"

namespace sd {

// Which frames get detected tracks (`synthdrive synth --detect-objects`).
enum class DetectObjectsMode {
  kOff,          // none: frames without boxes are planned against their LiDAR obstacles only (and warned about)
  kUnannotated,  // frames whose source carries no boxes (Frame::has_annotations == false); the default
  kAlways,       // every frame with a sweep, annotated or not: detections are added next to the annotations, as
                 // extra keep-out for what the labels miss (unlabelled parked bikes, bins, posts)
};
const char* ToString(DetectObjectsMode mode);
// "off", "unannotated", "always"; InputError naming the option otherwise.
DetectObjectsMode DetectObjectsModeFromString(const std::string& word);

struct DetectTracksOptions {
  DetectObjectsMode mode = DetectObjectsMode::kUnannotated;
  perception::DetectOptions detect;  // sensor_xy and the ego body are set per frame from the log
  perception::TrackOptions track;
  double max_frame_gap_s = 2.0;      // frames further apart are tracked as separate sequences
  // Only log frames [first, last) are considered (synth: the span of the selected frames, so a one-frame
  // selection in a long log does not detect over all of it).
  size_t first = 0, last = std::numeric_limits<size_t>::max();
};

struct DetectTracksReport {
  int frames = 0;                 // frames given detected boxes
  int frames_without_sweep = 0;   // frames that wanted them but have no sweep on disk (left unannotated)
  int sequences = 0, tracks = 0, boxes = 0;
  int by_class[4] = {0, 0, 0, 0};  // tracks per perception::ObjectClass
  double seconds = 0;
  std::string Summary() const;    // one line for the log
};

// The obstacles of one frame's own sweep (read from disk), ego frame. The ground is GroundModel::Estimate of
// this sweep, with the frame's annotated boxes (if any) kept out of it. InputError when the frame has no sweep
// or the sweep cannot be read.
std::vector<perception::DetectedObject> DetectFrameObjects(const Frame& frame, const Log& log,
                                                           const perception::DetectOptions& options = {});

// Each point's height above the lowest road the sweep's height field (GroundModel) observed within `window`
// metres (a square of cells) of it. Why not HeightAboveGround directly: the height field follows grades, so a
// cell whose only returns are an object's lowest ones (a barrier at 25 m hides the road behind it; the field
// accepts steps of 8 cm + 8 % of the range) reads as road and the object as ground. The lowest road nearby
// is what the object stands on; on a grade the window costs 8 % x `window` (8 cm) of height, well under
// DetectOptions::min_height.
std::vector<float> HeightsAboveLowestGround(const GroundModel& ground, const std::vector<Eigen::Vector3d>& points_ego,
                                            double max_range, double window = 1.0);

// Fills the frames `options.mode` selects with detected tracks (see the file comment). Frames are cut into
// sequences where consecutive selected frames are more than max_frame_gap_s apart, or where the log is not
// sequential (KITTI object frames: each alone). Deterministic.
DetectTracksReport AddDetectedTracks(Log* log, const DetectTracksOptions& options = {});

// Removes every box of the log (the benchmark's "hide the annotations"): annotations cleared, has_annotations
// false.
void HideAnnotations(Log* log);

}  // namespace sd
