// bench_generate: the generate pipeline end to end (assetgen/generate.h) on the benchmark objects, from oracle
// views, with quality against ground truth, seconds per stage and peak memory.
//
// For each object of bench_objects.h (plus two textured road objects): the ground truth is put in its up axis,
// normalised into the unit sphere and rendered at the 6 Zero123++ rig views (320x320: normals, masks, unlit
// colour). GenerateFromViews then runs every stage with its defaults (visual hull 96^3, refinement, x2
// super-resolution with --sr, UV bake 1024^2, canonical frame). The scale prior is the ground truth's own
// height, so figures stay in units of the object's bounding-sphere radius (as bench_refine) and measure the
// pipeline rather than a size prior. The ground truth is mapped into the asset's frame with the asset's own
// views_to_asset transform and compared: Chamfer / F-score / volume IoU (geometry/metrics.h protocol) and
// PSNR / SSIM at 8 held-out views (texture_eval.h protocol; textured objects only). Peak memory is the
// process's peak resident set after the object (it only grows).
//
// Usage: bench_generate [--objects a,b] [--sr auto|none|bicubic|esrgan-slim|esrgan-medium] [--steps N]
//                       [--device cpu|cuda]
#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "assetgen/canonical.h"
#include "assetgen/generate.h"
#include "assetgen/texture_eval.h"
#include "assetgen/views.h"
#include "core/device.h"
#include "core/error.h"
#include "core/log.h"
#include "geometry/metrics.h"
#include "io/json.h"
#include "raster/raster.h"
#include "io/mesh_io.h"

#include "bench_objects.h"

namespace {

namespace fs = std::filesystem;
using namespace sd;

double PeakResidentMegabytes() {
  std::ifstream status("/proc/self/status");
  for (std::string line; std::getline(status, line);)
    if (line.rfind("VmHWM:", 0) == 0) return std::atof(line.c_str() + 6) / 1024.0;
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<std::string> only;
  std::string sr = "auto";
  int steps = RefineOptions{}.steps;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "bench_generate: %s needs a value\n", a.c_str());
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "--objects") {
      std::stringstream ss(next());
      for (std::string item; std::getline(ss, item, ',');) only.push_back(item);
    } else if (a == "--sr") {
      sr = next();
    } else if (a == "--steps") {
      steps = std::max(1, std::atoi(next().c_str()));
    } else if (a == "--device") {
      SetDevice(ParseDevice(next()));
    } else {
      std::fprintf(stderr, "bench_generate: unknown argument %s\n", a.c_str());
      return 2;
    }
  }
  const char* env = std::getenv("SYNTHDRIVE_SOURCE_DIR");
  const fs::path root = env ? fs::path(env) : fs::weakly_canonical(fs::path(argv[0])).parent_path().parent_path().parent_path();
  const fs::path assets = root / ".." / "shared" / "data" / "assets";
  if (!fs::exists(assets)) {
    std::fprintf(stderr, "bench_generate: %s not found (the benchmark needs ../shared/data beside the repo)\n", assets.c_str());
    return 2;
  }
  SetLogLevel(LogLevel::kWarn);
  std::vector<bench::BenchObject> objects = bench::Objects();
  objects.push_back({"cesium_milk_truck", "road", "truck/cesium_milk_truck/obj/cesium_milk_truck.obj", "+y"});
  objects.push_back({"torcs_155_dtm", "road", "car/torcs_155_dtm/obj/torcs_155_dtm.obj", "+y"});

  const geometry::GeometryMetricsOptions metric_options;
  std::printf("device: %s%s\n", ToString(CurrentDevice()),
              CurrentDevice() == Device::kCuda ? (" (" + raster::CudaDeviceDescription() + ")").c_str() : "");
  std::printf("geometry protocol: %s\ntexture protocol: %s\n", geometry::DescribeProtocol(metric_options).c_str(),
              DescribeTextureProtocol().c_str());
  std::printf("views: 6 Zero123++ rig views 320x320 (oracle); refinement %d steps; super-resolution: %s\n\n", steps,
              sr.c_str());
  std::printf("%-26s %8s %6s %6s %7s %6s | %6s %6s %6s %6s %6s %7s %8s\n", "object", "CD", "F", "IoU", "PSNR", "SSIM",
              "hull s", "ref s", "SR s", "tex s", "can s", "total s", "peak MB");
  const std::vector<ViewCamera> rig = Zero123PlusPlusRig(320);
  nlohmann::json results = nlohmann::json::array();
  for (const bench::BenchObject& obj : objects) {
    if (!only.empty() && std::find(only.begin(), only.end(), obj.name) == only.end()) continue;
    TriangleMesh gt;
    bool textured = true;
    try {
      gt = LoadMesh(assets / obj.file);
    } catch (const InputError&) {
      gt = bench::LoadGeometry(assets / obj.file, fs::temp_directory_path());  // texture files missing
      textured = false;
    }
    textured = textured && !gt.uvs.empty() &&
               std::any_of(gt.materials.begin(), gt.materials.end(),
                           [](const Material& m) { return m.base_color_texture != nullptr; });
    gt.Transform(Rigid3d(AxesToCanonical(obj.up, obj.up == "+z" ? "+x" : "+z"), Eigen::Vector3d::Zero()));
    NormalizeIntoSphere(gt).Apply(&gt);
    const MultiViewSet views = RenderOracleViews(gt, rig, 2);

    GenerateOptions options;
    options.refine.steps = steps;
    options.refine.show_progress = false;
    options.upscale = sr;
    options.canonical.up = "+z";
    options.canonical.front = "+x";
    options.canonical.target_height = static_cast<double>(gt.Bounds().Size().z());
    GeneratedMesh g;
    try {
      g = GenerateFromViews(views, options);
    } catch (const InputError& e) {
      std::printf("%-26s failed: %s\n", obj.name.c_str(), e.what());
      continue;
    }
    const TriangleMesh gt_asset = g.ToAssetFrame(gt);
    const geometry::GeometryMetrics m = geometry::CompareMeshes(g.mesh, gt_asset, metric_options);
    TextureMetrics t;
    if (textured) t = CompareTextures(g.mesh, gt_asset);
    std::map<std::string, double> sec;
    double total = 0;
    for (const StageReport& s : g.stages) {
      sec[s.stage] = s.seconds;
      total += s.seconds;
    }
    const double peak = PeakResidentMegabytes();
    std::printf("%-26s %8.5f %6.4f %6.4f %7s %6s | %6.2f %6.2f %6.2f %6.2f %6.2f %7.2f %8.0f\n", obj.name.c_str(),
                m.chamfer, m.fscore, m.volume_iou, textured ? (Msg() << t.psnr).str().substr(0, 6).c_str() : "-",
                textured ? (Msg() << t.ssim).str().substr(0, 6).c_str() : "-", sec["coarse_mesh"], sec["refine"],
                sec["super_resolution"], sec["texture"], sec["canonical"], total, peak);
    std::fflush(stdout);
    nlohmann::json stages = nlohmann::json::object();
    for (const StageReport& s : g.stages) stages[s.stage] = {{"seconds", s.seconds}, {"method", s.method}};
    nlohmann::json row = {{"object", obj.name},        {"chamfer", m.chamfer}, {"fscore", m.fscore},
                          {"volume_iou", m.volume_iou}, {"textured", textured}, {"stages", stages},
                          {"total_seconds", total},     {"peak_rss_mb", peak}};
    if (textured) {
      row["psnr"] = t.psnr;
      row["ssim"] = t.ssim;
    }
    results.push_back(row);
  }
  const fs::path json_out = root / "bench" / "results" / "generate.json";
  WriteJsonFile(json_out, {{"geometry_protocol", geometry::DescribeProtocol(metric_options)},
                           {"texture_protocol", DescribeTextureProtocol()},
                           {"super_resolution", sr},
                           {"results", results}});
  std::printf("\nwrote %s\n", json_out.c_str());
  return 0;
}
