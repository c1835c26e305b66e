// LiDAR detection and tracking for logs without labels (synth/detected_tracks.h, docs/detection.md), measured by
// hiding each log's own annotations:
//  - recall of annotated objects within 30 m of the LiDAR (horizontal) that hold at least 5 of the sweep's
//    returns, per class group (vehicles, pedestrians, cones and barriers, two-wheelers, other), class-agnostic:
//    a detection of any class may match. Two criteria:
//      centre: one-to-one greedy matching (shortest first) on the BEV centre distance, at most 2.0 m for
//              vehicles and 1.0 m for every other group (the detection metric);
//      covered: some detected box's footprint overlaps the annotated footprint (what keep-out needs);
//  - false positives: detections within 30 m that match no annotation (centre criterion), per frame; of them,
//    how many overlap no annotated box at all (unlabelled obstacles: poles, bins, walls, vegetation, or noise);
//  - track id switches: for each annotated track, changes of the matched detected track between the frames
//    where it is matched (sequences only); as in CLEAR MOT, a correspondence is kept while it stays within the
//    gate, so only a real change of track counts;
//  - class agreement of matched pairs (vehicle group vs "vehicle", pedestrian vs "pedestrian", cone/barrier vs
//    "small_object");
//  - end to end: a world-fixed scenario (cones, barriers and cars scattered over the road) planned with
//    PlanSynthesis (synth/synth_plan.h, as `synth --dry-run`) against the detected tracks only, then the planned
//    objects whose footprint overlaps a real annotated box at any frame, beside the same count when planned
//    against the annotations; over several scenario seeds.
// Logs: PandaSet 002 (12 frames), Argoverse 2 (the 2 sweeps on disk), KITTI object (5 frames), the repo's
// nuScenes keyframe. nuScenes mini-val infos have no sweeps: nothing to detect in. A plain program:
// build/bin/bench_lidar_detect [--no-e2e] [--seeds N] [--misses N] [tuning flags, see usage]; prints markdown tables.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <vector>

#include "bench_paths.h"
#include "core/box3.h"
#include "core/error.h"
#include "datasets/categories.h"
#include "datasets/readers.h"
#include "io/files.h"
#include "synth/detected_tracks.h"
#include "synth/scenario.h"
#include "synth/sequence_plan.h"
#include "synth/synth_plan.h"

namespace fs = std::filesystem;
using sd::Annotation;
using sd::Box3;
using sd::Frame;
using sd::Log;

namespace {

constexpr double kRange = 30.0;
// What synth uses (DetectTracksOptions' defaults) unless a flag changes it, for tuning.
sd::DetectTracksOptions g_options;
bool g_show_switches = false;  // --switches: each annotated track's matched detected tracks, where they change
constexpr int kMinPoints = 5;

enum Group { kVehicles, kPedestrians, kConesBarriers, kTwoWheelers, kOtherGroup, kGroups };
const char* kGroupNames[kGroups] = {"vehicles", "pedestrians", "cones/barriers", "two-wheelers", "other"};

Group GroupOf(const std::string& dataset_category) {
  const std::string c = sd::CanonicalCategory(dataset_category);
  if (c == "car" || c == "truck" || c == "bus" || c == "trailer" || c == "construction_vehicle") return kVehicles;
  if (c == "pedestrian") return kPedestrians;
  if (c == "traffic_cone" || c == "barrier") return kConesBarriers;
  if (c == "bicycle" || c == "motorcycle") return kTwoWheelers;
  std::string lower = dataset_category;
  for (char& ch : lower) ch = static_cast<char>(std::tolower(static_cast<unsigned char>(ch)));
  for (const char* w : {"cone", "bollard", "pylon", "barrier", "barrel"})
    if (lower.find(w) != std::string::npos) return kConesBarriers;
  return kOtherGroup;
}

struct GroupCounts {
  int eligible = 0, centre = 0, covered = 0, class_agree = 0;
};

struct Miss {
  std::string frame, category;
  double distance = 0;
  int points = 0;
  Eigen::Vector3d size;
  double nearest = 0;  // BEV distance to the nearest detection centre
  std::string covering;  // the detected boxes whose footprint overlaps it: class, size, centre offset
};

struct DatasetResult {
  std::string name;
  int frames = 0;
  GroupCounts groups[kGroups];
  int detections_in_range = 0, false_positives = 0, fp_overlapping_nothing = 0;
  int tracked_objects = 0, matched_pairs = 0, id_switches = 0;  // annotated tracks with >= 2 matched frames
  double seconds = 0;
  std::vector<Miss> misses;
  sd::DetectTracksReport report;
};

double Horizontal(const Eigen::Vector3d& p, const Eigen::Vector2d& sensor) { return (p.head<2>() - sensor).norm(); }

// Only the frames with a sweep on disk: what the detector can see, and what the comparison is over.
Log WithSweepsOnly(const Log& in) {
  Log out = in;
  out.frames.clear();
  for (const Frame& f : in.frames)
    if (f.lidar && fs::is_regular_file(f.lidar->path)) out.frames.push_back(f);
  return out;
}

DatasetResult Evaluate(const std::string& name, const Log& truth) {
  DatasetResult r;
  r.name = name;
  Log detected = truth;
  sd::HideAnnotations(&detected);
  const auto t0 = std::chrono::steady_clock::now();
  r.report = sd::AddDetectedTracks(&detected, g_options);
  r.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  std::map<std::string, std::vector<std::pair<size_t, std::string>>> matched_track;  // annotated track -> (frame, detected track)
  std::map<std::string, std::string> last_match;  // annotated track -> the detected track it matched last
  for (size_t fi = 0; fi < truth.frames.size(); ++fi) {
    const Frame& tf = truth.frames[fi];
    const Frame& df = detected.frames[fi];
    ++r.frames;
    const sd::PointCloud sweep = sd::ReadLidar(*tf.lidar);
    std::vector<Eigen::Vector3d> pts(sweep.size());
    for (size_t i = 0; i < sweep.size(); ++i) pts[i] = tf.lidar->T_ego_lidar * sweep.xyz(i).cast<double>();
    const Eigen::Vector2d sensor = tf.lidar->T_ego_lidar.translation.head<2>();
    // Annotated objects and the points inside each.
    struct Obj { const Annotation* a; Group g; int points; double dist; bool eligible; };
    std::vector<Obj> objs;
    for (const Annotation& a : tf.annotations) {
      int n = 0;
      for (const auto& p : pts) n += a.box.Contains(p) ? 1 : 0;
      const double d = Horizontal(a.box.center(), sensor);
      objs.push_back({&a, GroupOf(a.category), n, d, d <= kRange && n >= kMinPoints});
    }
    std::vector<const Annotation*> dets;
    for (const Annotation& a : df.annotations) dets.push_back(&a);
    // Centre matching, one to one, shortest first; every annotation takes part (so a detection of an
    // ineligible annotated object is no false positive), eligibility only decides what recall counts.
    std::vector<std::tuple<double, size_t, size_t>> pairs;
    for (size_t i = 0; i < objs.size(); ++i)
      for (size_t j = 0; j < dets.size(); ++j) {
        const double d = (objs[i].a->box.center().head<2>() - dets[j]->box.center().head<2>()).norm();
        const double gate = objs[i].g == kVehicles ? 2.0 : 1.0;
        if (d <= gate) pairs.emplace_back(d, i, j);
      }
    std::sort(pairs.begin(), pairs.end());
    std::vector<int> obj_match(objs.size(), -1), det_match(dets.size(), -1);
    // CLEAR MOT (Bernardin and Stiefelhagen 2008): a correspondence of the previous frame is kept while it is
    // still within the gate, before the rest is matched; so a nearer fragment is no id switch.
    for (const auto& [d, i, j] : pairs) {
      const auto it = last_match.find(objs[i].a->instance_token);
      if (objs[i].a->instance_token.empty() || it == last_match.end() || it->second != dets[j]->instance_token) continue;
      if (obj_match[i] >= 0 || det_match[j] >= 0) continue;
      obj_match[i] = static_cast<int>(j);
      det_match[j] = static_cast<int>(i);
    }
    for (const auto& [d, i, j] : pairs) {
      if (obj_match[i] >= 0 || det_match[j] >= 0) continue;
      obj_match[i] = static_cast<int>(j);
      det_match[j] = static_cast<int>(i);
    }
    for (size_t i = 0; i < objs.size(); ++i) {
      if (!objs[i].eligible) continue;
      GroupCounts& gc = r.groups[objs[i].g];
      ++gc.eligible;
      bool covered = false;
      double nearest = 1e9;
      for (const Annotation* d : dets) {
        covered = covered || sd::FootprintsOverlap(objs[i].a->box, d->box, 0.0);
        nearest = std::min(nearest, (d->box.center().head<2>() - objs[i].a->box.center().head<2>()).norm());
      }
      gc.covered += covered ? 1 : 0;
      std::string covering;
      for (const Annotation* d : dets)
        if (sd::FootprintsOverlap(objs[i].a->box, d->box, 0.0)) {
          char buf[160];
          const Eigen::Vector2d off = d->box.center().head<2>() - objs[i].a->box.center().head<2>();
          std::snprintf(buf, sizeof buf, " [%s %.1fx%.1fx%.1f at %+.1f,%+.1f]", d->category.c_str() + 9, d->box.size.x(), d->box.size.y(),
                        d->box.size.z(), off.x(), off.y());
          covering += buf;
        }
      if (obj_match[i] >= 0) {
        ++gc.centre;
        const std::string& c = dets[obj_match[i]]->category;
        const bool agree = (objs[i].g == kVehicles && c == "detected.vehicle") || (objs[i].g == kPedestrians && c == "detected.pedestrian") ||
                           (objs[i].g == kConesBarriers && c == "detected.small_object");
        gc.class_agree += agree ? 1 : 0;
        if (!objs[i].a->instance_token.empty())
          matched_track[objs[i].a->instance_token].push_back({fi, dets[obj_match[i]]->instance_token});
      } else {
        r.misses.push_back({tf.token, objs[i].a->category, objs[i].dist, objs[i].points, objs[i].a->box.size, nearest, covering});
      }
    }
    for (size_t i = 0; i < objs.size(); ++i)
      if (obj_match[i] >= 0 && !objs[i].a->instance_token.empty()) last_match[objs[i].a->instance_token] = dets[obj_match[i]]->instance_token;
    for (size_t j = 0; j < dets.size(); ++j) {
      if (Horizontal(dets[j]->box.center(), sensor) > kRange) continue;
      ++r.detections_in_range;
      if (det_match[j] >= 0) continue;
      ++r.false_positives;
      bool touches = false;
      for (const Obj& o : objs) touches = touches || sd::FootprintsOverlap(o.a->box, dets[j]->box, 0.0);
      r.fp_overlapping_nothing += touches ? 0 : 1;
    }
  }
  for (const auto& [token, seq] : matched_track) {
    if (seq.size() < 2) continue;
    ++r.tracked_objects;
    int switches = 0;
    for (size_t k = 1; k < seq.size(); ++k) {
      ++r.matched_pairs;
      switches += seq[k].second != seq[k - 1].second ? 1 : 0;
    }
    r.id_switches += switches;
    if (switches > 0 && g_show_switches) {
      std::printf("  id switches of %s:", token.c_str());
      for (const auto& [frame, track] : seq) std::printf(" %zu:%s", frame, track.c_str() + 9);
      std::printf("\n");
    }
  }
  return r;
}

// A world-fixed scenario scattering objects over the road around the ego path, so some candidates fall next to
// real (parked, moving) objects and only the obstacle set keeps them off.
constexpr const char* kScatterScenario = R"({
  "seed": 1,
  "margin_m": 0.25,
  "world_fixed": true,
  "objects": [
    {"category": "traffic_cone", "count": 4, "distance_m": [4, 30], "lateral_m": [-7, 7], "yaw": "random"},
    {"category": "barrier", "count": 2, "distance_m": [4, 30], "lateral_m": [-7, 7], "yaw": "aligned"},
    {"category": "car", "count": 1, "distance_m": [4, 30], "lateral_m": [-7, 7], "yaw": "aligned"}
  ]
})";

struct PlanCount {
  int runs = 0, failed = 0, objects = 0, overlapping = 0;
  std::string first_error;
};

// Planned objects (world) overlapping any annotated box of `truth` (world, every frame of the plan's range);
// each printed with the real object it overlaps when `why`.
int OverlapsWithTruth(const Log& truth, const sd::SynthPlan& plan, bool why) {
  int n = 0;
  for (const auto& seq : plan.sequences) {
    struct Real { Box3 world; const Annotation* a; size_t frame; };
    std::vector<Real> real;
    for (size_t k = seq.plan.frame_begin; k < seq.plan.frame_end; ++k)
      for (const Annotation& a : truth.frames[k].annotations) real.push_back({a.box.Transformed(truth.frames[k].T_world_ego), &a, k});
    for (const sd::PlannedObject& o : seq.plan.objects) {
      const Real* hit = nullptr;
      for (const Real& r : real)
        if (!hit && sd::FootprintsOverlap(o.box, r.world, 0.0)) hit = &r;
      n += hit ? 1 : 0;
      if (hit && why)
        std::printf("    %s %s at world (%.1f, %.1f) overlaps %s (%.1fx%.1fx%.1f, %d returns, frame %zu, %.1f m from the ego)\n",
                    o.source.c_str(), o.category.c_str(), o.box.center().x(), o.box.center().y(), hit->a->category.c_str(),
                    hit->a->box.size.x(), hit->a->box.size.y(), hit->a->box.size.z(), hit->a->num_lidar_pts, hit->frame,
                    hit->a->box.center().head<2>().norm());
    }
  }
  return n;
}

// One plan per seed over the whole log, or per frame where the frames are no sequence (KITTI object frames: an
// impossible frame would fail the others).
void PlanRuns(const Log& planned_on, const Log& truth, const fs::path& scenario_file, int seeds, bool why, PlanCount* out) {
  sd::Scenario scenario = sd::ReadScenario(scenario_file);
  std::vector<std::vector<size_t>> selections(1);
  for (size_t k = 0; k < planned_on.frames.size(); ++k) {
    if (!planned_on.sequential && !selections.back().empty()) selections.emplace_back();
    selections.back().push_back(k);
  }
  for (int s = 1; s <= seeds; ++s) {
    scenario.seed = static_cast<uint32_t>(s);
    for (const auto& selected : selections) {
      ++out->runs;
      try {
        const sd::SynthPlan plan = sd::PlanSynthesis(planned_on, selected, scenario, {}, scenario_file, false);
        for (const auto& seq : plan.sequences) out->objects += static_cast<int>(seq.plan.objects.size());
        out->overlapping += OverlapsWithTruth(truth, plan, why);
      } catch (const sd::InputError& e) {
        ++out->failed;
        if (out->first_error.empty()) out->first_error = e.what();
      }
    }
  }
}

std::string Ratio(int a, int b) {
  if (b == 0) return "–";
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.2f (%d/%d)", static_cast<double>(a) / b, a, b);
  return buf;
}

}  // namespace

int main(int argc, char** argv) {
  bool e2e = true;
  int seeds = 5, show_misses = 12;
  for (int i = 1; i < argc; ++i) {
    if (!std::strcmp(argv[i], "--no-e2e")) e2e = false;
    else if (!std::strcmp(argv[i], "--seeds") && i + 1 < argc) seeds = std::atoi(argv[++i]);
    else if (!std::strcmp(argv[i], "--misses") && i + 1 < argc) show_misses = std::atoi(argv[++i]);
    else if (!std::strcmp(argv[i], "--switches")) g_show_switches = true;
    else if (!std::strcmp(argv[i], "--cluster-distance") && i + 1 < argc) g_options.detect.cluster_distance = std::atof(argv[++i]);
    else if (!std::strcmp(argv[i], "--cell") && i + 1 < argc) g_options.detect.cell = std::atof(argv[++i]);
    else if (!std::strcmp(argv[i], "--min-height") && i + 1 < argc) g_options.detect.min_height = std::atof(argv[++i]);
    else if (!std::strcmp(argv[i], "--min-points") && i + 1 < argc) g_options.detect.min_points = std::atoi(argv[++i]);
    else if (!std::strcmp(argv[i], "--min-hits") && i + 1 < argc) g_options.track.min_hits = std::atoi(argv[++i]);
    else {
      std::fprintf(stderr, "usage: %s [--no-e2e] [--seeds N] [--misses N] [--switches] [--cluster-distance M] [--cell M] [--min-height M] "
                           "[--min-points N] [--min-hits N] (defaults: synth's)\n", argv[0]);
      return 2;
    }
  }
  const std::optional<fs::path> found_root = sd::bench::RepoRootOrSay();
  if (!found_root) return 1;
  const fs::path root = *found_root;
  const fs::path shared = sd::bench::SharedDriving(root);
  struct Source { std::string name; fs::path path; };
  std::vector<Source> sources = {
      {"PandaSet 002 f44-55", shared / "pandaset-002-f44-55"},
      {"Argoverse 2 (2 sweeps)", shared / "argoverse2-av2-api" / "val" / "7fab2350-7eaf-3b7e-a39d-6937a4c1bede"},
      {"KITTI object (5 frames)", shared / "kitti-object-openpcdet"},
      {"nuScenes keyframe (repo)", root / "data" / "driving" / "nuscenes-scene0061-kf0" / "mmdet3d_info" / "n015-2018-07-24-11-22-45+0800.json"},
  };
  const fs::path scenario_file = fs::temp_directory_path() / "bench_lidar_detect_scenario.json";
  sd::WriteFileAtomic(scenario_file, kScatterScenario);

  std::vector<DatasetResult> results;
  struct Plans { PlanCount annotations, detected, nothing; };
  std::vector<Plans> plans;
  for (const Source& src : sources) {
    if (!fs::exists(src.path)) {
      std::printf("(%s skipped: %s not found)\n", src.name.c_str(), src.path.string().c_str());
      continue;
    }
    const Log truth = WithSweepsOnly(sd::OpenLog(src.path));
    DatasetResult r = Evaluate(src.name, truth);
    std::printf("%s: %s\n", src.name.c_str(), r.report.Summary().c_str());
    std::sort(r.misses.begin(), r.misses.end(), [](const Miss& a, const Miss& b) { return a.points > b.points; });
    std::printf("  misses (centre criterion), most points first:\n");
    for (int k = 0; k < std::min<int>(show_misses, static_cast<int>(r.misses.size())); ++k) {
      const Miss& m = r.misses[k];
      std::printf("    frame %s %-28s %5.1f m %5d pts size %.1fx%.1fx%.1f nearest detection %.2f m; overlapping:%s\n", m.frame.c_str(),
                  m.category.c_str(), m.distance, m.points, m.size.x(), m.size.y(), m.size.z(), m.nearest,
                  m.covering.empty() ? " none" : m.covering.c_str());
    }
    results.push_back(r);
    if (e2e) {
      Log detected = truth;
      sd::HideAnnotations(&detected);
      sd::AddDetectedTracks(&detected, g_options);
      PlanCount with_truth, with_detected;
      PlanRuns(truth, truth, scenario_file, seeds, false, &with_truth);
      std::printf("  planned against detected tracks only, overlaps:\n");
      PlanRuns(detected, truth, scenario_file, seeds, true, &with_detected);
      Log nothing = truth;  // planned against no boxes at all: what the obstacle set is worth
      sd::HideAnnotations(&nothing);
      PlanCount with_nothing;
      PlanRuns(nothing, truth, scenario_file, seeds, false, &with_nothing);
      plans.push_back({with_truth, with_detected, with_nothing});
      std::printf("  plan overlaps with real boxes: annotations %d/%d, detections %d/%d, no boxes %d/%d (objects)%s%s\n",
                  with_truth.overlapping, with_truth.objects, with_detected.overlapping, with_detected.objects,
                  with_nothing.overlapping, with_nothing.objects, with_detected.first_error.empty() ? "" : "; first error: ",
                  with_detected.first_error.c_str());
    }
    std::fflush(stdout);
  }
  std::remove(scenario_file.c_str());

  std::printf("\n### Recall within %.0f m (annotated objects with >= %d returns), class-agnostic\n\n", kRange, kMinPoints);
  std::printf("| log | frames | group | objects | recall (centre) | recall (covered) | class agrees |\n|---|---|---|---|---|---|---|\n");
  GroupCounts total[kGroups];
  for (const DatasetResult& r : results)
    for (int g = 0; g < kGroups; ++g) {
      const GroupCounts& c = r.groups[g];
      total[g].eligible += c.eligible, total[g].centre += c.centre, total[g].covered += c.covered, total[g].class_agree += c.class_agree;
      if (c.eligible == 0) continue;
      std::printf("| %s | %d | %s | %d | %s | %s | %s |\n", r.name.c_str(), r.frames, kGroupNames[g], c.eligible,
                  Ratio(c.centre, c.eligible).c_str(), Ratio(c.covered, c.eligible).c_str(), Ratio(c.class_agree, c.centre).c_str());
    }
  for (int g = 0; g < kGroups; ++g)
    if (total[g].eligible > 0)
      std::printf("| **all** | | %s | %d | %s | %s | %s |\n", kGroupNames[g], total[g].eligible, Ratio(total[g].centre, total[g].eligible).c_str(),
                  Ratio(total[g].covered, total[g].eligible).c_str(), Ratio(total[g].class_agree, total[g].centre).c_str());
  std::printf("\n### False positives and tracking\n\n");
  std::printf("| log | detections within 30 m / frame | unmatched / frame | of them overlapping no annotated box / frame | annotated tracks matched in >= 2 frames | id switches / consecutive matched pairs | seconds / frame |\n|---|---|---|---|---|---|---|\n");
  for (const DatasetResult& r : results)
    std::printf("| %s | %.1f | %.1f | %.1f | %d | %d / %d | %.2f |\n", r.name.c_str(), static_cast<double>(r.detections_in_range) / r.frames,
                static_cast<double>(r.false_positives) / r.frames, static_cast<double>(r.fp_overlapping_nothing) / r.frames,
                r.tracked_objects, r.id_switches, r.matched_pairs, r.seconds / r.frames);
  if (e2e) {
    std::printf("\n### End to end: planned objects overlapping a real annotated box (%d seeds)\n\n", seeds);
    std::printf("| log | planned against annotations | against detected tracks only | against no boxes | plans failed (annotations / detected / runs) |\n|---|---|---|---|---|\n");
    for (size_t i = 0; i < plans.size(); ++i) {
      const Plans& p = plans[i];
      std::printf("| %s | %d of %d | %d of %d | %d of %d | %d / %d / %d |\n", results[i].name.c_str(), p.annotations.overlapping,
                  p.annotations.objects, p.detected.overlapping, p.detected.objects, p.nothing.overlapping, p.nothing.objects,
                  p.annotations.failed, p.detected.failed, p.annotations.runs);
    }
  }
  return 0;
}
