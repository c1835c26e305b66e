#include "synth/pipeline.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <fstream>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <tuple>

#include "bank/bank.h"
#include "core/log.h"
#include "core/parallel.h"
#include "datasets/categories.h"
#include "datasets/coco.h"
#include "datasets/format.h"
#include "io/files.h"
#include "io/image_io.h"
#include "io/json.h"
#include "io/pointcloud_io.h"
#include "models/harmonization.h"
#include "render/camera_render.h"
#include "render/ray_scene.h"
#include "synth/lidar_sim.h"
#include "synth/environment.h"
#include "synth/lighting.h"
#include "synth/object_light.h"
#include "synth/occlusion.h"
#include "synth/report.h"
#include "synth/road_surface.h"

namespace sd {
namespace fs = std::filesystem;
namespace {

// A flat square of road under an object, large enough to catch its shadow, on the object's local plane.
void AddReceiverPatch(const PlacedObject& o, const Eigen::Vector3d& sun_dir, TriangleMesh* receiver) {
  const double h = o.box.size.z();
  const double sun_el = std::asin(std::clamp(sun_dir.z(), 0.26, 1.0));  // >= 15 deg keeps patches bounded
  const double half = 0.5 * o.box.size.head<2>().norm() + h / std::tan(sun_el) + 1.0;
  const int n = std::clamp(static_cast<int>(2 * half / 0.25), 4, 160);
  const int base = static_cast<int>(receiver->positions.size());
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) {
      const double u = -half + 2 * half * i / n, v = -half + 2 * half * j / n;
      // In the asset frame (origin on the ground, z along the local normal), lifted 1 mm so shadow rays
      // from the receiver do not start inside the object's base.
      receiver->positions.push_back((o.T_ego_asset * Eigen::Vector3d(u, v, 0.001)).cast<float>());
    }
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const int a = base + j * (n + 1) + i;
      receiver->faces.push_back({a, a + 1, a + n + 2});
      receiver->faces.push_back({a, a + n + 2, a + n + 1});
    }
}

// Drivable ground points within `margin_m` of the objects' footprints (their bounding circles).
std::vector<Eigen::Vector3d> RoadPointsNear(const GroundModel& ground, const std::vector<PlacedObject>& objects,
                                            double margin_m = 6.0) {
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

std::vector<Eigen::Vector3d> PointsInEgo(const Frame& frame, const PointCloud& sweep) {
  std::vector<Eigen::Vector3d> points_ego(sweep.size());
  for (size_t i = 0; i < sweep.size(); ++i) points_ego[i] = frame.lidar->T_ego_lidar * sweep.xyz(i).cast<double>();
  return points_ego;
}

// The one ground estimate of a frame: synthesis places on it and the merge recomputes it for the report, so it
// must depend on nothing but the frame and the scenario.
GroundModel EstimateFrameGround(const Frame& frame, const std::vector<Eigen::Vector3d>& points_ego, const Scenario& scenario) {
  std::vector<Box3> real_boxes;
  for (const auto& a : frame.annotations) real_boxes.push_back(a.box);
  GroundOptions gopt;
  gopt.seed = scenario.seed;
  gopt.sensor_xy = frame.lidar->T_ego_lidar.translation.head<2>();
  return GroundModel::Estimate(points_ego, real_boxes, gopt);
}

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

// The LiDAR model of a frame's own sweep (docs/lidar.md), or nullopt where none applies: a sweep of several
// merged lidars (Argoverse 2) or one too small to fit (the caller falls back to the ideal sensor, which is not
// worth failing the frame for).
std::optional<LidarModel> FitFrameLidarModel(const Frame& frame, const PointCloud& sweep) {
  if (!frame.lidar->one_beam_pattern) return std::nullopt;
  LidarFitOptions fit;
  const Rigid3d T_lidar_ego = frame.lidar->T_ego_lidar.Inverse();
  for (const auto& a : frame.annotations)
    if (!a.category.empty()) fit.annotated.push_back({a.category, a.box.Transformed(T_lidar_ego)});
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

// The LiDAR noise/dropout seed of a frame: the scenario seed and the frame index alone, so every shard draws
// the same numbers for a frame.
uint64_t LidarSeed(uint32_t scenario_seed, size_t frame_index) {
  uint64_t z = (static_cast<uint64_t>(scenario_seed) << 32) ^ (static_cast<uint64_t>(frame_index) + 0x9E3779B97F4A7C15ull);
  z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;  // splitmix64 finaliser: nearby seeds, unrelated streams
  z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
  return z ^ (z >> 31);
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

// Pixels of dense depth around the rendered rectangle: DenseVisibility reads the scene depth up to twice its
// guide radius (2) beyond an object's box.
constexpr int kDepthMargin = 8;

// The road that decides whether an object stands in the sun: within 1.5 m of its footprint. Shade boundaries
// are sharp; the 6 m the level of the light is read from would mix a shaded spot with the sunlit road beside it.
// Where no camera shows road that close (a cone whose near road its neighbours and the parked cars hide), the
// nearest wider ring that has road, before the road of all objects: over a sequence the closest road comes and
// goes as the view changes, and jumping to the frame-wide level made a cone's brightness change by 70 % from one
// frame to the next (PandaSet 002, bench_sequence).
constexpr double kOwnRoadMargins[] = {1.5, 3.0, 6.0};

// Shadow rays over the sun's disk per road pixel: soft edges without visible noise at 4 samples per pixel.
constexpr int kShadowSunRays = 8;

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

// The classical harmoniser as synth uses it: colour cast and a little chroma, no lightness transfer (see
// SynthOptions::harmonizer).
models::HarmonizeOptions SynthHarmonizeOptions() {
  models::HarmonizeOptions o;
  o.lightness_strength = 0.0f;
  return o;
}

models::Harmonizer ResolveSynthHarmonizer(const std::string& choice) {
  if (choice == "classical") return models::Harmonizer::Classical(SynthHarmonizeOptions());
  if (choice != "auto" && !fs::exists(choice))
    throw InputError(choice, "no such harmoniser: give none, classical, auto or a TorchScript file (docs/models.md)");
  return models::Harmonizer::Resolve(choice, {}, SynthHarmonizeOptions());
}

int NuScenesVisibility(double fraction) {
  if (fraction < 0.4) return 1;
  if (fraction < 0.6) return 2;
  if (fraction < 0.8) return 3;
  return 4;
}

}  // namespace

FrameOutcome SynthesizeFrame(const Log& log, size_t frame_index, const std::vector<Asset>& assets,
                             const Scenario& scenario, const SynthOptions& options, const SequencePlan* plan) {
  const Frame& frame = log.frames.at(frame_index);
  if (!frame.lidar) throw InputError(log.source, "frame " + frame.token + " has no LiDAR sweep; synth needs one");
  FrameOutcome out;
  out.frame_index = frame_index;
  out.edit.frame_index = frame_index;

  // LiDAR in the ego frame, ground, placement.
  out.sweep_before = ReadLidar(*frame.lidar);
  const PointCloud& sweep = out.sweep_before;
  const std::vector<Eigen::Vector3d> points_ego = PointsInEgo(frame, sweep);
  std::vector<Box3> real_boxes;
  std::vector<std::pair<std::string, Box3>> annotated;
  for (const auto& a : frame.annotations) {
    real_boxes.push_back(a.box);
    annotated.push_back({a.category, a.box});
  }
  out.ground = EstimateFrameGround(frame, points_ego, scenario);
  const GroundModel& ground = out.ground;

  PlacementInput pin;
  pin.ground = &ground;
  pin.points_ego = points_ego;
  pin.real_boxes = real_boxes;
  for (const auto& c : frame.cameras) pin.cameras.push_back(&c);
  std::vector<PlacedObject> placed;
  std::vector<int> plan_index;
  if (plan) {
    placed = PlacedFromPlan(*plan, frame_index, assets, &plan_index);
  } else {
    Scenario frame_scenario = scenario;
    frame_scenario.seed = scenario.seed + static_cast<uint32_t>(frame_index) * 7919u;  // distinct, reproducible per frame
    placed = PlaceObjects(frame_scenario, assets, pin);
  }

  // Camera images, read once; the environment map stitches the whole rig, the road light only needs the
  // cameras that see the objects.
  std::vector<ImageU8> images(frame.cameras.size());  // empty until read
  const auto image_of = [&](size_t k) -> const ImageU8& {
    if (images[k].empty()) {
      const CameraSensor& cam = frame.cameras[k];
      images[k] = ReadImage(cam.image_path, 3);
      if (images[k].width() != cam.intrinsics.width || images[k].height() != cam.intrinsics.height)
        throw InputError(cam.image_path, Msg() << "image is " << images[k].width() << "x" << images[k].height()
                                               << " but the calibration says " << cam.intrinsics.width << "x"
                                               << cam.intrinsics.height);
    }
    return images[k];
  };

  // Light: the sun, and the environment map it is checked against.
  std::string sun_source;
  Eigen::Vector3d sun_dir = SunDirectionEgo(frame, scenario.location ? scenario.location : log.location, scenario.sun, &sun_source);
  std::optional<EnvironmentMap> env;
  if (options.light == SynthOptions::Light::kEnvironment && !placed.empty()) {
    for (size_t k = 0; k < frame.cameras.size(); ++k) image_of(k);
    EnvironmentOptions eo;
    eo.ephemeris_sun_ego = sun_dir;
    eo.detect_sun_in_images = !scenario.sun;  // a scenario's sun is the user's word
    env = BuildEnvironmentMap(frame, images, eo);
    if (env->sun_source != "ephemeris") {
      sun_dir = env->sun_direction;
      sun_source = env->sun_source;
    }
    out.light = EnvironmentSummary(*env, sun_source);
  } else {
    out.light = options.light == SynthOptions::Light::kRoad ? "road calibration per camera" : "no objects";
  }
  out.sun_source = sun_source;

  // Scene in the ego frame: objects, then one receiver mesh for shadows.
  RayScene scene;
  auto receiver = std::make_shared<TriangleMesh>();
  std::vector<size_t> receiver_faces_end;  // object k's patch: faces [end of k - 1, end of k) of the receiver
  for (const auto& o : placed) {
    auto mesh = std::make_shared<TriangleMesh>(o.asset->mesh);
    mesh->Transform(o.T_ego_asset);
    if (mesh->normals.empty()) mesh->ComputeVertexNormals();
    scene.AddMesh(mesh);
    AddReceiverPatch(o, sun_dir, receiver.get());
    receiver_faces_end.push_back(receiver->faces.size());
  }
  const int receiver_id = scene.AddMesh(receiver);
  scene.Commit();

  out.objects.resize(placed.size());
  for (size_t k = 0; k < placed.size(); ++k) {
    auto& oc = out.objects[k];
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

  std::shared_ptr<const models::Harmonizer> harmonizer = options.harmonizer_model;
  if (!harmonizer && options.harmonizer != "none" && !placed.empty())
    harmonizer = std::make_shared<const models::Harmonizer>(ResolveSynthHarmonizer(options.harmonizer));

  // Cameras.
  std::vector<uint8_t> is_ground(points_ego.size(), 0);
  for (int i : ground.ground_indices()) is_ground[i] = 1;
  const std::vector<Eigen::Vector3d> road_points = RoadPointsNear(ground, placed);
  // The sun's visibility per object, decided once from every camera that sees its road (a building's shade
  // can cover one cone of a closure and not the next); objects whose road no camera shows enough of take the
  // verdict over all objects' road.
  std::vector<std::vector<Eigen::Vector3d>> road_points_of(placed.size());  // each object's own road
  std::optional<double> sun_at_objects;
  std::vector<std::optional<double>> sun_at_object(placed.size());
  std::vector<bool> own_verdict(placed.size(), false);
  if (env) {
    std::vector<const ImageU8*> rig;
    for (size_t k = 0; k < frame.cameras.size(); ++k) rig.push_back(&image_of(k));
    const SunVerdict all = SunVisibilityAt(*env, frame, rig, road_points);
    if (all.road_samples > 0) sun_at_objects = all.sun_visibility;
    for (size_t k = 0; k < placed.size(); ++k) {
      for (double margin : kOwnRoadMargins) {
        road_points_of[k] = RoadPointsNear(ground, {placed[k]}, margin);
        const SunVerdict own = SunVisibilityAt(*env, frame, rig, road_points_of[k]);
        own_verdict[k] = own.road_samples > 0;
        sun_at_object[k] = own_verdict[k] ? std::optional<double>(own.sun_visibility) : sun_at_objects;
        if (own_verdict[k]) break;
      }
    }
  }
  const PlaneSurface ground_plane(ground.seed_plane().normal, ground.seed_plane().d);
  // Everything a camera may need to redraw: the objects' boxes and their shadow receivers.
  std::vector<Eigen::Vector3d> extent_points;
  for (const auto& o : placed)
    for (const auto& c : o.box.Corners()) extent_points.push_back(c);
  for (const auto& p : receiver->positions) extent_points.push_back(p.cast<double>());
  for (size_t cam_index = 0; cam_index < frame.cameras.size(); ++cam_index) {
    const CameraSensor& cam = frame.cameras[cam_index];
    const Rigid3d T_cam_ego = cam.T_ego_cam.Inverse();
    const auto rect = ProjectedRect(cam.intrinsics, T_cam_ego, extent_points, 2);
    if (!rect) continue;

    const ImageU8& original = image_of(cam_index);
    ImageF linear = ToLinear(original);
    std::optional<ObjectLight> object_light;
    // Each object under its own sun verdict; the level from its road in this view, else from all objects' road.
    std::vector<ObjectLight> light_of_object;
    Lighting lighting;
    if (env) {
      object_light = LightAtObjects(*env, cam_index, cam, linear, road_points, {}, sun_at_objects);
      lighting = object_light->lighting;
      for (size_t k = 0; k < placed.size(); ++k) {
        // The level from the object's nearest road this camera sees (the rings of kOwnRoadMargins), else all.
        ObjectLight own = LightAtObjects(*env, cam_index, cam, linear, road_points_of[k], {}, sun_at_object[k]);
        for (double margin : kOwnRoadMargins) {
          if (own.road_samples > 0) break;
          own = LightAtObjects(*env, cam_index, cam, linear, RoadPointsNear(ground, {placed[k]}, margin), {}, sun_at_object[k]);
        }
        if (own.road_samples == 0) own = LightAtObjects(*env, cam_index, cam, linear, road_points, {}, sun_at_object[k]);
        light_of_object.push_back(own);
      }
    } else {
      lighting = CalibrateLighting(linear, cam, road_points, sun_dir);
    }
    CameraRenderOptions ropt;
    ropt.samples_per_pixel = options.samples_per_pixel;
    ropt.ao_samples = options.ao_samples;
    ropt.receiver_mesh = receiver_id;
    ropt.receiver_shadow = !object_light;  // the map's light shades the road below (ReceiverShadowImage)
    for (const ObjectLight& l : light_of_object) ropt.mesh_lighting.push_back(l.lighting);  // mesh k = object k
    ropt.x0 = (*rect)[0];
    ropt.y0 = (*rect)[1];
    ropt.x1 = (*rect)[2];
    ropt.y1 = (*rect)[3];
    ropt.seed = scenario.seed + static_cast<uint32_t>(frame_index);
    const CameraRender render = RenderCamera(scene, cam.intrinsics, cam.T_ego_cam, lighting, ropt);
    // The renderer's hard, one-ray shadow is the road light's; the map's light has a sun disk and a sky with
    // bright and dark sides.
    ImageF shadow = render.shadow;
    if (object_light) {
      EnvShadingOptions so;
      so.sun_rays = kShadowSunRays;
      so.sky_rays = options.ao_samples;
      so.seed = ropt.seed;
      so.skip_mesh = receiver_id;
      std::vector<const EnvironmentLight*> light_of_face(receiver->faces.size());
      for (size_t k = 0, f = 0; k < placed.size(); ++k)
        for (; f < receiver_faces_end[k]; ++f) light_of_face[f] = &light_of_object[k].shading;
      shadow = ReceiverShadowImage(scene, cam.intrinsics, cam.T_ego_cam, receiver_id, light_of_face, so, ropt.x0, ropt.y0,
                                   ropt.x1, ropt.y1);
    }

    // Occlusion by the real scene: of the objects, and of the road their shadows fall on (the ground under a
    // shadow must not be hidden by a real object).
    const auto projected = ProjectPoints(points_ego, is_ground, cam.intrinsics, T_cam_ego);
    ImageF receiver_depth(render.depth.width(), render.depth.height(), 1, std::numeric_limits<float>::infinity());
    const GroundPlane& plane = ground.seed_plane();
    for (int y = ropt.y0; y < ropt.y1; ++y)
      for (int x = ropt.x0; x < ropt.x1; ++x) {
        if (shadow.at(x, y) >= 0.999f) continue;
        const Eigen::Vector3d d_cam = cam.intrinsics.RayDirection(Eigen::Vector2d(x + 0.5, y + 0.5));
        const Eigen::Vector3d o = cam.T_ego_cam.translation, d = cam.T_ego_cam.rotation * d_cam;
        const double denom = plane.normal.dot(d);
        if (std::abs(denom) < 1e-6) continue;
        const double t = -(plane.normal.dot(o) + plane.d) / denom;
        if (t > 0) receiver_depth.at(x, y) = static_cast<float>(t * d_cam.z());
      }
    ImageF visibility, receiver_visibility;
    if (options.dense_occlusion) {
      DepthPriors priors;
      priors.boxes_ego = real_boxes;
      priors.surface = &ground_plane;  // ego frame: T_world_ego stays identity
      // Only where objects or their shadows are, plus the band the visibility mattes from (guide radius 2).
      DenseDepthOptions dopt;
      dopt.x0 = ropt.x0 - kDepthMargin, dopt.y0 = ropt.y0 - kDepthMargin;
      dopt.x1 = ropt.x1 + kDepthMargin, dopt.y1 = ropt.y1 + kDepthMargin;
      const DepthMap scene_depth = DenseDepth(projected, original, cam.intrinsics, T_cam_ego, priors, dopt);
      visibility = DenseVisibility(scene_depth, original, render.depth);
      receiver_visibility = DenseVisibility(scene_depth, original, receiver_depth);
    } else {
      visibility = ComputeVisibility(projected, render.depth);
      receiver_visibility = ComputeVisibility(projected, receiver_depth);
    }

    // Composite in linear light: objects over the photo, the photo darkened by their shadows.
    bool changed = false;
    ImageF object_alpha(linear.width(), linear.height(), 1, 0.0f);
    ImageF shadow_only_loss(linear.width(), linear.height(), 3, 0.0f);  // what the shadows took from the photo
    std::vector<double> rendered(placed.size(), 0), visible(placed.size(), 0);
    std::vector<Box2> boxes(placed.size(), Box2{1e9, 1e9, -1e9, -1e9});
    for (int y = ropt.y0; y < ropt.y1; ++y)
      for (int x = ropt.x0; x < ropt.x1; ++x) {
        const float a = render.coverage.at(x, y);
        const float vis = visibility.at(x, y);
        const float shade = receiver_visibility.at(x, y) > 0.5f ? shadow.at(x, y) : 1.0f;
        if (a <= 0 && shade >= 1.0f) continue;
        const float av = a * vis;
        object_alpha.at(x, y) = av;
        float* px = linear.pixel(x, y);
        for (int c = 0; c < 3; ++c) {
          shadow_only_loss.at(x, y, c) = px[c] * (1 - av) * (1 - shade);
          px[c] = render.color.at(x, y, c) * vis + px[c] * (1 - av);  // shadows are taken away below
        }
        changed = true;
        const int id = render.object.at(x, y);
        if (id >= 0 && id < static_cast<int>(placed.size()) && a >= 0.5f) {
          rendered[id] += 1;
          if (vis > 0.5f) {
            visible[id] += 1;
            Box2& b = boxes[id];
            b.x1 = std::min<double>(b.x1, x);
            b.y1 = std::min<double>(b.y1, y);
            b.x2 = std::max<double>(b.x2, x + 1);
            b.y2 = std::max<double>(b.y2, y + 1);
          }
        }
      }
    if (!changed) continue;
    // Harmonisation sees the objects over the unshadowed photo (their own shadow would otherwise count as the
    // surroundings they are matched to), one object at a time; the shadows are applied after it.
    std::string harmonized;
    if (harmonizer) {
      // On a crop: the objects' rectangle grown by the widest background ring the classical transfer reads
      // (0.25 sqrt(object pixels), HarmonizeOptions::ring_px), so the whole photograph is not converted per camera.
      const int margin = 2 + static_cast<int>(std::ceil(0.25 * std::sqrt(double(ropt.x1 - ropt.x0) * (ropt.y1 - ropt.y0))));
      const int cx0 = std::max(0, ropt.x0 - margin), cy0 = std::max(0, ropt.y0 - margin);
      const int cx1 = std::min(linear.width(), ropt.x1 + margin), cy1 = std::min(linear.height(), ropt.y1 + margin);
      ImageF composite(cx1 - cx0, cy1 - cy0, 3);
      for (int y = cy0; y < cy1; ++y)
        for (int x = cx0; x < cx1; ++x)
          for (int c = 0; c < 3; ++c) composite.at(x - cx0, y - cy0, c) = LinearToSrgb(std::clamp(linear.at(x, y, c), 0.0f, 1.0f));
      int objects_harmonized = 0;
      for (size_t k = 0; k < placed.size(); ++k) {
        if (visible[k] < 4) continue;
        ImageF mask(composite.width(), composite.height(), 1, 0.0f);
        for (int y = ropt.y0; y < ropt.y1; ++y)
          for (int x = ropt.x0; x < ropt.x1; ++x)
            if (render.object.at(x, y) == static_cast<int>(k)) mask.at(x - cx0, y - cy0) = object_alpha.at(x, y);
        composite = harmonizer->Harmonize(composite, mask);
        ++objects_harmonized;
      }
      // Back to linear only where an object is: elsewhere the harmoniser returned the composite bit for bit,
      // and the round trip through sRGB would not be.
      for (int y = ropt.y0; y < ropt.y1; ++y)
        for (int x = ropt.x0; x < ropt.x1; ++x)
          if (object_alpha.at(x, y) > 0)
            for (int c = 0; c < 3; ++c) linear.at(x, y, c) = SrgbToLinear(composite.at(x - cx0, y - cy0, c));
      harmonized = Msg() << "; harmonised: " << objects_harmonized << " object(s) (" << (harmonizer->learned() ? "learned" : "classical") << ")";
    }
    for (int y = ropt.y0; y < ropt.y1; ++y)
      for (int x = ropt.x0; x < ropt.x1; ++x)
        for (int c = 0; c < 3; ++c) linear.at(x, y, c) = std::max(0.0f, linear.at(x, y, c) - shadow_only_loss.at(x, y, c));
    CameraOutcome co;
    co.channel = cam.channel;
    co.before = original;
    co.after = ToSrgb8(linear);
    if (object_light) {
      co.light = Msg() << "sun visibility " << Fixed(object_light->sun_visibility, 2) << ", scale " << Fixed(object_light->scale, 2)
                       << " (" << object_light->road_samples << " road pixels)";
      std::string own;
      for (size_t k = 0; k < placed.size(); ++k)
        if (own_verdict[k] && visible[k] >= 4)
          own += Msg() << (own.empty() ? "" : ", ") << "#" << k << " " << Fixed(light_of_object[k].sun_visibility, 2) << " x"
                       << Fixed(light_of_object[k].scale, 2);
      if (!own.empty()) co.light += "; per object (sun visibility x scale): " + own;
    } else {
      co.light = "road calibration";
    }
    co.light += harmonized;
    for (size_t k = 0; k < placed.size(); ++k) {
      out.objects[k].rendered_pixels += rendered[k];
      out.objects[k].visible_pixels += visible[k];
      if (visible[k] < 4) continue;  // a few pixels are not a labelable object
      CameraBox cb;
      cb.channel = cam.channel;
      cb.box = boxes[k];
      cb.visible_fraction = rendered[k] > 0 ? visible[k] / rendered[k] : 0;
      // Truncation: share of the projected 3D box rectangle that falls outside the image.
      double u0 = 1e18, v0 = 1e18, u1 = -1e18, v1 = -1e18;
      bool all_front = true;
      for (const auto& c : placed[k].box.Corners()) {
        const auto uv = cam.intrinsics.Project(T_cam_ego * c, 0.1);
        if (!uv) { all_front = false; break; }
        u0 = std::min(u0, uv->x()); v0 = std::min(v0, uv->y()); u1 = std::max(u1, uv->x()); v1 = std::max(v1, uv->y());
      }
      if (all_front && u1 > u0 && v1 > v0) {
        const double inside = std::max(0.0, std::min(u1, double(cam.intrinsics.width)) - std::max(u0, 0.0)) *
                              std::max(0.0, std::min(v1, double(cam.intrinsics.height)) - std::max(v0, 0.0));
        cb.truncation = std::clamp(1.0 - inside / ((u1 - u0) * (v1 - v0)), 0.0, 1.0);
      } else {
        cb.truncation = 1.0;
      }
      out.objects[k].label.camera_boxes.push_back(cb);
      co.objects.push_back(static_cast<int>(k));
    }
    out.edit.images[cam.channel] = co.after;
    out.cameras.push_back(std::move(co));
  }

  // LiDAR.
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
  lin.reference_intensity = ReferenceIntensities(sweep, points_ego, ground.ground_indices(), annotated, ptrs);
  if (options.lidar_realism) out.lidar_model_fit = FitFrameLidarModel(frame, sweep);
  if (out.lidar_model_fit) {
    const LidarModel& model = *out.lidar_model_fit;
    out.lidar_model = model.Summary();
    LidarRealism& re = lin.realism;
    re.model = &model;
    re.noise = re.dropout = re.intensity = true;
    re.seed = LidarSeed(scenario.seed, frame_index);
    // nuScenes (tables and mmdet3d infos) de-skew their sweeps and stamp them at the end of the turn.
    re.motion_compensated_output = frame.lidar->motion_compensated;
    if (const auto poses = NeighbourSweepPoses(log, frame_index, model.SweepPeriod(), model.SweepPeriod())) {
      re.ego_motion = out.lidar_ego_motion = true;
      std::tie(re.T_ref_ego_start, re.T_ref_ego_end) = *poses;
    }
  }
  LidarSimResult lidar = SimulateLidar(lin);
  out.lidar_object_points = lidar.object_points;

  for (size_t k = 0; k < placed.size(); ++k) {
    auto& oc = out.objects[k];
    oc.lidar_points = lidar.points_on_object[k];
    oc.label.annotation.num_lidar_pts = lidar.points_on_object[k];
    const double frac = oc.rendered_pixels > 0 ? oc.visible_pixels / oc.rendered_pixels : 0.0;
    oc.label.annotation.visibility = NuScenesVisibility(frac);
    out.edit.added.push_back(oc.label);
  }
  out.edit.points = std::move(lidar.cloud);
  if (plan) DropUnobserved(&out);
  return out;
}

// ---------------------------------------------------------------------------------------------------------
// Batch: parts, shards, merge.

namespace {

using nlohmann::json;

// Everything a shard and the merge load before doing any work; bad input fails here, before any output.
struct SynthInputs {
  Log log;
  std::vector<Asset> assets;
  Scenario scenario;
  std::vector<size_t> selected;  // frame indices, in the order the user named them
  json fingerprint;              // what a part's content depends on (see RequestFingerprint)
  std::shared_ptr<const models::Harmonizer> harmonizer;  // resolved once; null for "none" and dry runs
  bool world_fixed = false;      // the scenario is planned once per sequence (PlanSynthesis)
  SynthPlan plan;                // when world_fixed (or a dry run)
  const SequencePlan* PlanFor(size_t frame_index) const {
    if (!world_fixed) return nullptr;
    const SequencePlan* p = plan.ForFrame(frame_index);
    SD_CHECK(p != nullptr, << "frame " << frame_index << " is in no plan");
    return p;
  }
};

std::string Fnv1a64Hex(std::string_view bytes) {
  uint64_t h = 1469598103934665603ull;
  for (unsigned char c : bytes) {
    h ^= c;
    h *= 1099511628211ull;
  }
  char buf[17];
  std::snprintf(buf, sizeof buf, "%016llx", static_cast<unsigned long long>(h));
  return buf;
}

// What a part's bytes depend on: the log, the scenario, the assets and the render options. Write options
// (JPEG quality, symlinks) and the frame selection apply at the merge, so parts stay valid across them.
json RequestFingerprint(const SynthRequest& request, const std::vector<Asset>& assets) {
  json j;
  j["log"] = fs::absolute(request.log).lexically_normal().string();
  j["format"] = request.log_options.format ? ToString(*request.log_options.format) : "probe";
  j["data_root"] = request.log_options.data_root.empty() ? "" : fs::absolute(request.log_options.data_root).lexically_normal().string();
  j["scenario_fnv1a64"] = Fnv1a64Hex(ReadFileToString(request.scenario));
  j["assets"] = json::array();
  for (const Asset& a : assets) {
    std::string bytes = ReadFileToString(a.dir / "asset.json");
    if (fs::exists(a.dir / "mesh.glb")) bytes += ReadFileToString(a.dir / "mesh.glb");
    j["assets"].push_back({{"id", a.info.id}, {"fnv1a64", Fnv1a64Hex(bytes)}});
  }
  j["samples_per_pixel"] = request.options.samples_per_pixel;
  j["ao_samples"] = request.options.ao_samples;
  j["lidar_realism"] = request.options.lidar_realism;
  j["light"] = request.options.light == SynthOptions::Light::kEnvironment ? "environment" : "road";
  j["dense_occlusion"] = request.options.dense_occlusion;
  j["harmonizer"] = request.options.harmonizer;
  return j;
}

// The asset folders the scenario's bank queries name, in query order; an asset matched by several queries (or
// also given with --asset) is an error of duplicate ids below, so queries must not overlap.
std::vector<fs::path> BankAssets(const Scenario& scenario, const fs::path& scenario_file) {
  std::vector<fs::path> dirs;
  for (size_t i = 0; i < scenario.bank_queries.size(); ++i) {
    fs::path bank_path;
    const bank::BankQuery query = bank::BankQueryFromJson(scenario.bank_queries[i], scenario_file, &bank_path);
    if (bank_path.empty()) bank_path = bank::DefaultBankPath();
    if (!query.text.empty())
      throw InputError(scenario_file, "assets_from_bank: text queries need a CLIP model; use category, extent "
                                      "and quality, or pick the assets with `synthdrive bank query --text`");
    const std::vector<bank::BankEntry> found = bank::Bank::Open(bank_path, false).Query(query);
    if (found.empty())
      throw InputError(scenario_file, Msg() << "assets_from_bank[" << i << "] matches no asset in " << bank_path.string());
    SD_LOG(Info, "bank " << bank_path.string() << ": query " << i << " gives " << found.size() << " asset(s)");
    for (const bank::BankEntry& e : found) dirs.push_back(e.dir);
  }
  return dirs;
}

// True when the scenario is planned once per sequence: it has arrangements, or says "world_fixed": true.
bool WorldFixedScenario(const Scenario& scenario) { return !scenario.arrangements.empty() || scenario.world_fixed; }

SynthInputs LoadInputs(const SynthRequest& request, bool dry_run = false) {
  SynthInputs in;
  in.log = OpenLog(request.log, request.log_options);
  const Log& log = in.log;
  SD_LOG(Info, "log: " << request.log.string() << " (" << ToString(log.format) << ", " << log.frames.size() << " frames)");
  if (!FormatInfo(log.format).write && !dry_run)  // refused now rather than after synthesising every frame
    throw InputError(request.log, std::string(FormatInfo(log.format).read_only_message) + "; --dry-run plans on them");
  in.scenario = ReadScenario(request.scenario);
  std::vector<fs::path> asset_dirs = request.assets;
  for (const fs::path& dir : BankAssets(in.scenario, request.scenario)) asset_dirs.push_back(dir);
  if (asset_dirs.empty() && !dry_run) throw InputError("", "no --asset given, and the scenario names no assets_from_bank");
  std::set<std::string> ids;
  for (const auto& path : asset_dirs) {
    in.assets.push_back(LoadAsset(path));
    const auto& info = in.assets.back().info;
    if (!FindCategory(info.category))
      throw InputError(path, "unknown category '" + info.category + "' (see `synthdrive categories`)");
    if (!ids.insert(info.id).second) throw InputError(path, "duplicate asset id '" + info.id + "'");
  }
  if (request.options.frames.empty()) {
    for (size_t i = 0; i < log.frames.size(); ++i) in.selected.push_back(i);
  } else {
    std::set<size_t> seen;
    for (const auto& f : request.options.frames) {
      size_t found = log.frames.size();
      for (size_t i = 0; i < log.frames.size(); ++i)
        if (log.frames[i].token == f) found = i;
      if (found == log.frames.size() && !f.empty() && std::all_of(f.begin(), f.end(), ::isdigit)) found = std::stoul(f);
      if (found >= log.frames.size()) throw InputError(request.log, "no frame '" + f + "'");
      if (!seen.insert(found).second) throw InputError(request.log, "frame '" + f + "' selected twice");
      in.selected.push_back(found);
    }
  }
  if (in.selected.empty()) throw InputError(request.log, "log has no frames");
  in.fingerprint = RequestFingerprint(request, in.assets);
  if (!dry_run && request.options.harmonizer != "none") {
    in.harmonizer = std::make_shared<const models::Harmonizer>(ResolveSynthHarmonizer(request.options.harmonizer));
    SD_LOG(Info, "harmoniser: " << in.harmonizer->Describe());
    // "auto" is learned on a machine with the model installed and classical on one without: parts made on
    // both are of different requests.
    in.fingerprint["harmonizer_path"] = in.harmonizer->learned() ? "learned" : "classical";
  }
  in.world_fixed = WorldFixedScenario(in.scenario);
  if (in.world_fixed || dry_run) {
    in.plan = PlanSynthesis(in.log, in.selected, in.scenario, in.assets, request.scenario, !dry_run);
    // Every shard plans from the whole selection; a part made under another plan (other frames selected, other
    // sweeps) is of another request.
    if (in.world_fixed) in.fingerprint["plan_fnv1a64"] = Fnv1a64Hex(SynthPlanToJson(in.plan).dump());
  }
  return in;
}

fs::path NormalOut(const fs::path& out) {
  fs::path p = fs::absolute(out).lexically_normal();
  if (p.filename().empty()) p = p.parent_path();
  return p;
}

// The check StagingDirectory makes at the merge, made up front so a shard does not work for a refused output;
// and the output (or its parts folder, which a local run removes) must not be, hold, or lie inside anything
// the run reads: with --overwrite, replacing it would delete the log, its sensor files or the assets.
void CheckOutputFree(const SynthRequest& request, const SynthInputs& in) {
  const fs::path out = NormalOut(request.out);
  // Folders first, so the message names the folder the output would replace rather than a file inside it.
  std::vector<fs::path> inputs = {in.log.data_root};
  for (const Asset& a : in.assets) inputs.push_back(a.dir);
  for (const fs::path& p : {request.log, in.log.source, in.log.annotation_path, request.scenario}) inputs.push_back(p);
  const std::string& h = request.options.harmonizer;
  if (h != "none" && h != "classical" && h != "auto") inputs.push_back(h);  // a TorchScript file
  for (const Frame& f : in.log.frames) {
    for (const CameraSensor& c : f.cameras) inputs.push_back(c.image_path);
    if (f.lidar) inputs.push_back(f.lidar->path);
  }
  RefuseOutputOverInputs(out, inputs);
  RefuseOutputOverInputs(SynthPartsDir(out), inputs);
  std::error_code ec;
  if (fs::exists(out, ec) && !request.options.overwrite)
    throw InputError(out, "output already exists (pass --overwrite to replace it)");
}

std::string PartName(const Log& log, size_t frame_index) {
  std::string token = log.frames[frame_index].token;
  for (char& c : token)
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '-' && c != '_' && c != '.') c = '_';
  return std::to_string(frame_index) + "-" + token;
}

// Doubles go through nlohmann's shortest round-trip formatting, so a value read back is the value written;
// non-finite values (unknown velocities) are written as null.
json Num(double v) { return std::isfinite(v) ? json(v) : json(nullptr); }
double NumFrom(const JsonReader& r) {
  return r.raw().is_null() ? std::numeric_limits<double>::quiet_NaN() : r.Number();
}
json VecJson(const Eigen::Vector3d& v) { return {Num(v.x()), Num(v.y()), Num(v.z())}; }
Eigen::Vector3d VecFrom(const JsonReader& r) { return {NumFrom(r[0]), NumFrom(r[1]), NumFrom(r[2])}; }
json RigidJson(const Rigid3d& T) {
  const Eigen::Quaterniond& q = T.rotation;
  return {{"q_wxyz", {q.w(), q.x(), q.y(), q.z()}}, {"t", VecJson(T.translation)}};
}
Rigid3d RigidFrom(const JsonReader& r) {
  Rigid3d T;  // fields set directly: the constructor's normalisation could change the last bit
  const JsonReader q = r["q_wxyz"];
  T.rotation = Eigen::Quaterniond(q[0].Number(), q[1].Number(), q[2].Number(), q[3].Number());
  T.translation = VecFrom(r["t"]);
  return T;
}
json BoxJson(const Box3& b) { return {{"T_frame_box", RigidJson(b.T_frame_box)}, {"size", VecJson(b.size)}}; }
Box3 BoxFrom(const JsonReader& r) {
  Box3 b;
  b.T_frame_box = RigidFrom(r["T_frame_box"]);
  b.size = VecFrom(r["size"]);
  return b;
}
json Box2Json(const Box2& b) { return {b.x1, b.y1, b.x2, b.y2}; }
Box2 Box2From(const JsonReader& r) { return Box2{r[0].Number(), r[1].Number(), r[2].Number(), r[3].Number()}; }

json AnnotationJson(const Annotation& a) {
  json j = {{"category", a.category},       {"box", BoxJson(a.box)},          {"token", a.token},
            {"instance_token", a.instance_token}, {"num_lidar_pts", a.num_lidar_pts},
            {"velocity", {Num(a.velocity.x()), Num(a.velocity.y())}}, {"visibility", a.visibility},
            {"truncation", Num(a.truncation)}, {"box2d_by_camera", json::object()}};
  for (const auto& [channel, b] : a.box2d_by_camera) j["box2d_by_camera"][channel] = Box2Json(b);
  return j;
}
Annotation AnnotationFrom(const JsonReader& r) {
  Annotation a;
  a.category = r["category"].String();
  a.box = BoxFrom(r["box"]);
  a.token = r["token"].String();
  a.instance_token = r["instance_token"].String();
  a.num_lidar_pts = static_cast<int>(r["num_lidar_pts"].Integer());
  a.velocity = Eigen::Vector2d(NumFrom(r["velocity"][0]), NumFrom(r["velocity"][1]));
  a.visibility = static_cast<int>(r["visibility"].Integer());
  a.truncation = NumFrom(r["truncation"]);
  for (const auto& [channel, b] : r["box2d_by_camera"].raw().items())
    a.box2d_by_camera[channel] = Box2From(r["box2d_by_camera"][channel]);
  return a;
}

json AddedJson(const AddedObject& o) {
  json boxes = json::array();
  for (const CameraBox& cb : o.camera_boxes)
    boxes.push_back({{"channel", cb.channel}, {"box", Box2Json(cb.box)}, {"visible_fraction", cb.visible_fraction},
                     {"truncation", cb.truncation}});
  return {{"category", o.category}, {"annotation", AnnotationJson(o.annotation)}, {"camera_boxes", boxes}, {"asset_id", o.asset_id}};
}
AddedObject AddedFrom(const JsonReader& r) {
  AddedObject o;
  o.category = r["category"].String();
  o.annotation = AnnotationFrom(r["annotation"]);
  for (size_t i = 0; i < r["camera_boxes"].Size(); ++i) {
    const JsonReader b = r["camera_boxes"][i];
    o.camera_boxes.push_back(CameraBox{b["channel"].String(), Box2From(b["box"]), b["visible_fraction"].Number(), b["truncation"].Number()});
  }
  o.asset_id = r["asset_id"].String();
  return o;
}

constexpr int kPartVersion = 2;

// A part: part.json (the request fingerprint, the frame, the labels and everything synth.json and the report
// need) + images/<channel>.png (replacement images, lossless, re-encoded by WriteDerivative exactly as a local
// run encodes them) + sweep.bin (the replacement sweep in its record layout). The ground model, the original
// images and sweep are not stored: the merge recomputes or re-reads them from the log.
void WritePart(const fs::path& dir, const FrameOutcome& o, const SynthInputs& in, const SynthOptions& options) {
  SD_CHECK(o.edit.images.size() == o.cameras.size(), << o.edit.images.size() << " images, " << o.cameras.size() << " cameras");
  SD_CHECK(o.edit.added.size() == o.objects.size(), << o.edit.added.size() << " labels, " << o.objects.size() << " objects");
  json cameras = json::array();
  for (size_t c = 0; c < o.cameras.size(); ++c) {
    const CameraOutcome& co = o.cameras[c];
    const auto it = o.edit.images.find(co.channel);
    SD_CHECK(it != o.edit.images.end(), << co.channel);
    const std::string file = "images/" + std::to_string(c) + ".png";
    WriteImage(dir / file, it->second);
    cameras.push_back({{"channel", co.channel}, {"image", file}, {"objects", co.objects}, {"light", co.light}});
  }
  json sweep = nullptr;
  if (o.edit.points) {
    WritePointCloudBin(dir / "sweep.bin", *o.edit.points);
    sweep = {{"file", "sweep.bin"}, {"num_features", o.edit.points->num_features},
             {"feature_names", o.edit.points->feature_names}, {"points", o.edit.points->size()}};
  }
  if (options.part_written_hook) options.part_written_hook(o.frame_index, dir);
  json objects = json::array();
  for (size_t k = 0; k < o.objects.size(); ++k) {
    const ObjectOutcome& ob = o.objects[k];
    objects.push_back({{"label", AddedJson(o.edit.added[k])},
                       {"asset", ob.placement.asset->info.id},
                       {"request", ob.placement.request},
                       {"T_ego_asset", RigidJson(ob.placement.T_ego_asset)},
                       {"box", BoxJson(ob.placement.box)},
                       {"ground_height", ob.placement.ground_height},
                       {"lidar_points", ob.lidar_points},
                       {"rendered_pixels", ob.rendered_pixels},
                       {"visible_pixels", ob.visible_pixels}});
    if (ob.plan_object >= 0) objects.back()["plan_object"] = ob.plan_object;
  }
  json lidar_object_points = json::array();
  for (const auto& [i, k] : o.lidar_object_points) lidar_object_points.push_back({i, k});
  json j = {{"version", kPartVersion},
            {"request", in.fingerprint},
            {"frame", {{"index", o.frame_index}, {"token", in.log.frames[o.frame_index].token}}},
            {"sun", o.sun_source},
            {"light", o.light},
            {"objects", objects},
            {"cameras", cameras},
            {"sweep", sweep},
            {"lidar_model", o.lidar_model},
            {"lidar_ego_motion", o.lidar_ego_motion},
            {"lidar_object_points", lidar_object_points}};
  WriteJsonFile(dir / "part.json", j, -1);
}

std::string Short(const json& v) {
  std::string s = v.dump();
  return s.size() > 80 ? s.substr(0, 77) + "..." : s;
}

// InputError unless the part was made for the request `in` describes; names the first thing that differs.
void CheckPartRequest(const fs::path& part_json, const json& part, const SynthInputs& in) {
  if (!part.is_object() || part.value("version", 0) != kPartVersion)
    throw InputError(part_json, Msg() << "not a synth part of version " << kPartVersion);
  const json& theirs = part.contains("request") ? part["request"] : json();
  if (theirs == in.fingerprint) return;
  std::string what;
  for (const auto& [key, ours] : in.fingerprint.items())
    if (!theirs.is_object() || !theirs.contains(key) || theirs[key] != ours)
      what += (what.empty() ? "" : "; ") + key + " is " +
              (theirs.is_object() && theirs.contains(key) ? Short(theirs[key]) : "missing") + ", this run's is " + Short(ours);
  throw InputError(part_json, "part of a different synth request (" + (what.empty() ? "request differs" : what) +
                                  "); give the shards' arguments, or another --out");
}

FrameOutcome ReadPart(const fs::path& dir, size_t frame_index, const SynthInputs& in, bool for_report) {
  const fs::path file = dir / "part.json";
  const json j = ReadJsonFile(file);
  CheckPartRequest(file, j, in);
  const JsonReader r(j, file);
  const Frame& frame = in.log.frames.at(frame_index);
  if (static_cast<size_t>(r["frame"]["index"].Integer()) != frame_index || r["frame"]["token"].String() != frame.token)
    r["frame"].Fail(Msg() << "part is for frame " << r["frame"]["index"].Integer() << " (" << r["frame"]["token"].String()
                          << "), its folder says frame " << frame_index << " (" << frame.token << ")");
  FrameOutcome o;
  o.frame_index = frame_index;
  o.edit.frame_index = frame_index;
  o.sun_source = r["sun"].String();
  o.light = r["light"].String();
  std::map<std::string, const Asset*> by_id;
  for (const Asset& a : in.assets) by_id[a.info.id] = &a;
  for (size_t k = 0; k < r["objects"].Size(); ++k) {
    const JsonReader ro = r["objects"][k];
    ObjectOutcome ob;
    ob.label = AddedFrom(ro["label"]);
    const auto asset = by_id.find(ro["asset"].String());
    if (asset == by_id.end()) ro["asset"].Fail("no such asset in this request");
    ob.placement.asset = asset->second;
    ob.placement.request = static_cast<int>(ro["request"].Integer());
    ob.placement.T_ego_asset = RigidFrom(ro["T_ego_asset"]);
    ob.placement.box = BoxFrom(ro["box"]);
    ob.placement.ground_height = ro["ground_height"].Number();
    ob.lidar_points = static_cast<int>(ro["lidar_points"].Integer());
    ob.rendered_pixels = ro["rendered_pixels"].Number();
    ob.visible_pixels = ro["visible_pixels"].Number();
    if (ro.Has("plan_object")) ob.plan_object = static_cast<int>(ro["plan_object"].Integer());
    o.edit.added.push_back(ob.label);
    o.objects.push_back(std::move(ob));
  }
  for (size_t c = 0; c < r["cameras"].Size(); ++c) {
    const JsonReader rc = r["cameras"][c];
    CameraOutcome co;
    co.channel = rc["channel"].String();
    co.light = rc["light"].String();
    const CameraSensor* cam = frame.FindCamera(co.channel);
    if (!cam) rc["channel"].Fail("the log's frame has no such camera");
    co.after = ReadImage(dir / rc["image"].String(), 3);
    if (for_report) co.before = ReadImage(cam->image_path, 3);
    for (size_t i = 0; i < rc["objects"].Size(); ++i) co.objects.push_back(static_cast<int>(rc["objects"][i].Integer()));
    o.edit.images[co.channel] = co.after;
    o.cameras.push_back(std::move(co));
  }
  if (!r["sweep"].raw().is_null()) {
    PointLayout layout;
    layout.num_features = static_cast<int>(r["sweep"]["num_features"].Integer());
    for (size_t i = 0; i < r["sweep"]["feature_names"].Size(); ++i) layout.feature_names.push_back(r["sweep"]["feature_names"][i].String());
    PointCloud cloud = ReadPointCloudBin(dir / r["sweep"]["file"].String(), layout);
    cloud.feature_names = layout.feature_names;
    if (cloud.size() != static_cast<size_t>(r["sweep"]["points"].Integer()))
      r["sweep"]["points"].Fail(Msg() << "sweep.bin holds " << cloud.size() << " points");
    o.edit.points = std::move(cloud);
  }
  o.lidar_model = r["lidar_model"].String();
  o.lidar_ego_motion = r["lidar_ego_motion"].Bool();
  for (size_t i = 0; i < r["lidar_object_points"].Size(); ++i) {
    const JsonReader p = r["lidar_object_points"][i];
    o.lidar_object_points.push_back({static_cast<int>(p[0].Integer()), static_cast<int>(p[1].Integer())});
  }
  if (for_report && frame.lidar) {
    o.sweep_before = ReadLidar(*frame.lidar);
    o.ground = EstimateFrameGround(frame, PointsInEgo(frame, o.sweep_before), in.scenario);
  }
  return o;
}

struct FrameFailure {
  size_t frame = 0;
  std::exception_ptr error;
};

struct ShardRun {
  SynthShardSummary summary;
  std::vector<FrameFailure> failures;
};

// The shard loop shared by `--shard` and the local run.
ShardRun SynthesizeParts(const SynthInputs& in, const SynthRequest& request, const ShardSpec& shard, bool log_failures) {
  ShardRun run;
  SynthShardSummary& summary = run.summary;
  summary.parts = SynthPartsDir(request.out);
  std::vector<size_t> owned;
  for (size_t i = 0; i < in.selected.size(); ++i)
    if (shard.Owns(i)) owned.push_back(in.selected[i]);
  summary.owned = owned.size();
  std::error_code ec;
  fs::create_directories(summary.parts, ec);
  if (ec) throw InputError(summary.parts, "cannot create directory: " + ec.message());

  // Parts already there must be of this request; staging folders of our frames are what a killed run left
  // (other shards' frames are not touched: they may be running now).
  std::set<std::string> names;
  for (size_t fi : owned) names.insert(PartName(in.log, fi));
  for (const auto& entry : fs::directory_iterator(summary.parts)) {
    const std::string name = entry.path().filename().string();
    const size_t tmp = name.find(".tmp-");
    if (tmp != std::string::npos && names.count(name.substr(0, tmp))) {
      SD_LOG(Debug, "removing the unfinished part " << entry.path().string());
      fs::remove_all(entry.path(), ec);
    }
  }
  for (size_t fi : owned) {
    const fs::path part = summary.parts / PartName(in.log, fi);
    if (fs::exists(part)) CheckPartRequest(part / "part.json", ReadJsonFile(part / "part.json"), in);
  }

  summary.run_log = summary.parts / ("log-" + std::to_string(shard.index) + "-of-" + std::to_string(shard.count) + ".jsonl");
  std::ofstream run_log(summary.run_log, std::ios::app);
  if (!run_log) throw InputError(summary.run_log, "cannot open for appending");
  Progress progress("synthesising frames (shard " + shard.ToString() + ")", owned.size());
  for (size_t fi : owned) {
    const auto start = std::chrono::steady_clock::now();
    const std::string& token = in.log.frames[fi].token;
    const fs::path part = summary.parts / PartName(in.log, fi);
    json line = {{"frame", fi}, {"token", token}};
    if (fs::exists(part)) {
      ++summary.skipped;
      line["status"] = "skipped";
      line["error"] = "";
    } else {
      try {
        SynthOptions frame_options = request.options;
        frame_options.harmonizer_model = in.harmonizer;
        const FrameOutcome outcome = SynthesizeFrame(in.log, fi, in.assets, in.scenario, frame_options, in.PlanFor(fi));
        StagingDirectory staging(part, false);
        WritePart(staging.path(), outcome, in, request.options);
        staging.Commit();
        ++summary.done;
        line["status"] = "done";
        line["error"] = "";
      } catch (const std::exception& e) {
        summary.failed.push_back(fi);
        run.failures.push_back({fi, std::current_exception()});
        line["status"] = "failed";
        line["error"] = e.what();
        if (log_failures) SD_LOG(Error, "frame " << fi << " (" << token << "): " << e.what());
      }
    }
    line["seconds"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    run_log << line.dump() << '\n' << std::flush;
    progress.Advance();
  }
  progress.Finish();
  return run;
}

json PlanFileJson(const SynthInputs& in, const SynthRequest& request) {
  json j = {{"tool", "synthdrive synth"}, {"log", fs::absolute(request.log).string()}, {"scenario", ReadJsonFile(request.scenario)}};
  j.update(SynthPlanToJson(in.plan));
  return j;
}

// The derivative dataset, synth.json and report.html from the frames' outcomes, published by one rename.
SynthSummary WriteSynthOutput(const SynthInputs& in, const SynthRequest& request, const std::vector<FrameOutcome>& outcomes) {
  const Log& log = in.log;
  StagingDirectory staging(request.out, request.options.overwrite);
  std::vector<FrameEdit> edits;
  for (const auto& o : outcomes) {
    edits.push_back(o.edit);
    edits.back().point_objects = o.lidar_object_points;
  }
  WriteDerivative(log, edits, staging.path(), request.options.write);
  if (request.options.coco) WriteCoco2D(log, edits, staging.path() / "coco_2d.json");

  // Provenance and placements, machine-readable. No wall-clock fields: a merge writes the same bytes as a
  // local run.
  nlohmann::json j;
  j["tool"] = "synthdrive synth";
  j["log"] = fs::absolute(request.log).string();
  j["format"] = ToString(log.format);
  j["scenario"] = ReadJsonFile(request.scenario);
  j["frames"] = nlohmann::json::array();
  SynthSummary summary;
  for (const auto& o : outcomes) {
    nlohmann::json jf;
    jf["token"] = log.frames[o.frame_index].token;
    jf["sun"] = o.sun_source;
    jf["light"] = o.light;
    jf["camera_light"] = nlohmann::json::object();
    for (const auto& co : o.cameras) jf["camera_light"][co.channel] = co.light;
    jf["lidar_model"] = o.lidar_model;  // LidarModel::Summary() of the frame's sweep, or "off"
    jf["lidar_ego_motion"] = o.lidar_ego_motion;
    jf["objects"] = nlohmann::json::array();
    for (const auto& ob : o.objects) {
      const Box3& b = ob.placement.box;
      jf["objects"].push_back({{"asset", ob.label.asset_id},
                               {"category", ob.label.category},
                               {"center_ego_m", {b.center().x(), b.center().y(), b.center().z()}},
                               {"size_m", {b.size.x(), b.size.y(), b.size.z()}},
                               {"yaw_ego_rad", b.Yaw()},
                               {"ground_height_m", ob.placement.ground_height},
                               {"lidar_points", ob.lidar_points},
                               {"visible_fraction", ob.rendered_pixels > 0 ? ob.visible_pixels / ob.rendered_pixels : 0.0}});
      if (ob.plan_object >= 0) {
        // World-fixed: the same plan object (plan.json "objects") in every frame that observes it.
        const SequencePlan* plan = in.PlanFor(o.frame_index);
        const Eigen::Vector3d c = plan->objects.at(static_cast<size_t>(ob.plan_object)).box.center();
        jf["objects"].back()["plan_object"] = ob.plan_object;
        jf["objects"].back()["center_world_m"] = {c.x(), c.y(), c.z()};
      }
      ++summary.objects;
    }
    j["frames"].push_back(jf);
  }
  if (in.world_fixed) {
    j["plan"] = "plan.json";
    WriteJsonFile(staging.path() / "plan.json", PlanFileJson(in, request));
    if (request.options.report) WritePlanReport(log, in.plan, staging.path() / "plan.html");
  }
  WriteJsonFile(staging.path() / "synth.json", j);
  if (request.options.report) WriteSynthReport(log, outcomes, in.assets, staging.path() / "report.html");
  staging.Commit();
  summary.out = staging.final_path();
  summary.report = summary.out / "report.html";
  summary.frames = outcomes.size();
  return summary;
}

SynthSummary Merge(const SynthInputs& in, const SynthRequest& request) {
  const fs::path parts = SynthPartsDir(request.out);
  std::vector<size_t> missing;
  for (size_t fi : in.selected)
    if (!fs::is_directory(parts / PartName(in.log, fi))) missing.push_back(fi);
  if (!missing.empty()) {
    Msg m;
    m << "no part for " << missing.size() << " of the " << in.selected.size() << " selected frame(s): ";
    for (size_t i = 0; i < missing.size() && i < 20; ++i) m << (i ? ", " : "") << missing[i];
    if (missing.size() > 20) m << " and " << missing.size() - 20 << " more";
    m << " (run the shards that own them, --shard K/N, first)";
    throw InputError(parts, m.str());
  }
  std::vector<FrameOutcome> outcomes;
  Progress progress("reading parts", in.selected.size());
  for (size_t fi : in.selected) {
    outcomes.push_back(ReadPart(parts / PartName(in.log, fi), fi, in, request.options.report));
    progress.Advance();
  }
  progress.Finish();
  return WriteSynthOutput(in, request, outcomes);
}

}  // namespace

fs::path SynthPartsDir(const fs::path& out) {
  const fs::path p = NormalOut(out);
  return p.parent_path() / (p.filename().string() + ".parts");
}

SynthShardSummary RunSynthShard(const SynthRequest& request, const ShardSpec& shard) {
  const SynthInputs in = LoadInputs(request);
  CheckOutputFree(request, in);
  ShardRun run = SynthesizeParts(in, request, shard, true);
  return run.summary;
}

SynthSummary MergeSynthParts(const SynthRequest& request) {
  const SynthInputs in = LoadInputs(request);
  CheckOutputFree(request, in);
  return Merge(in, request);
}

SynthSummary RunSynth(const SynthRequest& request) {
  const SynthInputs in = LoadInputs(request);
  CheckOutputFree(request, in);
  const ShardRun run = SynthesizeParts(in, request, ShardSpec{}, false);
  std::error_code ec;
  if (!run.failures.empty()) {
    for (size_t i = 1; i < run.failures.size(); ++i) {
      try {
        std::rethrow_exception(run.failures[i].error);
      } catch (const std::exception& e) {
        SD_LOG(Error, "frame " << run.failures[i].frame << " (" << in.log.frames[run.failures[i].frame].token << "): " << e.what());
      }
    }
    // Keep finished parts for a rerun to resume from; a folder of logs only is no use to anyone.
    if (run.summary.done + run.summary.skipped == 0) fs::remove_all(run.summary.parts, ec);
    else SD_LOG(Info, "parts of the frames that worked are kept in " << run.summary.parts.string() << "; a rerun resumes from them");
    std::rethrow_exception(run.failures.front().error);
  }
  SynthSummary summary = Merge(in, request);
  fs::remove_all(run.summary.parts, ec);
  return summary;
}


// ---------------------------------------------------------------------------------------------------------
// Sequence planning for synth.

const SequencePlan* SynthPlan::ForFrame(size_t frame_index) const {
  for (const auto& s : sequences)
    for (const PlannedFrame& f : s.plan.frames)
      if (f.frame_index == frame_index) return &s.plan;
  return nullptr;
}

namespace {

// Frames a < b of one sequence: every step between them within the planner's time gap.
bool OneSequence(const Log& log, size_t a, size_t b, double max_gap_s) {
  if (!log.sequential) return false;  // object frames: no world pose, no time order
  for (size_t k = a; k < b; ++k) {
    const double gap = log.frames[k + 1].timestamp - log.frames[k].timestamp;
    if (!(gap >= 0 && gap <= max_gap_s)) return false;
  }
  return true;
}

double Median(std::vector<double> v) {
  SD_CHECK(!v.empty(), << "median of nothing");
  std::nth_element(v.begin(), v.begin() + static_cast<long>(v.size() / 2), v.end());
  return v[v.size() / 2];
}

// Where no sweep measured the road: horizontal at the height of the nearest ego origin plus `ground_offset`
// (the road's height in the ego frame: 0 in nuScenes and Argoverse 2, whose ego origin is on the ground; about
// -1.73 m for KITTI's Velodyne frame), drivable everywhere (nothing is known there; the plan's lane geometry
// and the annotated boxes still apply).
class EgoPoseSurface final : public SurfaceModel {
 public:
  EgoPoseSurface(std::vector<Rigid3d> poses, double ground_offset) : poses_(std::move(poses)), offset_(ground_offset) {
    SD_CHECK(!poses_.empty(), << "no poses");
  }
  std::optional<SurfacePoint> At(const Eigen::Vector2d& xy) const override {
    double best = std::numeric_limits<double>::infinity(), z = 0;
    for (const Rigid3d& T : poses_) {
      const double d = (T.translation.head<2>() - xy).squaredNorm();
      if (d < best) {
        best = d;
        z = T.translation.z();
      }
    }
    return SurfacePoint{z + offset_, Eigen::Vector3d::UnitZ(), false};
  }
  bool IsDrivable(const Eigen::Vector2d&) const override { return true; }

 private:
  std::vector<Rigid3d> poses_;
  double offset_;
};

// How far from a sweep's sensor its road surface decides. RoadSurface keeps points to 50 m, but beyond about
// 30 m the ground rings are too sparse for an unmeasured cell to mean "no road" (one Argoverse 2 log with 2 of
// its 156 sweeps refused every lane closure ahead at 50 m, "off the surface"; at 30 m it plans).
constexpr double kSweepCoverage = 30.0;

// The LiDAR road surface within `coverage` of some sweep's sensor (there it alone decides: a hole is a
// building or an occlusion shadow, not missing data), the ego poses' height beyond it.
class CoveredRoadSurface final : public SurfaceModel {
 public:
  CoveredRoadSurface(RoadSurface road, const std::vector<SweepInWorld>& sweeps, std::vector<Rigid3d> poses, double coverage)
      : road_(std::move(road)), poses_(poses, GroundUnderEgo(road_, poses)), coverage2_(coverage * coverage) {
    for (const auto& s : sweeps) sensors_.push_back(s.sensor_origin.head<2>());
  }
  // The measured road's height under the ego origins, relative to them (median).
  static double GroundUnderEgo(const RoadSurface& road, const std::vector<Rigid3d>& poses) {
    std::vector<double> dz;
    for (const Rigid3d& T : poses)
      if (const auto p = road.At(T.translation.head<2>())) dz.push_back(p->height - T.translation.z());
    return dz.empty() ? 0.0 : Median(dz);
  }
  const RoadSurface& road() const { return road_; }
  std::optional<SurfacePoint> At(const Eigen::Vector2d& xy) const override { return Covered(xy) ? road_.At(xy) : poses_.At(xy); }
  bool IsDrivable(const Eigen::Vector2d& xy) const override { return Covered(xy) ? road_.IsDrivable(xy) : true; }

 private:
  bool Covered(const Eigen::Vector2d& xy) const {
    for (const auto& s : sensors_)
      if ((s - xy).squaredNorm() <= coverage2_) return true;
    return false;
  }
  RoadSurface road_;
  EgoPoseSurface poses_;
  double coverage2_;
  std::vector<Eigen::Vector2d> sensors_;
};

}  // namespace

SynthPlan PlanSynthesis(const Log& log, const std::vector<size_t>& selected, const Scenario& scenario,
                        const std::vector<Asset>& assets, const fs::path& scenario_file, bool need_assets) {
  SequencePlanOptions options;
  for (const Asset& a : assets) {
    const auto cat = FindCategory(a.info.category);
    options.assets.push_back(PlanAsset{a.info.id, cat ? cat->name : a.info.category, a.info.extent});
  }
  std::vector<size_t> sorted = selected;
  std::sort(sorted.begin(), sorted.end());
  std::vector<std::pair<size_t, size_t>> ranges;  // [first, last] selected frames of each sequence
  for (size_t fi : sorted) {
    if (!ranges.empty() && OneSequence(log, ranges.back().second, fi, options.max_frame_gap_s)) ranges.back().second = fi;
    else ranges.push_back({fi, fi});
  }
  SynthPlan out;
  for (const auto& [first, last] : ranges) {
    SynthPlanSequence seq;
    std::vector<Rigid3d> poses;
    for (size_t k = first; k <= last; ++k) poses.push_back(log.frames[k].T_world_ego);
    // The sweeps on disk, read by runs of consecutive frames that have one (info files may list sweeps that
    // were never downloaded; Argoverse 2 test logs hold a few of their sweeps).
    std::vector<SweepInWorld> sweeps;
    for (size_t k = first; k <= last;) {
      auto on_disk = [&](size_t i) {
        std::error_code ec;
        return log.frames[i].lidar && fs::is_regular_file(log.frames[i].lidar->path, ec);
      };
      if (!on_disk(k)) { ++k; continue; }
      size_t e = k;
      while (e <= last && on_disk(e)) ++e;
      for (SweepInWorld& sw : SweepsFromLog(log, k, e)) sweeps.push_back(std::move(sw));
      k = e;
    }
    std::unique_ptr<SurfaceModel> surface;
    if (!sweeps.empty()) {
      auto road = std::make_unique<CoveredRoadSurface>(RoadSurface::Build(sweeps), sweeps, poses, kSweepCoverage);
      const RoadSurface::Stats& st = road->road().stats();
      seq.surface = "road_surface";
      seq.surface_detail = Msg() << sweeps.size() << " of " << last - first + 1 << " frames' LiDAR sweeps, " << st.observed_cells
                                 << " observed + " << st.filled_cells << " filled cells, " << st.drivable_cells
                                 << " drivable; beyond " << kSweepCoverage << " m of every sweep: the ego poses' height";
      surface = std::move(road);
    } else {
      seq.surface = "ego_poses";
      seq.surface_detail = "no LiDAR files on disk: the height of the nearest ego origin (on the ground in nuScenes and "
                           "Argoverse 2), drivable everywhere";
      // The road under the ego origin: on it by convention, except where the ego frame is a sensor's (KITTI's
      // Velodyne): there the boxes say.
      std::vector<double> bottoms;
      if (!log.ego_origin_on_ground)
        for (size_t k = first; k <= last; ++k)
          for (const auto& a : log.frames[k].annotations) bottoms.push_back(a.box.center().z() - 0.5 * a.box.size.z());
      surface = std::make_unique<EgoPoseSurface>(poses, bottoms.empty() ? 0.0 : Median(bottoms));
    }
    try {
      seq.plan = PlanSequence(log, scenario, *surface, FrameRange{first, last + 1}, options);
    } catch (const InputError& e) {
      if (!e.where().empty()) throw;
      throw InputError(scenario_file, e.what());
    }
    if (need_assets)
      for (const PlannedObject& o : seq.plan.objects)
        if (o.asset_id.empty())
          throw InputError(scenario_file, Msg() << o.source << " places a " << o.category << " (" << o.role
                                                << "), and no asset of that category was given: rendering needs one "
                                                   "(--asset or assets_from_bank; --dry-run plans without)");
    SD_LOG(Info, "plan of frames " << first << ".." << last << ": " << seq.plan.objects.size() << " world-fixed object(s), surface: "
                                   << seq.surface << " (" << seq.surface_detail << ")");
    out.sequences.push_back(std::move(seq));
  }
  return out;
}

json SynthPlanToJson(const SynthPlan& plan) {
  json seqs = json::array();
  for (const auto& s : plan.sequences) {
    json j = PlanToJson(s.plan);
    j["surface"] = s.surface;
    j["surface_detail"] = s.surface_detail;
    seqs.push_back(std::move(j));
  }
  return {{"sequences", std::move(seqs)}};
}

DryRunSummary RunSynthDryRun(const SynthRequest& request) {
  const SynthInputs in = LoadInputs(request, true);
  CheckOutputFree(request, in);
  DryRunSummary summary;
  StagingDirectory staging(request.out, request.options.overwrite);
  WriteJsonFile(staging.path() / "plan.json", PlanFileJson(in, request));
  WritePlanReport(in.log, in.plan, staging.path() / "plan.html");
  staging.Commit();
  summary.out = staging.final_path();
  for (const auto& s : in.plan.sequences) {
    const SequencePlan& p = s.plan;
    summary.objects += p.objects.size();
    summary.lines.push_back(Msg() << "frames " << p.frame_begin << ".." << p.frame_end - 1 << " (ego path " << p.ego_path_length_m
                                  << " m; " << p.annotated_boxes << " annotated boxes, " << p.tracks << " tracks, " << p.swept_boxes
                                  << " swept boxes; surface: " << s.surface << ", " << s.surface_detail << "): "
                                  << p.objects.size() << " object(s) placed");
    for (const PlanStats& st : p.stats) {
      std::string what;
      const size_t idx = static_cast<size_t>(std::stoul(st.source.substr(st.source.find('[') + 1)));
      if (st.source.rfind("arrangements", 0) == 0) what = ToString(in.scenario.arrangements.at(idx).kind);
      else what = ObjectSpec{in.scenario.objects.at(idx).asset_id, in.scenario.objects.at(idx).category}.Describe();
      int objects = 0, visible_frames = 0;  // frames that see at least one object of this source
      for (const PlannedObject& o : p.objects) objects += o.source == st.source ? 1 : 0;
      for (const PlannedFrame& f : p.frames) {
        bool seen = false;
        for (size_t i = 0; i < p.objects.size(); ++i) seen = seen || (p.objects[i].source == st.source && f.objects[i].visible);
        visible_frames += seen ? 1 : 0;
      }
      summary.lines.push_back(Msg() << "  " << st.source << " " << what << ": " << st.placed << " placed (" << objects << " object(s)), seen in " << visible_frames
                                    << " of " << p.frames.size() << " frames; " << st.Summary());
    }
  }
  summary.plan = in.plan;
  return summary;
}

}  // namespace sd
