#include "synth/batch.h"

#include <chrono>


#include "core/log.h"
#include "datasets/coco.h"
#include "datasets/writers.h"
#include "io/batch.h"
#include "io/files.h"
#include "io/geometry_json.h"
#include "io/json.h"
#include "synth/parts.h"
#include "synth/report.h"

namespace sd {
namespace fs = std::filesystem;
using nlohmann::json;
namespace {

// The frames of `shard` into parts, through the batch runner (io/batch.h): a frame whose part exists is skipped,
// what a killed run left of a part is removed, one run-log line per frame, and a frame that fails does not stop
// the others. Shared by `--shard` and the local run.
struct ShardRun {
  SynthShardSummary summary;
  std::vector<BatchFailure> failures;  // items are positions in in.selected
};
ShardRun SynthesizeParts(const SynthInputs& in, const SynthRequest& request, const ShardSpec& shard, bool log_failures) {
  ShardRun run;
  SynthShardSummary& summary = run.summary;
  summary.parts = SynthPartsDir(request.out);
  std::error_code ec;
  fs::create_directories(summary.parts, ec);
  if (ec) throw InputError(summary.parts, "cannot create directory: " + ec.message());
  auto part_of = [&](size_t i) { return summary.parts / PartName(in.log, in.selected[i]); };
  // Parts already there must be of this request (a resumed shard must not mix requests).
  for (size_t i = 0; i < in.selected.size(); ++i)
    if (shard.Owns(i) && fs::exists(part_of(i))) CheckPartRequest(part_of(i) / "part.json", ReadJsonFile(part_of(i) / "part.json"), in);

  BatchJob job;
  job.size = in.selected.size();
  job.describe = [&](size_t i) { return json{{"frame", in.selected[i]}, {"token", in.log.frames[in.selected[i]].token}}; };
  job.name = [&](size_t i) -> std::string { return Msg() << "frame " << in.selected[i] << " (" << in.log.frames[in.selected[i]].token << ")"; };
  job.output = part_of;
  job.complete = [&](size_t i) { return fs::exists(part_of(i)); };
  job.run = [&](size_t i, json*) {
    const size_t fi = in.selected[i];
    SynthOptions frame_options = request.options;
    frame_options.harmonizer_model = in.harmonizer;
    const FrameOutcome outcome = SynthesizeFrame(in.log, fi, in.assets, in.scenario, frame_options, in.PlanFor(fi));
    const auto t0 = std::chrono::steady_clock::now();
    StagingDirectory staging(part_of(i), false);
    WritePart(staging.path(), outcome, in, request.options);
    staging.Commit();
    SD_LOG(Debug, "frame " << fi << ": " << outcome.timings.Summary() << ", write "
                           << Fixed(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count(), 2) << " s");
  };
  BatchOptions batch;
  batch.label = "synthesising frames";
  batch.shard = shard;
  batch.run_log = summary.parts / ("log-" + std::to_string(shard.index) + "-of-" + std::to_string(shard.count) + ".jsonl");
  batch.log_failures = log_failures;
  BatchSummary done = RunBatch(job, batch);
  summary.run_log = done.run_log;
  summary.owned = done.owned;
  summary.done = done.done;
  summary.skipped = done.skipped;
  for (const BatchFailure& f : done.failures) summary.failed.push_back(in.selected[f.item]);
  run.failures = std::move(done.failures);
  return run;
}

// True when `parts` holds no finished part: only run logs, or what a killed writer left half-written.
bool HoldsNoPart(const fs::path& parts) {
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(parts, ec))
    if (e.is_directory(ec) && e.path().filename().string().find(".tmp-") == std::string::npos) return false;
  return true;
}

// What --detect-objects put into the log: keep-out tracks the plan and placement avoided (never labels).
json DetectedJson(const SynthInputs& in, const SynthRequest& request) {
  const DetectTracksReport& d = in.detected;
  return {{"mode", ToString(request.detect_objects)}, {"frames", d.frames}, {"frames_without_sweep", d.frames_without_sweep},
          {"sequences", d.sequences}, {"tracks", d.tracks}, {"boxes", d.boxes},
          {"tracks_by_class", {{"vehicle", d.by_class[0]}, {"pedestrian", d.by_class[1]}, {"small_object", d.by_class[2]}, {"other", d.by_class[3]}}}};
}

json PlanFileJson(const SynthInputs& in, const SynthRequest& request) {
  json j = {{"tool", "synthdrive synth"}, {"log", fs::absolute(request.log).string()}, {"scenario", ReadJsonFile(request.scenario)}};
  j.update(SynthPlanToJson(in.plan));
  j["detected"] = DetectedJson(in, request);
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
  j["detected"] = DetectedJson(in, request);
  j["frames"] = nlohmann::json::array();
  SynthSummary summary;
  for (const auto& o : outcomes) {
    nlohmann::json jf;
    jf["token"] = log.frames[o.frame_index].token;
    jf["sun"] = o.sun_source;
    jf["sun_direction_ego"] = {o.sun_direction_ego.x(), o.sun_direction_ego.y(), o.sun_direction_ego.z()};
    jf["light"] = o.light;
    jf["camera_light"] = nlohmann::json::object();
    for (const auto& co : o.cameras) jf["camera_light"][co.channel] = co.light;
    jf["camera_look"] = nlohmann::json::object();  // per camera: the look estimated from its image and applied
    for (const auto& co : o.cameras)
      if (!co.look.is_null()) jf["camera_look"][co.channel] = co.look;
    jf["road"] = o.road;  // the frame's LiDAR sweep, its cameras' stereo, or an assumed plane
    jf["lidar_model"] = o.lidar_model;  // LidarModel::Summary() of the frame's sweep, "off", or kNoLidar
    jf["lidar_ego_motion"] = o.lidar_ego_motion;
    jf["objects"] = nlohmann::json::array();
    for (const auto& ob : o.objects) {
      const Box3& b = ob.placement.box;
      jf["objects"].push_back({{"asset", ob.label.asset_id},
                               {"category", ob.label.category},
                               {"center_ego_m", {b.center().x(), b.center().y(), b.center().z()}},
                               {"size_m", {b.size.x(), b.size.y(), b.size.z()}},
                               {"yaw_ego_rad", b.Yaw()},  // the heading; the box tilts with the road
                               {"box_ego", Box3Json(b)},  // the whole box, rotation included
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

SynthShardSummary RunSynthShard(const SynthRequest& request, const ShardSpec& shard) {
  const SynthInputs in = LoadSynthInputs(request);
  CheckOutputFree(request, in);
  ShardRun run = SynthesizeParts(in, request, shard, true);
  return run.summary;
}

SynthSummary MergeSynthParts(const SynthRequest& request) {
  const SynthInputs in = LoadSynthInputs(request);
  CheckOutputFree(request, in);
  return Merge(in, request);
}

SynthSummary RunSynth(const SynthRequest& request) {
  const SynthInputs in = LoadSynthInputs(request);
  CheckOutputFree(request, in);
  // A local run owns "<out>.parts": one that holds no finished part (a run killed before its first frame, or
  // one that failed on the way in) is of no use to resume from and is not left behind.
  const fs::path parts = SynthPartsDir(request.out);
  std::error_code ec;
  if (fs::exists(parts, ec) && HoldsNoPart(parts)) fs::remove_all(parts, ec);
  ShardRun run;
  try {
    run = SynthesizeParts(in, request, ShardSpec{}, false);
  } catch (...) {
    if (HoldsNoPart(parts)) fs::remove_all(parts, ec);
    throw;
  }
  if (!run.failures.empty()) {
    for (size_t i = 1; i < run.failures.size(); ++i) {
      try {
        std::rethrow_exception(run.failures[i].exception);
      } catch (const std::exception& e) {
        const size_t fi = in.selected[run.failures[i].item];
        SD_LOG(Error, "frame " << fi << " (" << in.log.frames[fi].token << "): " << e.what());
      }
    }
    // Keep finished parts for a rerun to resume from; a folder of logs only is no use to anyone.
    if (run.summary.done + run.summary.skipped == 0) fs::remove_all(run.summary.parts, ec);
    else SD_LOG(Info, "parts of the frames that worked are kept in " << run.summary.parts.string() << "; a rerun resumes from them");
    std::rethrow_exception(run.failures.front().exception);
  }
  SynthSummary summary = Merge(in, request);
  fs::remove_all(run.summary.parts, ec);
  return summary;
}



DryRunSummary RunSynthDryRun(const SynthRequest& request) {
  const SynthInputs in = LoadSynthInputs(request, true);
  CheckOutputFree(request, in);
  DryRunSummary summary;
  StagingDirectory staging(request.out, request.options.overwrite);
  WriteJsonFile(staging.path() / "plan.json", PlanFileJson(in, request));
  WritePlanReport(in.log, in.plan, staging.path() / "plan.html");
  staging.Commit();
  summary.out = staging.final_path();
  if (in.detected.frames > 0 || in.detected.frames_without_sweep > 0) summary.lines.push_back(in.detected.Summary());
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
