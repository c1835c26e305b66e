#include "synth/detected_tracks.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <filesystem>
#include <optional>
#include <sstream>

#include "core/error.h"
#include "core/log.h"
#include "datasets/readers.h"
#include "synth/frame.h"
#include "synth/ground.h"

namespace sd {
namespace fs = std::filesystem;
namespace {

bool Wanted(const Frame& f, DetectObjectsMode mode) {
  switch (mode) {
    case DetectObjectsMode::kOff: return false;
    case DetectObjectsMode::kUnannotated: return !f.has_annotations;
    case DetectObjectsMode::kAlways: return true;
  }
  return false;
}

bool SweepOnDisk(const Frame& f) {
  std::error_code ec;
  return f.lidar && fs::is_regular_file(f.lidar->path, ec);
}

// The ego body the detector ignores. Where the ego origin is on the road (nuScenes, Argoverse 2: the rear axle),
// DetectOptions' default car around it; where the ego frame is a sensor's or a roof reference (KITTI's Velodyne,
// PandaSet's pose), a 5 m x 2.2 m car centred under the LiDAR.
void SetEgoBody(const Log& log, const Frame& f, perception::DetectOptions* o) {
  o->sensor_xy = f.lidar->T_ego_lidar.translation.head<2>();
  if (!log.ego_origin_on_ground) {
    o->ego_body_min = o->sensor_xy + Eigen::Vector2d(-2.5, -1.1);
    o->ego_body_max = o->sensor_xy + Eigen::Vector2d(2.5, 1.1);
  }
}

}  // namespace

std::vector<float> HeightsAboveLowestGround(const GroundModel& ground, const std::vector<Eigen::Vector3d>& points_ego,
                                            double max_range, double window) {
  // The height field's z at each cell centre (observed cells only; elsewhere the seed plane), then its minimum
  // over the window, a separable min filter.
  const double cell = ground.cell();
  const int half = static_cast<int>(std::ceil(max_range / cell)) + 1, n = 2 * half + 1;
  const int r = std::max(0, static_cast<int>(std::lround(window / cell)));
  std::vector<float> z(static_cast<size_t>(n) * n), tmp(z.size());
  auto centre = [&](int i) { return (i - half) * cell; };
  for (int iy = 0; iy < n; ++iy)
    for (int ix = 0; ix < n; ++ix) {
      const double x = centre(ix), y = centre(iy);
      const double seed = ground.seed_plane().HeightAt(x, y);
      z[static_cast<size_t>(iy) * n + ix] =
          static_cast<float>(ground.IsObserved(x, y) ? -ground.HeightAboveGround(Eigen::Vector3d(x, y, 0)) : seed);
    }
  for (int iy = 0; iy < n; ++iy)
    for (int ix = 0; ix < n; ++ix) {
      float m = z[static_cast<size_t>(iy) * n + ix];
      for (int d = -r; d <= r; ++d)
        if (ix + d >= 0 && ix + d < n) m = std::min(m, z[static_cast<size_t>(iy) * n + ix + d]);
      tmp[static_cast<size_t>(iy) * n + ix] = m;
    }
  for (int iy = 0; iy < n; ++iy)
    for (int ix = 0; ix < n; ++ix) {
      float m = tmp[static_cast<size_t>(iy) * n + ix];
      for (int d = -r; d <= r; ++d)
        if (iy + d >= 0 && iy + d < n) m = std::min(m, tmp[static_cast<size_t>(iy + d) * n + ix]);
      z[static_cast<size_t>(iy) * n + ix] = m;
    }
  std::vector<float> height(points_ego.size());
  for (size_t i = 0; i < points_ego.size(); ++i) {
    const Eigen::Vector3d& p = points_ego[i];
    const int ix = static_cast<int>(std::lround(p.x() / cell)) + half, iy = static_cast<int>(std::lround(p.y() / cell)) + half;
    if (ix < 0 || iy < 0 || ix >= n || iy >= n) {
      height[i] = static_cast<float>(ground.HeightAboveGround(p));  // beyond max_range: not an obstacle candidate anyway
      continue;
    }
    height[i] = static_cast<float>(p.z() - z[static_cast<size_t>(iy) * n + ix]);
  }
  return height;
}

const char* ToString(DetectObjectsMode mode) {
  switch (mode) {
    case DetectObjectsMode::kOff: return "off";
    case DetectObjectsMode::kUnannotated: return "unannotated";
    case DetectObjectsMode::kAlways: return "always";
  }
  return "off";
}

DetectObjectsMode DetectObjectsModeFromString(const std::string& word) {
  for (DetectObjectsMode m : {DetectObjectsMode::kOff, DetectObjectsMode::kUnannotated, DetectObjectsMode::kAlways})
    if (word == ToString(m)) return m;
  throw InputError("", "--detect-objects: unknown mode '" + word + "' (give off, unannotated or always)");
}

std::string DetectTracksReport::Summary() const {
  std::ostringstream s;
  s << "detected " << tracks << " track(s) (" << by_class[0] << " vehicle, " << by_class[1] << " pedestrian, " << by_class[2]
    << " small object, " << by_class[3] << " other; " << boxes << " boxes) from LiDAR in " << frames << " frame(s) without "
    << "annotations, " << sequences << " sequence(s), " << Fixed(seconds, 1) << " s; keep-out only, never written as labels";
  if (frames_without_sweep > 0) s << "; " << frames_without_sweep << " frame(s) have no sweep on disk and stay unannotated";
  return s.str();
}

std::vector<perception::DetectedObject> DetectFrameObjects(const Frame& frame, const Log& log,
                                                           const perception::DetectOptions& options) {
  if (!frame.lidar) throw InputError(log.source, "frame " + frame.token + " has no LiDAR sweep to detect objects in");
  const PointCloud sweep = ReadLidar(*frame.lidar);
  const std::vector<Eigen::Vector3d> points_ego = PointsInEgo(frame, sweep);
  perception::DetectOptions o = options;
  SetEgoBody(log, frame, &o);
  if (points_ego.empty()) return {};
  // The road of this sweep, as synthesis estimates it (synth/frame.cpp EstimateFrameGround): a second LiDAR
  // merged into the sweep is left out of the road fit, annotated boxes (kAlways) are not road.
  std::vector<Box3> annotated;
  for (const Annotation& a : frame.annotations) annotated.push_back(a.box);
  GroundOptions g;
  g.sensor_xy = o.sensor_xy;
  g.max_range = std::max(g.max_range, o.max_range);
  g.ego_body_min = o.ego_body_min;
  g.ego_body_max = o.ego_body_max;
  const GroundModel ground = GroundModel::Estimate(points_ego, annotated, g, SecondSensorReturns(frame, sweep));
  return perception::DetectObjects(points_ego, HeightsAboveLowestGround(ground, points_ego, o.max_range), o);
}

DetectTracksReport AddDetectedTracks(Log* log, const DetectTracksOptions& options) {
  DetectTracksReport report;
  if (options.mode == DetectObjectsMode::kOff) return report;
  const auto start = std::chrono::steady_clock::now();
  // Sequences of wanted frames with a sweep on disk.
  std::vector<std::vector<size_t>> sequences;
  for (size_t k = options.first; k < std::min(options.last, log->frames.size()); ++k) {
    const Frame& f = log->frames[k];
    if (!Wanted(f, options.mode)) continue;
    if (!SweepOnDisk(f)) {
      ++report.frames_without_sweep;
      continue;
    }
    const bool cut = sequences.empty() || !log->sequential ||
                     !(f.timestamp - log->frames[sequences.back().back()].timestamp <= options.max_frame_gap_s) ||
                     !(f.timestamp > log->frames[sequences.back().back()].timestamp);
    if (cut) sequences.emplace_back();
    sequences.back().push_back(k);
  }
  // A long selection reads and clusters a sweep per frame (0.2 s each on 2 cores): show it.
  size_t total = 0;
  for (const std::vector<size_t>& seq : sequences) total += seq.size();
  std::optional<Progress> progress;
  if (total > 1) progress.emplace("detect objects", total);
  for (size_t s = 0; s < sequences.size(); ++s) {
    std::vector<perception::TrackFrameInput> inputs;
    for (size_t k : sequences[s]) {
      const Frame& f = log->frames[k];
      inputs.push_back({f.timestamp, f.T_world_ego, DetectFrameObjects(f, *log, options.detect)});
      if (progress) progress->Advance();
    }
    perception::TrackStats st;
    const auto tracked = perception::TrackObjects(inputs, options.track, &st);
    report.tracks += st.output_tracks;
    std::vector<int> seen_track;
    for (size_t i = 0; i < sequences[s].size(); ++i) {
      Frame& f = log->frames[sequences[s][i]];
      for (size_t j = 0; j < tracked[i].size(); ++j) {
        const perception::TrackedObject& t = tracked[i][j];
        Annotation a;
        a.category = std::string("detected.") + perception::ToString(t.object_class);
        a.box = t.box;
        a.token = "detected:" + f.token + ":" + std::to_string(j);
        a.instance_token = "detected:" + std::to_string(s + 1) + "-" + std::to_string(t.track_id);
        a.num_lidar_pts = t.num_points;
        a.velocity = t.velocity_ego;
        a.detected = true;
        f.annotations.push_back(std::move(a));
        ++report.boxes;
        if (std::find(seen_track.begin(), seen_track.end(), t.track_id) == seen_track.end()) {
          seen_track.push_back(t.track_id);
          ++report.by_class[static_cast<int>(t.object_class)];
        }
      }
      f.has_annotations = true;
      ++report.frames;
    }
  }
  report.sequences = static_cast<int>(sequences.size());
  report.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  return report;
}

void HideAnnotations(Log* log) {
  for (Frame& f : log->frames) {
    f.annotations.clear();
    f.has_annotations = false;
  }
}

}  // namespace sd
