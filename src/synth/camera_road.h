#pragma once
// Road points from the cameras alone, for logs that have no LiDAR: plane-sweep stereo over road heights between
// a frame's cameras and the same cameras in neighbouring frames of the log (known poses).
//
// Method (per camera of the reference frame):
//  1. Images are read once per (frame, camera), turned grey, shrunk by `downsample` (box filter: less noise,
//     fewer pixels) and, where the calibration has distortion, resampled once onto the ideal pinhole of the
//     same K, so every later step is a plain homography.
//  2. Sources: the same camera channel in up to `neighbours` frames before and after, only when
//     `Log::sequential` and the time gap is at most `max_gap`, and only where the camera moved at least
//     `min_baseline` (a parked car gives no parallax, only cost).
//  3. For each grid pixel (every `stride` working pixels) whose ray points below the prior plane's horizon and
//     hits it within `max_range`, the horizontal plane z = prior + h of the reference ego frame is swept,
//     h in [-search, +search] by `step`. Each plane is a homography reference -> source,
//     H(h) = K_s (R_sc + t_sc n_c^T / d(h)) K_r^-1, with the plane n_c^T X_c = d(h) in the reference camera.
//     Score = mean over the sources that see the warped patch of the zero-mean normalised cross-correlation
//     (NCC) of the (2 `patch` + 1)^2 patch, sampled bilinearly. Coarse to fine (about 5x faster): the cost
//     curve is every second height with every second patch sample; the full patch then scores the heights
//     next to the coarse best.
//  4. The best height is refined by a parabola through its neighbours' scores and accepted only when
//       - the score is at least `min_ncc` and the patch has texture (grey std >= `min_texture`),
//       - the minimum is distinct: every hypothesis whose patch centre lands more than `peak_px` working pixels
//         away (in the source with the most parallax) scores at least `min_margin` lower — texture-less asphalt
//         and repeated patterns give flat or multi-modal curves and are rejected rather than guessed,
//       - the peak is resolved inside the range (neither end of the sweep lies within `peak_px` of it: a height
//         at the range's edge is an object above or a hole below the road, not the road), and
//       - one working pixel of parallax spans at most `max_height_per_px` metres of height (far points and
//         points near the epipole have no height resolution), and
//       - a vertical plane facing the camera through the found point does not explain the patch at least as
//         well (the back of a car, a kerb's face: surfaces within the searched heights that are not road).
//  5. The accepted point is the pixel's ray hitting the plane at the refined height, in the reference ego frame.
// Deterministic (rows run in parallel, results kept in grid order). The plane is horizontal in the reference
// ego frame: a tilted road costs a little correlation (the patch is small), not a bias.
#include <string>
#include <vector>

#include <Eigen/Core>

#include "datasets/log.h"

namespace sd {

struct CameraRoadOptions {
  double max_range = 40;           // metres from the ego origin (horizontal), on the prior plane
  double search = 0.6;             // +- metres of road height searched around the prior plane
  double step = 0.01;              // height step of the sweep, metres
  int downsample = 2;              // the images are shrunk by this factor before matching (1 = full resolution)
  int stride = 4;                  // grid of reference pixels, in working (downsampled) pixels
  int patch = 5;                   // NCC patch half-size, working pixels
  double min_ncc = 0.7;            // acceptance: the best mean NCC
  double min_margin = 0.1;         // acceptance: best NCC minus the best NCC away from the peak
  double peak_px = 1.5;            // "away from the peak": the patch centre moved this far (working pixels)
  double max_height_per_px = 0.1;  // acceptance: metres of height per working pixel of parallax, at most
  double min_texture = 2.0;        // grey standard deviation (0..255) a reference patch needs
  // Frames before and after used as sources (same camera channel). On PandaSet 002 (slow urban traffic) 2 moved the
  // points onto the carriageway ahead and lowered the p90 a little, but found fewer points in all at 1.5x the time
  // (bench_camera_road --neighbours 2), so 1.
  int neighbours = 1;
  double max_gap = 0.6;            // seconds between the reference and a source frame, at most
  double min_baseline = 0.1;       // metres the camera must have moved for a source to be used
  // A road point more than `outlier_tolerance` off the median height of its neighbours within `outlier_radius`
  // (metres, all cameras; fewer than 3 neighbours: no verdict) is dropped as a mismatch.
  double outlier_radius = 1.0, outlier_tolerance = 0.06;
  // Scene points: where a grid pixel is not road, the camera's fronto-parallel planes are swept too (inverse depths
  // evenly between 1 / min_depth and 1 / max_depth), with the same acceptance, for what stands on the road (the
  // depth occlusion and placement need where there is no sweep).
  bool scene_points = false;
  double min_depth = 1.5, max_depth = 40;  // metres along the optical axis
  int depth_steps = 96;
  double max_depth_share_per_px = 0.05;    // acceptance: one working pixel of parallax spans at most this share of the depth
};

struct CameraRoadResult {
  std::vector<Eigen::Vector3d> points_ego;  // accepted road points, ego frame of the reference frame, metres
  std::vector<int> camera_of;               // index into frame.cameras of the camera each point came from
  // CameraRoadOptions::scene_points: points of the surfaces that are not road (cars, poles, walls, kerbs' faces),
  // ego frame; empty otherwise.
  std::vector<Eigen::Vector3d> scene_points_ego;
  int pixels_tried = 0;                     // grid pixels below the horizon and within range, with a source
  int pixels_accepted = 0;                  // road points kept
  int outliers = 0;                         // road points dropped as off their neighbours' height
  int source_views = 0;                     // (camera, neighbouring frame) pairs used as sources
  int cameras_used = 0;                     // reference cameras with at least one source
  std::vector<std::string> skipped;         // one line per view left out (missing image, no source, ...)
  std::string summary;  // one line: "stereo over N source views of M cameras: K of P pixels accepted" or why none
};

// Road points of `log.frames[frame_index]` from its cameras and the same channels in neighbouring frames.
// `prior_ground_z`: the road height in the ego frame to search around (0 where the ego origin lies on the road —
// nuScenes, AV2; PandaSet's ego origin is 0.30 m above the road, so -0.30; KITTI's Velodyne frame -1.73).
// No neighbouring frame (a single keyframe, a non-sequential log, gaps over `max_gap`): no points, and the
// summary says so. A missing image file leaves its view out (listed in `skipped`); an image that exists but
// cannot be decoded, or whose size disagrees with its calibration, throws InputError naming the file.
CameraRoadResult EstimateRoadFromCameras(const Log& log, size_t frame_index, double prior_ground_z,
                                         const CameraRoadOptions& options = {});

}  // namespace sd
