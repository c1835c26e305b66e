// bench_texture: texture fusion quality and speed on textured real meshes.
//
// For each textured object of ../shared/data/assets (scanned GSO / HOPE / YCB and textured road objects): the
// ground truth is put in its up axis and normalised into the unit sphere, rendered (unlit base colour) at the
// 6 Zero123++ rig views at 320x320, and those colour views are fused onto
//   (a) the ground-truth geometry, and
//   (b) the refined mesh (visual hull of the rig masks + RefineMesh with defaults, as bench_refine),
// as per-vertex colours (the paper's fusion) and as a baked UV atlas (1024²). Each result is compared with the
// ground truth at the 8 held-out views of texture_eval.h (PSNR / SSIM inside the GT silhouette). Seconds are
// wall time of the fusion and of atlas + bake (median of --repeats runs). Objects whose textures are missing
// are skipped with the reason.
//
// Super-resolution (--sr, a list): each listed upscaler turns the 6 views into 640x640 ones (cameras at the new
// resolution) before fusion — "none" fuses the 320x320 views as rendered, "bicubic" is the classical path, and
// model names are installed TorchScript models (models/super_resolution.h; scripts/fetch_models.sh). Upscaling
// seconds (all 6 views) are reported on their own, not inside the fusion times.
//
// Usage: bench_texture [--objects name,...] [--repeats N] [--texture-size N] [--no-refined]
//                      [--sr none,bicubic,esrgan-slim,esrgan-medium] [--view-size N]
// --view-size renders the rig views smaller than 320 (e.g. 160: views softer than the held-out renders, the
// case super-resolution is for).
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "assetgen/canonical.h"
#include "assetgen/refine.h"
#include "assetgen/texture.h"
#include "assetgen/texture_eval.h"
#include "assetgen/uv_atlas.h"
#include "assetgen/views.h"
#include "core/error.h"
#include "io/json.h"
#include "io/mesh_io.h"
#include "models/super_resolution.h"

#include "bench_objects.h"

namespace {

namespace fs = std::filesystem;
using namespace sd;

double Median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v.empty() ? 0 : v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
}

template <typename F>
double Seconds(F&& f) {
  const auto t0 = std::chrono::steady_clock::now();
  f();
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
}

struct Variant {
  std::string geometry, method, sr = "none";
  TextureMetrics metrics;
  double seconds = 0, sr_seconds = 0;
};

// The views each --sr choice fuses, with the median seconds its upscaling of all views took.
struct UpscaledViews {
  std::string name;
  ColorViewSet views;
  double seconds = 0;
};

std::vector<UpscaledViews> Upscale(const ColorViewSet& views, const std::vector<std::string>& choices, int repeats) {
  std::vector<UpscaledViews> out;
  for (const std::string& choice : choices) {
    if (choice == "none") {
      out.push_back({choice, views, 0});
      continue;
    }
    const models::Upscaler upscaler = models::Upscaler::Resolve(choice, 2);
    UpscaledViews u{choice, {}, 0};
    std::vector<double> times;
    for (int r = 0; r < repeats; ++r) times.push_back(Seconds([&] { u.views = SuperResolveViews(views, upscaler); }));
    u.seconds = Median(times);
    out.push_back(std::move(u));
  }
  return out;
}

// Fuses the views onto `mesh` both ways and scores each against the ground truth.
std::vector<Variant> FuseAndScore(const std::string& geometry, const TriangleMesh& mesh, const TriangleMesh& gt,
                                  const ColorViewSet& views, int texture_size, int repeats) {
  std::vector<Variant> out;
  TriangleMesh plain;
  plain.positions = mesh.positions;
  plain.faces = mesh.faces;

  TriangleMesh vertex_coloured = plain;
  std::vector<double> times;
  for (int r = 0; r < repeats; ++r) {
    times.push_back(Seconds([&] {
      const VertexFusionResult fused = FuseVertexColors(plain, views);
      vertex_coloured.colors.resize(plain.NumVertices());
      for (size_t v = 0; v < plain.NumVertices(); ++v) vertex_coloured.colors[v] << fused.colors[v], 1.0f;
    }));
  }
  out.push_back({geometry, "vertex", "none", CompareTextures(vertex_coloured, gt), Median(times), 0});

  TriangleMesh baked;
  times.clear();
  for (int r = 0; r < repeats; ++r) {
    times.push_back(Seconds([&] {
      UvAtlasOptions options;
      options.texture_size = texture_size;
      baked = BuildUvAtlas(plain, options);
      Material m;
      m.base_color_texture = std::make_shared<ImageU8>(BakeTexture(baked, views, texture_size));
      baked.materials = {m};
    }));
  }
  out.push_back({geometry, "uv bake", "none", CompareTextures(baked, gt), Median(times), 0});
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<std::string> only;
  int repeats = 1, texture_size = 1024, view_size = 320;
  bool refined = true;
  std::vector<std::string> sr_choices{"none", "bicubic", "esrgan-slim", "esrgan-medium"};
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "bench_texture: %s needs a value\n", a.c_str());
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "--objects") {
      std::stringstream ss(next());
      for (std::string item; std::getline(ss, item, ',');) only.push_back(item);
    } else if (a == "--repeats") {
      repeats = std::max(1, std::atoi(next().c_str()));
    } else if (a == "--texture-size") {
      texture_size = std::atoi(next().c_str());
    } else if (a == "--view-size") {
      view_size = std::atoi(next().c_str());
    } else if (a == "--sr") {
      sr_choices.clear();
      std::stringstream ss(next());
      for (std::string item; std::getline(ss, item, ',');) sr_choices.push_back(item);
    } else if (a == "--no-refined") {
      refined = false;
    } else {
      std::fprintf(stderr, "bench_texture: unknown argument %s\n", a.c_str());
      return 2;
    }
  }
  const char* env = std::getenv("SYNTHDRIVE_SOURCE_DIR");
  const fs::path root = env ? fs::path(env) : fs::weakly_canonical(fs::path(argv[0])).parent_path().parent_path().parent_path();
  const fs::path assets = root / ".." / "shared" / "data" / "assets";
  if (!fs::exists(assets)) {
    std::fprintf(stderr, "bench_texture: %s not found (the benchmark needs ../shared/data beside the repo)\n", assets.c_str());
    return 2;
  }
  std::vector<bench::BenchObject> objects = bench::Objects();
  objects.push_back({"cesium_milk_truck", "road", "truck/cesium_milk_truck/obj/cesium_milk_truck.obj", "+y"});
  objects.push_back({"torcs_155_dtm", "road", "car/torcs_155_dtm/obj/torcs_155_dtm.obj", "+y"});

  std::printf("protocol: %s\nviews: 6 Zero123++ rig views, %dx%d, unlit base colour; atlas %d^2\n",
              DescribeTextureProtocol().c_str(), view_size, view_size, texture_size);
  for (const std::string& choice : sr_choices)
    if (choice != "none")
      std::printf("super-resolution %s: %s\n", choice.c_str(), models::Upscaler::Resolve(choice, 2).Describe().c_str());
  std::printf("\n%-26s %-8s %-8s %-14s %8s %7s %8s %8s\n", "object", "geometry", "method", "SR", "PSNR dB", "SSIM",
              "seconds", "SR s");
  nlohmann::json results = nlohmann::json::array();
  const std::vector<ViewCamera> rig = Zero123PlusPlusRig(view_size);
  for (const bench::BenchObject& obj : objects) {
    if (!only.empty() && std::find(only.begin(), only.end(), obj.name) == only.end()) continue;
    TriangleMesh gt;
    try {
      gt = LoadMesh(assets / obj.file);
    } catch (const InputError& e) {
      std::printf("%-26s skipped: %s\n", obj.name.c_str(), e.what());
      continue;
    }
    const bool textured = std::any_of(gt.materials.begin(), gt.materials.end(),
                                      [](const Material& m) { return m.base_color_texture != nullptr; });
    if (!textured || gt.uvs.empty()) {
      std::printf("%-26s skipped: no texture\n", obj.name.c_str());
      continue;
    }
    gt.Transform(Rigid3d(AxesToCanonical(obj.up, obj.up == "+z" ? "+x" : "+z"), Eigen::Vector3d::Zero()));
    NormalizeIntoSphere(gt).Apply(&gt);
    const MultiViewSet rendered = RenderOracleViews(gt, rig, 2);
    ColorViewSet views;
    for (const MultiView& v : rendered) views.push_back({v.view, v.color, v.mask});
    const std::vector<UpscaledViews> upscaled = Upscale(views, sr_choices, repeats);

    std::vector<std::pair<std::string, TriangleMesh>> geometries{{"gt", gt}};
    if (refined) {
      RefineOptions ro;
      ro.show_progress = false;
      geometries.emplace_back("refined", RefineMesh(CoarseMeshFromViews(rendered, 96), rendered, ro).mesh);
    }
    std::vector<Variant> variants;
    for (const auto& [geometry, mesh] : geometries)
      for (const UpscaledViews& u : upscaled)
        for (Variant& v : FuseAndScore(geometry, mesh, gt, u.views, texture_size, repeats)) {
          v.sr = u.name;
          v.sr_seconds = u.seconds;
          variants.push_back(v);
        }
    for (const Variant& v : variants) {
      std::printf("%-26s %-8s %-8s %-14s %8.2f %7.4f %8.2f %8.2f\n", obj.name.c_str(), v.geometry.c_str(),
                  v.method.c_str(), v.sr.c_str(), v.metrics.psnr, v.metrics.ssim, v.seconds, v.sr_seconds);
      results.push_back({{"object", obj.name}, {"geometry", v.geometry}, {"method", v.method}, {"psnr", v.metrics.psnr},
                         {"ssim", v.metrics.ssim}, {"seconds", v.seconds}, {"super_resolution", v.sr},
                         {"super_resolution_seconds", v.sr_seconds}});
    }
    std::fflush(stdout);
  }
  const fs::path json_out =
      root / "bench" / "results" / (view_size == 320 ? "texture.json" : "texture_" + std::to_string(view_size) + ".json");
  WriteJsonFile(json_out, {{"protocol", DescribeTextureProtocol()}, {"texture_size", texture_size},
                           {"view_size", view_size}, {"results", results}});
  std::printf("\nwrote %s\n", json_out.c_str());
  return 0;
}
