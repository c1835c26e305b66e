#include "synth/request.h"

#include <algorithm>
#include <set>

#include "bank/bank.h"
#include "core/log.h"
#include "datasets/categories.h"
#include "datasets/format.h"
#include "io/files.h"
#include "models/harmonization.h"
#include "synth/parts.h"

namespace sd {
namespace fs = std::filesystem;
namespace {

// The asset folders the scenario's bank queries name, in query order; an asset matched by several queries (or
// also given with --asset) is an error of duplicate ids below, so queries must not overlap.
std::vector<fs::path> BankAssets(const Scenario& scenario, const fs::path& scenario_file) {
  std::vector<fs::path> dirs;
  for (size_t i = 0; i < scenario.bank_queries.size(); ++i) {
    fs::path bank_path;
    const bank::BankQuery query = bank::BankQueryFromJson(scenario.bank_queries[i], scenario_file, &bank_path);
    if (bank_path.empty()) bank_path = bank::DefaultBankPath();
    if (!query.text.empty())
      throw InputError(scenario_file, "assets_from_bank: text queries need a CLIP model; use category, extent "
                                      "and quality, or pick the assets with `synthdrive bank query --text`");
    const std::vector<bank::BankEntry> found = bank::Bank::Open(bank_path, false).Query(query);
    if (found.empty())
      throw InputError(scenario_file, Msg() << "assets_from_bank[" << i << "] matches no asset in " << bank_path.string());
    SD_LOG(Info, "bank " << bank_path.string() << ": query " << i << " gives " << found.size() << " asset(s)");
    for (const bank::BankEntry& e : found) dirs.push_back(e.dir);
  }
  return dirs;
}

// The frames the user named (tokens or indices), in their order; all frames when none.
std::vector<size_t> SelectFrames(const Log& log, const std::vector<std::string>& frames, const fs::path& log_path) {
  std::vector<size_t> selected;
  if (frames.empty()) {
    for (size_t i = 0; i < log.frames.size(); ++i) selected.push_back(i);
  } else {
    std::set<size_t> seen;
    for (const auto& f : frames) {
      size_t found = log.frames.size();
      for (size_t i = 0; i < log.frames.size(); ++i)
        if (log.frames[i].token == f) found = i;
      if (found == log.frames.size() && !f.empty() && std::all_of(f.begin(), f.end(), ::isdigit)) found = std::stoul(f);
      if (found >= log.frames.size()) throw InputError(log_path, "no frame '" + f + "'");
      if (!seen.insert(found).second) throw InputError(log_path, "frame '" + f + "' selected twice");
      selected.push_back(found);
    }
  }
  if (selected.empty()) throw InputError(log_path, "log has no frames");
  return selected;
}

}  // namespace

const SequencePlan* SynthInputs::PlanFor(size_t frame_index) const {
  if (!world_fixed) return nullptr;
  const SequencePlan* p = plan.ForFrame(frame_index);
  SD_CHECK(p != nullptr, << "frame " << frame_index << " is in no plan");
  return p;
}

SynthInputs LoadSynthInputs(const SynthRequest& request, bool dry_run) {
  SynthInputs in;
  in.log = OpenLog(request.log, request.log_options);
  const Log& log = in.log;
  SD_LOG(Info, "log: " << request.log.string() << " (" << ToString(log.format) << ", " << log.frames.size() << " frames)");
  if (!FormatInfo(log.format).write && !dry_run)  // refused now rather than after synthesising every frame
    throw InputError(request.log, std::string(FormatInfo(log.format).read_only_message) + "; --dry-run plans on them");
  in.scenario = ReadScenario(request.scenario);
  std::vector<fs::path> asset_dirs = request.assets;
  for (const fs::path& dir : BankAssets(in.scenario, request.scenario)) asset_dirs.push_back(dir);
  if (asset_dirs.empty() && !dry_run) throw InputError("", "no --asset given, and the scenario names no assets_from_bank");
  std::set<std::string> ids;
  for (const auto& path : asset_dirs) {
    in.assets.push_back(LoadAsset(path));
    const auto& info = in.assets.back().info;
    if (!FindCategory(info.category))
      throw InputError(path, "unknown category '" + info.category + "' (see `synthdrive categories`)");
    if (!ids.insert(info.id).second) throw InputError(path, "duplicate asset id '" + info.id + "'");
  }
  in.selected = SelectFrames(log, request.options.frames, request.log);
  if (request.detect_objects != DetectObjectsMode::kOff) {
    // Before planning and placement, so both keep clear of the detected tracks exactly as of annotated ones.
    DetectTracksOptions detect;
    detect.mode = request.detect_objects;
    detect.first = *std::min_element(in.selected.begin(), in.selected.end());
    detect.last = *std::max_element(in.selected.begin(), in.selected.end()) + 1;
    in.detected = AddDetectedTracks(&in.log, detect);
    if (in.detected.frames > 0 || in.detected.frames_without_sweep > 0) SD_LOG(Info, in.detected.Summary());
  }
  if (!dry_run && request.options.harmonizer != "none") {
    in.harmonizer = std::make_shared<const models::Harmonizer>(ResolveSynthHarmonizer(request.options.harmonizer));
    SD_LOG(Info, "harmoniser: " << in.harmonizer->Describe());
  }
  in.world_fixed = WorldFixedScenario(in.scenario);
  if (in.world_fixed || dry_run)
    in.plan = PlanSynthesis(in.log, in.selected, in.scenario, in.assets, request.scenario, !dry_run);
  in.fingerprint = RequestFingerprint(request, in);
  return in;
}

fs::path NormalOut(const fs::path& out) {
  fs::path p = fs::absolute(out).lexically_normal();
  if (p.filename().empty()) p = p.parent_path();
  return p;
}

fs::path SynthPartsDir(const fs::path& out) {
  const fs::path p = NormalOut(out);
  return p.parent_path() / (p.filename().string() + ".parts");
}

void CheckOutputFree(const SynthRequest& request, const SynthInputs& in) {
  const fs::path out = NormalOut(request.out);
  // Folders first, so the message names the folder the output would replace rather than a file inside it.
  std::vector<fs::path> inputs = {in.log.data_root};
  for (const Asset& a : in.assets) inputs.push_back(a.dir);
  for (const fs::path& p : {request.log, in.log.source, in.log.annotation_path, request.scenario}) inputs.push_back(p);
  const std::string& h = request.options.harmonizer;
  if (h != "none" && h != "classical" && h != "auto") inputs.push_back(h);  // a TorchScript file
  for (const Frame& f : in.log.frames) {
    for (const CameraSensor& c : f.cameras) inputs.push_back(c.image_path);
    if (f.lidar) inputs.push_back(f.lidar->path);
  }
  RefuseOutputOverInputs(out, inputs);
  RefuseOutputOverInputs(SynthPartsDir(out), inputs);
  std::error_code ec;
  if (fs::exists(out, ec) && !request.options.overwrite)
    throw InputError(out, "output already exists (pass --overwrite to replace it)");
}

}  // namespace sd
