#include "synth/pipeline.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <memory>
#include <set>

#include "core/log.h"
#include "core/parallel.h"
#include "datasets/categories.h"
#include "io/files.h"
#include "io/image_io.h"
#include "io/json.h"
#include "render/camera_render.h"
#include "render/ray_scene.h"
#include "synth/lidar_sim.h"
#include "synth/lighting.h"
#include "synth/occlusion.h"
#include "synth/report.h"

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

std::vector<Eigen::Vector3d> RoadPointsNear(const GroundModel& ground, const std::vector<PlacedObject>& objects) {
  std::vector<Eigen::Vector3d> out;
  for (const auto& p : ground.ground_points()) {
    for (const auto& o : objects) {
      const double d = (p.head<2>() - o.box.center().head<2>()).norm();
      if (d < 0.5 * o.box.size.head<2>().norm() + 6.0 && ground.IsDrivable(p.x(), p.y())) {
        out.push_back(p);
        break;
      }
    }
  }
  return out;
}

int NuScenesVisibility(double fraction) {
  if (fraction < 0.4) return 1;
  if (fraction < 0.6) return 2;
  if (fraction < 0.8) return 3;
  return 4;
}

}  // namespace

FrameOutcome SynthesizeFrame(const Log& log, size_t frame_index, const std::vector<Asset>& assets,
                             const Scenario& scenario, const SynthOptions& options) {
  const Frame& frame = log.frames.at(frame_index);
  if (!frame.lidar) throw InputError(log.source, "frame " + frame.token + " has no LiDAR sweep; synth needs one");
  FrameOutcome out;
  out.frame_index = frame_index;
  out.edit.frame_index = frame_index;

  // LiDAR in the ego frame, ground, placement.
  out.sweep_before = ReadLidar(*frame.lidar);
  const PointCloud& sweep = out.sweep_before;
  std::vector<Eigen::Vector3d> points_ego(sweep.size());
  for (size_t i = 0; i < sweep.size(); ++i) points_ego[i] = frame.lidar->T_ego_lidar * sweep.xyz(i).cast<double>();
  std::vector<Box3> real_boxes;
  std::vector<std::pair<std::string, Box3>> annotated;
  for (const auto& a : frame.annotations) {
    real_boxes.push_back(a.box);
    annotated.push_back({a.category, a.box});
  }
  GroundOptions gopt;
  gopt.seed = scenario.seed;
  gopt.sensor_xy = frame.lidar->T_ego_lidar.translation.head<2>();
  out.ground = GroundModel::Estimate(points_ego, real_boxes, gopt);
  const GroundModel& ground = out.ground;

  PlacementInput pin;
  pin.ground = &ground;
  pin.points_ego = points_ego;
  pin.real_boxes = real_boxes;
  for (const auto& c : frame.cameras) pin.cameras.push_back(&c);
  Scenario frame_scenario = scenario;
  frame_scenario.seed = scenario.seed + static_cast<uint32_t>(frame_index) * 7919u;  // distinct, reproducible per frame
  std::vector<PlacedObject> placed = PlaceObjects(frame_scenario, assets, pin);

  // Scene in the ego frame: objects, then one receiver mesh for shadows.
  std::string sun_source;
  const Eigen::Vector3d sun_dir = SunDirectionEgo(frame, scenario.location ? scenario.location : log.location, scenario.sun, &sun_source);
  out.sun_source = sun_source;
  RayScene scene;
  auto receiver = std::make_shared<TriangleMesh>();
  for (const auto& o : placed) {
    auto mesh = std::make_shared<TriangleMesh>(o.asset->mesh);
    mesh->Transform(o.T_ego_asset);
    if (mesh->normals.empty()) mesh->ComputeVertexNormals();
    scene.AddMesh(mesh);
    AddReceiverPatch(o, sun_dir, receiver.get());
  }
  const int receiver_id = scene.AddMesh(receiver);
  scene.Commit();

  out.objects.resize(placed.size());
  for (size_t k = 0; k < placed.size(); ++k) {
    auto& oc = out.objects[k];
    oc.placement = placed[k];
    const auto cat = FindCategory(placed[k].asset->info.category);
    if (!cat) throw InputError(placed[k].asset->dir, "unknown category '" + placed[k].asset->info.category + "'");
    oc.label.category = cat->name;
    oc.label.asset_id = placed[k].asset->info.id;
    oc.label.annotation.category = DatasetCategoryName(*cat, log.format);
    oc.label.annotation.box = placed[k].box;
    oc.label.annotation.velocity = Eigen::Vector2d::Zero();
  }

  // Cameras.
  std::vector<uint8_t> is_ground(points_ego.size(), 0);
  for (int i : ground.ground_indices()) is_ground[i] = 1;
  const std::vector<Eigen::Vector3d> road_points = RoadPointsNear(ground, placed);
  // Everything a camera may need to redraw: the objects' boxes and their shadow receivers.
  std::vector<Eigen::Vector3d> extent_points;
  for (const auto& o : placed)
    for (const auto& c : o.box.Corners()) extent_points.push_back(c);
  for (const auto& p : receiver->positions) extent_points.push_back(p.cast<double>());
  for (const auto& cam : frame.cameras) {
    const Rigid3d T_cam_ego = cam.T_ego_cam.Inverse();
    const auto rect = ProjectedRect(cam.intrinsics, T_cam_ego, extent_points, 2);
    if (!rect) continue;

    const ImageU8 original = ReadImage(cam.image_path, 3);
    if (original.width() != cam.intrinsics.width || original.height() != cam.intrinsics.height)
      throw InputError(cam.image_path, Msg() << "image is " << original.width() << "x" << original.height()
                                             << " but the calibration says " << cam.intrinsics.width << "x" << cam.intrinsics.height);
    ImageF linear = ToLinear(original);
    const Lighting lighting = CalibrateLighting(linear, cam, road_points, sun_dir);
    CameraRenderOptions ropt;
    ropt.samples_per_pixel = options.samples_per_pixel;
    ropt.ao_samples = options.ao_samples;
    ropt.receiver_mesh = receiver_id;
    ropt.x0 = (*rect)[0];
    ropt.y0 = (*rect)[1];
    ropt.x1 = (*rect)[2];
    ropt.y1 = (*rect)[3];
    ropt.seed = scenario.seed + static_cast<uint32_t>(frame_index);
    const CameraRender render = RenderCamera(scene, cam.intrinsics, cam.T_ego_cam, lighting, ropt);

    const auto projected = ProjectPoints(points_ego, is_ground, cam.intrinsics, T_cam_ego);
    const ImageF visibility = ComputeVisibility(projected, render.depth);
    // Receiver visibility for shadows: the ground under the shadow must not be hidden by a real object.
    ImageF receiver_depth(render.depth.width(), render.depth.height(), 1, std::numeric_limits<float>::infinity());
    const GroundPlane& plane = ground.seed_plane();
    for (int y = ropt.y0; y < ropt.y1; ++y)
      for (int x = ropt.x0; x < ropt.x1; ++x) {
        if (render.shadow.at(x, y) >= 0.999f) continue;
        const Eigen::Vector3d d_cam = cam.intrinsics.RayDirection(Eigen::Vector2d(x + 0.5, y + 0.5));
        const Eigen::Vector3d o = cam.T_ego_cam.translation, d = cam.T_ego_cam.rotation * d_cam;
        const double denom = plane.normal.dot(d);
        if (std::abs(denom) < 1e-6) continue;
        const double t = -(plane.normal.dot(o) + plane.d) / denom;
        if (t > 0) receiver_depth.at(x, y) = static_cast<float>(t * d_cam.z());
      }
    const ImageF receiver_visibility = ComputeVisibility(projected, receiver_depth);

    bool changed = false;
    std::vector<double> rendered(placed.size(), 0), visible(placed.size(), 0);
    std::vector<Box2> boxes(placed.size(), Box2{1e9, 1e9, -1e9, -1e9});
    for (int y = ropt.y0; y < ropt.y1; ++y)
      for (int x = ropt.x0; x < ropt.x1; ++x) {
        const float a = render.coverage.at(x, y);
        const float vis = visibility.at(x, y);
        const float shadow = receiver_visibility.at(x, y) > 0.5f ? render.shadow.at(x, y) : 1.0f;
        if (a <= 0 && shadow >= 1.0f) continue;
        const float av = a * vis;
        float* px = linear.pixel(x, y);
        for (int c = 0; c < 3; ++c) px[c] = render.color.at(x, y, c) * vis + px[c] * (1 - av) * shadow;
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
    CameraOutcome co;
    co.channel = cam.channel;
    co.before = original;
    co.after = ToSrgb8(linear);
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
  lin.objects = ptrs;
  lin.reference_intensity = ReferenceIntensities(sweep, points_ego, ground.ground_indices(), annotated, ptrs);
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
  return out;
}

SynthSummary RunSynth(const SynthRequest& request) {
  // Validate and load every input before creating any output.
  const Log log = OpenLog(request.log, request.log_options);
  SD_LOG(Info, "log: " << request.log.string() << " (" << ToString(log.format) << ", " << log.frames.size() << " frames)");
  if (request.assets.empty()) throw InputError("", "no --asset given");
  std::vector<Asset> assets;
  std::set<std::string> ids;
  for (const auto& path : request.assets) {
    assets.push_back(LoadAsset(path));
    const auto& info = assets.back().info;
    if (!FindCategory(info.category))
      throw InputError(path, "unknown category '" + info.category + "' (see `synthdrive categories`)");
    if (!ids.insert(info.id).second) throw InputError(path, "duplicate asset id '" + info.id + "'");
  }
  const Scenario scenario = ReadScenario(request.scenario);
  std::vector<size_t> selected;
  if (request.options.frames.empty()) {
    for (size_t i = 0; i < log.frames.size(); ++i) selected.push_back(i);
  } else {
    for (const auto& f : request.options.frames) {
      size_t found = log.frames.size();
      for (size_t i = 0; i < log.frames.size(); ++i)
        if (log.frames[i].token == f) found = i;
      if (found == log.frames.size() && !f.empty() && std::all_of(f.begin(), f.end(), ::isdigit)) found = std::stoul(f);
      if (found >= log.frames.size()) throw InputError(request.log, "no frame '" + f + "'");
      selected.push_back(found);
    }
  }
  if (selected.empty()) throw InputError(request.log, "log has no frames");

  StagingDirectory staging(request.out, request.options.overwrite);
  std::vector<FrameOutcome> outcomes;
  std::vector<FrameEdit> edits;
  Progress progress("synthesising frames", selected.size());
  for (size_t fi : selected) {
    outcomes.push_back(SynthesizeFrame(log, fi, assets, scenario, request.options));
    edits.push_back(outcomes.back().edit);
    progress.Advance();
  }
  progress.Finish();
  WriteDerivative(log, edits, staging.path(), request.options.write);

  // Provenance and placements, machine-readable.
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
      ++summary.objects;
    }
    j["frames"].push_back(jf);
  }
  WriteJsonFile(staging.path() / "synth.json", j);
  if (request.options.report) WriteSynthReport(log, outcomes, staging.path() / "report.html");
  staging.Commit();
  summary.out = staging.final_path();
  summary.report = summary.out / "report.html";
  summary.frames = outcomes.size();
  return summary;
}

}  // namespace sd
