// synthdrive: one binary, one subcommand per pipeline stage (DESIGN.md).
#include <cstdio>
#include <filesystem>
#include <exception>
#include <map>

#include <CLI/CLI.hpp>

#include "cli/commands.h"
#include "core/device.h"
#include "core/error.h"
#include "core/log.h"
#include "core/parallel.h"

int main(int argc, char** argv) {
  CLI::App app{"SynthDrive: rare-object training data for autonomous-driving perception.\n"
               "Inserts metric 3D assets into real driving logs (camera + LiDAR + labels), in the log's own format."};
  app.require_subcommand(1);
  app.set_version_flag("--version", "synthdrive 0.1.0");
  bool verbose = false, quiet = false;
  int threads = 0;
  app.add_flag("-v,--verbose", verbose, "Print debug details");
  app.add_flag("-q,--quiet", quiet, "Print errors only");
  app.add_option("--threads", threads, "Worker threads (default: all cores)")->check(CLI::NonNegativeNumber);
  std::string device;
  app.add_option("--device", device,
                 "cpu or cuda: where differentiable rendering and the learned models run (default: "
                 "$SYNTHDRIVE_DEVICE, else cpu)")
      ->check(CLI::IsMember({"cpu", "cuda"}));

  std::map<CLI::App*, sd::cli::Runner> runners;
  auto add = [&](const char* name, const char* help, sd::cli::Runner (*factory)(CLI::App&)) {
    CLI::App* sub = app.add_subcommand(name, help);
    runners[sub] = factory(*sub);
  };
  add("synth", "Insert assets into a driving log (camera, LiDAR, labels) and write a derivative dataset",
      sd::cli::AddSynthCommand);
  add("mine", "Find object images for a prompt in driving logs, image folders and URL lists (index, query)",
      sd::cli::AddMineCommand);
  add("bank", "The asset catalogue: add, list, query, show, verify, remove", sd::cli::AddBankCommand);
  add("slurm", "Run a batch command's shards as a Slurm job array (submit, status)", sd::cli::AddSlurmCommand);
  add("asset", "Make and inspect asset folders (asset.json + mesh.glb + preview.png)", sd::cli::AddAssetCommand);
  add("views", "Render oracle normal maps and masks of a mesh at the Zero123++ rig (for refinement and evaluation)",
      sd::cli::AddViewsCommand);
  add("refine", "Refine a coarse mesh against multi-view normal maps and silhouettes (differentiable rendering)",
      sd::cli::AddRefineCommand);
  add("texture", "Fuse colour views onto a mesh: a baked UV texture atlas or per-vertex colours", sd::cli::AddTextureCommand);
  add("generate", "Build a textured, metric asset folder from object views (or one image, with the learned models)",
      sd::cli::AddGenerateCommand);
  add("upscale", "Super-resolve images (learned ESRGAN through LibTorch when installed, else bicubic)",
      sd::cli::AddUpscaleCommand);
  add("eval", "Quality figures against ground truth (geometry, texture)", sd::cli::AddEvalCommand);
  add("demo", "Run the pipeline end to end on the sample data in data/ and write a report", sd::cli::AddDemoCommand);
  add("categories", "List the object categories and their names in each dataset format", sd::cli::AddCategoriesCommand);

  try {
    app.parse(argc, argv);
  } catch (const CLI::ParseError& e) {
    // --help and --version are not errors; any other refused argument is status 2, as every refused input is.
    const int status = app.exit(e);
    return status == 0 ? 0 : 2;
  }
  sd::SetLogLevel(quiet ? sd::LogLevel::kError : verbose ? sd::LogLevel::kDebug : sd::LogLevel::kInfo);
  if (threads > 0) sd::SetMaxThreads(threads);
  try {
    if (!device.empty()) sd::SetDevice(sd::ParseDevice(device));
    for (auto& [sub, run] : runners)
      if (sub->parsed()) return run();
  } catch (const sd::InputError& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 2;
  } catch (const std::filesystem::filesystem_error& e) {
    // The file system refused a path the user gave or a file named one (a symlink loop, a permission): said as
    // an input error, the path first, without the library's "filesystem error: status:" prefix.
    std::fprintf(stderr, "error: %s: %s\n", e.path1().string().c_str(), e.code().message().c_str());
    return 2;
  } catch (const std::exception& e) {
    std::fprintf(stderr, "error: %s\n", e.what());
    return 1;
  }
  return 0;
}
