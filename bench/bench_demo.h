#pragma once
// What the synthesis benchmarks share: the repo's data/ (bench_paths.h), and the demo's three meshes with the axes and
// scales the demo imports them with (src/cli/cmd_demo.cpp, data/README.md): y-up; the cone scaled to 0.7 m,
// the barrier and the car in metres, the barrier's front along the file's z.
#include <unistd.h>

#include <algorithm>
#include <array>
#include <chrono>
#include <cstdlib>
#include <filesystem>
#include <functional>
#include <optional>
#include <stdexcept>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "assetgen/asset.h"
#include "assetgen/canonical.h"
#include "datasets/categories.h"
#include "datasets/readers.h"
#include "core/image.h"
#include "io/image_io.h"
#include "io/mesh_io.h"
#include "synth/scenario.h"
#include "bench_paths.h"

namespace sd::bench {

struct DemoMesh {
  const char* mesh;  // relative to data/
  const char* id;
  const char* category;
  const char* front;
  double scale, height;  // CanonicalizeOptions::scale (0 = from the height), target height (0 = none)

  CanonicalizeOptions Options() const {
    CanonicalizeOptions o;
    o.up = "+y";
    o.front = front;
    o.scale = scale;
    if (height > 0) o.target_height = height;
    return o;
  }
};

// The cone, barrier and car, in that order.
inline std::vector<DemoMesh> DemoMeshes() {
  return {{"assets/metadrive_traffic_cone/scene.gltf", "metadrive_traffic_cone", "traffic_cone", "+x", 0, 0.70},
          {"assets/metadrive_road_barrier/scene.gltf", "metadrive_road_barrier", "barrier", "+z", 1.0, 0},
          {"assets/torcs_p406/obj/torcs_p406.obj", "torcs_p406", "car", "+x", 1.0, 0}};
}

// The few lines of cli::ImportAsset the benchmarks need: load data/<m.mesh>, canonicalise, save the asset folder
// `out`, load it back (as RunSynth sees an asset: through its folder).
inline Asset ImportDemoAsset(const std::filesystem::path& data_dir, const DemoMesh& m, const std::filesystem::path& out) {
  const auto cat = FindCategory(m.category);
  if (!cat) throw std::runtime_error(std::string("unknown category ") + m.category);
  const CanonicalizeOptions opt = m.Options();
  CanonicalizeResult c = Canonicalize(LoadMesh(data_dir / m.mesh), opt);
  Asset a;
  a.mesh = std::move(c.mesh);
  if (a.mesh.normals.empty()) a.mesh.ComputeVertexNormals();
  a.info.id = m.id;
  a.info.name = m.id;
  a.info.category = cat->name;
  a.info.extent = c.extent;
  a.info.licence = "see data/README.md";
  a.info.source = std::string("data/") + m.mesh;
  a.info.stages = nlohmann::json::array({{{"stage", "import"},
                                          {"version", "synthdrive 0.1.0"},
                                          {"source_mesh", std::filesystem::path(m.mesh).filename().string()},
                                          {"up", opt.up},
                                          {"front", opt.front},
                                          {"scale_to_metres", c.scale}}});
  SaveAsset(a, out, /*overwrite=*/false);
  return LoadAsset(out);
}

// A scenario with the demo's settings and `cones` traffic cones (random yaw), `barriers` barriers and `cars` cars
// (aligned with the lane), all requested between dmin and dmax ahead and within +-lat.
inline Scenario ScenarioWithObjects(const Scenario& demo, int cones, int barriers, int cars, double dmin, double dmax,
                                    double lat) {
  Scenario s = demo;
  s.objects.clear();
  auto add = [&](const char* category, int count, ObjectRequest::Yaw yaw) {
    if (count <= 0) return;
    ObjectRequest r;
    r.category = category;
    r.count = count;
    r.distance_min = dmin;
    r.distance_max = dmax;
    r.lateral_min = -lat;
    r.lateral_max = lat;
    r.yaw_mode = yaw;
    s.objects.push_back(r);
  };
  add("traffic_cone", cones, ObjectRequest::Yaw::kRandom);
  add("barrier", barriers, ObjectRequest::Yaw::kAligned);
  add("car", cars, ObjectRequest::Yaw::kAligned);
  return s;
}

// The repo keyframe (nuScenes scene-0061), the demo's scenario and its three assets imported into a temp folder that
// goes with it: where the benchmarks of one keyframe's objects (bench_sky_filter, bench_road_shade) start.
struct DemoKeyframe {
  std::filesystem::path root, tmp;
  std::vector<Asset> assets;
  Log log;
  Scenario demo;

  DemoKeyframe(const std::filesystem::path& repo_root, const std::string& name)
      : root(repo_root),
        tmp(std::filesystem::temp_directory_path() / ("synthdrive-" + name + "-" + std::to_string(::getpid()))) {
    const std::filesystem::path data = root / "data";
    for (const DemoMesh& m : DemoMeshes()) assets.push_back(ImportDemoAsset(data, m, tmp / m.id));
    log = OpenLog(data / "driving/nuscenes-scene0061-kf0/mmdet3d_info/n015-2018-07-24-11-22-45+0800.json");
    demo = ReadScenario(data / "scenarios/demo.json");
  }
  ~DemoKeyframe() {
    std::error_code ec;
    std::filesystem::remove_all(tmp, ec);
  }
  DemoKeyframe(const DemoKeyframe&) = delete;
  DemoKeyframe& operator=(const DemoKeyframe&) = delete;
};

// `panels` crops of `rect` ({x0, y0, x1, y1}) side by side, each enlarged `zoom` times (nearest), 4 white pixels
// apart, written as sRGB to `path`; `linear(panel, x, y, channel)` is the linear value at image pixel (x, y).
inline void WriteZoomedStrip(int panels, const std::array<int, 4>& rect, int zoom, const std::filesystem::path& path,
                             const std::function<float(int, int, int, int)>& linear) {
  const int w = rect[2] - rect[0], h = rect[3] - rect[1], gap = 4;
  ImageU8 strip(panels * w * zoom + (panels - 1) * gap, h * zoom, 3, 255);
  for (int i = 0; i < panels; ++i)
    for (int y = 0; y < h * zoom; ++y)
      for (int x = 0; x < w * zoom; ++x)
        for (int c = 0; c < 3; ++c)
          strip.at(i * (w * zoom + gap) + x, y, c) = static_cast<uint8_t>(std::clamp(
              LinearToSrgb(linear(i, rect[0] + x / zoom, rect[1] + y / zoom, c)) * 255.0f + 0.5f, 0.0f, 255.0f));
  WriteImage(path, strip);
}

// Wall-clock seconds `f` takes.
inline double Seconds(const std::function<void()>& f) {
  const auto t0 = std::chrono::steady_clock::now();
  f();
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

}  // namespace sd::bench
