// `synthdrive mine index|query`: find the prompt's object in a team's own driving logs, image folders and
// URL lists (DESIGN.md "mine"; docs/mining.md).
#include <filesystem>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "cli/commands.h"
#include "core/error.h"
#include "core/log.h"
#include "core/shard.h"
#include "io/files.h"
#include "mining/index.h"
#include "mining/query.h"
#include "models/clip.h"

namespace sd::cli {

namespace {

namespace fs = std::filesystem;

// --clip: "none", "auto" (the installed CLIP folder when all its files are there, else none, said in the log)
// or a folder holding clip_image.pt, clip_text.pt and the BPE vocabulary.
std::optional<models::ClipEncoder> LoadClip(const std::string& spec, const std::string& device) {
  if (spec == "none") return std::nullopt;
  models::RuntimeOptions runtime;
  runtime.device = device;
  fs::path dir(spec);
  if (spec == "auto") {
    dir = models::DefaultModelDir() / "clip";
    if (!fs::exists(dir / models::kClipImageFile) || !fs::exists(dir / models::kClipTextFile) ||
        !fs::exists(dir / models::kClipVocabFile)) {
      SD_LOG(Info, "no CLIP model in " << dir.string()
                                       << " (tools/export/export_clip.py makes one): label and example search only");
      return std::nullopt;
    }
  }
  models::ClipEncoder clip = models::ClipEncoder::Load(dir, runtime);
  SD_LOG(Info, "CLIP: " << clip.Describe());
  return clip;
}

void AddIndexCommand(CLI::App& app, std::function<int()>& run) {
  struct Args {
    std::vector<std::string> logs, folders, url_lists, cameras, categories;
    std::string out, clip = "auto", device = "cpu", shard = "0/1";
    int chunk_size = 0, max_crop_px = 512, min_box_px = 12, max_image_px = 1024, fetch_concurrency = 8;
    double max_truncation = 0.75, timeout_s = 60, stall_s = 15, max_download_mb = 32;
    int retries = 2;
    size_t ann_min_rows = mining::kAnnMinRows;
  };
  auto a = std::make_shared<Args>();
  app.add_option("--log", a->logs, "Driving log: nuScenes/Lyft root, mmdet3d info .json or KITTI root (repeatable)");
  app.add_option("--images", a->folders, "Folder of .png/.jpg images, searched recursively (repeatable)");
  app.add_option("--urls", a->url_lists, "Text file of http(s) image URLs, one per line (repeatable)");
  app.add_option("--out", a->out, "Index folder: created, or extended when it already holds an index")->required();
  app.add_option("--clip", a->clip, "CLIP model folder, auto (installed one if any) or none")->default_val("auto");
  app.add_option("--device", a->device, "cpu, cuda or cuda:N (CLIP)")->default_val("cpu");
  app.add_option("--shard", a->shard, "Build only chunks K, K+N, ... of the work list (K/N, 0-based)")
      ->default_val("0/1");
  app.add_option("--chunk-size", a->chunk_size, "Frames, images or URLs per index shard (new index: 16)")
      ->check(CLI::Range(1, 100000));
  app.add_option("--cameras", a->cameras, "Camera channels to crop from (default: all)")->delimiter(',');
  app.add_option("--categories", a->categories, "Only these categories from logs (default: all)")->delimiter(',');
  app.add_option("--max-crop-px", a->max_crop_px, "Downscale crops larger than this")->default_val(512)
      ->check(CLI::Range(32, 8192));
  app.add_option("--min-box-px", a->min_box_px, "Skip objects smaller than this in the image")->default_val(12)
      ->check(CLI::Range(1, 10000));
  app.add_option("--max-truncation", a->max_truncation, "Skip objects more than this fraction outside the image")
      ->default_val(0.75)->check(CLI::Range(0.0, 1.0));
  app.add_option("--max-image-px", a->max_image_px, "Downscale folder/URL images larger than this")
      ->default_val(1024)->check(CLI::Range(32, 16384));
  app.add_option("--timeout", a->timeout_s, "Seconds per URL download")->default_val(60)->check(CLI::PositiveNumber);
  app.add_option("--stall-timeout", a->stall_s, "Abort a download that sends nothing for this long (s)")
      ->default_val(15)->check(CLI::PositiveNumber);
  app.add_option("--max-download-mb", a->max_download_mb, "Refuse URL images larger than this")
      ->default_val(32)->check(CLI::PositiveNumber);
  app.add_option("--retries", a->retries, "Retries of a transient download failure")->default_val(2)
      ->check(CLI::Range(0, 10));
  app.add_option("--fetch-concurrency", a->fetch_concurrency, "Parallel downloads")->default_val(8)
      ->check(CLI::Range(1, 64));
  app.add_option("--ann-min-rows", a->ann_min_rows,
                 "Build the approximate (IVF-PQ) index once the index holds this many vectors; 0: never (docs/mining.md)")
      ->default_val(mining::kAnnMinRows)->check(CLI::NonNegativeNumber);
  run = [a]() {
    mining::IndexBuildOptions o;
    for (const auto& p : a->logs) o.sources.push_back({mining::SourceKind::kLog, p});
    for (const auto& p : a->folders) o.sources.push_back({mining::SourceKind::kFolder, p});
    for (const auto& p : a->url_lists) o.sources.push_back({mining::SourceKind::kUrl, p});
    {
      std::vector<fs::path> inputs(a->logs.begin(), a->logs.end());
      inputs.insert(inputs.end(), a->folders.begin(), a->folders.end());
      inputs.insert(inputs.end(), a->url_lists.begin(), a->url_lists.end());
      RefuseOutputOverInputs(a->out, inputs);
    }
    o.shard = ParseShard(a->shard);
    o.chunk_size = a->chunk_size;
    o.crops.cameras = a->cameras;
    o.crops.categories = a->categories;
    o.crops.max_crop_px = a->max_crop_px;
    o.crops.min_box_px = a->min_box_px;
    o.crops.max_truncation = a->max_truncation;
    o.max_image_px = a->max_image_px;
    o.fetch.total_timeout_s = a->timeout_s;
    o.fetch.stall_timeout_s = a->stall_s;
    o.fetch.max_bytes = static_cast<size_t>(a->max_download_mb * 1024 * 1024);
    o.fetch.retries = a->retries;
    o.fetch_concurrency = a->fetch_concurrency;
    o.build_ann = a->ann_min_rows > 0;
    o.ann_min_rows = a->ann_min_rows;
    const std::optional<models::ClipEncoder> clip = LoadClip(a->clip, a->device);
    o.clip = clip ? &*clip : nullptr;
    const mining::IndexBuildReport r = mining::BuildIndex(a->out, o);
    SD_LOG(Info, "mine index: " << r.items << " object images in " << r.chunks_built << " new chunks ("
                                << r.chunks_skipped << " already done, " << r.failures << " failures) in "
                                << r.seconds << " s; " << a->out);
    for (const std::string& kind : r.ann_built)
      SD_LOG(Info, "mine index: approximate " << kind << " index (re)built (" << r.ann_seconds << " s for all)");
    if (o.shard.count > 1 && o.build_ann)
      SD_LOG(Info, "mine index: shard " << o.shard.ToString() << " done; once every shard is, a plain `mine index` with "
                                           "the same sources builds the approximate index (when it holds "
                                        << o.ann_min_rows << "+ vectors)");
    // The batch convention (README, "Exit status"): 1 when any item of this run failed, the others kept.
    if (!r.failed_chunks.empty()) {
      for (const std::string& f : r.failed_chunks) SD_LOG(Error, "mine index: chunk " << f);
      SD_LOG(Error, "mine index: " << r.failed_chunks.size() << " chunk(s) failed; a rerun builds only those");
      return 1;
    }
    if (r.failures > 0) {
      SD_LOG(Error, "mine index: " << r.failures << " image(s) could not be read or cropped and are not in the index; "
                                   "each chunk's chunk.json lists them with the reason");
      return 1;
    }
    return 0;
  };
}

void AddQueryCommand(CLI::App& app, std::function<int()>& run) {
  struct Args {
    std::string index, out, mode = "auto", clip = "auto", device = "cpu";
    std::vector<std::string> prompts, examples;
    mining::QueryOptions o;
    bool overwrite = false;
  };
  auto a = std::make_shared<Args>();
  mining::QueryOptions& o = a->o;
  app.add_option("--index", a->index, "Index folder (mine index --out)")->required();
  app.add_option("--prompt", a->prompts, "Text prompt, e.g. \"traffic cone\" (repeatable)");
  app.add_option("--example", a->examples, "Example image to find more of (repeatable)");
  app.add_option("--out", a->out, "Mining run folder: manifest.jsonl, crops/, masks/, run.json, index.html")
      ->required();
  app.add_option("--k", o.k, "Hits per prompt")->default_val(20)->check(CLI::Range(1, 100000));
  app.add_option("--mode", a->mode, "auto, clip, label, lexical or example")->default_val("auto");
  app.add_option("--clip", a->clip, "CLIP model folder, auto or none")->default_val("auto");
  app.add_option("--device", a->device, "cpu, cuda or cuda:N (CLIP)")->default_val("cpu");
  app.add_option("--min-score", o.min_clip_score, "Minimum CLIP cosine")->default_val(0.2)->check(CLI::Range(-1.0, 1.0));
  app.add_option("--min-example-score", o.min_example_score, "Minimum descriptor cosine in example mode")
      ->default_val(0.6)->check(CLI::Range(-1.0, 1.0));
  app.add_option("--min-size", o.min_size_px, "Minimum object size (shorter side, source pixels)")
      ->default_val(32)->check(CLI::NonNegativeNumber);
  app.add_option("--max-truncation", o.max_truncation, "Maximum fraction outside the image")->default_val(0.3)
      ->check(CLI::Range(0.0, 1.0));
  app.add_option("--max-occlusion", o.max_occlusion, "Maximum occluded fraction")->default_val(0.5)
      ->check(CLI::Range(0.0, 1.0));
  app.add_option("--min-sharpness", o.min_sharpness, "Minimum sharpness (variance of the Laplacian)")
      ->default_val(10)->check(CLI::NonNegativeNumber);
  app.add_option("--min-visibility", o.min_visibility_level, "Minimum dataset visibility level (nuScenes 1..4)")
      ->default_val(-1);
  app.add_option("--dedupe-bits", o.max_hash_distance, "Near-duplicate pHash distance (-1: keep duplicates)")
      ->default_val(6)->check(CLI::Range(-1, 64));
  app.add_option("--per-frame", o.max_per_frame, "Hits per source frame/image (0: unlimited)")->default_val(3)
      ->check(CLI::NonNegativeNumber);
  app.add_option("--per-instance", o.max_per_instance, "Hits per tracked object (0: unlimited)")->default_val(1)
      ->check(CLI::NonNegativeNumber);
  app.add_flag("--overwrite", a->overwrite, "Replace an existing run folder");
  run = [a]() {
    mining::QueryOptions o = a->o;
    o.prompts = a->prompts;
    for (const auto& e : a->examples) o.examples.push_back(e);
    o.mode = mining::QueryModeFromString(a->mode);
    if (o.prompts.empty() && o.examples.empty()) throw InputError({}, "mine query: give --prompt or --example");
    {
      std::vector<fs::path> inputs(a->examples.begin(), a->examples.end());
      inputs.push_back(a->index);
      RefuseOutputOverInputs(a->out, inputs);
    }
    if (fs::exists(a->out) && !a->overwrite) throw InputError(a->out, "exists (pass --overwrite to replace it)");
    const mining::MiningIndex index = mining::MiningIndex::Open(a->index);
    SD_LOG(Info, "index " << a->index << ": " << index.size() << " object images in " << index.shard_count()
                          << " shards" << (index.has_clip() ? ", CLIP " + index.clip_model() : ", no CLIP vectors")
                          << (index.ann(mining::VectorKind::kClip) ? ", approximate CLIP search" : ""));
    // Only load CLIP when the index can use it: loading is the slow part of a small query.
    const std::optional<models::ClipEncoder> clip =
        index.has_clip() && o.mode != mining::QueryMode::kLabel ? LoadClip(a->clip, a->device) : std::nullopt;
    o.clip = clip ? &*clip : nullptr;
    // WordNet for prompts CLIP does not serve (a 20 MB read: only then).
    std::optional<mining::Lexicon> lexicon;
    if (!o.prompts.empty() && !o.clip && (o.mode == mining::QueryMode::kAuto || o.mode == mining::QueryMode::kLexical)) {
      lexicon = mining::Lexicon::Load();
      o.lexicon = &*lexicon;
      if (!lexicon->has_wordnet())
        SD_LOG(Warn, "WordNet not found in " << mining::DefaultWordNetDir().string()
                                                << " (Debian's wordnet-base): prompts are read by category names and road words only");
    }
    const std::vector<mining::PromptResult> results = mining::RunQuery(index, o);
    mining::WriteMiningRun(a->out, index, results, o, a->overwrite);
    size_t hits = 0;
    for (const auto& r : results) hits += r.hits.size();
    SD_LOG(Info, "wrote " << a->out << "/manifest.jsonl (" << hits << " hits) and " << a->out
                          << "/index.html");
    return 0;
  };
}

}  // namespace

Runner AddMineCommand(CLI::App& app) {
  app.require_subcommand(1);
  auto index_run = std::make_shared<Runner>();
  auto query_run = std::make_shared<Runner>();
  CLI::App* index = app.add_subcommand("index", "Crawl logs, image folders and URL lists into an embedding index");
  CLI::App* query = app.add_subcommand("query", "Rank the index against prompts and write a mining run");
  AddIndexCommand(*index, *index_run);
  AddQueryCommand(*query, *query_run);
  return [index, query, index_run, query_run]() {
    if (index->parsed()) return (*index_run)();
    if (query->parsed()) return (*query_run)();
    return 1;
  };
}

}  // namespace sd::cli
