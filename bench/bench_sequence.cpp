// A real sequence synthesised end to end: PandaSet 002, frames 44-55 (../shared/data, 12 frames x 6 cameras + two
// LiDARs), with data/scenarios/pandaset_closure.json (a lane closure of cones and a breakdown), world-fixed.
// Measures what a person watching the sequence would judge, per frame and per inserted object:
//  - seconds per frame (SynthesizeFrame, defaults: environment light, dense occlusion, classical harmoniser);
//  - the world anchor of every object (T_world_ego * T_ego_object) across frames: drift 0 by construction;
//  - clearance: inserted boxes overlapping an annotated box in any frame (target 0);
//  - LiDAR: returns on the objects per sensor (Pandar64 / PandarGT) and the span of their per-point times;
//  - 2D-box flicker: each object's visible 2D box minus the projection of its world box at that frame (what the
//    ego motion explains), frame to frame, in pixels;
//  - colour flicker: the frame-to-frame change of each object's mean colour (sRGB, changed pixels inside its 2D
//    box), beside the same figure for the real cones of the same images (their pixels inside their projected
//    boxes), which is what the camera and the ego motion do to a real object.
// Prints a markdown table and writes bench/results/sequence.json. A plain program: run build/bin/bench_sequence.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <map>
#include <string>
#include <vector>

#include <unistd.h>

#include <nlohmann/json.hpp>

#include "bench_demo.h"
#include "core/box3.h"
#include "datasets/readers.h"
#include "io/files.h"
#include "io/image_io.h"
#include "synth/batch.h"
#include "synth/scenario.h"

namespace fs = std::filesystem;
using sd::Box2;
using sd::Box3;

namespace {

double Median(std::vector<double> v) {
  if (v.empty()) return NAN;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
}
double Max(const std::vector<double>& v) { return v.empty() ? NAN : *std::max_element(v.begin(), v.end()); }

// The 2D bounds of a box's corners seen by `cam`; nullopt when a corner is behind it or the bounds leave the image.
std::optional<Box2> Projected(const sd::CameraSensor& cam, const Box3& box_ego) {
  const sd::Rigid3d T_cam_ego = cam.T_ego_cam.Inverse();
  Box2 b{1e9, 1e9, -1e9, -1e9};
  for (const auto& c : box_ego.Corners()) {
    const auto uv = cam.intrinsics.Project(T_cam_ego * c, 0.5);
    if (!uv) return std::nullopt;
    b.x1 = std::min(b.x1, uv->x()), b.y1 = std::min(b.y1, uv->y()), b.x2 = std::max(b.x2, uv->x()), b.y2 = std::max(b.y2, uv->y());
  }
  if (b.x1 < 0 || b.y1 < 0 || b.x2 >= cam.intrinsics.width || b.y2 >= cam.intrinsics.height) return std::nullopt;
  return b;
}

// Mean sRGB (0..255, per channel) of `pixels` of `img`.
Eigen::Vector3d MeanColour(const sd::ImageU8& img, const std::vector<std::pair<int, int>>& pixels) {
  Eigen::Vector3d s = Eigen::Vector3d::Zero();
  for (const auto& [x, y] : pixels) {
    const uint8_t* p = img.pixel(x, y);
    s += Eigen::Vector3d(p[0], p[1], p[2]);
  }
  return pixels.empty() ? s : Eigen::Vector3d(s / static_cast<double>(pixels.size()));
}

// Relative change between two mean colours: |a - b| / |a| (Euclidean in sRGB), in percent.
double ColourChange(const Eigen::Vector3d& a, const Eigen::Vector3d& b) { return 100 * (a - b).norm() / std::max(1.0, a.norm()); }

}  // namespace

int main() {
  const auto root = sd::bench::FindRepoRoot();
  if (!root) {
    std::fprintf(stderr, "bench_sequence: cannot find the repo's data/ (set SYNTHDRIVE_SOURCE_DIR)\n");
    return 2;
  }
  const fs::path seq = *root / ".." / "shared" / "data" / "driving" / "pandaset-002-f44-55";
  if (!fs::is_directory(seq)) {
    std::printf("bench_sequence: %s not present (needs ../shared/data beside the repo); skipped\n", seq.string().c_str());
    return 0;
  }
  const fs::path data = *root / "data";
  const fs::path tmp = fs::temp_directory_path() / ("bench_sequence_" + std::to_string(::getpid()));
  std::vector<sd::Asset> assets;
  const auto meshes = sd::bench::DemoMeshes();
  assets.push_back(sd::bench::ImportDemoAsset(data, meshes[0], tmp / "cone"));
  assets.push_back(sd::bench::ImportDemoAsset(data, meshes[2], tmp / "car"));
  const fs::path scenario_file = data / "scenarios" / "pandaset_closure.json";
  const sd::Scenario scenario = sd::ReadScenario(scenario_file);
  const sd::Log log = sd::OpenLog(seq);
  std::vector<size_t> selected;
  for (size_t i = 0; i < log.frames.size(); ++i) selected.push_back(i);
  const sd::SynthPlan plan = sd::PlanSynthesis(log, selected, scenario, assets, scenario_file, true);
  const sd::SequencePlan* p = plan.ForFrame(0);
  if (!p) {
    std::fprintf(stderr, "bench_sequence: no plan for frame 0\n");
    return 1;
  }
  sd::SynthOptions options;

  std::vector<double> seconds;
  std::vector<sd::FrameOutcome> outcomes;
  for (size_t i : selected) {
    const auto t0 = std::chrono::steady_clock::now();
    outcomes.push_back(sd::SynthesizeFrame(log, i, assets, scenario, options, p));
    seconds.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    std::printf("frame %s: %.2f s, %zu objects\n", log.frames[i].token.c_str(), seconds.back(), outcomes.back().objects.size());
    std::fflush(stdout);
  }
  fs::remove_all(tmp);

  // World anchors, clearance, LiDAR.
  double drift = 0;
  size_t pairs = 0, overlaps = 0, on_pandar64 = 0, on_pandargt = 0;
  float t_min = 1e9f, t_max = -1e9f;
  for (const sd::FrameOutcome& o : outcomes) {
    const sd::Frame& f = log.frames[o.frame_index];
    for (const sd::ObjectOutcome& ob : o.objects) {
      if (ob.plan_object < 0) continue;
      const sd::Rigid3d T_world_object = f.T_world_ego * ob.placement.T_ego_asset;
      drift = std::max(drift, (T_world_object.translation - p->objects[static_cast<size_t>(ob.plan_object)].T_world_object.translation).norm());
      for (const sd::Annotation& a : f.annotations) {
        ++pairs;
        overlaps += sd::BoxesOverlap(ob.placement.box, a.box);
      }
    }
    if (o.edit.points) {
      const int si = o.edit.points->FeatureIndex("sensor"), ti = o.edit.points->FeatureIndex("time");
      for (const auto& [i, k] : o.lidar_object_points) {
        (void)k;
        const float s = si >= 0 ? o.edit.points->feature(static_cast<size_t>(i), si) : 0;
        (s == 0 ? on_pandar64 : on_pandargt)++;
        if (ti >= 0) {
          t_min = std::min(t_min, o.edit.points->feature(static_cast<size_t>(i), ti));
          t_max = std::max(t_max, o.edit.points->feature(static_cast<size_t>(i), ti));
        }
      }
    }
  }

  // 2D boxes and colours of the inserted objects, per (plan object, camera), frame by frame.
  struct Sample {
    size_t frame;
    Box2 box, projected;
    Eigen::Vector3d colour;
  };
  std::map<std::pair<int, std::string>, std::vector<Sample>> tracks;
  for (const sd::FrameOutcome& o : outcomes) {
    const sd::Frame& f = log.frames[o.frame_index];
    for (const sd::CameraOutcome& co : o.cameras) {
      const sd::CameraSensor* cam = f.FindCamera(co.channel);
      for (int k : co.objects) {
        const sd::ObjectOutcome& ob = o.objects[static_cast<size_t>(k)];
        for (const sd::CameraBox& cb : ob.label.camera_boxes) {
          if (cb.channel != co.channel || cb.truncation > 0 || cb.visible_fraction < 0.95) continue;
          const auto proj = Projected(*cam, ob.placement.box);
          if (!proj) continue;
          std::vector<std::pair<int, int>> pixels;
          for (int y = static_cast<int>(cb.box.y1); y < static_cast<int>(cb.box.y2); ++y)
            for (int x = static_cast<int>(cb.box.x1); x < static_cast<int>(cb.box.x2); ++x) {
              const uint8_t *a = co.after.pixel(x, y), *b = co.before.pixel(x, y);
              if (std::abs(a[0] - b[0]) + std::abs(a[1] - b[1]) + std::abs(a[2] - b[2]) > 12) pixels.push_back({x, y});
            }
          if (pixels.size() < 30) continue;
          tracks[{ob.plan_object, co.channel}].push_back({o.frame_index, cb.box, *proj, MeanColour(co.after, pixels)});
        }
      }
    }
  }
  std::vector<double> box_flicker, colour_flicker, box_motion;
  std::string worst_colour;
  double worst_colour_value = -1;
  for (const auto& [key, samples] : tracks)
    for (size_t k = 1; k < samples.size(); ++k) {
      const Sample &a = samples[k - 1], &b = samples[k];
      if (b.frame != a.frame + 1) continue;
      const double r[4] = {(b.box.x1 - b.projected.x1) - (a.box.x1 - a.projected.x1), (b.box.y1 - b.projected.y1) - (a.box.y1 - a.projected.y1),
                           (b.box.x2 - b.projected.x2) - (a.box.x2 - a.projected.x2), (b.box.y2 - b.projected.y2) - (a.box.y2 - a.projected.y2)};
      for (double v : r) box_flicker.push_back(std::abs(v));
      box_motion.push_back(std::hypot(0.5 * (b.box.x1 + b.box.x2 - a.box.x1 - a.box.x2), 0.5 * (b.box.y1 + b.box.y2 - a.box.y1 - a.box.y2)));
      colour_flicker.push_back(ColourChange(a.colour, b.colour));
      if (colour_flicker.back() > worst_colour_value) {
        worst_colour_value = colour_flicker.back();
        char buf[200];
        std::snprintf(buf, sizeof buf, "object %d in %s, frames %s -> %s", key.first, key.second.c_str(),
                      log.frames[a.frame].token.c_str(), log.frames[b.frame].token.c_str());
        worst_colour = buf;
      }
    }
  // The real cones of the same cameras: their pixels inside their projected boxes, frame to frame.
  std::map<std::pair<std::string, std::string>, std::vector<std::pair<size_t, Eigen::Vector3d>>> real;
  for (const sd::Frame& f : log.frames) {
    const size_t fi = static_cast<size_t>(&f - log.frames.data());
    for (const sd::CameraSensor& cam : f.cameras) {
      std::optional<sd::ImageU8> img;
      for (const sd::Annotation& a : f.annotations) {
        if (a.category != "Cones") continue;
        const auto proj = Projected(cam, a.box);
        if (!proj || proj->y2 - proj->y1 < 30) continue;
        if (!img) img = sd::ReadImage(cam.image_path, 3);
        std::vector<std::pair<int, int>> pixels;
        for (int y = static_cast<int>(proj->y1); y < static_cast<int>(proj->y2); ++y)
          for (int x = static_cast<int>(proj->x1); x < static_cast<int>(proj->x2); ++x) pixels.push_back({x, y});
        real[{a.instance_token, cam.channel}].push_back({fi, MeanColour(*img, pixels)});
      }
    }
  }
  std::vector<double> real_flicker;
  for (const auto& [key, samples] : real)
    for (size_t k = 1; k < samples.size(); ++k)
      if (samples[k].first == samples[k - 1].first + 1) real_flicker.push_back(ColourChange(samples[k - 1].second, samples[k].second));

  const double s_median = Median(seconds);
  std::printf("\n| figure | value |\n|---|---|\n");
  std::printf("| frames, inserted objects (plan) | %zu, %zu |\n", outcomes.size(), p->objects.size());
  std::printf("| seconds per frame (median, min-max) | %.2f (%.2f-%.2f) |\n", s_median, *std::min_element(seconds.begin(), seconds.end()), Max(seconds));
  std::printf("| world-anchor drift, max over objects and frames | %.2e m |\n", drift);
  std::printf("| inserted-annotated box pairs overlapping, any frame | %zu of %zu |\n", overlaps, pairs);
  std::printf("| LiDAR returns on inserted objects: Pandar64 / PandarGT | %zu / %zu |\n", on_pandar64, on_pandargt);
  std::printf("| their per-point times (s from the sweep stamp) | %.3f .. %.3f |\n", t_min, t_max);
  std::printf("| object-camera tracks, consecutive pairs | %zu, %zu |\n", tracks.size(), colour_flicker.size());
  std::printf("| 2D box centre motion frame to frame (median, max) | %.1f, %.1f px |\n", Median(box_motion), Max(box_motion));
  std::printf("| 2D-box flicker beyond the ego motion (median, max) | %.2f, %.2f px |\n", Median(box_flicker), Max(box_flicker));
  std::printf("| mean-colour change frame to frame, inserted (median, max) | %.2f, %.2f %% |\n", Median(colour_flicker), Max(colour_flicker));
  std::printf("| largest colour change: %s | %.1f %% |\n", worst_colour.c_str(), worst_colour_value);
  std::printf("| the same for the real cones (median, max; %zu pairs) | %.2f, %.2f %% |\n", real_flicker.size(), Median(real_flicker), Max(real_flicker));

  nlohmann::json j = {{"frames", outcomes.size()}, {"objects", p->objects.size()}, {"seconds", seconds},
                      {"world_anchor_drift_m", drift}, {"overlaps", overlaps}, {"pairs", pairs},
                      {"lidar_points", {{"pandar64", on_pandar64}, {"pandargt", on_pandargt}}},
                      {"lidar_time_s", {t_min, t_max}}, {"box_flicker_px", box_flicker}, {"box_motion_px", box_motion},
                      {"colour_flicker_pct", colour_flicker}, {"real_cone_colour_flicker_pct", real_flicker}};
  sd::WriteFileAtomic(*root / "bench" / "results" / "sequence.json", j.dump(1));
  return 0;
}
