// The camera-only path of synth (a frame without a LiDAR sweep: synth/frame.h EstimateCameraGround, then
// placement and occlusion without LiDAR points) measured against the data's own LiDAR, held back from it:
//  1. Placement. The demo scenario's objects (data/scenarios/demo.json: 3 cones, 1 barrier, 1 car, a per-frame
//     scenario) placed by PlaceObjects (synth/placement.h) as synth places them (PlaceFrameObjects in
//     synth/frame.cpp: the frame's placement seed, its annotated boxes, its cameras) on (a) the LiDAR ground with
//     the sweep's points, (b) the camera ground (EstimateCameraGround) with the stereo's road and scene points, and (c) the level plane
//     EstimateCameraGround assumes where stereo finds too little, with no points. Per log: requested vs placed
//     objects (a frame whose scenario cannot be placed throws InputError: a failed frame, with its message), and
//     how much of the request area each ground calls drivable. Each placement is judged against the LiDAR truth of
//     its frame (the (a) rows are the reference, right by construction up to the growth and threshold below):
//       - ground height error: the object's ground contact (T_ego_asset's origin, the bottom of its box at its
//         centre) against the LiDAR SurfaceAt there, over the radius placement itself fits (footprint + 0.5 m);
//       - on drivable road: the LiDAR ground's DrivableFraction of the footprint >= 0.9 (placement's own test);
//       - collides with unannotated things: >= 3 LiDAR points 0.25..3 m above the LiDAR ground inside the
//         footprint grown by 0.2 m, points of annotated boxes (grown 0.2 m) left out: those are the next column;
//       - overlaps an annotated box (footprints, no margin: a wrong road height must not hide an overlap).
//     Also the camera ground's height where (a) put its objects: its height error apart from its free space.
//     Several scenario seeds per frame (--seeds): placement is cheap once the grounds are made.
//  2. Occlusion. A placement is handed to SynthesizeFrame as a one-frame SequencePlan, once on the log and once on
//     a copy whose frames have `lidar.reset()`: the same objects at the same poses, rendered alike, so only the
//     depth source differs (sweep + boxes + road vs boxes + road plane). Two sets per frame: the first LiDAR
//     placement that succeeded, and the first camera-only one (b, else c): where a camera-only run puts objects.
//     Per object and camera: the visible fraction (CameraBox::visible_fraction = visible / rendered pixels of that
//     camera; a camera where a run labels no box has < 4 visible pixels there: fraction 0), the mean |difference|,
//     the views the camera-only run shows (>= 0.5) that the LiDAR run hides (< 0.5) and the reverse, the views
//     labelled by one run only, and the IoU of the boxes labelled by both. For each view the camera-only run shows
//     wrongly, the LiDAR points in front of the object inside its box: what the occluder was. (The camera-only run
//     gets the assumed plane, not the stereo ground, by default: see g_stereo_occlusion.)
//  3. Seconds per frame of the camera ground (EstimateCameraGround, images read included) and of the runs.
// Range bands: horizontal distance of the object's centre from the ego origin, cumulative (<= 10, 20, 40 m).
// Logs: PandaSet 002 frames 44-55 (../shared: 12 frames, 6 cameras; stereo against the neighbouring frames) and
// the repo's nuScenes keyframe (1 frame: no neighbour, so the assumed level plane).
// A plain program: build/bin/bench_camera_only [--frames N] [--seeds N] [--no-occlusion] [--verbose]; prints
// markdown tables.
#include <unistd.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "bench_demo.h"
#include "core/box3.h"
#include "core/error.h"
#include "datasets/readers.h"
#include "synth/frame.h"
#include "synth/ground.h"
#include "synth/placement.h"
#include "synth/scenario.h"
#include "synth/sequence_plan.h"

namespace fs = std::filesystem;
using sd::Box3;
using sd::Frame;
using sd::Log;

namespace {

constexpr double kRanges[] = {10, 20, 40};
constexpr int kBands = 3;
// The collision test of the brief, a little stricter than placement's own (margin 0.5 m, > 2 points): what a
// real unannotated thing inside or right next to the object's footprint looks like in the sweep.
constexpr double kObstacleLow = 0.25, kObstacleHigh = 3.0, kFootprintGrowth = 0.2;
constexpr int kCollisionPoints = 3;
constexpr double kDrivable = 0.9;  // placement's own drivable share
constexpr double kShown = 0.5;     // a view "shows" the object at this visible fraction

double Percentile(std::vector<double> v, double q) {
  if (v.empty()) return std::nan("");
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<size_t>(q * static_cast<double>(v.size())))];
}

double Seconds(std::chrono::steady_clock::time_point t0) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

double Distance(const Box3& b) { return b.center().head<2>().norm(); }

// ---------------------------------------------------------------------------------------------------------------
// The LiDAR truth of one frame: its sweep in the ego frame, the ground synth estimates from it, and per point its
// height above that ground and whether it lies in an annotated box (so "unannotated" obstacles can be told apart).

struct LidarTruth {
  std::vector<Eigen::Vector3d> points_ego;
  sd::GroundModel ground;
  std::vector<double> height;         // above the LiDAR ground
  std::vector<uint8_t> in_annotated;  // inside an annotated box grown by kFootprintGrowth
};

LidarTruth ReadLidarTruth(const Frame& frame, const sd::Scenario& scenario) {
  LidarTruth t;
  const sd::PointCloud sweep = sd::ReadLidar(*frame.lidar);
  t.points_ego = sd::PointsInEgo(frame, sweep);
  t.ground = sd::EstimateFrameGround(frame, sweep, t.points_ego, scenario);
  t.height.resize(t.points_ego.size());
  t.in_annotated.assign(t.points_ego.size(), 0);
  for (size_t i = 0; i < t.points_ego.size(); ++i) {
    t.height[i] = t.ground.HeightAboveGround(t.points_ego[i]);
    for (const sd::Annotation& a : frame.annotations)
      if (a.box.Contains(t.points_ego[i], kFootprintGrowth)) {
        t.in_annotated[i] = 1;
        break;
      }
  }
  return t;
}

// ---------------------------------------------------------------------------------------------------------------
// Placement, as synth does it for a frame without a plan (synth/frame.cpp PlaceFrameObjects): the frame's
// placement seed, its annotated boxes, its cameras; `points_ego` empty for the camera-only path.

struct Placement {
  std::vector<sd::PlacedObject> objects;
  std::optional<std::string> error;  // the InputError of a frame that cannot be placed
};

Placement Place(const Frame& frame, size_t frame_index, const sd::GroundModel& ground,
                const std::vector<Eigen::Vector3d>& points_ego, const sd::Scenario& scenario,
                const std::vector<sd::Asset>& assets) {
  sd::PlacementInput in;
  in.ground = &ground;
  in.points_ego = points_ego;
  for (const sd::Annotation& a : frame.annotations) in.real_boxes.push_back(a.box);
  for (const sd::CameraSensor& c : frame.cameras) in.cameras.push_back(&c);
  sd::Scenario s = scenario;
  s.seed = sd::FrameSeedsOf(scenario.seed, frame_index).placement;
  Placement p;
  try {
    p.objects = sd::PlaceObjects(s, assets, in);
  } catch (const sd::InputError& e) {
    p.error = e.what();
  }
  return p;
}

// One placed object judged against the LiDAR truth of its frame.
struct PlacementCheck {
  double distance = 0, height_error = 0, drivable = 0;
  int obstacle_points = 0;
  double obstacle_low = 0, obstacle_high = 0;  // height range of those points above the LiDAR ground
  bool overlaps_annotated = false;
  std::string category;
};

PlacementCheck CheckAgainstLidar(const sd::PlacedObject& o, const Frame& frame, const LidarTruth& truth) {
  PlacementCheck c;
  c.category = o.asset->info.category;
  c.distance = Distance(o.box);
  const Eigen::Vector3d& contact = o.T_ego_asset.translation;
  // The radius placement fits the local plane over (synth/placement.cpp), so the LiDAR path would have put the
  // object's contact exactly here.
  const double radius = 0.5 * o.box.size.head<2>().norm() + 0.5;
  c.height_error = contact.z() - truth.ground.SurfaceAt(contact.x(), contact.y(), radius).height;
  c.drivable = truth.ground.DrivableFraction(o.box);
  const sd::Rigid3d T_box_ego = o.box.T_frame_box.Inverse();
  c.obstacle_low = 1e9, c.obstacle_high = -1e9;
  for (size_t i = 0; i < truth.points_ego.size(); ++i) {
    if (truth.height[i] < kObstacleLow || truth.height[i] > kObstacleHigh || truth.in_annotated[i]) continue;
    const Eigen::Vector3d local = T_box_ego * truth.points_ego[i];
    if (std::abs(local.x()) > 0.5 * o.box.size.x() + kFootprintGrowth ||
        std::abs(local.y()) > 0.5 * o.box.size.y() + kFootprintGrowth)
      continue;
    ++c.obstacle_points;
    c.obstacle_low = std::min(c.obstacle_low, truth.height[i]);
    c.obstacle_high = std::max(c.obstacle_high, truth.height[i]);
  }
  for (const sd::Annotation& a : frame.annotations)
    if (sd::FootprintsOverlap(o.box, a.box, 0.0)) c.overlaps_annotated = true;
  return c;
}

// Per path (LiDAR / camera) and range band.
struct PlacementTally {
  int objects = 0, drivable = 0, collide_points = 0, collide_boxes = 0;
  std::vector<double> height_errors;  // |error|
  void Add(const PlacementCheck& c) {
    ++objects;
    height_errors.push_back(std::abs(c.height_error));
    drivable += c.drivable >= kDrivable;
    collide_points += c.obstacle_points >= kCollisionPoints;
    collide_boxes += c.overlaps_annotated;
  }
};

// ---------------------------------------------------------------------------------------------------------------
// Occlusion: the same placement rendered with and without the sweep. A one-frame SequencePlan is how
// SynthesizeFrame takes objects it did not place (PlacedFromPlan renders them at T_ego_object as given).

sd::SequencePlan OneFramePlan(const Frame& frame, size_t frame_index, const std::vector<sd::PlacedObject>& placed) {
  sd::SequencePlan plan;
  plan.frame_begin = frame_index;
  plan.frame_end = frame_index + 1;
  sd::PlannedFrame pf;
  pf.frame_index = frame_index;
  pf.token = frame.token;
  pf.timestamp = frame.timestamp;
  for (const sd::PlacedObject& p : placed) {
    sd::PlannedObject po;
    po.source = "objects[" + std::to_string(p.request) + "]";
    po.request = p.request;
    po.role = "object";
    po.category = p.asset->info.category;
    po.asset_id = p.asset->info.id;
    po.T_world_object = frame.T_world_ego * p.T_ego_asset;
    po.box = p.box.Transformed(frame.T_world_ego);
    plan.objects.push_back(po);
    sd::PlannedView v;
    v.T_ego_object = p.T_ego_asset;
    v.box_ego = p.box;
    v.distance_m = Distance(p.box);
    v.in_range = v.visible = true;
    pf.objects.push_back(v);
  }
  plan.frames.push_back(pf);
  return plan;
}

// One (object, camera) seen by either run.
struct View {
  int object = -1;  // index into the placement
  std::string channel, category;
  double distance = 0;
  double lidar_fraction = 0, camera_fraction = 0;
  std::optional<sd::Box2> lidar_box, camera_box;
};

// The camera boxes of each plan object in one run: (object, channel) -> box. Objects a plan run observes in no
// camera are dropped from its outcome (DropUnobserved), which here reads as "no box".
std::map<std::pair<int, std::string>, sd::CameraBox> BoxesOf(const sd::FrameOutcome& o) {
  std::map<std::pair<int, std::string>, sd::CameraBox> out;
  for (const sd::ObjectOutcome& ob : o.objects)
    for (const sd::CameraBox& cb : ob.label.camera_boxes) out[{ob.plan_object, cb.channel}] = cb;
  return out;
}

std::vector<View> CompareViews(const sd::FrameOutcome& lidar_run, const sd::FrameOutcome& camera_run,
                               const std::vector<sd::PlacedObject>& placed) {
  const auto lidar_boxes = BoxesOf(lidar_run), camera_boxes = BoxesOf(camera_run);
  std::map<std::pair<int, std::string>, View> views;
  const auto view = [&](const std::pair<int, std::string>& key) -> View& {
    View& v = views[key];
    v.object = key.first;
    v.channel = key.second;
    v.category = placed[static_cast<size_t>(key.first)].asset->info.category;
    v.distance = Distance(placed[static_cast<size_t>(key.first)].box);
    return v;
  };
  for (const auto& [key, cb] : lidar_boxes) {
    View& v = view(key);
    v.lidar_fraction = cb.visible_fraction;
    v.lidar_box = cb.box;
  }
  for (const auto& [key, cb] : camera_boxes) {
    View& v = view(key);
    v.camera_fraction = cb.visible_fraction;
    v.camera_box = cb.box;
  }
  std::vector<View> out;
  for (auto& [key, v] : views) out.push_back(v);
  return out;
}

// Per object over all cameras (ObjectOutcome::visible_pixels / rendered_pixels). The render is the same in both
// runs, so an object one run dropped had the other run's rendered pixels and (almost) none visible.
std::vector<std::optional<std::pair<double, double>>> ObjectFractions(const sd::FrameOutcome& lidar_run, const sd::FrameOutcome& camera_run,
                                                       size_t objects) {
  std::vector<double> rendered(objects, 0), lidar_visible(objects, 0), camera_visible(objects, 0);
  for (const sd::ObjectOutcome& ob : lidar_run.objects) {
    rendered[static_cast<size_t>(ob.plan_object)] = ob.rendered_pixels;
    lidar_visible[static_cast<size_t>(ob.plan_object)] = ob.visible_pixels;
  }
  for (const sd::ObjectOutcome& ob : camera_run.objects) {
    rendered[static_cast<size_t>(ob.plan_object)] = std::max(rendered[static_cast<size_t>(ob.plan_object)], ob.rendered_pixels);
    camera_visible[static_cast<size_t>(ob.plan_object)] = ob.visible_pixels;
  }
  std::vector<std::optional<std::pair<double, double>>> out(objects);  // none: no camera renders it
  for (size_t k = 0; k < objects; ++k)
    if (rendered[k] > 0) out[k] = std::pair{lidar_visible[k] / rendered[k], camera_visible[k] / rendered[k]};
  return out;
}

struct OcclusionTally {
  int views = 0, lidar_hides = 0, camera_shows_lidar_hides = 0, lidar_shows_camera_hides = 0, only_lidar = 0, only_camera = 0;
  double abs_diff = 0;
  std::vector<double> iou;  // boxes labelled by both runs
  int objects = 0;
  double object_abs_diff = 0;
  void Add(const View& v) {
    ++views;
    abs_diff += std::abs(v.lidar_fraction - v.camera_fraction);
    lidar_hides += v.lidar_fraction < kShown;
    camera_shows_lidar_hides += v.camera_fraction >= kShown && v.lidar_fraction < kShown;
    lidar_shows_camera_hides += v.lidar_fraction >= kShown && v.camera_fraction < kShown;
    only_lidar += v.lidar_box && !v.camera_box;
    only_camera += v.camera_box && !v.lidar_box;
    if (v.lidar_box && v.camera_box) iou.push_back(sd::IoU(*v.lidar_box, *v.camera_box));
  }
};

// What hid a view from the LiDAR run that the camera-only run shows: the LiDAR points that project inside the
// camera-only run's box of it and lie nearer the camera than the object's nearest corner, off the road (more
// than 0.25 m above the LiDAR ground, where occluders are; the road itself is in both runs' priors).
std::string DescribeOccluder(const View& v, const Frame& frame, const LidarTruth& truth, const sd::PlacedObject& o) {
  const sd::CameraSensor* cam = frame.FindCamera(v.channel);
  if (!cam || !v.camera_box) return "?";
  const sd::Rigid3d T_cam_ego = cam->T_ego_cam.Inverse();
  double nearest = 1e9;
  for (const Eigen::Vector3d& c : o.box.Corners()) nearest = std::min(nearest, (T_cam_ego * c).z());
  std::vector<double> depth, height;
  int annotated = 0;
  for (size_t i = 0; i < truth.points_ego.size(); ++i) {
    if (truth.height[i] <= kObstacleLow) continue;
    const Eigen::Vector3d p = T_cam_ego * truth.points_ego[i];
    if (p.z() >= nearest) continue;
    const auto uv = cam->intrinsics.Project(p, 0.5);
    if (!uv || uv->x() < v.camera_box->x1 || uv->x() >= v.camera_box->x2 || uv->y() < v.camera_box->y1 ||
        uv->y() >= v.camera_box->y2)
      continue;
    depth.push_back(p.z());
    height.push_back(truth.height[i]);
    annotated += truth.in_annotated[i];
  }
  if (depth.empty()) return "no LiDAR point off the road in front of it (the LiDAR run's depth densified over it)";
  char buf[256];
  std::snprintf(buf, sizeof buf, "%zu LiDAR points in front, depth %.1f m (median; object from %.1f m), %.2f..%.2f m above the road, %d %% in annotated boxes",
                depth.size(), Percentile(depth, 0.5), nearest, Percentile(height, 0.0), Percentile(height, 1.0),
                static_cast<int>(std::lround(100.0 * annotated / static_cast<double>(depth.size()))));
  return buf;
}

// What hid a view from the camera-only run that the LiDAR run shows: annotated boxes in front of it inside its box
// (the camera-only run's box prior), and the camera road plane against the LiDAR's at the object.
std::string DescribeCameraHider(const View& v, const Frame& frame, const sd::FrameOutcome& camera_run,
                                const LidarTruth& truth, const sd::PlacedObject& o) {
  const sd::CameraSensor* cam = frame.FindCamera(v.channel);
  if (!cam) return "?";
  const sd::Rigid3d T_cam_ego = cam->T_ego_cam.Inverse();
  double nearest = 1e9;
  for (const Eigen::Vector3d& c : o.box.Corners()) nearest = std::min(nearest, (T_cam_ego * c).z());
  int boxes_in_front = 0;
  const sd::Box2 box = v.lidar_box.value_or(sd::Box2{});
  for (const sd::Annotation& a : frame.annotations) {
    double x1 = 1e9, y1 = 1e9, x2 = -1e9, y2 = -1e9, zmin = 1e9;
    bool any = false;
    for (const Eigen::Vector3d& c : a.box.Corners()) {
      const Eigen::Vector3d p = T_cam_ego * c;
      zmin = std::min(zmin, p.z());
      const auto uv = cam->intrinsics.Project(p, 0.1);
      if (!uv) continue;
      any = true;
      x1 = std::min(x1, uv->x()), y1 = std::min(y1, uv->y()), x2 = std::max(x2, uv->x()), y2 = std::max(y2, uv->y());
    }
    if (any && zmin < nearest && sd::IoU(box, sd::Box2{x1, y1, x2, y2}) > 0) ++boxes_in_front;
  }
  const Eigen::Vector3d& c = o.box.center();
  char buf[200];
  std::snprintf(buf, sizeof buf, "%d annotated box(es) in front overlapping its box; camera road plane %+.2f m against the LiDAR's at it",
                boxes_in_front,
                camera_run.ground.seed_plane().HeightAt(c.x(), c.y()) - truth.ground.seed_plane().HeightAt(c.x(), c.y()));
  return buf;
}

// ---------------------------------------------------------------------------------------------------------------

// The grounds placement is run on: synth's two paths, and the camera-only path's fallback on its own.
enum Path { kLidar, kCamera, kPlane, kPaths };
const char* kPathNames[kPaths] = {"LiDAR (ground + sweep)", "camera-only (EstimateCameraGround + stereo points)",
                                  "assumed plane (the camera-only fallback, no points)"};

struct PathResult {
  int requested = 0, placed = 0, failed = 0;
  PlacementTally bands[kBands];
};

// How much of the scenario's request area (the union of its objects' distance x lateral ranges, 0.25 m grid) each
// ground calls drivable: where the camera ground's free space ends against where the LiDAR's does.
struct AreaAgreement {
  int samples = 0, lidar = 0, camera = 0, both = 0;
};

struct LogResult {
  std::string name;
  int frames = 0, seeds = 0;
  PathResult paths[kPaths];
  std::vector<std::string> failures;
  // The camera ground's height where the LiDAR path put its objects: its height error apart from its free space.
  std::vector<double> camera_height_at_lidar[kBands];
  AreaAgreement area;
  std::vector<std::string> collisions;  // camera-only / plane placements that collide, for people
  // Two object sets are rendered: where the LiDAR path places (clear of every unannotated thing it sees), and
  // where the camera-only path places (its camera ground's placement, or the assumed plane's where that fails):
  // the places a camera-only run really puts objects, next to the things it cannot see.
  OcclusionTally occlusion[2][kBands];
  int occlusion_frames[2] = {0, 0};
  std::vector<std::string> misses;
  std::vector<std::string> grounds;  // per frame: the camera ground's source
  std::vector<std::string> occlusion_roads;  // per frame: the road the camera-only SynthesizeFrame used
  double camera_ground_s = 0, lidar_run_s = 0, camera_run_s = 0;
  int stereo_frames = 0;
};

int RequestedObjects(const sd::Scenario& s) {
  int n = 0;
  for (const sd::ObjectRequest& r : s.objects) n += r.count;
  return n;
}

bool g_verbose = false;
// --stereo-occlusion: the camera-only SynthesizeFrame on the log as it is, so frames with neighbours get the stereo
// ground. Off by default: SynthesizeFrame (synth/frame.cpp ReadFrameInputs) marks the stereo ground's
// ground_indices() — indices into the stereo points — in `is_ground`, which is sized for the (absent) sweep: an
// out-of-bounds write that crashes every camera-only frame whose road came from stereo. By default the
// camera-only run therefore sees a non-sequential copy of the log (no neighbour, so EstimateCameraGround's
// assumed plane; same frame index, so the same render seed and the same rendered pixels).
bool g_stereo_occlusion = false;

void MeasureArea(const sd::Scenario& scenario, const sd::GroundModel& lidar, const sd::GroundModel& camera, AreaAgreement* a) {
  double x0 = 1e9, x1 = -1e9, y0 = 1e9, y1 = -1e9;
  for (const sd::ObjectRequest& r : scenario.objects) {
    x0 = std::min(x0, r.distance_min), x1 = std::max(x1, r.distance_max);
    y0 = std::min(y0, r.lateral_min), y1 = std::max(y1, r.lateral_max);
  }
  for (double x = x0; x <= x1; x += 0.25)
    for (double y = y0; y <= y1; y += 0.25) {
      const bool l = lidar.IsDrivable(x, y), c = camera.IsDrivable(x, y);
      ++a->samples;
      a->lidar += l;
      a->camera += c;
      a->both += l && c;
    }
}

// The road EstimateCameraGround assumes where stereo finds too little: level at RoadPriorHeight, drivable within
// the camera road's range.
sd::GroundModel AssumedPlane(const Log& log, const Frame& frame, const sd::Scenario& scenario) {
  sd::GroundPlane plane;
  plane.d = -sd::RoadPriorHeight(log, frame);
  sd::GroundOptions gopt;
  gopt.seed = scenario.seed;
  gopt.max_range = std::min(gopt.max_range, sd::CameraRoadOptions{}.max_range);
  return sd::GroundModel::Plane(plane, gopt);
}

// Places the scenario on every path for `seeds` scenario seeds and judges each placement against the LiDAR truth.
// Returns the first LiDAR placement that succeeded and the first camera-only one (the camera ground's, else the
// assumed plane's), which the occlusion measure renders; empty where none succeeded.
std::array<std::vector<sd::PlacedObject>, 2> MeasurePlacement(const Log& log, size_t fi, const LidarTruth& truth,
                                               const sd::CameraGround& camera_ground, const sd::Scenario& scenario,
                                               const std::vector<sd::Asset>& assets, int seeds, LogResult* r) {
  const Frame& frame = log.frames[fi];
  const sd::GroundModel plane = AssumedPlane(log, frame, scenario);
  const sd::GroundModel* grounds[kPaths] = {&truth.ground, &camera_ground.ground, &plane};
  MeasureArea(scenario, truth.ground, camera_ground.ground, &r->area);
  std::array<std::vector<sd::PlacedObject>, kPaths> first;
  for (int seed = 0; seed < seeds; ++seed) {
    sd::Scenario s = scenario;
    s.seed = scenario.seed + static_cast<uint32_t>(seed) * 1000u;
    for (int path = 0; path < kPaths; ++path) {
      // Each path with the points synthesis gives it: the sweep's, the stereo's (road and scene), none for the plane.
      const std::vector<Eigen::Vector3d> none;
      const std::vector<Eigen::Vector3d>& points =
          path == kLidar ? truth.points_ego : path == kCamera ? camera_ground.points_ego : none;
      const Placement p = Place(frame, fi, *grounds[path], points, s, assets);
      PathResult& pr = r->paths[path];
      pr.requested += RequestedObjects(s);
      pr.placed += static_cast<int>(p.objects.size());
      if (p.error) {
        ++pr.failed;
        r->failures.push_back(frame.token + " seed " + std::to_string(s.seed) + " (" + kPathNames[path] + "): " + *p.error);
      }
      if (first[path].empty()) first[path] = p.objects;
      for (const sd::PlacedObject& o : p.objects) {
        const PlacementCheck c = CheckAgainstLidar(o, frame, truth);
        for (int b = 0; b < kBands; ++b)
          if (c.distance <= kRanges[b]) pr.bands[b].Add(c);
        if (path == kLidar) {
          const Eigen::Vector3d& at = o.T_ego_asset.translation;
          const double radius = 0.5 * o.box.size.head<2>().norm() + 0.5;
          const double err = std::abs(camera_ground.ground.SurfaceAt(at.x(), at.y(), radius).height - at.z());
          for (int b = 0; b < kBands; ++b)
            if (c.distance <= kRanges[b]) r->camera_height_at_lidar[b].push_back(err);
          continue;
        }
        const bool collides = c.obstacle_points >= kCollisionPoints || c.overlaps_annotated;
        if (collides || g_verbose) {  // off-drivable ones are many (the table counts them); --verbose lists all
          char buf[400];
          std::snprintf(buf, sizeof buf,
                        "%s %s seed %u: %s at (%.1f, %.1f), %.1f m: height err %+.2f m, LiDAR drivable %.2f, %d "
                        "unannotated points (%.2f..%.2f m up)%s",
                        path == kCamera ? "[camera]" : "[plane]", frame.token.c_str(), s.seed, c.category.c_str(),
                        o.box.center().x(), o.box.center().y(), c.distance, c.height_error, c.drivable, c.obstacle_points,
                        c.obstacle_points ? c.obstacle_low : 0.0, c.obstacle_points ? c.obstacle_high : 0.0,
                        c.overlaps_annotated ? ", overlaps an annotated box" : "");
          r->collisions.push_back(buf);
        }
      }
    }
  }
  return {first[kLidar], first[kCamera].empty() ? first[kPlane] : first[kCamera]};
}

void MeasureOcclusion(const Log& lidar_log, const Log& camera_log, size_t fi, const LidarTruth& truth,
                      const std::vector<sd::PlacedObject>& placed, int set, const sd::Scenario& scenario,
                      const std::vector<sd::Asset>& assets, LogResult* r) {
  if (placed.empty()) return;
  const Frame& frame = lidar_log.frames[fi];
  const sd::SequencePlan plan = OneFramePlan(frame, fi, placed);
  // Cheap settings: the visible fraction depends on the render's coverage and the occlusion masks only, not on
  // the light, the harmoniser or the camera look (the pixel counts come from the sharp render), so those are off
  // or the cheapest there is.
  sd::SynthOptions options;
  options.samples_per_pixel = 1;
  options.ao_samples = 2;
  options.light = sd::SynthOptions::Light::kRoad;
  options.harmonizer = "none";
  options.camera_look = {false, false, false, false};
  options.lidar_realism = false;
  auto t0 = std::chrono::steady_clock::now();
  const sd::FrameOutcome lidar_run = sd::SynthesizeFrame(lidar_log, fi, assets, scenario, options, &plan);
  r->lidar_run_s += Seconds(t0);
  t0 = std::chrono::steady_clock::now();
  const sd::FrameOutcome camera_run = sd::SynthesizeFrame(camera_log, fi, assets, scenario, options, &plan);
  r->camera_run_s += Seconds(t0);
  if (set == 0) r->occlusion_roads.push_back(frame.token + ": " + camera_run.road);
  ++r->occlusion_frames[set];

  for (const View& v : CompareViews(lidar_run, camera_run, placed)) {
    for (int b = 0; b < kBands; ++b)
      if (v.distance <= kRanges[b]) r->occlusion[set][b].Add(v);
    const sd::PlacedObject& o = placed[static_cast<size_t>(v.object)];
    const bool camera_wrongly_shows = v.camera_fraction >= kShown && v.lidar_fraction < kShown;
    const bool camera_wrongly_hides = v.lidar_fraction >= kShown && v.camera_fraction < kShown;
    if (!camera_wrongly_shows && !camera_wrongly_hides) continue;
    char head[200];
    std::snprintf(head, sizeof head, "%s %s %s #%d at %.1f m: visible %.2f (LiDAR) vs %.2f (camera-only): ", frame.token.c_str(),
                  v.channel.c_str(), v.category.c_str(), v.object, v.distance, v.lidar_fraction, v.camera_fraction);
    r->misses.push_back(std::string(set == 0 ? "LiDAR-placed " : "camera-placed ") +
                        (camera_wrongly_shows ? "[shows] " : "[hides] ") + head +
                        (camera_wrongly_shows ? DescribeOccluder(v, frame, truth, o)
                                              : DescribeCameraHider(v, frame, camera_run, truth, o)));
  }
  // Per object over all cameras, in the same bands.
  const auto fractions = ObjectFractions(lidar_run, camera_run, placed.size());
  for (size_t k = 0; k < placed.size(); ++k) {
    if (!fractions[k]) continue;
    for (int b = 0; b < kBands; ++b)
      if (Distance(placed[k].box) <= kRanges[b]) {
        ++r->occlusion[set][b].objects;
        r->occlusion[set][b].object_abs_diff += std::abs(fractions[k]->first - fractions[k]->second);
      }
  }
}

LogResult Evaluate(const std::string& name, const Log& log, const sd::Scenario& scenario,
                   const std::vector<sd::Asset>& assets, int max_frames, int seeds, bool occlusion) {
  LogResult r;
  r.name = name;
  r.seeds = seeds;
  // The camera-only log: the same frames with their sweeps held back.
  Log camera_log = log;
  for (Frame& f : camera_log.frames) f.lidar.reset();
  Log occlusion_log = camera_log;  // see g_stereo_occlusion
  if (!g_stereo_occlusion) occlusion_log.sequential = false;
  for (size_t fi = 0; fi < log.frames.size() && static_cast<int>(fi) < max_frames; ++fi) {
    const Frame& frame = log.frames[fi];
    if (!frame.lidar) continue;
    ++r.frames;
    const LidarTruth truth = ReadLidarTruth(frame, scenario);
    const auto t0 = std::chrono::steady_clock::now();
    const sd::CameraGround camera_ground = sd::EstimateCameraGround(camera_log, fi, scenario);
    r.camera_ground_s += Seconds(t0);
    r.stereo_frames += camera_ground.from_stereo;
    r.grounds.push_back(frame.token + ": " + camera_ground.source);
    const auto placements = MeasurePlacement(log, fi, truth, camera_ground, scenario, assets, seeds, &r);
    if (occlusion)
      for (int set = 0; set < 2; ++set) MeasureOcclusion(log, occlusion_log, fi, truth, placements[set], set, scenario, assets, &r);
    std::fprintf(stderr, "%s frame %zu: %.1f s in all, %.1f s camera ground so far\n", name.c_str(), fi, Seconds(t0),
                 r.camera_ground_s);
  }
  return r;
}

// ---------------------------------------------------------------------------------------------------------------

void PrintPlacement(const LogResult& r) {
  std::printf("### Placement (%d frames x %d seeds)\n\n", r.frames, r.seeds);
  std::printf("| path | requested | placed | failed frames |\n|---|---|---|---|\n");
  for (int p = 0; p < kPaths; ++p)
    std::printf("| %s | %d | %d | %d |\n", kPathNames[p], r.paths[p].requested, r.paths[p].placed, r.paths[p].failed);
  const AreaAgreement& a = r.area;
  const double n = std::max(1, a.samples);
  std::printf("\nThe request area (union of the objects' distance x lateral ranges): LiDAR ground drivable %.1f %%, camera "
              "ground drivable %.1f %%, both %.1f %%.\n\n",
              100.0 * a.lidar / n, 100.0 * a.camera / n, 100.0 * a.both / n);
  for (const std::string& f : r.failures) std::printf("- failed: %s\n", f.c_str());
  if (!r.failures.empty()) std::printf("\n");
  std::printf("Against the LiDAR truth of the same frame (height error: object contact vs LiDAR SurfaceAt, |m|; drivable: "
              "LiDAR DrivableFraction >= %.1f; collides: >= %d unannotated LiDAR points %.2f..%.0f m up in the footprint "
              "+ %.1f m; boxes: footprint overlaps an annotated box). Last rows: the camera ground's height where the "
              "LiDAR path put its objects.\n\n",
              kDrivable, kCollisionPoints, kObstacleLow, kObstacleHigh, kFootprintGrowth);
  std::printf("| path | range | objects | height err median / p90 | on drivable | collides (points) | overlaps annotated |\n");
  std::printf("|---|---|---|---|---|---|---|\n");
  for (int p = 0; p < kPaths; ++p)
    for (int b = 0; b < kBands; ++b) {
      const PlacementTally& t = r.paths[p].bands[b];
      const double m = std::max(1, t.objects);
      std::printf("| %s | <= %.0f m | %d | %.3f / %.3f | %.0f %% | %d (%.0f %%) | %d |\n", kPathNames[p], kRanges[b],
                  t.objects, Percentile(t.height_errors, 0.5), Percentile(t.height_errors, 0.9), 100.0 * t.drivable / m,
                  t.collide_points, 100.0 * t.collide_points / m, t.collide_boxes);
    }
  for (int b = 0; b < kBands; ++b)
    std::printf("| camera ground at the LiDAR placements | <= %.0f m | %zu | %.3f / %.3f | | | |\n", kRanges[b],
                r.camera_height_at_lidar[b].size(), Percentile(r.camera_height_at_lidar[b], 0.5),
                Percentile(r.camera_height_at_lidar[b], 0.9));
  std::printf("\n");
  if (!r.collisions.empty()) {
    std::printf("Camera-only and plane placements that collide (LiDAR drivable: the share of the footprint the LiDAR "
                "ground calls drivable):\n\n");
    for (const std::string& c : r.collisions) std::printf("- %s\n", c.c_str());
    std::printf("\n");
  }
}

void PrintOcclusion(const LogResult& r) {
  if (r.occlusion_frames[0] + r.occlusion_frames[1] == 0) return;
  std::printf("### Occlusion (the same objects rendered with the sweep and camera-only)\n\n");
  std::printf("Views = (object, camera) pairs labelled by either run; vis = visible / rendered pixels in that camera (0 "
              "where a run labels no box). Objects: the same over all cameras. LiDAR-placed: the first LiDAR placement "
              "that succeeded per frame; camera-placed: the first camera-only one (camera ground, else assumed plane).\n\n");
  std::printf("| objects | frames | range | views | LiDAR run hides | mean abs(d vis) | camera-only shows, LiDAR hides | LiDAR shows, camera-only "
              "hides | labelled by LiDAR run only | by camera-only only | box IoU median / p10 (both) | objects | mean "
              "abs(d vis) per object |\n");
  std::printf("|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
  for (int set = 0; set < 2; ++set)
    for (int b = 0; b < kBands; ++b) {
      const OcclusionTally& t = r.occlusion[set][b];
      std::printf("| %s | %d | <= %.0f m | %d | %d | %.3f | %d | %d | %d | %d | %.3f / %.3f | %d | %.3f |\n",
                  set == 0 ? "LiDAR-placed" : "camera-placed", r.occlusion_frames[set], kRanges[b], t.views, t.lidar_hides,
                  t.views ? t.abs_diff / t.views : 0.0, t.camera_shows_lidar_hides, t.lidar_shows_camera_hides,
                  t.only_lidar, t.only_camera, Percentile(t.iou, 0.5), Percentile(t.iou, 0.1), t.objects,
                  t.objects ? t.object_abs_diff / t.objects : 0.0);
    }
  std::printf("\n");
  if (!r.misses.empty()) {
    std::printf("Views whose verdict differs ([shows]: camera-only shows what the LiDAR run hides; [hides]: the reverse):\n\n");
    for (const std::string& m : r.misses) std::printf("- %s\n", m.c_str());
    std::printf("\n");
  }
}

void Print(const LogResult& r) {
  std::printf("## %s\n\n", r.name.c_str());
  const int runs = r.occlusion_frames[0] + r.occlusion_frames[1];
  std::printf("Camera ground: %.2f s per frame (EstimateCameraGround, images read included), stereo in %d of %d frames; "
              "SynthesizeFrame %.2f s per run with the LiDAR, %.2f s camera-only (its own camera ground included).\n\n",
              r.frames ? r.camera_ground_s / r.frames : 0.0, r.stereo_frames, r.frames, runs ? r.lidar_run_s / runs : 0.0,
              runs ? r.camera_run_s / runs : 0.0);
  PrintPlacement(r);
  PrintOcclusion(r);
  if (!r.occlusion_roads.empty()) {
    std::printf("Road of the camera-only occlusion runs:\n\n");
    for (const std::string& g : r.occlusion_roads) std::printf("- %s\n", g.c_str());
    std::printf("\n");
  }
  std::printf("Camera ground per frame:\n\n");
  for (const std::string& g : r.grounds) std::printf("- %s\n", g.c_str());
  std::printf("\n");
}

}  // namespace

int main(int argc, char** argv) {
  int max_frames = 1 << 30, seeds = 4;
  bool occlusion = true;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    const bool has = i + 1 < argc;
    if (a == "--frames" && has) max_frames = std::atoi(argv[++i]);
    else if (a == "--seeds" && has) seeds = std::max(1, std::atoi(argv[++i]));
    else if (a == "--no-occlusion") occlusion = false;
    else if (a == "--verbose") g_verbose = true;
    else if (a == "--stereo-occlusion") g_stereo_occlusion = true;
    else {
      std::fprintf(stderr, "usage: bench_camera_only [--frames N] [--seeds N] [--no-occlusion] [--stereo-occlusion] [--verbose]\n");
      return 2;
    }
  }
  const auto root = sd::bench::RepoRootOrSay();
  if (!root) return 1;
  const fs::path shared = sd::bench::SharedDriving(*root);
  const fs::path tmp = fs::temp_directory_path() / ("bench_camera_only_" + std::to_string(::getpid()));
  const auto start = std::chrono::steady_clock::now();
  std::vector<LogResult> results;
  int rc = 0, requested = 0;
  try {
    // The demo's meshes as synth sees assets (through their folders); the scenario as the demo runs it.
    std::vector<sd::Asset> assets;
    for (const sd::bench::DemoMesh& m : sd::bench::DemoMeshes())
      assets.push_back(sd::bench::ImportDemoAsset(*root / "data", m, tmp / m.id));
    const sd::Scenario scenario = sd::ReadScenario(*root / "data" / "scenarios" / "demo.json");
    requested = RequestedObjects(scenario);
    const fs::path pandaset = shared / "pandaset-002-f44-55";
    if (fs::exists(pandaset)) {
      results.push_back(Evaluate("PandaSet 002 f44-55", sd::OpenLog(pandaset), scenario, assets, max_frames, seeds, occlusion));
    } else {
      std::printf("PandaSet: %s not present, skipped\n", pandaset.string().c_str());
    }
    const fs::path keyframe = *root / "data" / "driving" / "nuscenes-scene0061-kf0" / "mmdet3d_info" /
                              "n015-2018-07-24-11-22-45+0800.json";
    results.push_back(Evaluate("nuScenes scene-0061 keyframe (repo)", sd::OpenLog(keyframe), scenario, assets, max_frames,
                               seeds, occlusion));
  } catch (const sd::InputError& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    rc = 1;
  }
  std::error_code ec;
  fs::remove_all(tmp, ec);
  if (rc) return rc;
  std::printf("# Camera-only synthesis against the held-back LiDAR\n\n");
  std::printf("Scenario data/scenarios/demo.json (%d objects per frame), demo assets; occlusion runs: 1 spp, 2 AO "
              "samples, road light, no harmoniser or camera look.\n\n",
              requested);
  for (const LogResult& r : results) Print(r);
  std::printf("Total %.1f s.\n", Seconds(start));
  return 0;
}
