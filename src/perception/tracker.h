#pragma once
// Multi-frame tracking of detected objects (perception/lidar_objects.h) in the WORLD frame of a log, so a
// parked car stays put while the ego drives past it and a moving one gets a velocity.
//
// Method, and why:
//  - Each track is a constant-velocity Kalman filter on the detection's seen centre (DetectedObject::seen_center)
//    in world xy: state (x, y, vx, vy), process noise a white acceleration of `accel_sigma` m/s^2 (the discrete
//    Wiener model, Bar-Shalom et al., "Estimation with Applications to Tracking and Navigation", sec. 6.3.2),
//    measurement noise `position_sigma` metres (an L-shape centre moves with the visible sides as the view
//    changes).
//  - Association per frame: greedy on BEV centre distance between predicted tracks and detections, shortest
//    pair first, gated by `gate_m` + `max_speed` x dt (a car at 15 m/s moves 1.5 m between 10 Hz sweeps; a 2 Hz
//    keyframe log needs the speed term; a pedestrian's or small object's gate grows by `max_speed_small`, so a
//    coasting cone cannot take a passer-by's detection metres away). Greedy rather than Hungarian: with a gate
//    this tight the two rarely differ, and ties resolve in a fixed order (track id, then detection index), so the
//    result is deterministic. A detection whose class disagrees with the track's most frequent class (vehicle
//    against pedestrian or small object) joins it only within `gate_m`, without the speed allowance: a car's odd
//    partial view may read as a small box, but a cone beside a parked car must not take the car's track when the
//    car is not detected.
//  - Birth: every unmatched detection starts a tentative track. A track is confirmed after `min_hits` matched
//    frames. Death: after `max_misses` consecutive frames without a match, or when its last match is more than
//    `max_coast_s` seconds old.
//  - Output per frame: every matched detection of a track with at least `min_hits` hits by the end of the
//    sequence (its earlier frames included: a track confirmed at its second sweep keeps its first), the box where
//    the detection put it, heading from the velocity when the track moves faster than `moving_speed` and than
//    twice the filter's velocity standard deviation (a box fitted to a partial view has a 90-degree ambiguity;
//    motion has none; two sweeps 0.1 s apart with 10 cm of jitter make 1 m/s of "speed"), and the track's
//    velocity. With `min_hits` = 1 every detection is output: for keep-out, an object seen once is still there.
#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/rigid3.h"
#include "perception/lidar_objects.h"

namespace sd::perception {

struct TrackOptions {
  double position_sigma = 0.3;   // metres, measurement noise of a box centre
  double accel_sigma = 2.0;      // m/s^2, white-acceleration process noise
  double initial_speed_sigma = 10.0;  // m/s, velocity uncertainty at birth
  double gate_m = 1.5;           // association gate at dt = 0, metres
  double max_speed = 20.0;       // m/s: the gate of a vehicle (or unclassed) track grows by this x dt
  double max_speed_small = 4.0;  // m/s: ... of a pedestrian or small-object track (a person runs, a cone stands)
  int min_hits = 1;              // matched frames before a track's boxes are output
  int max_misses = 3;            // consecutive unmatched frames before a track dies
  double max_coast_s = 1.5;      // seconds since its last match before a track dies
  double moving_speed = 1.0;     // m/s: faster tracks take their heading from the velocity
};

// One frame's detections and where the ego was.
struct TrackFrameInput {
  double timestamp = 0;          // seconds; strictly increasing over the sequence
  Rigid3d T_world_ego;
  std::vector<DetectedObject> detections;  // ego frame
};

struct TrackedObject {
  int track_id = 0;              // 1, 2, ... in birth order over the sequence
  Box3 box;                      // ego frame of its frame, geometric centre
  ObjectClass object_class = ObjectClass::kOther;  // the track's most frequent class
  Eigen::Vector2d velocity_ego = Eigen::Vector2d::Zero();  // m/s, world velocity in the frame's ego axes
  Eigen::Vector2d velocity_world = Eigen::Vector2d::Zero();
  int num_points = 0;
  int detection = -1;            // index into the frame's detections
};

struct TrackStats {
  int tracks = 0, output_tracks = 0, detections = 0, output_boxes = 0;
};

// Tracks one sequence. Returns one vector per input frame. InputError when timestamps do not increase (the
// message names the frame index), or when a pose or timestamp is not finite.
std::vector<std::vector<TrackedObject>> TrackObjects(const std::vector<TrackFrameInput>& frames,
                                                     const TrackOptions& options = {}, TrackStats* stats = nullptr);

}  // namespace sd::perception
