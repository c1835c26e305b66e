#include <iostream>
#include <sstream>

#include <CLI/CLI.hpp>

#include "cli/commands.h"
#include "core/error.h"
#include "core/log.h"
#include "core/shard.h"
#include "datasets/format.h"
#include "synth/batch.h"

namespace sd::cli {

Runner AddSynthCommand(CLI::App& app) {
  auto req = std::make_shared<SynthRequest>();
  auto format = std::make_shared<std::string>();
  auto data_root = std::make_shared<std::string>();
  auto symlink = std::make_shared<bool>(false);
  auto shard = std::make_shared<std::string>();
  auto merge = std::make_shared<bool>(false);
  auto dry_run = std::make_shared<bool>(false);
  auto no_lidar_realism = std::make_shared<bool>(false);
  auto light = std::make_shared<std::string>("environment");
  auto occlusion = std::make_shared<std::string>("dense");
  auto camera_look = std::make_shared<std::string>("blur,noise,jpeg,colour");
  auto detect_objects = std::make_shared<std::string>("unannotated");
  app.add_option("--log", req->log, "Driving log: a dataset root (nuScenes tables, KITTI, a PandaSet sequence) or an info file (mmdet3d .pkl or .json)")
      ->required();
  app.add_option("--asset", req->assets,
                 "Asset folder(s) to insert (asset.json + mesh.glb); see `synthdrive asset import`. Optional when the "
                 "scenario names assets_from_bank");
  app.add_option("--scenario", req->scenario, "Scenario JSON: which objects, how many, where, seed (README)")->required();
  app.add_option("--out", req->out, "Output directory for the derivative dataset (must not exist unless --overwrite)")
      ->required();
  app.add_option("--frame", req->options.frames, "Frame token(s) or index(es) to synthesise (default: all)");
  std::string format_words;
  for (const std::string& w : LogFormatOptions()) format_words += (format_words.empty() ? "" : ", ") + w;
  app.add_option("--format", *format, "Force the log reader: " + format_words + " (default: probe)")
      ->check(CLI::IsMember(LogFormatOptions()));
  app.add_option("--data-root", *data_root, "Directory the log's relative sensor paths resolve against (default: probe)");
  app.add_option("--spp", req->options.samples_per_pixel, "Camera samples per pixel (anti-aliasing)")->check(CLI::Range(1, 64));
  app.add_option("--ao-samples", req->options.ao_samples, "Sky-visibility rays per pixel of the objects (per sub-sample with --sky-filter-radius 0 or --light road) and per pixel of their shadows on the road")->check(CLI::Range(1, 256));
  app.add_option("--sky-filter-radius", req->options.sky_filter_radius, "Radius in pixels of the filter that denoises the objects' sky, shared by a pixel's sub-samples; 0: each sub-sample traces its own --ao-samples rays, unfiltered (slower, the reference)")->check(CLI::Range(0, 8));
  app.add_option("--jpeg-quality", req->options.write.jpeg_quality, "Quality of re-encoded JPEG images")->check(CLI::Range(1, 100));
  app.add_flag("--symlink-unchanged", *symlink, "Symlink unchanged sensor files instead of copying them");
  app.add_flag("--overwrite", req->options.overwrite, "Replace an existing output directory (only once the new one is complete)");
  auto* shard_opt = app.add_option("--shard", *shard,
                                   "Synthesise only frames K, K+N, ... of the selection (K/N, 0-based) into parts under "
                                   "<out>.parts/ (resumable); then --merge");
  app.add_flag("--merge", *merge, "Write <out> from the parts the --shard runs left in <out>.parts/ (same arguments)")
      ->excludes(shard_opt);
  app.add_flag("--dry-run", *dry_run,
               "Plan only: place the scenario's objects once for the selected frames (world-fixed, "
               "docs/sequence_placement.md), write <out>/plan.json and plan.html, render nothing; needs no sensor files");
  app.add_flag("--coco", req->options.coco, "Also write coco_2d.json (COCO 2D boxes of the edited frames) into <out>");
  app.add_flag("--no-lidar-realism", *no_lidar_realism,
               "Insert into the LiDAR sweep with the ideal sensor (no model fitted from the sweep: no range noise, "
               "dropout, fitted intensity or rolling shutter; docs/lidar.md): the output synth wrote before realism");
  app.add_option("--light", *light,
                 "Light on the objects: environment (HDR map stitched from the frame's cameras, soft shadows; "
                 "docs/lighting.md) or road (one sun and sky per camera from the road; faster)")
      ->check(CLI::IsMember({"environment", "road"}));
  app.add_option("--occlusion", *occlusion,
                 "Hiding objects behind real geometry: dense (edge-aware depth from the sweep, matted edges; "
                 "docs/occlusion.md) or sparse (per LiDAR ring)")
      ->check(CLI::IsMember({"dense", "sparse"}));
  app.add_option("--harmonizer", req->options.harmonizer,
                 "Colour harmonisation after compositing: none, classical, auto (the installed learned model, else "
                 "classical) or a TorchScript file (docs/models.md)");
  app.add_option("--camera-look", *camera_look,
                 "What of each camera's own look the inserted pixels get, estimated from its image (docs/camera_look.md): "
                 "a comma list of blur (its edge rise), noise (its signal-dependent noise), jpeg (its JPEG quality), "
                 "colour (no more saturated than its real objects of the category), or none");
  app.add_option("--detect-objects", *detect_objects,
                 "Keep-out tracks detected and tracked from the LiDAR (docs/detection.md), which placement and sequence "
                 "planning avoid like annotated tracks and which are never written as labels: unannotated (frames "
                 "whose log carries no boxes), always (every frame, added to the annotations) or off")
      ->check(CLI::IsMember({"off", "unannotated", "always"}));
  return [=]() {
    SynthRequest r = *req;
    r.detect_objects = DetectObjectsModeFromString(*detect_objects);
    r.options.lidar_realism = !*no_lidar_realism;
    r.options.light = *light == "road" ? SynthOptions::Light::kRoad : SynthOptions::Light::kEnvironment;
    r.options.dense_occlusion = *occlusion == "dense";
    r.options.camera_look = CameraLookOptions{false, false, false, false};
    if (*camera_look != "none") {
      std::stringstream words(*camera_look);
      for (std::string w; std::getline(words, w, ',');) {
        if (w == "blur") r.options.camera_look.blur = true;
        else if (w == "noise") r.options.camera_look.noise = true;
        else if (w == "jpeg") r.options.camera_look.jpeg = true;
        else if (w == "colour") r.options.camera_look.colour = true;
        else throw InputError({}, "--camera-look: unknown '" + w + "' (give blur, noise, jpeg, colour as a comma list, or none)");
      }
    }
    if (!format->empty()) r.log_options.format = LogFormatFromOption(*format);
    if (!data_root->empty()) r.log_options.data_root = *data_root;
    if (*symlink) r.options.write.unchanged = UnchangedFiles::kSymlink;
    if (*dry_run) {
      // Checked here rather than with CLI11's excludes so the message is the usual one line naming the output.
      if (*merge || !shard->empty() || r.options.coco)
        throw InputError(r.out, "--dry-run writes a plan, not a dataset: it cannot be combined with --merge, --shard or --coco");
      const DryRunSummary s = RunSynthDryRun(r);
      for (const std::string& line : s.lines) std::cout << line << '\n';
      std::cout << s.objects << " object(s) planned -> " << (s.out / "plan.json").string() << ", "
                << (s.out / "plan.html").string() << std::endl;
      return 0;
    }
    if (!shard->empty()) {
      const SynthShardSummary s = RunSynthShard(r, ParseShard(*shard));
      SD_LOG(Info, "shard " << *shard << ": " << s.owned << " frame(s), " << s.done << " synthesised, " << s.skipped
                            << " already done, " << s.failed.size() << " failed -> " << s.parts.string() << " (log: "
                            << s.run_log.filename().string() << ")");
      return s.failed.empty() ? 0 : 1;
    }
    const SynthSummary s = *merge ? MergeSynthParts(r) : RunSynth(r);
    SD_LOG(Info, "wrote " << s.frames << " frame(s) with " << s.objects << " inserted object(s) to " << s.out.string());
    SD_LOG(Info, "report: " << s.report.string());
    return 0;
  };
}

}  // namespace sd::cli
