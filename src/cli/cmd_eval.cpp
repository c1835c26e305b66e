// `synthdrive eval <what>`: quality figures against ground truth. `geometry` compares two meshes' shapes,
// `texture` their appearance at held-out views, `realism` a synth output's inserted objects with the real objects
// of the same images.
#include <cstdio>
#include <filesystem>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "assetgen/texture_eval.h"
#include "cli/commands.h"
#include "cli/mesh_files.h"
#include "core/log.h"
#include "geometry/metrics.h"
#include "io/files.h"
#include "io/json.h"
#include "synth/realism.h"

namespace sd::cli {

Runner AddEvalCommand(CLI::App& app) {
  app.require_subcommand(1);
  struct Args {
    std::string pred, gt, out;
    bool overwrite = false;
    geometry::GeometryMetricsOptions options;
  };
  auto a = std::make_shared<Args>();
  CLI::App* geo = app.add_subcommand("geometry", "Chamfer distance, F-score, volume IoU and normal consistency of a mesh against ground truth");
  geo->add_option("--pred", a->pred, "Predicted mesh (.glb/.gltf read as z-up assets, .obj as-is)")->required();
  geo->add_option("--gt", a->gt, "Ground-truth mesh, in the same frame")->required();
  geo->add_option("--out", a->out, "Metrics JSON to write (default: <pred>.geometry.json beside the prediction)");
  geo->add_option("--samples", a->options.num_samples, "Surface samples per mesh")->default_val(a->options.num_samples)
      ->check(CLI::Range(100, 10000000));
  geo->add_option("--tau", a->options.fscore_threshold, "F-score threshold, in units of the GT's longest side")
      ->default_val(a->options.fscore_threshold)->check(CLI::PositiveNumber);
  geo->add_option("--iou-resolution", a->options.iou_resolution, "Voxels along the longest side for volume IoU")
      ->default_val(a->options.iou_resolution)->check(CLI::Range(8, 1024));
  geo->add_option("--seed", a->options.seed, "Sampling seed")->default_val(a->options.seed);
  geo->add_flag("--overwrite", a->overwrite, "Replace an existing metrics file");

  struct TexArgs {
    std::string pred, gt, out;
    int size = 320;
    bool overwrite = false;
  };
  auto t = std::make_shared<TexArgs>();
  CLI::App* tex = app.add_subcommand("texture", "PSNR and SSIM of a textured mesh against ground truth at 8 held-out views");
  tex->add_option("--pred", t->pred, "Predicted textured mesh (.glb/.gltf read as z-up assets, .obj as-is)")->required();
  tex->add_option("--gt", t->gt, "Ground-truth textured mesh, in the same frame")->required();
  tex->add_option("--out", t->out, "Metrics JSON to write (default: <pred>.texture.json beside the prediction)");
  tex->add_option("--size", t->size, "Image size of the held-out views")->default_val(320)->check(CLI::Range(32, 4096));
  tex->add_flag("--overwrite", t->overwrite, "Replace an existing metrics file");

  struct RealismArgs {
    std::string synth, out;
    bool overwrite = false;
  };
  auto rz = std::make_shared<RealismArgs>();
  CLI::App* realism = app.add_subcommand(
      "realism", "Inserted objects against the real objects of the same images: noise, edge rise, saturation (synth/realism.h)");
  realism->add_option("--synth", rz->synth, "A `synthdrive synth` output folder (its synth.json names the original log)")->required();
  realism->add_option("--out", rz->out, "Figures JSON to write (default: <synth>.realism.json beside the folder)");
  realism->add_flag("--overwrite", rz->overwrite, "Replace an existing figures file");

  return [a, t, tex, rz, realism]() {
    if (realism->parsed()) {
      std::filesystem::path dir = std::filesystem::absolute(rz->synth).lexically_normal();
      if (dir.filename().empty()) dir = dir.parent_path();
      std::filesystem::path out = rz->out.empty() ? dir.parent_path() / (dir.filename().string() + ".realism.json")
                                                  : std::filesystem::path(rz->out);
      RefuseOutputOverInputs(out, {dir});
      RefuseExisting(out, rz->overwrite);
      const RealismReport report = EvaluateRealism(dir);
      std::printf("%-14s %5s %5s | %-22s | %-22s | %-22s\n", "category", "real", "ins", "noise real/ins (ratio)",
                  "edge rise px (ratio)", "saturation (ratio)");
      auto cell = [](double real, double ins) {
        char buf[64];
        if (real > 0 && ins > 0) std::snprintf(buf, sizeof buf, "%5.2f/%5.2f (%4.2f)", real, ins, ins / real);
        else std::snprintf(buf, sizeof buf, "%5.2f/%5.2f (  - )", real, ins);
        return std::string(buf);
      };
      for (const RealismSummary& s : report.summaries) {
        const LookComparison& c = s.comparison;
        std::printf("%-14s %5d %5d | %-22s | %-22s | %-22s\n", s.category.empty() ? "all" : s.category.c_str(), c.real, c.inserted,
                    cell(c.real_noise, c.inserted_noise).c_str(), cell(c.real_edge_rise, c.inserted_edge_rise).c_str(),
                    cell(c.real_saturation, c.inserted_saturation).c_str());
      }
      const TwoSampleTest& t = report.classifier;
      if (t.folds > 0)
        std::printf("real-vs-inserted classifier (noise, edge rise, saturation; %d-fold): balanced accuracy %.2f "
                    "(0.5 = chance) over %d real and %d inserted\n", t.folds, t.balanced_accuracy, t.real, t.inserted);
      else
        std::printf("real-vs-inserted classifier: fewer than two objects in a class (%d real, %d inserted)\n", t.real, t.inserted);
      const ShadowComparison& sh = report.shadow;
      if (sh.real > 0 || sh.inserted > 0)
        std::printf("cast shadows (road darkening, lit/shadow, 1 = none): real median %.2f over %d objects, inserted %.2f "
                    "over %d\n", sh.real_contrast, sh.real, sh.inserted_contrast, sh.inserted);
      else
        std::printf("cast shadows: no object with enough visible road around it (or synth.json without the frames' sun)\n");
      for (const ContactComparison& c : report.contact)
        if (c.real > 0 || c.inserted > 0)
          std::printf("contact darkening %s(road 0.6-1 m / 3-20 cm from the footprint, 1 = none): real median %.2f over %d "
                      "objects, inserted %.2f over %d\n", c.category.empty() ? "" : (c.category + " ").c_str(),
                      c.real_darkening, c.real, c.inserted_darkening, c.inserted);
      nlohmann::json j = report.ToJson();
      j["synth"] = dir.string();
      WriteJsonFile(out, j);
      SD_LOG(Info, "wrote " << out.string());
      return 0;
    }
    if (tex->parsed()) {
      std::filesystem::path out = t->out;
      if (out.empty()) out = std::filesystem::path(t->pred).replace_extension(".texture.json");
      RefuseOutputOverInputs(out, {t->pred, t->gt});
      RefuseExisting(out, t->overwrite);
      const TriangleMesh pred = ReadMeshFile(t->pred);
      const TriangleMesh gt = ReadMeshFile(t->gt);
      const TextureMetrics m = CompareTextures(pred, gt, t->size);
      const std::string protocol = DescribeTextureProtocol();
      std::printf("protocol: %s\n\n%-8s %10s %8s\n", protocol.c_str(), "view", "PSNR dB", "SSIM");
      for (size_t i = 0; i < m.psnr_per_view.size(); ++i)
        std::printf("%-8zu %10.2f %8.4f\n", i, m.psnr_per_view[i], m.ssim_per_view[i]);
      std::printf("%-8s %10.2f %8.4f\n", "all", m.psnr, m.ssim);
      WriteJsonFile(out, {{"pred", t->pred}, {"gt", t->gt}, {"protocol", protocol}, {"size", t->size}, {"psnr", m.psnr},
                          {"ssim", m.ssim}, {"psnr_per_view", m.psnr_per_view}, {"ssim_per_view", m.ssim_per_view}});
      SD_LOG(Info, "wrote " << out.string());
      return 0;
    }
    std::filesystem::path out = a->out;
    if (out.empty()) out = std::filesystem::path(a->pred).replace_extension(".geometry.json");
    RefuseOutputOverInputs(out, {a->pred, a->gt});
    RefuseExisting(out, a->overwrite);
    const TriangleMesh pred = ReadMeshFile(a->pred);
    const TriangleMesh gt = ReadMeshFile(a->gt);
    const geometry::GeometryMetrics m = geometry::CompareMeshes(pred, gt, a->options);
    const std::string protocol = geometry::DescribeProtocol(a->options);
    std::printf("protocol: %s\n\n", protocol.c_str());
    std::printf("%-20s %10s\n", "metric", "value");
    std::printf("%-20s %10.5f\n", "chamfer", m.chamfer);
    std::printf("%-20s %10.4f\n", "fscore", m.fscore);
    std::printf("%-20s %10.4f\n", "precision", m.precision);
    std::printf("%-20s %10.4f\n", "recall", m.recall);
    std::printf("%-20s %10.4f\n", "volume_iou", m.volume_iou);
    std::printf("%-20s %10.4f\n", "normal_consistency", m.normal_consistency);
    WriteJsonFile(out, {{"pred", a->pred},
                        {"gt", a->gt},
                        {"protocol", protocol},
                        {"options", {{"samples", a->options.num_samples}, {"tau", a->options.fscore_threshold},
                                     {"iou_resolution", a->options.iou_resolution}, {"seed", a->options.seed}}},
                        {"chamfer", m.chamfer},
                        {"fscore", m.fscore},
                        {"precision", m.precision},
                        {"recall", m.recall},
                        {"volume_iou", m.volume_iou},
                        {"normal_consistency", m.normal_consistency}});
    SD_LOG(Info, "wrote " << out.string());
    return 0;
  };
}

}  // namespace sd::cli
