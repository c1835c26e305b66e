// Road heights from the cameras alone (synth/camera_road.h: plane-sweep stereo against the neighbouring frames of
// a sequence), measured against the LiDAR road surface of the same frames, which the stereo never sees:
//  - the LiDAR ground of each frame is what synthesis uses (synth/frame.h: EstimateFrameGround on the frame's
//    sweep); for each stereo point whose (x, y) the LiDAR ground observed (GroundModel::IsObserved), the error is
//    stereo z - SurfaceAt(x, y).height;
//  - median and 90th percentile of |error| within 10 / 20 / 40 m (horizontal, from the ego origin), beside the
//    same figures for the flat prior plane alone (z = prior at the same (x, y)): what a log without LiDAR gets
//    today;
//  - points on non-road: the LiDAR ground did not observe their cell, or they sit more than 0.3 m off it;
//  - the same with "observed" relaxed to "a LiDAR ground cell within 1 m": the rings of a 64-beam LiDAR leave
//    most 0.5 m cells between them empty even at 5-10 m, so the strict row judges only a fifth of the points;
//  - seconds per frame (all cameras, images read included), and the same per camera.
// Logs: PandaSet 002 (12 frames at 10 Hz, six cameras; ego origin 0.30 m above the road). Argoverse 2 and the
// repo's nuScenes keyframe are listed with why they give nothing (no converted images; one frame).
// A plain program: build/bin/bench_camera_road [--frames N] [--stride N] [--downsample N] [--min-ncc X]
// [--margin X] [--max-hpp X] [--neighbours N] [--dump FILE.csv] [--overlay DIR];
// prints markdown tables.
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <ctime>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "bench_paths.h"
#include "core/error.h"
#include "datasets/readers.h"
#include "io/image_io.h"
#include "synth/camera_road.h"
#include "synth/frame.h"
#include "synth/ground.h"
#include "synth/scenario.h"

namespace fs = std::filesystem;
using sd::Frame;
using sd::Log;

namespace {

constexpr double kRanges[] = {10, 20, 40};
constexpr double kOffRoad = 0.3;  // metres off the LiDAR ground: not road
constexpr double kNear = 1.0;     // the relaxed row: some LiDAR ground cell within this many metres

struct Errors {
  std::vector<double> stereo[3], prior[3];
  int points = 0, unobserved = 0, off_road = 0;
};

FILE* g_dump = nullptr;
fs::path g_overlay;  // --overlay DIR: frame 1's images with the stereo points drawn (green road, red off, blue unseen)  // --dump FILE: every stereo point as CSV, for looking at where the misses are

double Percentile(std::vector<double> v, double q) {
  if (v.empty()) return std::nan("");
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<size_t>(q * static_cast<double>(v.size())))];
}

struct DatasetResult {
  std::string name;
  Errors all;
  std::map<std::string, Errors> per_camera;
  Errors all_near;  // "observed" relaxed to a cell within 1 m: the LiDAR's rings leave gaps between cells
  std::map<std::string, double> camera_seconds;
  int frames = 0;
  double seconds = 0, cpu_seconds = 0;
  std::vector<std::string> summaries;
};

// Whether the LiDAR ground observed a cell within `reach` metres of (x, y) (0: the point's own cell).
bool ObservedNear(const sd::GroundModel& ground, double x, double y, double reach) {
  const int n = static_cast<int>(std::ceil(reach / ground.cell()));
  for (int i = -n; i <= n; ++i)
    for (int j = -n; j <= n; ++j)
      if (ground.IsObserved(x + i * ground.cell(), y + j * ground.cell())) return true;
  return false;
}

void Add(Errors* e, const Eigen::Vector3d& p, const sd::GroundModel& ground, double prior, double reach) {
  ++e->points;
  if (!ObservedNear(ground, p.x(), p.y(), reach)) {
    ++e->unobserved;
    return;
  }
  const double road = ground.SurfaceAt(p.x(), p.y()).height;
  const double err = std::abs(p.z() - road);
  if (err > kOffRoad) ++e->off_road;
  const double r = p.head<2>().norm();
  for (int k = 0; k < 3; ++k)
    if (r <= kRanges[k]) {
      e->stereo[k].push_back(err);
      e->prior[k].push_back(std::abs(prior - road));
    }
}

DatasetResult Evaluate(const std::string& name, const Log& log, double prior, const sd::CameraRoadOptions& options,
                       int max_frames, bool per_camera_timing) {
  DatasetResult r;
  r.name = name;
  for (size_t i = 0; i < log.frames.size() && static_cast<int>(i) < max_frames; ++i) {
    const Frame& frame = log.frames[i];
    const auto t0 = std::chrono::steady_clock::now();
    const std::clock_t c0 = std::clock();
    const sd::CameraRoadResult cr = sd::EstimateRoadFromCameras(log, i, prior, options);
    r.seconds += std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    r.cpu_seconds += static_cast<double>(std::clock() - c0) / CLOCKS_PER_SEC;
    ++r.frames;
    r.summaries.push_back(frame.token + ": " + cr.summary);
    if (!frame.lidar) continue;
    const sd::PointCloud sweep = sd::ReadLidar(*frame.lidar);
    const sd::GroundModel ground = sd::EstimateFrameGround(frame, sweep, sd::PointsInEgo(frame, sweep), sd::Scenario{});
    for (size_t k = 0; k < cr.points_ego.size(); ++k) {
      Add(&r.all, cr.points_ego[k], ground, prior, 0);
      Add(&r.all_near, cr.points_ego[k], ground, prior, kNear);
      Add(&r.per_camera[frame.cameras[cr.camera_of[k]].channel], cr.points_ego[k], ground, prior, 0);
      if (g_dump) {
        const Eigen::Vector3d& p = cr.points_ego[k];
        std::fprintf(g_dump, "%s,%s,%.3f,%.3f,%.3f,%d,%d,%.3f\n", frame.token.c_str(),
                     frame.cameras[cr.camera_of[k]].channel.c_str(), p.x(), p.y(), p.z(),
                     ground.IsObserved(p.x(), p.y()) ? 1 : 0, ObservedNear(ground, p.x(), p.y(), kNear) ? 1 : 0,
                     ground.SurfaceAt(p.x(), p.y()).height);
      }
    }
    if (!g_overlay.empty() && i == 1) {
      fs::create_directories(g_overlay);
      for (size_t c = 0; c < frame.cameras.size(); ++c) {
        const sd::CameraSensor& cam = frame.cameras[c];
        if (!fs::exists(cam.image_path)) continue;
        sd::ImageU8 img = sd::ReadImage(cam.image_path, 3);
        const sd::Rigid3d T_cam_ego = cam.T_ego_cam.Inverse();
        for (size_t k = 0; k < cr.points_ego.size(); ++k) {
          if (cr.camera_of[k] != static_cast<int>(c)) continue;
          const Eigen::Vector3d& p = cr.points_ego[k];
          const auto uv = cam.intrinsics.Project(T_cam_ego * p);
          if (!uv) continue;
          const bool seen = ObservedNear(ground, p.x(), p.y(), kNear);
          const double err = p.z() - ground.SurfaceAt(p.x(), p.y()).height;
          const uint8_t rgb[3] = {static_cast<uint8_t>(seen && std::abs(err) > 0.15 ? (err > 0 ? 255 : 255) : 0),
                                  static_cast<uint8_t>(seen && std::abs(err) <= 0.15 ? 255 : (err < 0 ? 255 : 0)),
                                  static_cast<uint8_t>(seen ? 0 : 255)};
          for (int dy = -2; dy <= 2; ++dy)
            for (int dx = -2; dx <= 2; ++dx) {
              const int x = static_cast<int>(uv->x()) + dx, y = static_cast<int>(uv->y()) + dy;
              if (x < 0 || y < 0 || x >= img.width() || y >= img.height()) continue;
              for (int ch = 0; ch < 3; ++ch) img.at(x, y, ch) = rgb[ch];
            }
        }
        sd::WriteImage(g_overlay / (cam.channel + ".png"), img);
      }
    }
    if (per_camera_timing && i == 1) {  // one frame, camera by camera: where the time goes
      for (const sd::CameraSensor& cam : frame.cameras) {
        Log one = log;
        for (Frame& f : one.frames) {
          std::vector<sd::CameraSensor> keep;
          for (const sd::CameraSensor& c : f.cameras)
            if (c.channel == cam.channel) keep.push_back(c);
          f.cameras = keep;
        }
        const auto t1 = std::chrono::steady_clock::now();
        sd::EstimateRoadFromCameras(one, i, prior, options);
        r.camera_seconds[cam.channel] = std::chrono::duration<double>(std::chrono::steady_clock::now() - t1).count();
      }
    }
  }
  return r;
}

void PrintRow(const std::string& label, const Errors& e) {
  const double n = std::max(1, e.points);
  std::printf("| %s | %d | %.1f %% | %.1f %% |", label.c_str(), e.points, 100.0 * e.unobserved / n, 100.0 * e.off_road / n);
  for (int k = 0; k < 3; ++k)
    std::printf(" %zu | %.3f / %.3f | %.3f / %.3f |", e.stereo[k].size(), Percentile(e.stereo[k], 0.5),
                Percentile(e.stereo[k], 0.9), Percentile(e.prior[k], 0.5), Percentile(e.prior[k], 0.9));
  std::printf("\n");
}

}  // namespace

int main(int argc, char** argv) {
  sd::CameraRoadOptions options;
  int max_frames = 1 << 30;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    const bool has = i + 1 < argc;
    if (a == "--frames" && has) max_frames = std::atoi(argv[++i]);
    else if (a == "--stride" && has) options.stride = std::atoi(argv[++i]);
    else if (a == "--downsample" && has) options.downsample = std::atoi(argv[++i]);
    else if (a == "--min-ncc" && has) options.min_ncc = std::atof(argv[++i]);
    else if (a == "--margin" && has) options.min_margin = std::atof(argv[++i]);
    else if (a == "--max-hpp" && has) options.max_height_per_px = std::atof(argv[++i]);
    else if (a == "--neighbours" && has) options.neighbours = std::atoi(argv[++i]);
    else if (a == "--dump" && has) g_dump = std::fopen(argv[++i], "w");
    else if (a == "--overlay" && has) g_overlay = argv[++i];
    else {
      std::fprintf(stderr,
                   "usage: bench_camera_road [--frames N] [--stride N] [--downsample N] [--min-ncc X] [--margin X] "
                   "[--max-hpp X] [--neighbours N] [--dump FILE.csv] [--overlay DIR]\n");
      return 2;
    }
  }
  const std::optional<fs::path> found_root = sd::bench::RepoRootOrSay();
  if (!found_root) return 1;
  const fs::path root = *found_root;
  const fs::path shared = sd::bench::SharedDriving(root);

  std::printf("# Camera road heights (plane-sweep stereo) against the LiDAR road surface\n\n");
  std::printf("options: downsample %d, stride %d, patch %d, step %.3f m, search +-%.2f m, min NCC %.2f, margin %.2f, "
              "max %.2f m/px, neighbours %d\n\n",
              options.downsample, options.stride, options.patch, options.step, options.search, options.min_ncc,
              options.min_margin, options.max_height_per_px, options.neighbours);
  std::vector<DatasetResult> results;
  try {
    const fs::path pandaset = shared / "pandaset-002-f44-55";
    if (fs::exists(pandaset)) {
      const Log log = sd::OpenLog(pandaset);
      // PandaSet's ego origin is 0.30 m above the road (datasets/readers.h).
      results.push_back(Evaluate("PandaSet 002 f44-55", log, -0.30, options, max_frames, true));
    } else {
      std::printf("PandaSet: %s not present, skipped\n", pandaset.string().c_str());
    }
    const fs::path av2 = shared / "argoverse2-av2-api" / "val";
    if (fs::exists(av2)) {
      for (const auto& e : fs::directory_iterator(av2)) {
        const Log log = sd::OpenLog(e.path());
        size_t cameras = 0;
        for (const Frame& f : log.frames) cameras += f.cameras.size();
        if (cameras == 0) {
          std::printf("Argoverse 2 %s: %zu frames, no camera images in the conversion (sensors/ holds lidar/ only): "
                      "skipped\n", e.path().filename().string().c_str(), log.frames.size());
          continue;
        }
        results.push_back(Evaluate("Argoverse 2 " + e.path().filename().string(), log, 0.0, options, max_frames, false));
      }
    }
    const fs::path keyframe = root / "data" / "driving" / "nuscenes-scene0061-kf0" / "mmdet3d_info" /
                              "n015-2018-07-24-11-22-45+0800.json";
    if (fs::exists(keyframe)) {
      const Log log = sd::OpenLog(keyframe);
      const sd::CameraRoadResult cr = sd::EstimateRoadFromCameras(log, 0, 0.0, options);
      std::printf("nuScenes keyframe (repo, %zu frame): %s\n", log.frames.size(), cr.summary.c_str());
    }
  } catch (const sd::InputError& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 1;
  }
  std::printf("\n");
  for (const DatasetResult& r : results) {
    std::printf("## %s: %d frames, %.2f s per frame (%.2f s of CPU)\n\n", r.name.c_str(), r.frames,
                r.frames ? r.seconds / r.frames : 0.0, r.frames ? r.cpu_seconds / r.frames : 0.0);
    std::printf("|err| in metres, median / p90, over the points whose cell the LiDAR ground observed; prior = the flat "
                "prior plane at the same (x, y). Not observed / off: shares of all points (non-road).\n\n");
    std::printf("| camera | points | not observed | > %.1f m off |", kOffRoad);
    for (double rr : kRanges) std::printf(" n <= %.0f m | stereo | prior |", rr);
    std::printf("\n|---|---|---|---|---|---|---|---|---|---|---|---|---|\n");
    PrintRow("all", r.all);
    PrintRow("all, ground within 1 m", r.all_near);
    for (const auto& [channel, e] : r.per_camera) PrintRow(channel, e);
    if (!r.camera_seconds.empty()) {
      std::printf("\nseconds per camera (frame 1):");
      for (const auto& [channel, s] : r.camera_seconds) std::printf(" %s %.2f", channel.c_str(), s);
      std::printf("\n");
    }
    std::printf("\n");
    for (const std::string& s : r.summaries) std::printf("  %s\n", s.c_str());
    std::printf("\n");
  }
  if (g_dump) std::fclose(g_dump);
  return 0;
}
