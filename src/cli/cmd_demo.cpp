#include <unistd.h>

#include <cstdlib>
#include <filesystem>

#include <CLI/CLI.hpp>

#include "cli/commands.h"
#include "cli/import.h"
#include "core/error.h"
#include "core/log.h"
#include "io/files.h"
#include "mining/index.h"
#include "mining/query.h"
#include "synth/pipeline.h"

namespace sd::cli {
namespace fs = std::filesystem;

std::string FindDataDir(const std::string& explicit_dir) {
  std::vector<fs::path> candidates;
  if (!explicit_dir.empty()) return explicit_dir;
  if (const char* env = std::getenv("SYNTHDRIVE_DATA")) candidates.emplace_back(env);
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (!ec) candidates.push_back(exe.parent_path() / ".." / ".." / "data");
  candidates.emplace_back("data");
  for (const auto& c : candidates)
    if (fs::exists(c / "driving") && fs::exists(c / "assets")) return fs::canonical(c).string();
  throw InputError("", "cannot find the sample data directory (data/); pass --data");
}

Runner AddDemoCommand(CLI::App& app) {
  auto data = std::make_shared<std::string>();
  auto out = std::make_shared<std::string>("out/demo");
  auto overwrite = std::make_shared<bool>(false);
  auto spp = std::make_shared<int>(4);
  app.add_option("--data", *data, "The sample data directory (default: the repo's data/)");
  app.add_option("--out", *out, "Output directory")->capture_default_str();
  app.add_option("--spp", *spp, "Camera samples per pixel")->check(CLI::Range(1, 64));
  app.add_flag("--overwrite", *overwrite, "Replace an existing output directory");
  return [=]() {
    const fs::path data_dir = FindDataDir(*data);
    RefuseOutputOverInputs(*out, {data_dir});
    StagingDirectory staging(*out, *overwrite);

    // 0. Mining: index the shipped logs' objects (crops, LiDAR masks, quality figures) and find the demo's
    // categories by label (no CLIP weights ship with the repo); the contact sheet shows what was found. Turning
    // those crops into assets needs the multi-view models (generate --manifest), so the assets below come from
    // the shipped meshes.
    mining::IndexBuildOptions mine;
    mine.sources = {{mining::SourceKind::kLog,
                     data_dir / "driving/nuscenes-scene0061-kf0/mmdet3d_info/n015-2018-07-24-11-22-45+0800.json"},
                    {mining::SourceKind::kLog, data_dir / "driving/kitti-object"}};
    mine.progress = false;
    const mining::IndexBuildReport mined = mining::BuildIndex(staging.path() / "mine" / "index", mine);
    const mining::MiningIndex index = mining::MiningIndex::Open(staging.path() / "mine" / "index");
    mining::QueryOptions query;
    query.prompts = {"traffic cone", "barrier", "car"};
    query.k = 8;
    query.min_size_px = 12;
    const std::vector<mining::PromptResult> hits = mining::RunQuery(index, query);
    mining::WriteMiningRun(staging.path() / "mine" / "run", index, hits, query, false);
    SD_LOG(Info, "mining: " << mined.items << " object crops from 2 logs; hits: " << hits[0].hits.size()
                            << " traffic cone, " << hits[1].hits.size() << " barrier, " << hits[2].hits.size()
                            << " car (label mode)");

    // 1. Assets: the shipped meshes become canonical, metric asset folders.
    // Axes and units checked against the files (data/README.md): all three are y-up. The cone is modelled at
    // 0.29 file units tall, so it is scaled to a 0.7 m road cone; the barricade (a Type III with lamps, 2.2 m)
    // and the car are in metres. The barricade's panels face along the file's z axis, its front.
    struct Source { const char* mesh; const char* id; const char* category; const char* up; const char* front; double scale, height; };
    const Source sources[] = {
        {"assets/metadrive_traffic_cone/scene.gltf", "metadrive_traffic_cone", "traffic_cone", "+y", "+x", 0, 0.70},
        {"assets/metadrive_road_barrier/scene.gltf", "metadrive_road_barrier", "barrier", "+y", "+z", 1.0, 0},
        {"assets/torcs_p406/obj/torcs_p406.obj", "torcs_p406", "car", "+y", "+x", 1.0, 0},
    };
    std::vector<fs::path> assets;
    for (const auto& s : sources) {
      ImportRequest r;
      r.mesh = data_dir / s.mesh;
      r.out = staging.path() / "assets" / s.id;
      r.id = s.id;
      r.category = s.category;
      r.canonical.up = s.up;
      r.canonical.front = s.front;
      r.canonical.scale = s.scale;
      if (s.height > 0) r.height = s.height;
      r.source = std::string("data/") + s.mesh;
      r.licence = "see data/README.md";
      const Asset a = ImportAsset(r);
      SD_LOG(Info, "asset " << a.info.id << ": " << a.info.extent.x() << " x " << a.info.extent.y() << " x "
                            << a.info.extent.z() << " m");
      assets.push_back(r.out);
    }

    // 2. Synthesis into the nuScenes keyframe.
    SynthRequest req;
    req.log = data_dir / "driving/nuscenes-scene0061-kf0/mmdet3d_info/n015-2018-07-24-11-22-45+0800.json";
    req.assets = assets;
    req.scenario = data_dir / "scenarios/demo.json";
    req.out = staging.path() / "nuscenes-scene0061-kf0-synth";
    req.options.samples_per_pixel = *spp;
    const SynthSummary s = RunSynth(req);
    staging.Commit();
    const fs::path final_report = staging.final_path() / s.out.filename() / "report.html";
    SD_LOG(Info, "demo: inserted " << s.objects << " objects into " << s.frames << " frame(s)");
    std::printf("report: %s\n", final_report.string().c_str());
    std::printf("mining contact sheet: %s\n", (staging.final_path() / "mine" / "run" / "index.html").string().c_str());
    return 0;
  };
}

}  // namespace sd::cli
