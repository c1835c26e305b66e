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
// are skipped with the reason. Super-resolution of the views is not in this build yet (rows say "none").
//
// Usage: bench_texture [--objects name,...] [--repeats N] [--texture-size N] [--no-refined]
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
  std::string geometry, method;
  TextureMetrics metrics;
  double seconds = 0;
};

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
  out.push_back({geometry, "vertex", CompareTextures(vertex_coloured, gt), Median(times)});

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
  out.push_back({geometry, "uv bake", CompareTextures(baked, gt), Median(times)});
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  std::vector<std::string> only;
  int repeats = 1, texture_size = 1024;
  bool refined = true;
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

  std::printf("protocol: %s\nviews: 6 Zero123++ rig views, 320x320, unlit base colour; atlas %d^2; super-resolution: none\n\n",
              DescribeTextureProtocol().c_str(), texture_size);
  std::printf("%-26s %-8s %-8s %8s %7s %8s\n", "object", "geometry", "method", "PSNR dB", "SSIM", "seconds");
  nlohmann::json results = nlohmann::json::array();
  const std::vector<ViewCamera> rig = Zero123PlusPlusRig(320);
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

    std::vector<Variant> variants = FuseAndScore("gt", gt, gt, views, texture_size, repeats);
    if (refined) {
      RefineOptions ro;
      ro.show_progress = false;
      const TriangleMesh mesh = RefineMesh(CoarseMeshFromViews(rendered, 96), rendered, ro).mesh;
      for (Variant& v : FuseAndScore("refined", mesh, gt, views, texture_size, repeats)) variants.push_back(v);
    }
    for (const Variant& v : variants) {
      std::printf("%-26s %-8s %-8s %8.2f %7.4f %8.2f\n", obj.name.c_str(), v.geometry.c_str(), v.method.c_str(),
                  v.metrics.psnr, v.metrics.ssim, v.seconds);
      results.push_back({{"object", obj.name}, {"geometry", v.geometry}, {"method", v.method}, {"psnr", v.metrics.psnr},
                         {"ssim", v.metrics.ssim}, {"seconds", v.seconds}, {"super_resolution", "none"}});
    }
    std::fflush(stdout);
  }
  const fs::path json_out = root / "bench" / "results" / "texture.json";
  WriteJsonFile(json_out, {{"protocol", DescribeTextureProtocol()}, {"texture_size", texture_size}, {"results", results}});
  std::printf("\nwrote %s\n", json_out.c_str());
  return 0;
}
