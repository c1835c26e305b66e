#include "synth/frame.h"

#include <algorithm>
#include <cmath>
#include <memory>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <tuple>

#include "core/log.h"
#include "core/parallel.h"
#include "core/stats.h"
#include "datasets/categories.h"
#include "datasets/readers.h"
#include "io/files.h"
#include "io/image_io.h"
#include "models/harmonization.h"
#include "synth/frame_stages.h"
#include "synth/lidar_sim.h"
#include "synth/lighting.h"
#include "synth/object_light.h"
#include "synth/realism.h"

namespace sd {
namespace fs = std::filesystem;
namespace frame_stages {

const ImageU8& FrameInputs::Image(size_t k) const {
  if (images[k].empty()) {
    const CameraSensor& cam = frame->cameras[k];
    images[k] = ReadImage(cam.image_path, 3);
    if (images[k].width() != cam.intrinsics.width || images[k].height() != cam.intrinsics.height)
      throw InputError(cam.image_path, Msg() << "image is " << images[k].width() << "x" << images[k].height()
                                             << " but the calibration says " << cam.intrinsics.width << "x"
                                             << cam.intrinsics.height);
  }
  return images[k];
}

std::optional<int> FrameInputs::JpegQuality(size_t k) const { return EstimateJpegQuality(ReadFileToString(frame->cameras[k].image_path)); }

FrameInputs ReadFrameInputs(const Log& log, size_t frame_index, const Scenario& scenario, FrameOutcome* out) {
  const Frame& frame = log.frames.at(frame_index);
  FrameInputs in;
  in.log = &log;
  in.frame = &frame;
  in.index = frame_index;
  in.seeds = FrameSeedsOf(scenario.seed, frame_index);
  for (const auto& a : frame.annotations) {
    in.real_boxes.push_back(a.box);  // detected boxes too: placement keeps clear of them
    if (!a.detected) in.annotated.push_back({a.category, a.box});  // a guessed class says nothing of intensity
  }
  if (frame.lidar) {
    out->sweep_before = ReadLidar(*frame.lidar);
    in.sweep = &out->sweep_before;
    in.points_ego = PointsInEgo(frame, out->sweep_before);
    out->ground = EstimateFrameGround(frame, out->sweep_before, in.points_ego, scenario);
    out->road = Msg() << "LiDAR sweep (" << out->ground.ground_points().size() << " road returns)";
  } else {
    // A camera-only frame: the road from the cameras, no sweep read, none written, none invented.
    CameraGround camera_ground = EstimateCameraGround(log, frame_index, scenario);
    in.points_ego = std::move(camera_ground.points_ego);  // the stereo's, for placement and occlusion
    out->ground = std::move(camera_ground.ground);
    out->road = std::move(camera_ground.source);
    out->lidar_model = kNoLidar;
  }
  in.ground = &out->ground;
  in.is_ground.assign(in.points_ego.size(), 0);
  for (int i : out->ground.ground_indices()) in.is_ground[i] = 1;
  in.images.resize(frame.cameras.size());
  return in;
}

std::map<std::string, SaturationReference> ColourReference(const FrameInputs& in, const std::vector<PlacedObject>& placed,
                                                           const SequencePlan* plan) {
  if (plan) return plan->colour_reference;
  std::set<std::string> categories;
  for (const PlacedObject& p : placed) categories.insert(CanonicalCategory(p.asset->info.category));
  return RealSaturation(*in.log, {in.index}, categories, [&](size_t, size_t camera) -> const ImageU8& { return in.Image(camera); });
}

std::vector<Eigen::Vector3d> RoadPointsNear(const GroundModel& ground, const std::vector<PlacedObject>& objects, double margin_m) {
  std::vector<Eigen::Vector3d> out;
  for (const auto& p : ground.ground_points()) {
    for (const auto& o : objects) {
      const double d = (p.head<2>() - o.box.center().head<2>()).norm();
      if (d < 0.5 * o.box.size.head<2>().norm() + margin_m && ground.IsDrivable(p.x(), p.y())) {
        out.push_back(p);
        break;
      }
    }
  }
  return out;
}

namespace {

// The plan's world-fixed objects a frame renders: those within the plan's range gate, at their ego-frame pose.
std::vector<PlacedObject> PlacedFromPlan(const SequencePlan& plan, size_t frame_index, const std::vector<Asset>& assets,
                                         std::vector<int>* plan_index) {
  const PlannedFrame* pf = nullptr;
  for (const PlannedFrame& f : plan.frames)
    if (f.frame_index == frame_index) pf = &f;
  SD_CHECK(pf != nullptr, << "frame " << frame_index << " is not in the plan [" << plan.frame_begin << ", " << plan.frame_end << ")");
  std::vector<PlacedObject> placed;
  for (size_t i = 0; i < plan.objects.size(); ++i) {
    const PlannedView& v = pf->objects[i];
    if (!v.in_range) continue;
    const Asset* asset = nullptr;
    for (const Asset& a : assets)
      if (a.info.id == plan.objects[i].asset_id) asset = &a;
    SD_CHECK(asset != nullptr, << "planned object " << i << " has no asset '" << plan.objects[i].asset_id << "'");
    placed.push_back(PlacedObject{asset, plan.objects[i].request, v.T_ego_object, v.box_ego, v.T_ego_object.translation.z()});
    plan_index->push_back(static_cast<int>(i));
  }
  return placed;
}

// Placement: the plan's objects in range, or the scenario's objects placed for this frame alone.
std::vector<PlacedObject> PlaceFrameObjects(const FrameInputs& in, const std::vector<Asset>& assets, const Scenario& scenario,
                                            const SequencePlan* plan, std::vector<int>* plan_index) {
  if (plan) return PlacedFromPlan(*plan, in.index, assets, plan_index);
  PlacementInput pin;
  pin.ground = in.ground;
  pin.points_ego = in.points_ego;
  pin.real_boxes = in.real_boxes;
  for (const auto& c : in.frame->cameras) pin.cameras.push_back(&c);
  Scenario frame_scenario = scenario;
  frame_scenario.seed = in.seeds.placement;
  return PlaceObjects(frame_scenario, assets, pin);
}

// `sun_source`: where the frame's sun came from (SunDirectionEgo's note, or the camera that sees it).
std::string EnvironmentSummary(const EnvironmentMap& env, const std::string& sun_source) {
  Msg m;
  m << "environment map " << env.width() << "x" << env.height() << ": sun " << sun_source;
  if (env.shadow_objects > 0)
    m << " (checked against the real shadows of " << env.shadow_objects << " object(s): agreement " << Fixed(env.shadow_agreement, 2) << ")";
  m << ", " << (env.sun_road_contrast > 0 ? "sun/sky from real shadows (road contrast " + Fixed(env.sun_road_contrast, 2) + ")"
                                          : std::string("default sun/sky split"));
  if (env.overlap_pixels > 0)
    m << ", seam error " << Fixed(env.seam_error_before, 2) << " -> " << Fixed(env.seam_error_after, 2);
  return m;
}

// The frame's light: the sun (the scenario's, the images' or the ephemeris'), the environment map it is checked
// against, and the sun's visibility per object (a building's shade can cover one cone of a closure and not the
// next); objects whose road no camera shows enough of take the verdict over all objects' road.
FrameLight LightFrame(const FrameInputs& in, const Scenario& scenario, const SynthOptions& options,
                      const std::vector<PlacedObject>& placed, FrameOutcome* out) {
  const Frame& frame = *in.frame;
  FrameLight light;
  std::string sun_source;
  light.sun_dir = SunDirectionEgo(frame, scenario.location ? scenario.location : in.log->location, scenario.sun, &sun_source);
  if (options.light == SynthOptions::Light::kEnvironment && !placed.empty()) {
    ScopedStage decode_stage(out ? &out->timings : nullptr, "light: decode");
    // Each camera's image into its own slot, at once: six JPEG decodes are a tenth of a second in turn.
    ParallelForRethrow(0, frame.cameras.size(), [&](size_t k) { in.Image(k); });
    decode_stage.Stop();
    ScopedStage map_stage(out ? &out->timings : nullptr, "light: map");
    EnvironmentOptions eo;
    eo.ephemeris_sun_ego = light.sun_dir;
    eo.detect_sun_in_images = !scenario.sun;  // a scenario's sun is the user's word
    light.env = BuildEnvironmentMap(frame, in.images, eo);
    if (light.env->sun_source != "ephemeris") {
      light.sun_dir = light.env->sun_direction;
      sun_source = light.env->sun_source;
    }
    out->light = EnvironmentSummary(*light.env, sun_source);
    map_stage.Stop();
  } else {
    out->light = options.light == SynthOptions::Light::kRoad ? "road calibration per camera" : "no objects";
  }
  out->sun_source = sun_source;
  out->sun_direction_ego = light.sun_dir;

  const GroundModel& ground = *in.ground;
  light.road_points = RoadPointsNear(ground, placed);
  light.road_points_of.resize(placed.size());
  light.sun_at_object.resize(placed.size());
  light.own_verdict.assign(placed.size(), false);
  if (!light.env) return light;
  ScopedStage verdict_stage(out ? &out->timings : nullptr, "light: sun verdicts");
  std::vector<const ImageU8*> rig;
  for (size_t k = 0; k < frame.cameras.size(); ++k) rig.push_back(&in.Image(k));
  const SunVerdict all = SunVisibilityAt(*light.env, frame, rig, light.road_points);
  if (all.road_samples > 0) light.sun_at_objects = all.sun_visibility;
  for (size_t k = 0; k < placed.size(); ++k) {
    for (double margin : kOwnRoadMargins) {
      light.road_points_of[k] = RoadPointsNear(ground, {placed[k]}, margin);
      const SunVerdict own = SunVisibilityAt(*light.env, frame, rig, light.road_points_of[k]);
      light.own_verdict[k] = own.road_samples > 0;
      light.sun_at_object[k] = light.own_verdict[k] ? std::optional<double>(own.sun_visibility) : light.sun_at_objects;
      if (light.own_verdict[k]) break;
    }
  }
  return light;
}

// A flat rectangle of road under an object, on the object's local plane, that catches what the object takes from
// the road's light: its sky occlusion all round (a margin of its height, at least 1 m, beyond its footprint) and
// its sun shadow, which falls only away from the sun (so the rectangle reaches the shadow's length further on that
// side). Every pixel of it is shaded with soft-shadow and sky rays: a square reaching the shadow's length on all
// four sides was 3-5 times the area, and the largest cost of a frame. Two triangles: the patch is flat, and every
// ray of the frame traverses it (a 25 cm grid of it outnumbered the objects' own triangles). `extent` receives a
// grid of its points, for the rectangle a camera redraws: a patch reaching behind a camera still projects the part
// in front.
void AddReceiverPatch(const PlacedObject& o, const Eigen::Vector3d& sun_dir, TriangleMesh* receiver,
                      std::vector<Eigen::Vector3d>* extent) {
  const double h = o.box.size.z();
  const Eigen::Vector3d sun_local = o.T_ego_asset.rotation.inverse() * sun_dir;
  const double sun_el = std::asin(std::clamp(sun_local.z(), 0.26, 1.0));  // >= 15 deg keeps patches bounded
  const double shadow_length = h / std::tan(sun_el);
  Eigen::Vector2d away = -sun_local.head<2>();  // the direction the shadow falls in
  if (away.norm() < 1e-6) away = Eigen::Vector2d::UnitX();  // sun overhead: no direction, and no length
  away.normalize();
  const Eigen::Vector2d across(-away.y(), away.x());
  const double footprint = 0.5 * o.box.size.head<2>().norm(), margin = std::max(1.0, h);
  const double u0 = -(footprint + margin), u1 = footprint + shadow_length + margin, v_half = footprint + margin;
  // In the asset frame (origin on the ground, z along the local normal), lifted 1 mm so shadow rays from the
  // receiver do not start inside the object's base.
  const auto at = [&](double u, double v) {
    const Eigen::Vector2d p = u * away + v * across;
    return o.T_ego_asset * Eigen::Vector3d(p.x(), p.y(), 0.001);
  };
  const int base = static_cast<int>(receiver->positions.size());
  for (const auto& [u, v] : {std::pair{u0, -v_half}, {u1, -v_half}, {u1, v_half}, {u0, v_half}})
    receiver->positions.push_back(at(u, v).cast<float>());
  // Wound counter-clockwise seen from above whatever the shadow's direction: (away, across) is right-handed.
  receiver->faces.push_back({base, base + 1, base + 2});
  receiver->faces.push_back({base, base + 2, base + 3});
  constexpr int kExtentGrid = 8;
  for (int j = 0; j <= kExtentGrid; ++j)
    for (int i = 0; i <= kExtentGrid; ++i)
      extent->push_back(at(u0 + (u1 - u0) * i / kExtentGrid, -v_half + 2 * v_half * j / kExtentGrid));
}


// Each object's label as far as placement decides it: category in the log's vocabulary, 3D box, track.
std::vector<ObjectOutcome> LabelObjects(const Log& log, const std::vector<PlacedObject>& placed, const SequencePlan* plan,
                                        const std::vector<int>& plan_index) {
  std::vector<ObjectOutcome> objects(placed.size());
  for (size_t k = 0; k < placed.size(); ++k) {
    auto& oc = objects[k];
    oc.placement = placed[k];
    if (plan) {
      oc.plan_object = plan_index[k];
      // One track per planned object, the same in every frame that shows it (formats with track ids use it).
      oc.label.annotation.instance_token = Msg() << "synthdrive-plan:" << log.frames[plan->frame_begin].token << ":"
                                                 << plan_index[k] << ":" << placed[k].asset->info.id;
    }
    const auto cat = FindCategory(placed[k].asset->info.category);
    if (!cat) throw InputError(placed[k].asset->dir, "unknown category '" + placed[k].asset->info.category + "'");
    oc.label.category = cat->name;
    oc.label.asset_id = placed[k].asset->info.id;
    oc.label.annotation.category = DatasetCategoryName(*cat, log.format);
    oc.label.annotation.box = placed[k].box;
    oc.label.annotation.velocity = Eigen::Vector2d::Zero();
  }
  return objects;
}

// The classical harmoniser as synth uses it: colour cast and a little chroma, no lightness transfer (see
// SynthOptions::harmonizer).
models::HarmonizeOptions SynthHarmonizeOptions() {
  models::HarmonizeOptions o;
  o.lightness_strength = 0.0f;
  return o;
}

// The LiDAR model of a frame's own sweep (docs/lidar.md), or nullopt where none applies: a sweep of several
// merged lidars (Argoverse 2) or one too small to fit (the caller falls back to the ideal sensor, which is not
// worth failing the frame for).
std::optional<LidarModel> FitFrameLidarModel(const Frame& frame, const PointCloud& sweep) {
  if (!frame.lidar->one_beam_pattern) return std::nullopt;
  LidarFitOptions fit;
  const Rigid3d T_lidar_ego = frame.lidar->T_ego_lidar.Inverse();
  for (const auto& a : frame.annotations)
    if (!a.category.empty() && !a.detected) fit.annotated.push_back({a.category, a.box.Transformed(T_lidar_ego)});
  // The record order, where the reader knows it (KITTI: azimuth order, clockwise, starting behind).
  fit.spin_direction = frame.lidar->spin_direction;
  if (std::isfinite(frame.lidar->start_azimuth)) fit.start_azimuth = frame.lidar->start_azimuth;
  try {
    return FitLidarModel(sweep, fit);
  } catch (const InputError& e) {
    SD_LOG(Warn, "frame " << frame.token << ": no LiDAR model (" << e.what() << "); inserting with the ideal sensor");
    return std::nullopt;
  }
}

// Ego poses at the sweep's start and end (reference = the frame's ego pose, `reference_time` s after the sweep
// start) from the ego motion between the previous and next log frames of the same sequence (or the frame and
// its one neighbour); nullopt without one (KITTI object frames have no world pose, nor a sequence).
std::optional<std::pair<Rigid3d, Rigid3d>> NeighbourSweepPoses(const Log& log, size_t frame_index, double period,
                                                               double reference_time) {
  if (!log.sequential) return std::nullopt;
  const double max_gap = SequencePlanOptions{}.max_frame_gap_s;
  const Frame& f = log.frames[frame_index];
  auto near = [&](size_t k) {
    const double gap = std::abs(log.frames[k].timestamp - f.timestamp);
    return gap > 0 && gap <= max_gap;
  };
  const Frame* a = &f;
  const Frame* b = &f;
  if (frame_index > 0 && near(frame_index - 1)) a = &log.frames[frame_index - 1];
  if (frame_index + 1 < log.frames.size() && near(frame_index + 1)) b = &log.frames[frame_index + 1];
  if (a == b || a->timestamp == b->timestamp) return std::nullopt;
  return SweepPosesFromEgoPoses(f.T_world_ego, a->T_world_ego, a->timestamp, b->T_world_ego, b->timestamp, period,
                                reference_time);
}

// The LiDAR: blocked returns move onto the objects, with the noise, dropout, intensity and ego motion of the
// model fitted to the frame's own sweep.
void SimulateFrameLidar(const FrameInputs& in, const std::vector<PlacedObject>& placed, const SynthOptions& options,
                        FrameOutcome* out) {
  if (!in.sweep) return;  // a camera-only frame: no sweep to insert into, and none is made up
  const Frame& frame = *in.frame;
  const PointCloud& sweep = *in.sweep;
  std::vector<const PlacedObject*> ptrs;
  for (const auto& o : placed) ptrs.push_back(&o);
  LidarSimInput lin;
  lin.sweep = &sweep;
  lin.T_ego_lidar = frame.lidar->T_ego_lidar;
  if (!frame.lidar->sensor_feature.empty()) {
    lin.sensor_feature = sweep.FeatureIndex(frame.lidar->sensor_feature);
    lin.T_lidar_sensors = frame.lidar->T_lidar_sensors;
  }
  lin.objects = ptrs;
  lin.reference_intensity = ReferenceIntensities(sweep, in.points_ego, in.ground->ground_indices(), in.annotated, ptrs);
  if (options.lidar_realism) out->lidar_model_fit = FitFrameLidarModel(frame, sweep);
  if (out->lidar_model_fit) {
    const LidarModel& model = *out->lidar_model_fit;
    out->lidar_model = model.Summary();
    LidarRealism& re = lin.realism;
    re.model = &model;
    re.noise = re.dropout = re.intensity = true;
    re.seed = in.seeds.lidar;
    // nuScenes (tables and mmdet3d infos) de-skew their sweeps and stamp them at the end of the turn.
    re.motion_compensated_output = frame.lidar->motion_compensated;
    if (const auto poses = NeighbourSweepPoses(*in.log, in.index, model.SweepPeriod(), model.SweepPeriod())) {
      re.ego_motion = out->lidar_ego_motion = true;
      std::tie(re.T_ref_ego_start, re.T_ref_ego_end) = *poses;
    }
  }
  LidarSimResult lidar = SimulateLidar(lin);
  out->lidar_object_points = lidar.object_points;
  for (size_t k = 0; k < placed.size(); ++k) {
    out->objects[k].lidar_points = lidar.points_on_object[k];
    out->objects[k].label.annotation.num_lidar_pts = lidar.points_on_object[k];
  }
  out->edit.points = std::move(lidar.cloud);
}

int NuScenesVisibility(double fraction) {
  if (fraction < 0.4) return 1;
  if (fraction < 0.6) return 2;
  if (fraction < 0.8) return 3;
  return 4;
}

// The labels once cameras and LiDAR have counted: visibility from the visible share of the rendered pixels.
void FinishLabels(FrameOutcome* out) {
  for (auto& oc : out->objects) {
    const double frac = oc.rendered_pixels > 0 ? oc.visible_pixels / oc.rendered_pixels : 0.0;
    oc.label.annotation.visibility = NuScenesVisibility(frac);
    out->edit.added.push_back(oc.label);
  }
}

// Drops the objects a frame does not observe (no LiDAR point, no labelable camera box): a world-fixed object
// far behind or hidden has no label in that frame. Indices in cameras and LiDAR bookkeeping follow.
void DropUnobserved(FrameOutcome* out) {
  std::vector<int> new_index(out->objects.size(), -1);
  std::vector<ObjectOutcome> kept;
  for (size_t k = 0; k < out->objects.size(); ++k) {
    if (out->objects[k].label.camera_boxes.empty() && out->objects[k].lidar_points == 0) continue;
    new_index[k] = static_cast<int>(kept.size());
    kept.push_back(std::move(out->objects[k]));
  }
  out->objects = std::move(kept);
  out->edit.added.clear();
  for (const auto& o : out->objects) out->edit.added.push_back(o.label);
  for (auto& co : out->cameras) {
    std::vector<int> objects;
    for (int k : co.objects)
      if (new_index[static_cast<size_t>(k)] >= 0) objects.push_back(new_index[static_cast<size_t>(k)]);
    co.objects = std::move(objects);
  }
  std::vector<std::pair<int, int>> points;
  for (const auto& [i, k] : out->lidar_object_points)
    if (new_index[static_cast<size_t>(k)] >= 0) points.push_back({i, new_index[static_cast<size_t>(k)]});
  out->lidar_object_points = std::move(points);
}

}  // namespace

// The scene in the ego frame: the objects, then one receiver mesh for their shadows.
ObjectScene BuildObjectScene(const std::vector<PlacedObject>& placed, const Eigen::Vector3d& sun_dir) {
  ObjectScene s;
  s.receiver = std::make_shared<TriangleMesh>();
  for (const auto& o : placed) {
    auto mesh = std::make_shared<TriangleMesh>(o.asset->mesh);
    mesh->Transform(o.T_ego_asset);
    if (mesh->normals.empty()) mesh->ComputeVertexNormals();
    s.scene.AddMesh(mesh);
    std::vector<Eigen::Vector3d> extent;
    for (const auto& c : o.box.Corners()) extent.push_back(c);
    AddReceiverPatch(o, sun_dir, s.receiver.get(), &extent);
    s.receiver_faces_end.push_back(s.receiver->faces.size());
    s.extent_points.insert(s.extent_points.end(), extent.begin(), extent.end());
    s.extent_of.push_back(std::move(extent));
  }
  s.receiver_id = s.scene.AddMesh(s.receiver);
  s.scene.SetOftenSkipped(s.receiver_id);  // the objects' rays never see their own ground
  s.scene.SetFastOcclusion();              // the render's and the road shade's sky and sun rays are counted
  s.scene.Commit();
  return s;
}

}  // namespace frame_stages

models::Harmonizer ResolveSynthHarmonizer(const std::string& choice) {
  if (choice == "classical") return models::Harmonizer::Classical(frame_stages::SynthHarmonizeOptions());
  if (choice != "auto" && !fs::exists(choice))
    throw InputError(choice, "no such harmoniser: give none, classical, auto or a TorchScript file (docs/models.md)");
  return models::Harmonizer::Resolve(choice, {}, frame_stages::SynthHarmonizeOptions());
}

FrameSeeds FrameSeedsOf(uint32_t scenario_seed, size_t frame_index) {
  FrameSeeds s;
  // Placement and rendering keep the offsets every recorded figure was made with: distinct per frame and
  // reproducible. 7919 (a prime) keeps a frame's placement stream away from its neighbours' render streams.
  s.placement = scenario_seed + static_cast<uint32_t>(frame_index) * 7919u;
  s.render = scenario_seed + static_cast<uint32_t>(frame_index);
  // The LiDAR stream through the splitmix64 finaliser: nearby seeds, unrelated streams.
  uint64_t z = (static_cast<uint64_t>(scenario_seed) << 32) ^ (static_cast<uint64_t>(frame_index) + 0x9E3779B97F4A7C15ull);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  s.lidar = z ^ (z >> 31);
  // The sensor noise stream: the same finaliser on another offset of the LiDAR's input.
  z = (static_cast<uint64_t>(scenario_seed) << 32) ^ (static_cast<uint64_t>(frame_index) + 0xD1B54A32D192ED03ull);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  s.sensor = z ^ (z >> 31);
  return s;
}

std::vector<Eigen::Vector3d> PointsInEgo(const Frame& frame, const PointCloud& sweep) {
  std::vector<Eigen::Vector3d> points_ego(sweep.size());
  for (size_t i = 0; i < sweep.size(); ++i) points_ego[i] = frame.lidar->T_ego_lidar * sweep.xyz(i).cast<double>();
  return points_ego;
}

std::vector<uint8_t> SecondSensorReturns(const Frame& frame, const PointCloud& sweep) {
  std::vector<uint8_t> other_sensor;
  const int sensor = frame.lidar->sensor_feature.empty() ? -1 : sweep.FeatureIndex(frame.lidar->sensor_feature);
  if (sensor >= 0) {
    other_sensor.resize(sweep.size());
    for (size_t i = 0; i < sweep.size(); ++i) other_sensor[i] = std::lround(sweep.feature(i, sensor)) != 0;
  }
  return other_sensor;
}

GroundModel EstimateFrameGround(const Frame& frame, const PointCloud& sweep, const std::vector<Eigen::Vector3d>& points_ego,
                                const Scenario& scenario) {
  std::vector<Box3> real_boxes;
  for (const auto& a : frame.annotations) real_boxes.push_back(a.box);
  GroundOptions gopt;
  gopt.seed = scenario.seed;
  gopt.sensor_xy = frame.lidar->T_ego_lidar.translation.head<2>();
  return GroundModel::Estimate(points_ego, real_boxes, gopt, SecondSensorReturns(frame, sweep));
}

namespace {
constexpr int kCameraGroundSectors = 120;
constexpr double kCameraKerbStep = 0.10;
// 4 sectors of 3 deg: the front camera's wedge without parallax is about +-6 deg around the direction of travel.
constexpr int kCameraBridgedSectors = 4;
}  // namespace

CameraRoadOptions SynthCameraRoadOptions() {
  CameraRoadOptions o;
  o.scene_points = true;
  return o;
}

double RoadPriorHeight(const Log& log, const Frame& frame) {
  std::vector<double> bottoms;
  for (const auto& a : frame.annotations)
    if (!a.detected) bottoms.push_back(a.box.center().z() - 0.5 * a.box.size.z());
  return bottoms.empty() ? log.nominal_road_z : Median(bottoms);
}

CameraGround EstimateCameraGround(const Log& log, size_t frame_index, const Scenario& scenario,
                                  const CameraRoadOptions& options) {
  const Frame& frame = log.frames.at(frame_index);
  const double prior = RoadPriorHeight(log, frame);
  std::vector<Box3> real_boxes;
  for (const auto& a : frame.annotations) real_boxes.push_back(a.box);
  GroundOptions gopt;
  gopt.seed = scenario.seed;
  gopt.max_range = std::min(gopt.max_range, options.max_range);
  // The free-space walk in sectors as wide as the stereo's road points are dense: a few thousand points leave most
  // of a sweep's 720 sectors (0.5 deg) empty, and an empty sector is not drivable.
  gopt.sectors = kCameraGroundSectors;
  // A kerb is what stands out of the stereo's noise (2-3 cm median, 7 cm p90 on PandaSet), not a LiDAR's 4 cm:
  // at 2.5 cm every sector's walk ended at its first noisy return, and the roughness it measures comes from
  // the returns that walk accepted, so it could not raise the threshold itself.
  gopt.kerb_step = kCameraKerbStep;
  gopt.bridge_empty_sectors = kCameraBridgedSectors;
  gopt.open_sectors_reach_obstacles = true;
  CameraGround out;
  const CameraRoadResult road = EstimateRoadFromCameras(log, frame_index, prior, options);
  std::string why = road.summary;
  // Fewer points than this make no surface worth trusting over the plane (a few patches of texture).
  constexpr size_t kMinStereoPoints = 200;
  if (!road.points_ego.empty() && road.points_ego.size() < kMinStereoPoints) {
    why += Msg() << "; too few road points for a surface";
  } else if (!road.points_ego.empty()) {
    try {
      // The road points and the scene's, as a sweep's returns: the height field and the free-space walk read them as
      // they read a LiDAR's, except that a sector's walk which runs out of road points reaches on to its first
      // obstacle (the stereo's road ends where its parallax does).
      out.points_ego = road.points_ego;
      out.points_ego.insert(out.points_ego.end(), road.scene_points_ego.begin(), road.scene_points_ego.end());
      out.ground = GroundModel::Estimate(out.points_ego, real_boxes, gopt);
      out.source = Msg() << "cameras: " << road.summary << "; " << out.ground.ground_points().size() << " points on the fitted road";
      out.from_stereo = true;
      return out;
    } catch (const InputError& e) {
      why += Msg() << "; " << e.what();
    }
  }
  GroundPlane plane;
  plane.d = -prior;
  out.ground = GroundModel::Plane(plane, gopt);
  out.source = Msg() << "assumed: a level road at z = " << Fixed(prior, 2) << " m in the ego frame ("
                     << (std::any_of(frame.annotations.begin(), frame.annotations.end(), [](const Annotation& a) { return !a.detected; })
                             ? "the annotated boxes' bottoms" : "the rig's nominal height")
                     << "), drivable within " << Fixed(gopt.max_range, 0) << " m, no obstacle known but the boxes (" << why << ")";
  return out;
}

FrameOutcome SynthesizeFrame(const Log& log, size_t frame_index, const std::vector<Asset>& assets,
                             const Scenario& scenario, const SynthOptions& options, const SequencePlan* plan) {
  using namespace frame_stages;
  FrameOutcome out;
  out.frame_index = frame_index;
  out.edit.frame_index = frame_index;
  StageTimes* times = &out.timings;
  ScopedStage read_stage(times, "read");
  const FrameInputs in = ReadFrameInputs(log, frame_index, scenario, &out);
  read_stage.Stop();
  std::vector<int> plan_index;
  ScopedStage place_stage(times, "place");
  const std::vector<PlacedObject> placed = PlaceFrameObjects(in, assets, scenario, plan, &plan_index);
  place_stage.Stop();
  ScopedStage light_stage(times, "light");
  const FrameLight light = LightFrame(in, scenario, options, placed, &out);
  light_stage.Stop();
  ScopedStage scene_stage(times, "scene");
  const ObjectScene scene = BuildObjectScene(placed, light.sun_dir);
  scene_stage.Stop();
  out.objects = LabelObjects(log, placed, plan, plan_index);

  std::shared_ptr<const models::Harmonizer> harmonizer = options.harmonizer_model;
  if (!harmonizer && options.harmonizer != "none" && !placed.empty())
    harmonizer = std::make_shared<const models::Harmonizer>(ResolveSynthHarmonizer(options.harmonizer));
  std::map<std::string, SaturationReference> colour_reference;
  ScopedStage reference_stage(times, "colour reference");
  if (options.camera_look.colour && !placed.empty()) colour_reference = ColourReference(in, placed, plan);
  reference_stage.Stop();
  const CameraStageInput stage{&in,      &placed, &light, &scene, harmonizer.get(), &options,
                               options.camera_look.colour ? &colour_reference : nullptr,
                               plan != nullptr,  times};
  // The cameras and the LiDAR depend on nothing but the stages above, so they run at once: a camera's stages after
  // its render (occlusion, composite, harmonisation, colour, sensor) and the LiDAR are mostly serial, and overlap
  // this way with each other and with the other cameras' rendering. Each writes only its own slot (the LiDAR its
  // fields of `out`); they are gathered in camera order, so the outcome is the one a serial loop gives, and the
  // error of the lowest camera (then the LiDAR's) is the one thrown.
  struct CameraSlot {
    std::optional<CameraOutcome> camera;
    std::vector<CameraObjectView> views;
    StageTimes times;
  };
  const size_t n_cameras = in.frame->cameras.size();
  std::vector<CameraSlot> slots(n_cameras);
  StageTimes lidar_times;
  ParallelForRethrow(0, n_cameras + 1, [&](size_t i) {
    if (i == n_cameras) {
      ScopedStage lidar_stage(&lidar_times, "lidar");
      SimulateFrameLidar(in, placed, options, &out);
      return;
    }
    CameraStageInput own = stage;
    own.times = &slots[i].times;
    slots[i].camera = SynthesizeCamera(own, i, &slots[i].views);
  });
  for (CameraSlot& slot : slots) {
    times->Merge(slot.times);
    AddCameraViews(slot.views, &out.objects);
    if (!slot.camera) continue;
    out.edit.images[slot.camera->channel] = slot.camera->after;
    out.cameras.push_back(std::move(*slot.camera));
  }
  times->Merge(lidar_times);
  FinishLabels(&out);
  if (plan) DropUnobserved(&out);
  return out;
}

}  // namespace sd
