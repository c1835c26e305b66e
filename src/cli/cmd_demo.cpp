#include <unistd.h>

#include <cstdlib>
#include <algorithm>
#include <filesystem>
#include <map>

#include <CLI/CLI.hpp>

#include "cli/commands.h"
#include "cli/hit_assets.h"
#include "cli/import.h"
#include "core/error.h"
#include "core/log.h"
#include "assetgen/asset.h"
#include "bank/bank.h"
#include "datasets/categories.h"
#include "io/files.h"
#include "io/image_io.h"
#include "io/json.h"
#include "mining/index.h"
#include "mining/query.h"
#include "synth/batch.h"

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

namespace {

// The repo's real photos of cones (data/images/roadanomaly-cones: Road Anomaly, CC BY-SA, masks by its authors):
// each cone whose mask covers at least 1500 pixels and does not touch the photo's border, largest first.
struct PhotoObject {
  fs::path photo;
  ImageF mask;  // the photo's size
  int id = 0;
  double pixels = 0;
};
std::vector<PhotoObject> ShippedConePhotos(const fs::path& dir, size_t limit) {
  std::vector<PhotoObject> out;
  if (!fs::is_directory(dir / "frames")) return out;
  std::vector<fs::path> photos;
  for (const auto& e : fs::directory_iterator(dir / "frames"))
    if (e.path().extension() == ".jpg") photos.push_back(e.path());
  std::sort(photos.begin(), photos.end());
  for (const fs::path& photo : photos) {
    const fs::path labels = dir / "frames" / (photo.stem().string() + ".labels");
    const nlohmann::json index = ReadJsonFile(labels / "index.json");
    const ImageU8 image = ReadImage(photo, 3);
    for (const auto& inst : index.at("instances")) {
      const int id = inst.at("id").get<int>();
      const int x0 = inst.at("crop_rect")[0][0].get<int>(), y0 = inst.at("crop_rect")[0][1].get<int>();
      char name[64];
      std::snprintf(name, sizeof(name), "instance_%03d_gc_mask.png", id);
      const ImageU8 crop_mask = ReadImage(labels / name, 1);
      PhotoObject o{photo, ImageF(image.width(), image.height(), 1, 0.0f), id, 0};
      bool border = false;
      for (int y = 0; y < crop_mask.height(); ++y)
        for (int x = 0; x < crop_mask.width(); ++x) {
          // The masks hold the labelling tool's GrabCut labels: 1 sure and 3 probable object, 0 and 2 background.
          if (crop_mask.at(x, y) != 1 && crop_mask.at(x, y) != 3) continue;
          const int u = x0 + x, v = y0 + y;
          if (u < 0 || v < 0 || u >= image.width() || v >= image.height()) continue;
          border = border || u == 0 || v == 0 || u == image.width() - 1 || v == image.height() - 1;
          o.mask.at(u, v) = 1.0f;
          o.pixels += 1;
        }
      if (!border && o.pixels >= 1500) out.push_back(std::move(o));
    }
  }
  std::sort(out.begin(), out.end(), [](const PhotoObject& a, const PhotoObject& b) { return a.pixels > b.pixels; });
  if (out.size() > limit) out.resize(limit);
  return out;
}

// Catalogues the asset folders in a new bank behind the default quality gate; with `report`, one line per asset
// with its figures and the gate's verdict. Returns how many of each category went in.
std::map<std::string, int> BankBehindTheGate(const fs::path& bank_path, const std::vector<fs::path>& dirs, bool report) {
  bank::Bank bank = bank::Bank::Open(bank_path, true);
  const bank::QualityGate gate = bank::DefaultQualityGate();
  std::map<std::string, int> banked;
  for (const fs::path& dir : dirs) {
    const AssetInfo info = LoadAsset(dir).info;
    std::string verdict = "banked";
    if (const auto failed = bank::GateFailure(info.quality, gate)) {
      verdict = "refused: " + *failed;
    } else {
      bank.Add(dir);
      ++banked[info.category];
    }
    if (!report) continue;
    const nlohmann::json& q = info.quality;
    auto figure = [&](const char* key) -> std::string {
      return q.contains(key) && q[key].is_number() ? Fixed(q[key].get<double>(), 3) : std::string("-");
    };
    SD_LOG(Info, "demo: " << info.id << " " << info.category << ": real texture " << figure(quality::kRealTextureFraction)
                          << ", by symmetry " << figure("synthetic_texture_fraction") << ", propagated "
                          << figure("propagated_texture_fraction") << ", held-out IoU "
                          << figure(quality::kHeldOutSilhouetteIou) << ", LiDAR p2m "
                          << figure(quality::kLidarPointToMeshMedianM) << " m -> " << verdict);
  }
  return banked;
}

}  // namespace

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
    const fs::path keyframe = data_dir / "driving/nuscenes-scene0061-kf0/mmdet3d_info/n015-2018-07-24-11-22-45+0800.json";

    // 0. Mining: index the shipped logs' objects (crops, LiDAR masks, quality figures) and find the demo's
    // categories by label (no CLIP weights ship with the repo); the contact sheet shows what was found.
    mining::IndexBuildOptions mine;
    mine.sources = {{mining::SourceKind::kLog, keyframe}, {mining::SourceKind::kLog, data_dir / "driving/kitti-object"}};
    mine.progress = false;
    const mining::IndexBuildReport mined = mining::BuildIndex(staging.path() / "mine" / "index", mine);
    const mining::MiningIndex index = mining::MiningIndex::Open(staging.path() / "mine" / "index");
    mining::QueryOptions query;
    query.prompts = {"traffic cone", "barrier", "car"};
    query.k = 6;
    query.min_size_px = 24;
    const std::vector<mining::PromptResult> hits = mining::RunQuery(index, query);
    mining::WriteMiningRun(staging.path() / "mine" / "run", index, hits, query, false);
    SD_LOG(Info, "mining: " << mined.items << " object crops from 2 logs; hits: " << hits[0].hits.size()
                            << " traffic cone, " << hits[1].hits.size() << " barrier, " << hits[2].hits.size()
                            << " car (label mode)");

    // 1. Assets from real pixels, no learned model: every mined hit harvested from its log (its views, its
    // returns, its box: docs/harvest.md), one per track; and the shipped cone photos by the revolve prior.
    HitAssetOptions hit_options;
    hit_options.generate.refine.show_progress = false;
    HitAssetBuilder builder(hit_options);
    std::vector<fs::path> built;
    int failed = 0;
    const std::vector<mining::ManifestEntry> entries =
        mining::ReadManifest(staging.path() / "mine" / "run" / "manifest.jsonl");
    Progress progress("demo: assets", entries.size());
    for (size_t i = 0; i < entries.size(); ++i) {
      const mining::ManifestEntry& e = entries[i];
      const auto category = FindCategory(e.item.category);
      const fs::path dir = staging.path() / "assets" / e.item.id;
      progress.Advance();
      if (!category || fs::exists(dir)) continue;
      try {
        BuiltAsset a = builder.Build(e, Msg() << "hit " << i + 1, *category, category->default_size);
        AssetInfo info;
        info.id = e.item.id;
        info.name = e.prompt + " #" + std::to_string(e.rank);
        info.category = category->name;
        info.licence = "CC BY-NC-SA 4.0 (nuScenes; non-commercial, share-alike; data/README.md)";
        info.attribution = "nuScenes (Caesar et al. 2020)";
        if (e.item.source.find("kitti") != std::string::npos) {
          info.licence = "CC BY-NC-SA 3.0 (KITTI; non-commercial, share-alike; data/README.md)";
          info.attribution = "KITTI (Geiger et al. 2012)";
        }
        a.front.insert(a.front.begin(), StageReport{"mine", Msg() << "label mode, prompt '" << e.prompt << "', rank " << e.rank, 0.0});
        SaveGenerated(std::move(a.mesh), a.views, a.front, info, a.source, dir, false, a.quality);
        built.push_back(dir);
      } catch (const InputError& err) {
        ++failed;
        SD_LOG(Info, "demo: hit " << i + 1 << " (" << e.item.category << ") not built: " << err.what());
      }
    }
    progress.Finish();
    for (const PhotoObject& p : ShippedConePhotos(data_dir / "images/roadanomaly-cones", 4)) {
      const std::string id = "photo_" + p.photo.stem().string().substr(0, 6) + "_" + std::to_string(p.id);
      const CategoryInfo cone = *FindCategory("traffic_cone");
      try {
        PhotoObservation photo;
        photo.image = ReadImage(p.photo, 3);
        photo.mask = p.mask;
        ShapePriorOptions prior;
        prior.category = cone.name;
        prior.size = Eigen::Vector3d(0.41, 0.41, 0.7);
        const fs::path labels = p.photo.parent_path() / (p.photo.stem().string() + ".labels");
        BuiltAsset a = PhotoAsset(photo, prior, hit_options.generate,
                                  {"segment", "the photo's own instance mask (Road Anomaly labels)", 0.0}, p.photo, labels,
                                  "data/images/roadanomaly-cones/frames/" + p.photo.filename().string());
        AssetInfo info;
        info.id = id;
        info.name = "traffic cone photo " + p.photo.stem().string() + " #" + std::to_string(p.id);
        info.category = cone.name;
        info.licence = "CC BY-SA (the photo's author; data/images/roadanomaly-cones/credits.txt)";
        info.attribution = "Road Anomaly (Lis et al. 2019), photo from Wikimedia Commons";
        SaveGenerated(std::move(a.mesh), a.views, a.front, info, a.source, staging.path() / "assets" / id, false, a.quality);
        built.push_back(staging.path() / "assets" / id);
      } catch (const InputError& err) {
        ++failed;
        SD_LOG(Info, "demo: photo " << p.photo.filename().string() << " #" << p.id << " not built: " << err.what());
      }
    }

    // 2. The bank, behind its quality gate: what a detector should learn from.
    const fs::path bank_path = staging.path() / "bank.sqlite";
    std::map<std::string, int> banked = BankBehindTheGate(bank_path, built, true);
    SD_LOG(Info, "demo: " << built.size() << " assets built (" << failed << " hits not buildable), "
                          << banked["traffic_cone"] << " cones, " << banked["barrier"] << " barriers, "
                          << banked["car"] << " cars passed the bank's gate");

    // 3. Synthesis of the nuScenes keyframe from the bank: the shipped scenario's objects, for each category the
    // bank holds an asset of whose texture is at most 30 % invented — the rest real pixels, seen or turned or
    // mirrored by the prior (one log view leaves 40-80 % of a car or a barrier to propagation: banked, but not
    // what the demo shows) — the assets chosen by the scenario's seed.
    constexpr double kDemoPropagated = 0.3;
    std::map<std::string, int> shown;
    {
      bank::BankQuery q;
      q.max_quality = {{"propagated_texture_fraction", kDemoPropagated}};
      for (const bank::BankEntry& e : bank::Bank::Open(bank_path, false).Query(q)) ++shown[e.category];
    }
    nlohmann::json scenario = ReadJsonFile(data_dir / "scenarios/demo.json");
    nlohmann::json objects = nlohmann::json::array();
    for (const auto& o : scenario.at("objects")) {
      const std::string category = o.value("category", std::string());
      if (shown[category] > 0) objects.push_back(o);
      else SD_LOG(Info, "demo: no " << category << " asset in the bank has under 30 % of its texture propagated: none inserted");
    }
    if (objects.empty()) throw InputError(bank_path, "no generated asset passed the quality gate: nothing to insert");
    scenario["objects"] = objects;
    // The bank relative to the scenario file (bank queries resolve it there), so the scenario, and synth.json's copy
    // of it, stay true once the staging folder is published.
    scenario["assets_from_bank"] = {{"bank", "bank.sqlite"},
                                    {"max_quality", {{"propagated_texture_fraction", kDemoPropagated}}}};
    WriteJsonFile(staging.path() / "scenario.json", scenario);
    SynthRequest req;
    req.log = keyframe;
    req.scenario = staging.path() / "scenario.json";
    req.out = staging.path() / "nuscenes-scene0061-kf0-synth";
    req.options.samples_per_pixel = *spp;
    const SynthSummary s = RunSynth(req);
    staging.Commit();
    // The bank references asset folders by absolute path, which named the staging folder, so it is written again
    // for the published one (under a temporary name, then renamed).
    {
      const fs::path final_bank = staging.final_path() / "bank.sqlite";
      const fs::path fresh = TemporarySibling(final_bank);
      std::vector<fs::path> published;
      for (const fs::path& dir : built) published.push_back(staging.final_path() / "assets" / dir.filename());
      BankBehindTheGate(fresh, published, false);
      for (const char* suffix : {"", "-wal", "-shm"}) fs::remove(final_bank.string() + suffix);
      fs::rename(fresh, final_bank);
      for (const char* suffix : {"-wal", "-shm"}) fs::remove(fresh.string() + suffix);
    }
    const fs::path final_report = staging.final_path() / s.out.filename() / "report.html";
    SD_LOG(Info, "demo: inserted " << s.objects << " objects into " << s.frames << " frame(s)");
    std::printf("report: %s\n", final_report.string().c_str());
    std::printf("mining contact sheet: %s\n", (staging.final_path() / "mine" / "run" / "index.html").string().c_str());
    return 0;
  };
}

}  // namespace sd::cli
