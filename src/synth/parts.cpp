#include "synth/parts.h"

#include <cmath>
#include <cstdio>
#include <map>
#include <string_view>

#include "core/log.h"
#include "datasets/annotation_json.h"
#include "datasets/format.h"
#include "datasets/readers.h"
#include "io/files.h"
#include "io/geometry_json.h"
#include "io/image_io.h"
#include "io/json.h"
#include "io/pointcloud_io.h"
#include "models/harmonization.h"

namespace sd {
namespace fs = std::filesystem;
using nlohmann::json;

namespace {

// 3: poses, boxes and annotations in the shared codecs (io/geometry_json.h, datasets/annotation_json.h). A part
// of another version is refused, never read in the wrong layout.
constexpr int kPartVersion = 3;

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
  o.annotation = ReadAnnotation(r["annotation"]);
  for (size_t i = 0; i < r["camera_boxes"].Size(); ++i) {
    const JsonReader b = r["camera_boxes"][i];
    o.camera_boxes.push_back(CameraBox{b["channel"].String(), ReadBox2(b["box"]), b["visible_fraction"].Number(), b["truncation"].Number()});
  }
  o.asset_id = r["asset_id"].String();
  return o;
}

std::string Short(const json& v) {
  std::string s = v.dump();
  return s.size() > 80 ? s.substr(0, 77) + "..." : s;
}

}  // namespace

json RequestFingerprint(const SynthRequest& request, const SynthInputs& in) {
  const std::vector<Asset>& assets = in.assets;
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
  j["sky_filter_radius"] = request.options.sky_filter_radius;
  j["lidar_realism"] = request.options.lidar_realism;
  j["light"] = request.options.light == SynthOptions::Light::kEnvironment ? "environment" : "road";
  j["dense_occlusion"] = request.options.dense_occlusion;
  j["harmonizer"] = request.options.harmonizer;
  const CameraLookOptions& look = request.options.camera_look;
  j["camera_look"] = {{"blur", look.blur}, {"noise", look.noise}, {"jpeg", look.jpeg}};
  // "auto" is learned on a machine with the model installed and classical on one without: parts made on both
  // are of different requests.
  if (in.harmonizer) j["harmonizer_path"] = in.harmonizer->learned() ? "learned" : "classical";
  // Every shard plans from the whole selection; a part made under another plan (other frames selected, other
  // sweeps) is of another request.
  if (in.world_fixed) j["plan_fnv1a64"] = Fnv1a64Hex(SynthPlanToJson(in.plan).dump());
  // Detected keep-out boxes move per-frame placements: a part made against other detections is of another request.
  j["detect_objects"] = ToString(request.detect_objects);
  if (in.detected.boxes > 0) {
    std::string boxes;
    for (const Frame& f : in.log.frames)
      for (const Annotation& a : f.annotations)
        if (a.detected)
          boxes += a.token + " " + a.instance_token + " " + Fixed(a.box.center().x(), 4) + " " + Fixed(a.box.center().y(), 4) + " " +
                   Fixed(a.box.Yaw(), 4) + " " + Fixed(a.box.size.x(), 4) + " " + Fixed(a.box.size.y(), 4) + "\n";
    j["detected_fnv1a64"] = Fnv1a64Hex(boxes);
  }
  return j;
}

std::string PartName(const Log& log, size_t frame_index) {
  std::string token = log.frames[frame_index].token;
  for (char& c : token)
    if (!std::isalnum(static_cast<unsigned char>(c)) && c != '-' && c != '_' && c != '.') c = '_';
  return std::to_string(frame_index) + "-" + token;
}

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
    cameras.push_back({{"channel", co.channel}, {"image", file}, {"objects", co.objects}, {"light", co.light}, {"look", co.look}});
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
                       {"T_ego_asset", Rigid3dJson(ob.placement.T_ego_asset)},
                       {"box", Box3Json(ob.placement.box)},
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
            {"sun_direction_ego", {o.sun_direction_ego.x(), o.sun_direction_ego.y(), o.sun_direction_ego.z()}},
            {"light", o.light},
            {"objects", objects},
            {"cameras", cameras},
            {"sweep", sweep},
            {"road", o.road},
            {"lidar_model", o.lidar_model},
            {"lidar_ego_motion", o.lidar_ego_motion},
            {"lidar_object_points", lidar_object_points}};
  WriteJsonFile(dir / "part.json", j, -1);
}

void CheckPartRequest(const fs::path& part_json, const json& part, const SynthInputs& in) {
  if (!part.is_object() || !part.contains("version") || !part["version"].is_number_integer())
    throw InputError(part_json, Msg() << "not a synth part (no version; this build's parts are version " << kPartVersion << ")");
  if (part["version"] != kPartVersion)
    throw InputError(part_json, Msg() << "a synth part of version " << part["version"].dump() << ", this build reads version "
                                      << kPartVersion << ": merge it with the build that made it, or remove the part to make it again");
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
  // Optional: parts written before it was recorded read as the overhead default.
  if (r.Has("sun_direction_ego")) {
    for (int k = 0; k < 3; ++k) o.sun_direction_ego[k] = r["sun_direction_ego"][k].Number();
    if (!(std::abs(o.sun_direction_ego.norm() - 1) < 1e-3)) r["sun_direction_ego"].Fail("is not a unit vector");
  }
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
    ob.placement.T_ego_asset = ReadRigid3d(ro["T_ego_asset"]);
    ob.placement.box = ReadBox3(ro["box"]);
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
    co.look = rc.Has("look") ? rc["look"].raw() : nlohmann::json();
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
  if (r.Has("road")) o.road = r["road"].String();  // parts written before it was recorded have none
  o.lidar_model = r["lidar_model"].String();
  o.lidar_ego_motion = r["lidar_ego_motion"].Bool();
  for (size_t i = 0; i < r["lidar_object_points"].Size(); ++i) {
    const JsonReader p = r["lidar_object_points"][i];
    o.lidar_object_points.push_back({static_cast<int>(p[0].Integer()), static_cast<int>(p[1].Integer())});
  }
  if (for_report && frame.lidar) {
    o.sweep_before = ReadLidar(*frame.lidar);
    o.ground = EstimateFrameGround(frame, o.sweep_before, PointsInEgo(frame, o.sweep_before), in.scenario);
  }
  return o;
}

}  // namespace sd
