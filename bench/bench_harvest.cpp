// bench_harvest: real assets harvested from driving logs with no learned model (assetgen/harvest.h,
// GenerateFromHarvest), measured against what the logs themselves know.
//
// Objects: the PandaSet sequence of ../shared/data (12 frames, 6 cameras, two LiDARs, tracks): every cone, the
// road roller, and the parked cars the side cameras pass; the repo's nuScenes keyframe (one frame: cones,
// barriers, cars); the KITTI frames of ../shared (else the repo's; cars, one camera). Per object: harvest every view of its track, hold
// out the middle one, build the asset, and report
//   views      real views used / candidates (crops before the unhidden and spread selection); "+N cut": of the
//              views used, N show the object cut by the image border (their pixels past it unknown)
//   held IoU   silhouette IoU of the asset redrawn at the held-out real view against that view's mask (the mask
//              is the segmenter's, itself an estimate: read the figure as agreement, not ground truth)
//   held PSNR  masked PSNR of the asset's colour there (unlit base colour against the photo's pixels)
//   p2m        median distance of the object's LiDAR returns (all frames) to the asset's surface, metres
//   real tex   fraction of the surface textured from real camera pixels
//   charts     UV atlas charts and the share of the atlas they use (a crumpled surface cuts it into thousands)
//   s          seconds from the log to the asset (harvest + generate), 2 cores
// and writes a turntable strip per object (the largest real crop, then 8 unlit views) to
// bench/results/harvest/, figures to bench/results/harvest.json.
//
// Usage: bench_harvest [--set pandaset,nuscenes,kitti] [--steps N] [--max-objects N] [--category C] [--dump-views]
// (--dump-views: each object's harvested views as a views folder beside its turntable)
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <set>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "assetgen/asset.h"
#include "assetgen/generate.h"
#include "assetgen/harvest.h"
#include "assetgen/preview.h"
#include "core/error.h"
#include "core/log.h"
#include "datasets/categories.h"
#include "datasets/readers.h"
#include "io/image_io.h"
#include "io/json.h"

namespace {

namespace fs = std::filesystem;
using namespace sd;

struct Target {
  std::string set, label;
  const Log* log;
  HarvestTarget target;
};

double Median(std::vector<double> v) {
  if (v.empty()) return -1;
  std::sort(v.begin(), v.end());
  return v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
}

// One target per track (or per annotation without tracks), of the wanted categories, from the frame in the
// middle of the track (whose box the harvest starts from). Cars: only those that stand still and pass within
// `car_range_m` of the ego (parked cars the side cameras see whole).
std::vector<Target> Targets(const std::string& set, const Log& log, const std::set<std::string>& categories,
                            double car_range_m) {
  std::map<std::string, std::vector<std::pair<const Frame*, const Annotation*>>> tracks;
  std::vector<Target> out;
  for (const Frame& f : log.frames)
    for (const Annotation& a : f.annotations) {
      const auto c = FindCategory(a.category);
      if (!c || !categories.count(c->name)) continue;
      if (c->name == "car" && a.box.center().head<2>().norm() > car_range_m) continue;
      const std::string key = a.instance_token.empty() ? f.token + "/" + std::to_string(&a - f.annotations.data()) : a.instance_token;
      tracks[key].emplace_back(&f, &a);
    }
  for (const auto& [key, obs] : tracks) {
    if (obs.front().second->category.empty()) continue;
    // Cars that move are not harvested as parked cars (their boxes are fine, but the benchmark's question is the
    // side-camera pass).
    if (FindCategory(obs.front().second->category)->name == "car" && obs.size() > 1) {
      const Eigen::Vector3d a = obs.front().first->T_world_ego * obs.front().second->box.center();
      const Eigen::Vector3d b = obs.back().first->T_world_ego * obs.back().second->box.center();
      if ((a - b).norm() > 0.5) continue;
    }
    const auto& [f, a] = obs[obs.size() / 2];
    // Tracks by their id's first characters; single annotations by frame and index.
    const std::string label = a->instance_token.empty() ? f->token.substr(0, 6) + "#" + key.substr(key.rfind('/') + 1)
                                                        : key.substr(0, 8);
    out.push_back({set, FindCategory(a->category)->name + " " + label, &log, {f->token, a->box}});
  }
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  std::set<std::string> sets = {"pandaset", "nuscenes", "kitti"};
  int steps = RefineOptions{}.steps, max_objects = 1000;
  std::string only_category;
  bool dump_views = false;
  float point_weight = RefineOptions{}.lambda_points;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "bench_harvest: %s needs a value\n", a.c_str());
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "--set") {
      sets.clear();
      std::stringstream ss(next());
      for (std::string s; std::getline(ss, s, ',');) sets.insert(s);
    } else if (a == "--steps") {
      steps = std::atoi(next().c_str());
    } else if (a == "--max-objects") {
      max_objects = std::atoi(next().c_str());
    } else if (a == "--point-weight") {
      point_weight = static_cast<float>(std::atof(next().c_str()));
    } else if (a == "--dump-views") {
      dump_views = true;
    } else if (a == "--category") {
      only_category = next();
    } else {
      std::fprintf(stderr, "bench_harvest: unknown argument %s\n", a.c_str());
      return 2;
    }
  }
  const char* env = std::getenv("SYNTHDRIVE_SOURCE_DIR");
  const fs::path root = env ? fs::path(env) : fs::weakly_canonical(fs::path(argv[0])).parent_path().parent_path().parent_path();
  const fs::path shared = root / ".." / "shared" / "data" / "driving";
  SetLogLevel(LogLevel::kWarn);

  std::vector<Log> logs;
  logs.reserve(3);
  std::vector<Target> targets;
  auto wanted = [&](std::set<std::string> c) {
    if (only_category.empty()) return c;
    return c.count(only_category) ? std::set<std::string>{only_category} : std::set<std::string>{};
  };
  if (sets.count("pandaset")) {
    const fs::path p = shared / "pandaset-002-f44-55";
    if (fs::exists(p)) {
      logs.push_back(OpenLog(p));
      for (const Target& t : Targets("pandaset", logs.back(), wanted({"traffic_cone", "construction_vehicle", "car"}), 12))
        targets.push_back(t);
    } else {
      std::printf("pandaset: %s not found, skipped\n", p.c_str());
    }
  }
  if (sets.count("nuscenes")) {
    logs.push_back(OpenLog(root / "data/driving/nuscenes-scene0061-kf0/mmdet3d_info/n015-2018-07-24-11-22-45+0800.json"));
    for (const Target& t : Targets("nuscenes", logs.back(), wanted({"traffic_cone", "barrier", "car"}), 20)) targets.push_back(t);
  }
  if (sets.count("kitti")) {
    // ../shared's KITTI object sample has the repo's three frames and two more (a car 13 m ahead in 000003).
    const fs::path p = shared / "kitti-object-openpcdet";
    logs.push_back(OpenLog(fs::exists(p) ? p : root / "data/driving/kitti-object"));
    for (const Target& t : Targets("kitti", logs.back(), wanted({"car"}), 25)) targets.push_back(t);
  }
  if (static_cast<int>(targets.size()) > max_objects) targets.resize(max_objects);

  const fs::path out_dir = root / "bench" / "results" / "harvest";
  fs::create_directories(out_dir);
  std::printf("%-9s %-30s %7s %5s %8s %8s %8s %8s %7s  %s\n", "set", "object", "views", "fr", "held IoU", "held dB",
              "p2m m", "real tex", "s", "prior / charts, atlas used");
  nlohmann::json results = nlohmann::json::array();
  std::map<std::string, std::vector<double>> iou_by, p2m_by, psnr_by, sec_by;
  for (const Target& t : targets) {
    const auto start = std::chrono::steady_clock::now();
    try {
      const HarvestedObject object = HarvestObject(*t.log, t.target);
      std::string name = t.set + "_" + t.label;
      std::replace(name.begin(), name.end(), ' ', '_');
      if (dump_views) {
        SaveViews(object.views, out_dir / (name + "_views"), "world", true);
        std::printf("  %s: world spread %.3f m (%s), %zu returns (%d outside the masks dropped), %zu beams\n",
                    name.c_str(), object.world_spread_m, object.static_pose ? "static" : "moving", object.points.size(),
                    object.points_outside_masks, object.free_segments.size());
        for (const HarvestedView& v : object.view_info)
          std::printf("  frame %s %s: %d px, %.1f m, azimuth %.0f, elevation %.1f, truncation %.2f, occlusion %.2f, mask: %s\n",
                      v.frame_token.c_str(), v.camera.c_str(), v.object_px, v.distance_m, v.azimuth_deg,
                      v.elevation_deg, v.truncation, v.occlusion, v.mask_method.c_str());
      }
      GenerateOptions options;
      options.refine.steps = steps;
      options.refine.lambda_points = point_weight;
      options.refine.show_progress = false;
      options.upscale = "bicubic";
      HarvestFit fit;
      const GeneratedMesh g = GenerateFromHarvest(object, options, &fit);
      const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
      const nlohmann::json& q = fit.quality;
      auto fig = [&](const char* key) { return q.contains(key) ? q[key].get<double>() : -1.0; };
      const double iou = fig(quality::kHeldOutSilhouetteIou), psnr = fig("heldout_masked_psnr_db");
      const double p2m = fig(quality::kLidarPointToMeshMedianM), real = fig(quality::kRealTextureFraction);
      int cut = 0;
      for (const MultiView& v : object.views) cut += !IsWhole(v);
      int charts = 0, used = 0;
      for (const StageReport& st : g.stages)
        if (st.stage == "texture") std::sscanf(st.method.c_str(), "UV atlas %*d^2, %d charts, %d%% used", &charts, &used);
      std::printf("%-9s %-30s %3zu/%-3d %5d %8.3f %8.2f %8.4f %8.2f %7.2f  %s%s / %d, %d%%\n", t.set.c_str(), t.label.c_str(),
                  object.views.size(), object.candidate_views, object.frames, iou, psnr, p2m, real, seconds,
                  ToString(fit.prior), cut ? (" (" + std::to_string(cut) + " cut)").c_str() : "", charts, used);
      std::fflush(stdout);
      const std::string cls = object.category;
      if (iou >= 0) iou_by[cls].push_back(iou), psnr_by[cls].push_back(psnr);
      if (p2m >= 0) p2m_by[cls].push_back(p2m);
      sec_by[cls].push_back(seconds);
      results.push_back({{"set", t.set}, {"object", t.label}, {"category", cls}, {"views", object.views.size()},
                         {"candidate_views", object.candidate_views}, {"cut_views", cut}, {"frames", object.frames},
                         {"atlas_charts", charts}, {"atlas_used_percent", used},
                         {"seconds", seconds}, {"quality", q}, {"source", object.source}});
      // Turntable: the largest real crop, then the asset all round.
      const int size = 160;
      const ImageU8 turn = RenderTurntable(g.mesh, 8, size);
      size_t largest = 0;
      for (size_t i = 0; i < object.view_info.size(); ++i)
        if (object.view_info[i].object_px > object.view_info[largest].object_px) largest = i;
      const ImageU8 crop = ToSrgb8(object.views[largest].color);
      ImageU8 strip(turn.width() + size, size, 3, 217);
      for (int y = 0; y < size; ++y)
        for (int x = 0; x < size; ++x) {
          const int sx = x * crop.width() / size, sy = y * crop.height() / size;
          for (int c = 0; c < 3; ++c) strip.at(x, y, c) = crop.at(sx, sy, c);
        }
      for (int y = 0; y < size; ++y)
        for (int x = 0; x < turn.width(); ++x)
          for (int c = 0; c < 3; ++c) strip.at(size + x, y, c) = turn.at(x, y, c);
      WriteImage(out_dir / (name + ".png"), strip);
    } catch (const InputError& e) {
      std::printf("%-9s %-30s refused: %s\n", t.set.c_str(), t.label.c_str(), e.what());
    }
  }
  std::printf("\n%-22s %4s %10s %10s %10s %8s\n", "category", "n", "held IoU", "held dB", "p2m m", "s");
  for (const auto& [cls, secs] : sec_by)
    std::printf("%-22s %4zu %10.3f %10.2f %10.4f %8.2f\n", cls.c_str(), secs.size(), Median(iou_by[cls]),
                Median(psnr_by[cls]), Median(p2m_by[cls]), Median(secs));
  WriteJsonFile(root / "bench" / "results" / "harvest.json", {{"refine_steps", steps}, {"results", results}});
  std::printf("\nturntables: %s\n", out_dir.c_str());
  return 0;
}
