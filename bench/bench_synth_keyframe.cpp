// Synthesising one nuScenes keyframe (6 cameras + LiDAR) with 5 inserted objects, the way `synthdrive demo`
// does it, the same with 1, 5 and 20 objects (BM_SynthesizeKeyframeObjects, scenarios built in code from the
// demo's requests), and the ground estimation + placement stage alone.
//
// Setup (not timed, once per process): the three shipped meshes in data/assets are imported into a temp
// directory with the demo's axes and scales (see src/cli/cmd_demo.cpp), saved and re-loaded as asset folders;
// the log and data/scenarios/demo.json are opened. The timed loop of BM_SynthesizeKeyframe is exactly
// SynthesizeFrame(log, 0, assets, scenario, options): it reads the sweep and the touched camera images from
// disk (page cache after the first iteration), estimates the ground, places the objects, renders and
// composites the cameras and simulates the LiDAR. No files are written.
//
// Repo root: $SYNTHDRIVE_SOURCE_DIR, else the executable's location (build/bin -> ../../).
#include <unistd.h>

#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <benchmark/benchmark.h>

#include "assetgen/asset.h"
#include "assetgen/canonical.h"
#include "core/log.h"
#include "core/stage_times.h"
#include "datasets/categories.h"
#include "datasets/readers.h"
#include "io/files.h"
#include "io/image_io.h"
#include "io/mesh_io.h"
#include "synth/ground.h"
#include "synth/batch.h"
#include "synth/placement.h"
#include "synth/scenario.h"

#include "bench_demo.h"

namespace {
namespace fs = std::filesystem;

fs::path g_root;  // repo root, set in main

using sd::bench::FindRepoRoot;

// A temp directory removed at exit.
struct TempDir {
  fs::path path;
  TempDir() {
    std::string tmpl = (fs::temp_directory_path() / "synthdrive-bench-XXXXXX").string();
    if (!mkdtemp(tmpl.data())) throw std::runtime_error("cannot create a temp directory under " + tmpl);
    path = tmpl;
  }
  ~TempDir() {
    std::error_code ec;
    fs::remove_all(path, ec);
  }
};

struct Inputs {
  TempDir tmp;
  std::vector<sd::Asset> assets;
  sd::Log log;
  sd::Scenario scenario;
};

const Inputs& GetInputs() {
  static const std::unique_ptr<Inputs> inputs = [] {
    auto in = std::make_unique<Inputs>();
    const fs::path data = g_root / "data";
    for (const sd::bench::DemoMesh& m : sd::bench::DemoMeshes())
      in->assets.push_back(sd::bench::ImportDemoAsset(data, m, in->tmp.path / "assets" / m.id));
    in->log = sd::OpenLog(data / "driving/nuscenes-scene0061-kf0/mmdet3d_info/n015-2018-07-24-11-22-45+0800.json");
    in->scenario = sd::ReadScenario(data / "scenarios/demo.json");
    if (in->log.frames.empty()) throw std::runtime_error("the nuScenes log has no frames");
    return in;
  }();
  return *inputs;
}

// The timed loop of the whole-frame benchmarks, with what the frame placed and touched as counters.
void TimeSynthesis(benchmark::State& state, const Inputs& in, const sd::Scenario& scenario,
                   const sd::SynthOptions& options) {
  size_t objects = 0, cameras = 0;
  sd::StageTimes stages;
  for (auto _ : state) {
    sd::FrameOutcome out = sd::SynthesizeFrame(in.log, 0, in.assets, scenario, options);
    objects = out.objects.size();
    cameras = out.cameras.size();
    stages.Merge(out.timings);
    benchmark::DoNotOptimize(out.edit.points.has_value());
  }
  state.counters["objects"] = static_cast<double>(objects);
  state.counters["cameras_touched"] = static_cast<double>(cameras);
  // Where the frame's time went: seconds per stage and iteration (s_<stage>, in the JSON output), and one line.
  for (const auto& [stage, seconds] : stages.entries()) {
    std::string name = "s_" + stage;
    for (char& ch : name)
      if (ch == ' ') ch = '_';
    state.counters[name] = benchmark::Counter(seconds, benchmark::Counter::kAvgIterations);
  }
  std::fprintf(stderr, "%zu objects, %zu cameras: %s (summed over %lld iterations)\n", objects, cameras,
               stages.Summary().c_str(), static_cast<long long>(state.iterations()));
}

// The full frame: ground, placement, 6 cameras, LiDAR. Arg: camera samples per pixel (ao_samples 16).
void BM_SynthesizeKeyframe(benchmark::State& state) {
  const Inputs& in = GetInputs();
  sd::SynthOptions options;
  options.samples_per_pixel = static_cast<int>(state.range(0));
  options.ao_samples = 16;
  TimeSynthesis(state, in, in.scenario, options);
}
BENCHMARK(BM_SynthesizeKeyframe)
    ->ArgName("spp")
    ->Arg(1)
    ->Arg(4)
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->MeasureProcessCPUTime();

// The same frame at spp 4 with the camera's look off (synth/camera_look.h: no blur, noise or JPEG on the inserts):
// what the look costs, against BM_SynthesizeKeyframe/spp:4.
void BM_SynthesizeKeyframeCameraLookOff(benchmark::State& state) {
  const Inputs& in = GetInputs();
  sd::SynthOptions options;
  options.samples_per_pixel = 4;
  options.ao_samples = 16;
  options.camera_look = sd::CameraLookOptions{false, false, false, false};
  TimeSynthesis(state, in, in.scenario, options);
}
BENCHMARK(BM_SynthesizeKeyframeCameraLookOff)->Unit(benchmark::kMillisecond)->UseRealTime()->MeasureProcessCPUTime();

// Scenarios with 1, 5 and 20 inserted objects (bench_demo.h ScenarioWithObjects): 1 = the demo's car alone; 5 =
// data/scenarios/demo.json as is; 20 = 12 cones + 4 barriers + 4 cars over a wider area (5..45 m ahead, +-12 m
// lateral) so that 20 fit. Where placement cannot fit all of them, the cone count is lowered until it does (setup,
// not timed) and the "objects" counter says how many were placed.
using sd::bench::ScenarioWithObjects;

// What ground estimation and placement read of frame 0, prepared as SynthesizeFrame prepares it: the ground
// options for `seed`, and the placement input (the sweep in the ego frame, the annotated boxes, the cameras; no
// ground yet).
struct PlacementSetup {
  sd::GroundOptions ground_options;
  sd::PlacementInput input;
};
// nullopt when frame 0 has no sweep.
std::optional<PlacementSetup> SetUpPlacement(const Inputs& in, uint32_t seed) {
  const sd::Frame& frame = in.log.frames.at(0);
  if (!frame.lidar) return std::nullopt;
  PlacementSetup s;
  const sd::PointCloud sweep = sd::ReadLidar(*frame.lidar);
  s.input.points_ego.resize(sweep.size());
  for (size_t i = 0; i < sweep.size(); ++i) s.input.points_ego[i] = frame.lidar->T_ego_lidar * sweep.xyz(i).cast<double>();
  for (const auto& a : frame.annotations) s.input.real_boxes.push_back(a.box);
  s.ground_options.seed = seed;
  s.ground_options.sensor_xy = frame.lidar->T_ego_lidar.translation.head<2>();
  for (const auto& c : frame.cameras) s.input.cameras.push_back(&c);
  return s;
}

// Places `scenario` on frame 0 the way SynthesizeFrame does; the number placed, or -1 when placement fails.
int TryPlace(const Inputs& in, const sd::Scenario& scenario) {
  std::optional<PlacementSetup> s = SetUpPlacement(in, scenario.seed);
  if (!s) return -1;
  const sd::GroundModel ground = sd::GroundModel::Estimate(s->input.points_ego, s->input.real_boxes, s->ground_options);
  s->input.ground = &ground;
  try {
    return static_cast<int>(sd::PlaceObjects(scenario, in.assets, s->input).size());
  } catch (const std::exception&) {
    return -1;
  }
}

const sd::Scenario& ScenarioForCount(int count) {
  static std::map<int, sd::Scenario> cache;
  auto it = cache.find(count);
  if (it != cache.end()) return it->second;
  const Inputs& in = GetInputs();
  sd::Scenario s;
  if (count == 5) {
    s = in.scenario;
  } else if (count == 1) {
    s = ScenarioWithObjects(in.scenario, 0, 0, 1, 12, 30, 5);
  } else {
    const int fixed = 8;  // 4 barriers + 4 cars
    for (int cones = count - fixed; cones >= 0; --cones) {
      s = ScenarioWithObjects(in.scenario, cones, 4, 4, 5, 45, 12);
      if (TryPlace(in, s) >= 0) break;
    }
  }
  return cache.emplace(count, s).first->second;
}

// The full frame with N requested objects (spp 4 = the default, ao_samples 16). full:1 = the defaults
// (environment-map light with soft shadows, dense occlusion, classical harmonisation); full:0 = the fast path
// (`--light road --occlusion sparse --harmonizer none`, what synth did before those existed).
void BM_SynthesizeKeyframeObjects(benchmark::State& state) {
  const Inputs& in = GetInputs();
  const sd::Scenario& scenario = ScenarioForCount(static_cast<int>(state.range(0)));
  sd::SynthOptions options;
  options.samples_per_pixel = 4;
  options.ao_samples = 16;
  if (state.range(1) == 0) {
    options.light = sd::SynthOptions::Light::kRoad;
    options.dense_occlusion = false;
    options.harmonizer = "none";
  }
  TimeSynthesis(state, in, scenario, options);
}
BENCHMARK(BM_SynthesizeKeyframeObjects)
    ->ArgNames({"objects", "full"})
    ->ArgsProduct({{1, 5, 20}, {1, 0}})
    ->Unit(benchmark::kMillisecond)
    ->UseRealTime()
    ->MeasureProcessCPUTime();

// Ground estimation + placement alone, on the same frame and seeds as SynthesizeFrame(frame 0). The sweep is
// read and moved to the ego frame outside the timed loop.
void BM_GroundAndPlacement(benchmark::State& state) {
  const Inputs& in = GetInputs();
  std::optional<PlacementSetup> s = SetUpPlacement(in, in.scenario.seed);
  if (!s) {
    state.SkipWithError("frame 0 has no LiDAR sweep");
    return;
  }
  sd::Scenario frame_scenario = in.scenario;
  frame_scenario.seed = sd::FrameSeedsOf(in.scenario.seed, 0).placement;  // SynthesizeFrame's placement stream
  size_t placed_count = 0;
  for (auto _ : state) {
    const sd::GroundModel ground = sd::GroundModel::Estimate(s->input.points_ego, s->input.real_boxes, s->ground_options);
    s->input.ground = &ground;
    const std::vector<sd::PlacedObject> placed = sd::PlaceObjects(frame_scenario, in.assets, s->input);
    placed_count = placed.size();
    benchmark::DoNotOptimize(placed.data());
  }
  state.counters["objects"] = static_cast<double>(placed_count);
  state.counters["lidar_points"] = static_cast<double>(s->input.points_ego.size());
}
BENCHMARK(BM_GroundAndPlacement)->Unit(benchmark::kMillisecond)->UseRealTime()->MeasureProcessCPUTime();

}  // namespace

// The floor a one-frame synth process is measured against (bench/bench_synth_process.sh): one thread decoding and
// re-encoding the keyframe's six camera JPEGs with the program's own codecs, from bytes in memory.
void BM_JpegRoundTripFloor(benchmark::State& state) {
  const Inputs& in = GetInputs();
  std::vector<std::string> files;
  for (const auto& cam : in.log.frames[0].cameras) files.push_back(sd::ReadFileToString(cam.image_path));
  for (auto _ : state)
    for (const std::string& bytes : files) {
      const sd::ImageU8 image = sd::DecodeImage(bytes, "camera image");
      benchmark::DoNotOptimize(sd::EncodeImage(image, "jpg", 90).size());
    }
  state.counters["images"] = static_cast<double>(files.size());
}
BENCHMARK(BM_JpegRoundTripFloor)->Unit(benchmark::kMillisecond)->UseRealTime();

int main(int argc, char** argv) {
  benchmark::Initialize(&argc, argv);
  if (benchmark::ReportUnrecognizedArguments(argc, argv)) return 1;
  const auto root = FindRepoRoot();
  if (!root) {
    std::fprintf(stderr,
                 "bench_synth_keyframe: cannot find the repo's data/ directory (needs data/driving and data/assets).\n"
                 "Set SYNTHDRIVE_SOURCE_DIR to the repo root, or run the binary from <repo>/<build>/bin.\n");
    return 1;
  }
  g_root = *root;
  sd::SetLogLevel(sd::LogLevel::kWarn);
  try {
    GetInputs();  // import assets, open the log and scenario once, before any timing
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_synth_keyframe: setup failed: %s\n", e.what());
    return 1;
  }
  benchmark::RunSpecifiedBenchmarks();
  benchmark::Shutdown();
  return 0;
}
