#pragma once
// A `synthdrive synth` request, and everything a shard, the merge and a dry run load from it before doing any
// work: bad input (an unknown frame, a duplicate asset, a bank query that matches nothing, an output over an
// input) fails here, before any output exists.
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "assetgen/asset.h"
#include "datasets/readers.h"
#include "synth/detected_tracks.h"
#include "synth/frame.h"
#include "synth/scenario.h"
#include "synth/synth_plan.h"

namespace sd {

struct SynthRequest {
  std::filesystem::path log;            // dataset root or info file
  OpenLogOptions log_options;
  std::vector<std::filesystem::path> assets;  // asset folders
  std::filesystem::path scenario;
  std::filesystem::path out;
  SynthOptions options;
  // Frames without boxes get keep-out tracks detected from their own LiDAR (synth/detected_tracks.h,
  // docs/detection.md); `--detect-objects`.
  DetectObjectsMode detect_objects = DetectObjectsMode::kUnannotated;
};

struct SynthInputs {
  Log log;
  std::vector<Asset> assets;     // --asset folders, then the scenario's bank queries' matches
  Scenario scenario;
  std::vector<size_t> selected;  // frame indices, in the order the user named them
  nlohmann::json fingerprint;    // what a part's content depends on (see synth/parts.h)
  std::shared_ptr<const models::Harmonizer> harmonizer;  // resolved once; null for "none" and dry runs
  bool world_fixed = false;      // the scenario is planned once per sequence (PlanSynthesis)
  SynthPlan plan;                // when world_fixed (or a dry run)
  DetectTracksReport detected;   // what AddDetectedTracks put into `log` (keep-out only, never labels)
  // The plan of a frame of the selection for a world-fixed scenario; nullptr otherwise.
  const SequencePlan* PlanFor(size_t frame_index) const;
};

// Reads the log, the scenario and the assets (with the scenario's bank queries), resolves the frame selection,
// fills the selection's span of frames without boxes with tracks detected from LiDAR (request.detect_objects),
// resolves the harmoniser and plans world-fixed scenarios. `dry_run`: assets are optional, the log may be of a
// read-only format, nothing is resolved that only rendering needs.
SynthInputs LoadSynthInputs(const SynthRequest& request, bool dry_run = false);

// InputError unless `request.out` (and its parts folder) is free: not over anything the run reads (with
// --overwrite, replacing it would delete the log, its sensor files or the assets), and absent unless
// --overwrite. Made up front so a shard does not work for a refused output.
void CheckOutputFree(const SynthRequest& request, const SynthInputs& in);

// `out` made absolute and without a trailing separator.
std::filesystem::path NormalOut(const std::filesystem::path& out);

// Where the parts of `out` live: "<out>.parts" (a sibling, so the output folder itself only ever appears
// complete). Besides one folder per frame it holds each shard's run log, log-<K>-of-<N>.jsonl: one line per
// frame, {"frame", "token", "status": done|skipped|failed, "error", "seconds"} (seconds: wall clock).
std::filesystem::path SynthPartsDir(const std::filesystem::path& out);

}  // namespace sd
