#pragma once
// Sequence planning: where inserted objects stand, ONCE, in the world frame of a log, for a whole sequence of
// frames, so a world-fixed object appears consistently in every frame (synth/scenario.h "arrangements";
// docs/sequence_placement.md).
//
// Frames and units: world = the log's world frame (Frame::T_world_ego), metres, radians inside, degrees in
// the JSON. An object's frame is the canonical asset frame (origin at the centre of its ground contact, x
// forward, z up along the local surface normal); its box is the geometric centre, size = (l, w, h).
// Positions along the road are expressed on the EGO PATH: the polyline of the planned frames' ego positions,
// arc length s from the first planned frame (continued straight beyond both ends), lateral offset left (+).
//
// Why the constraints are what they are: an inserted object is static and exists at every time of the
// sequence, so it must be clear of the space EVERY real object occupies at ANY time, not just at the same
// frame. The obstacle set is therefore the union over frames of every annotated box in world space, plus what
// a moving object sweeps between keyframes (2 Hz keyframes let a 15 m/s car jump 7.5 m): consecutive boxes of
// one track (instance_token) are interpolated; boxes without a track but with a velocity (mmdet3d v0 infos)
// are swept along it until the next keyframe. The ego's own boxes (options.ego_box at every frame, interpolated
// the same way) are obstacles too: the real ego drove where it drove, so an object in its lane can only stand
// beyond the point the ego reaches within the planned frames (choose the frame range / distance accordingly;
// the error says how far the ego gets). Collisions are tested on footprints (z ignored): annotated objects
// stand on the road, and a wrong surface height must not hide an overlap.
#include <cstddef>
#include <cstdint>
#include <limits>
#include <map>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include "core/box3.h"
#include "core/rigid3.h"
#include "datasets/log.h"
#include "synth/camera_look.h"
#include "synth/scenario.h"
#include "synth/surface.h"

namespace sd {

// Half-open [begin, end) frame indices; end is clamped to the log's frame count.
struct FrameRange {
  size_t begin = 0;
  size_t end = std::numeric_limits<size_t>::max();
};

// The ego path (see the file comment). Knots closer than 1 m are merged, so a standing ego does not make the
// heading noisy; a path shorter than that is a straight line along the first frame's ego heading.
class EgoPath {
 public:
  EgoPath(const std::vector<Rigid3d>& T_world_ego);
  double length() const { return s_.back(); }
  // World xy of the point `lateral` metres left of the path at arc length s.
  Eigen::Vector2d At(double s, double lateral = 0) const;
  double Heading(double s) const;  // radians, world, direction of travel
  // Closest path point: (s, lateral) of `xy`.
  Eigen::Vector2d Project(const Eigen::Vector2d& xy) const;

 private:
  size_t Segment(double s) const;
  std::vector<Eigen::Vector2d> knots_;
  std::vector<double> s_;  // arc length at each knot
  std::vector<Eigen::Vector2d> dir_;  // unit direction of each segment (one entry for a single-knot path)
};

// Sizes of the assets the render will use (assetgen AssetInfo id/category/extent). Without them, a category
// stands for its canonical default size (datasets/categories.h) and asset_id stays empty.
struct PlanAsset {
  std::string id, category;
  Eigen::Vector3d extent = Eigen::Vector3d::Zero();
};

struct SequencePlanOptions {
  std::vector<PlanAsset> assets;
  // The ego vehicle in its own frame (nuScenes / AV2: origin at the rear axle on the ground): a Renault Zoe-
  // sized box by default.
  Box3 ego_box{Rigid3d(Eigen::Quaterniond::Identity(), Eigen::Vector3d(1.35, 0, 0.8)), Eigen::Vector3d(4.3, 1.9, 1.6)};
  double range_m = 60;            // per-frame gate: object centre within this distance of the ego
  bool require_visible = true;    // reject objects that no frame sees (in range and inside a camera image)
  int max_candidates = 2000;      // per arrangement instance (a whole cone line or breakdown is one candidate)
  double max_frame_gap_s = 2.0;   // consecutive planned frames further apart are not one sequence: InputError
  double sweep_step_m = 0.25;     // spacing of interpolated boxes of moving objects and the ego
};

struct PlannedObject {
  std::string source;  // "arrangements[1]" or "objects[0]"
  int arrangement = -1, request = -1;  // index into Scenario::arrangements / Scenario::objects (the other is -1)
  std::string role;    // "cone", "object", "clutter", "vehicle", "warning"
  std::string category, asset_id;  // asset_id empty: any asset of the category at its default size
  Rigid3d T_world_object;          // object (ground-contact) frame -> world
  Box3 box;                        // world frame, geometric centre
  double path_s = 0, path_lateral = 0;  // where it was placed on the ego path
};

// One planned object seen from one frame. T_ego_object = inv(T_world_ego) * T_world_object exactly.
struct PlannedView {
  Rigid3d T_ego_object;
  Box3 box_ego;
  double distance_m = 0;  // horizontal, ego origin to box centre
  bool in_range = false;
  std::vector<std::string> cameras;  // channels whose image contains the box centre (in front of the camera)
  bool visible = false;              // in range and (in some camera, or the frame has no cameras)
};

struct PlannedFrame {
  size_t frame_index = 0;
  std::string token;
  double timestamp = 0;
  std::vector<PlannedView> objects;  // parallel to SequencePlan::objects
};

// Why candidates were rejected, per arrangement / object request.
struct PlanStats {
  std::string source;
  int placed = 0, candidates = 0, off_surface = 0, off_drivable = 0, hits_ego_path = 0, overlaps_real = 0,
      overlaps_placed = 0, in_ego_lane = 0, never_visible = 0;
  std::string Summary() const;
};

struct SequencePlan {
  size_t frame_begin = 0, frame_end = 0;
  uint32_t seed = 0;
  double margin_m = 0;
  double ego_path_length_m = 0;
  size_t annotated_boxes = 0, tracks = 0, swept_boxes = 0;  // obstacle set: keyframe boxes, track ids, extra boxes
  std::vector<size_t> unannotated_frames;  // frames whose boxes are unknown (warned: not checked against)
  std::vector<PlannedObject> objects;
  std::vector<PlannedFrame> frames;
  std::vector<PlanStats> stats;
  // Per planned category: the most saturated real object over the sequence's frames (synth/realism.h
  // RealSaturation), the camera look's colour reference for every frame alike. Filled by PlanSynthesis when it
  // plans for rendering.
  std::map<std::string, SaturationReference> colour_reference;
};

// Plans every arrangement, then every plain object request (their distance_m / lateral_m read as path
// coordinates), in scenario order; each draws from its own generator seeded by (scenario.seed, index), so the
// same seed gives the same plan. InputError when the range is empty or spans a time gap, when a category or
// asset is unknown, or when an arrangement finds no valid candidate (the message counts each rejection).
SequencePlan PlanSequence(const Log& log, const Scenario& scenario, const SurfaceModel& surface, FrameRange frames = {},
                          const SequencePlanOptions& options = {});

// The dry-run report: frames, seed, every object's world pose and size, per frame its ego-frame pose, distance,
// gates and cameras, and the rejection counts.
nlohmann::json PlanToJson(const SequencePlan& plan);

// Footprint overlap (z ignored) with the BoxesOverlap margin convention: closer than `margin` counts.
bool FootprintsOverlap(const Box3& a, const Box3& b, double margin);

}  // namespace sd
