// `synthdrive bank add|list|query|show|verify|remove`: the asset catalogue (DESIGN.md "bank"; docs/bank.md).
// The bank file: --bank, else $SYNTHDRIVE_BANK, else ./bank.sqlite.
#include <algorithm>
#include <cstdio>
#include <filesystem>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include <CLI/CLI.hpp>

#include "bank/bank.h"
#include "cli/commands.h"
#include "core/error.h"
#include "core/log.h"
#include "core/shard.h"
#include "io/json.h"
#include "models/clip.h"

namespace sd::cli {

namespace {

namespace fs = std::filesystem;

// --clip: "none", "auto" (the installed CLIP folder when all its files are there, else none) or a folder.
std::optional<models::ClipEncoder> LoadBankClip(const std::string& spec, const std::string& device) {
  if (spec == "none") return std::nullopt;
  fs::path dir(spec);
  if (spec == "auto") {
    dir = models::DefaultModelDir() / "clip";
    if (!fs::exists(dir / models::kClipImageFile) || !fs::exists(dir / models::kClipTextFile) ||
        !fs::exists(dir / models::kClipVocabFile)) {
      SD_LOG(Debug, "no CLIP model in " << dir.string() << ": no embeddings, no text queries");
      return std::nullopt;
    }
  }
  models::RuntimeOptions runtime;
  runtime.device = device;
  models::ClipEncoder clip = models::ClipEncoder::Load(dir, runtime);
  SD_LOG(Info, "CLIP: " << clip.Describe());
  return clip;
}

fs::path BankPath(const std::string& option) { return option.empty() ? bank::DefaultBankPath() : fs::path(option); }

void AddBankOption(CLI::App& app, std::string& bank) {
  app.add_option("--bank", bank, "Bank file (default: $SYNTHDRIVE_BANK, else ./bank.sqlite)");
}

// The work list of `add`: each path is an asset folder (has asset.json) or a folder of asset folders.
std::vector<fs::path> AssetFolders(const std::vector<std::string>& paths) {
  std::vector<fs::path> out;
  for (const std::string& p : paths) {
    const fs::path path(p);
    if (!fs::exists(path)) throw InputError(path, "no such file or folder");
    if (fs::exists(path / "asset.json") || path.filename() == "asset.json") {
      out.push_back(path);
      continue;
    }
    if (!fs::is_directory(path)) throw InputError(path, "not an asset folder");
    std::vector<fs::path> found;
    for (const fs::directory_entry& e : fs::directory_iterator(path))
      if (e.is_directory() && fs::exists(e.path() / "asset.json")) found.push_back(e.path());
    if (found.empty()) throw InputError(path, "neither an asset folder (no asset.json) nor a folder of asset folders");
    std::sort(found.begin(), found.end());
    out.insert(out.end(), found.begin(), found.end());
  }
  return out;
}

std::string Extent(const Eigen::Vector3d& e) {
  char buf[64];
  std::snprintf(buf, sizeof(buf), "%.2f x %.2f x %.2f", e.x(), e.y(), e.z());
  return buf;
}

void PrintTable(const std::vector<bank::BankEntry>& entries) {
  const bool scored = !entries.empty() && entries[0].score.has_value();
  size_t wid = 2, wcat = 8;
  for (const bank::BankEntry& e : entries) {
    wid = std::max(wid, e.id.size());
    wcat = std::max(wcat, e.category.size());
  }
  const int iw = static_cast<int>(wid), cw = static_cast<int>(wcat);
  if (scored) std::printf("%-6s  ", "score");
  std::printf("%-*s  %-*s  %-22s  %-4s  %s\n", iw, "id", cw, "category", "extent L x W x H (m)", "clip", "folder");
  for (const bank::BankEntry& e : entries) {
    if (scored) std::printf("%6.3f  ", static_cast<double>(*e.score));
    std::printf("%-*s  %-*s  %-22s  %-4s  %s\n", iw, e.id.c_str(), cw, e.category.c_str(), Extent(e.extent).c_str(),
                e.clip_embedding.empty() ? "no" : "yes", e.dir.c_str());
  }
}

// `list` and `query` output: a table, or with --json an array of entries (without their file lists).
void PrintEntries(const std::vector<bank::BankEntry>& entries, bool json) {
  if (!json) {
    PrintTable(entries);
    return;
  }
  nlohmann::json j = nlohmann::json::array();
  for (const bank::BankEntry& e : entries) j.push_back(bank::BankEntryToJson(e, false));
  std::printf("%s\n", j.dump(2).c_str());
}

std::map<std::string, double> ParseFigures(const std::vector<std::string>& items, const char* option) {
  std::map<std::string, double> out;
  for (const std::string& item : items) {
    const size_t eq = item.find('=');
    try {
      if (eq == std::string::npos || eq == 0) throw std::invalid_argument("no '='");
      size_t used = 0;
      out[item.substr(0, eq)] = std::stod(item.substr(eq + 1), &used);
      if (used != item.size() - eq - 1) throw std::invalid_argument("trailing text");
    } catch (const std::exception&) {
      throw InputError({}, Msg() << option << " '" << item << "': expected NAME=NUMBER");
    }
  }
  return out;
}

Runner AddAdd(CLI::App& app) {
  struct Args {
    std::vector<std::string> paths;
    std::string bank, clip = "auto", device = "cpu", shard = "0/1";
    std::vector<std::string> gate;
    bool replace = false, no_gate = false;
  };
  auto a = std::make_shared<Args>();
  app.add_option("paths", a->paths, "Asset folders, or folders of asset folders")->required();
  AddBankOption(app, a->bank);
  app.add_flag("--replace", a->replace, "Replace an entry of the same id whose files differ");
  app.add_option("--gate", a->gate,
                 "NAME>=VALUE or NAME<=VALUE: a quality figure an asset must meet to be added, replacing the default "
                 "for NAME (repeatable; defaults: watertight>=1 heldout_silhouette_iou>=0.5 "
                 "lidar_p2m_median_m<=0.05 real_texture_fraction>=0.15 extent_to_size_max<=1.3; figures an asset lacks are not checked)");
  app.add_flag("--no-gate", a->no_gate, "Add assets whatever their quality figures");
  app.add_option("--clip", a->clip, "CLIP model folder for preview embeddings, auto (installed one if any) or none")
      ->default_val("auto");
  app.add_option("--device", a->device, "cpu, cuda or cuda:N (CLIP)")->default_val("cpu");
  app.add_option("--shard", a->shard, "Add only items K, K+N, ... of the work list (K/N, 0-based)")->default_val("0/1");
  return [a]() {
    const ShardSpec shard = ParseShard(a->shard);
    const std::vector<fs::path> all = AssetFolders(a->paths);
    std::vector<fs::path> mine;
    for (size_t i = 0; i < all.size(); ++i)
      if (shard.Owns(i)) mine.push_back(all[i]);
    const std::optional<models::ClipEncoder> clip = LoadBankClip(a->clip, a->device);
    // Everything that can be refused before the bank file exists is (a bad --gate left an empty bank.sqlite).
    bank::QualityGate gate = bank::DefaultQualityGate();
    for (const std::string& rule : a->gate) bank::ParseGateRule(rule, "--gate", &gate);
    if (a->no_gate && !a->gate.empty()) throw InputError({}, "--gate and --no-gate contradict each other");
    const fs::path bank_path = BankPath(a->bank);
    const bool created = !fs::exists(bank_path);
    std::optional<bank::Bank> opened = bank::Bank::Open(bank_path, true);
    bank::Bank& b = *opened;
    bank::AddOptions options;
    options.replace = a->replace;
    if (!a->no_gate) options.gate = &gate;
    options.clip = clip ? &*clip : nullptr;
    size_t added = 0, unchanged = 0, replaced = 0;
    std::vector<std::string> failures;
    {
      Progress progress("bank add", mine.size());
      for (const fs::path& dir : mine) {
        try {
          const bank::AddResult r = b.Add(dir, options);
          const bool is_new = r.status == bank::AddStatus::kAdded, same = r.status == bank::AddStatus::kUnchanged;
          (is_new ? added : same ? unchanged : replaced)++;
          SD_LOG(Debug, r.id << ": " << (is_new ? "added" : same ? "unchanged" : "replaced"));
        } catch (const InputError& e) {
          failures.push_back(e.what());
        }
        progress.Advance();
      }
    }
    for (const std::string& f : failures) SD_LOG(Error, f);
    SD_LOG(Info, b.path().string() << ": " << added << " added, " << unchanged << " unchanged, " << replaced
                                   << " replaced, " << failures.size() << " failed");
    if (created && added + replaced == 0) {
      // A bank this run created and put nothing in is not left behind as an empty file.
      opened.reset();
      for (const char* suffix : {"", "-journal", "-wal", "-shm"}) {
        std::error_code ec;
        fs::remove(bank_path.string() + suffix, ec);
      }
      SD_LOG(Info, bank_path.string() << ": nothing catalogued, not created");
    }
    return failures.empty() ? 0 : 1;
  };
}

Runner AddList(CLI::App& app) {
  auto bank_path = std::make_shared<std::string>();
  auto json = std::make_shared<bool>(false);
  AddBankOption(app, *bank_path);
  app.add_flag("--json", *json, "Print a JSON array instead of a table");
  return [bank_path, json]() {
    const std::vector<bank::BankEntry> entries = bank::Bank::Open(BankPath(*bank_path), false).Query({});
    PrintEntries(entries, *json);
    return 0;
  };
}

Runner AddQuery(CLI::App& app) {
  struct Args {
    std::string bank, category, text, clip = "auto", device = "cpu", from;
    std::vector<double> min_extent, max_extent;
    std::vector<std::string> min_quality, max_quality;
    size_t limit = 0;
    bool json = false;
  };
  auto a = std::make_shared<Args>();
  AddBankOption(app, a->bank);
  app.add_option("--from", a->from, "A JSON bank query file (docs/bank.md); the options below override it");
  app.add_option("--category", a->category, "Only this category");
  app.add_option("--min-extent", a->min_extent, "L,W,H: at least this size per axis (m)")->delimiter(',')->expected(3);
  app.add_option("--max-extent", a->max_extent, "L,W,H: at most this size per axis (m)")->delimiter(',')->expected(3);
  app.add_option("--text", a->text, "Rank by CLIP similarity of this text to the asset previews (needs --clip)");
  app.add_option("--clip", a->clip, "CLIP model folder, auto (installed one if any) or none")->default_val("auto");
  app.add_option("--device", a->device, "cpu, cuda or cuda:N (CLIP)")->default_val("cpu");
  app.add_option("--min-quality", a->min_quality, "NAME=VALUE: asset.json quality figure at least VALUE (repeatable)");
  app.add_option("--max-quality", a->max_quality, "NAME=VALUE: asset.json quality figure at most VALUE (repeatable)");
  app.add_option("--limit", a->limit, "At most this many results (0: all)");
  app.add_flag("--json", a->json, "Print a JSON array instead of a table");
  return [a]() {
    bank::BankQuery q;
    fs::path bank_path = BankPath(a->bank);
    if (!a->from.empty()) {
      fs::path named;
      q = bank::BankQueryFromJson(ReadJsonFile(a->from), a->from, &named);
      if (!named.empty() && a->bank.empty()) bank_path = named;
    }
    if (!a->category.empty()) q.category = a->category;
    if (!a->min_extent.empty()) q.min_extent = Eigen::Vector3d(a->min_extent[0], a->min_extent[1], a->min_extent[2]);
    if (!a->max_extent.empty()) q.max_extent = Eigen::Vector3d(a->max_extent[0], a->max_extent[1], a->max_extent[2]);
    if (!a->text.empty()) q.text = a->text;
    for (const auto& [k, v] : ParseFigures(a->min_quality, "--min-quality")) q.min_quality[k] = v;
    for (const auto& [k, v] : ParseFigures(a->max_quality, "--max-quality")) q.max_quality[k] = v;
    if (a->limit > 0) q.limit = a->limit;
    const bank::Bank b = bank::Bank::Open(bank_path, false);
    std::optional<models::ClipEncoder> clip;
    if (!q.text.empty()) clip = LoadBankClip(a->clip, a->device);
    const std::vector<bank::BankEntry> entries = b.Query(q, clip ? &*clip : nullptr);
    PrintEntries(entries, a->json);
    return 0;
  };
}

Runner AddShow(CLI::App& app) {
  auto bank_path = std::make_shared<std::string>();
  auto id = std::make_shared<std::string>();
  AddBankOption(app, *bank_path);
  app.add_option("id", *id, "Asset id")->required();
  return [bank_path, id]() {
    const bank::BankEntry e = bank::Bank::Open(BankPath(*bank_path), false).Show(*id);
    std::printf("%s\n", bank::BankEntryToJson(e, true).dump(2).c_str());
    return 0;
  };
}

Runner AddVerify(CLI::App& app) {
  auto bank_path = std::make_shared<std::string>();
  auto ids = std::make_shared<std::vector<std::string>>();
  AddBankOption(app, *bank_path);
  app.add_option("--id", *ids, "Verify only this asset (repeatable; default: every entry)");
  return [bank_path, ids]() {
    const bank::Bank b = bank::Bank::Open(BankPath(*bank_path), false);
    const bank::VerifyReport r = b.Verify(*ids);
    for (const bank::VerifyProblem& p : r.problems)
      std::printf("%s: %s: %s\n", p.id.c_str(), p.path.c_str(), p.what.c_str());
    SD_LOG(Info, b.path().string() << ": " << r.entries << " entries, " << r.files << " files checked, "
                                   << r.problems.size() << " problems");
    return r.problems.empty() ? 0 : 1;
  };
}

Runner AddRemove(CLI::App& app) {
  auto bank_path = std::make_shared<std::string>();
  auto ids = std::make_shared<std::vector<std::string>>();
  auto delete_files = std::make_shared<bool>(false);
  AddBankOption(app, *bank_path);
  app.add_option("ids", *ids, "Asset ids")->required();
  app.add_flag("--delete-files", *delete_files, "Also delete the asset folders");
  return [bank_path, ids, delete_files]() {
    bank::Bank b = bank::Bank::Open(BankPath(*bank_path), false);
    for (const std::string& id : *ids) {
      b.Remove(id, *delete_files);
      SD_LOG(Info, "removed " << id);
    }
    return 0;
  };
}

}  // namespace

Runner AddBankCommand(CLI::App& app) {
  app.require_subcommand(1);
  std::vector<std::pair<CLI::App*, Runner>> subs;
  auto sub = [&](const char* name, const char* help, Runner (*factory)(CLI::App&)) {
    CLI::App* s = app.add_subcommand(name, help);
    subs.emplace_back(s, factory(*s));
  };
  sub("add", "Catalogue asset folders (or folders of asset folders); reruns skip unchanged ones", AddAdd);
  sub("list", "List every catalogued asset", AddList);
  sub("query", "Find assets by category, size, quality and (with CLIP) text", AddQuery);
  sub("show", "One entry as JSON, with its files and their SHA-256", AddShow);
  sub("verify", "Re-hash every catalogued file and load every asset; one line per problem", AddVerify);
  sub("remove", "Remove entries (and, with --delete-files, their folders)", AddRemove);
  return [subs]() {
    for (const auto& [s, run] : subs)
      if (s->parsed()) return run();
    return 1;
  };
}

}  // namespace sd::cli
