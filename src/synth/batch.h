#pragma once
// `synthdrive synth`: insert assets into a real driving log, camera and LiDAR, with labels, written as a
// derivative dataset in the input's own format.
//
// A batch command (DESIGN.md): the work list is the selected frames. Each frame is synthesised
// (synth/frame.h) into a *part* (synth/parts.h), and the merge turns the parts of every selected frame into the
// derivative dataset. A local run is exactly "shard 0/1, then merge" (RunSynth), so shards + merge write the
// same bytes as a local run by construction.
#include <filesystem>
#include <string>
#include <vector>

#include "core/shard.h"
#include "synth/request.h"
#include "synth/synth_plan.h"

namespace sd {

struct SynthSummary {
  std::filesystem::path out, report;
  size_t frames = 0, objects = 0;
};

// The whole command: loads everything, synthesises the selected frames, writes the derivative dataset,
// synth.json (placements and provenance) and report.html into `out` atomically (world-fixed scenarios: also
// plan.json and plan.html, as --dry-run writes them; --coco: coco_2d.json). It is RunSynthShard(0/1)
// followed by MergeSynthParts; the parts folder is removed once the output is committed (and kept when a
// frame failed and others have parts, so a rerun resumes). A frame's failure does not stop the others; the
// first failure is rethrown at the end.
SynthSummary RunSynth(const SynthRequest& request);

struct SynthShardSummary {
  std::filesystem::path parts, run_log;
  size_t owned = 0, done = 0, skipped = 0;  // skipped: its part was already there
  std::vector<size_t> failed;               // frame indices whose synthesis failed (errors are in the run log)
};

// `synth --shard K/N`: synthesises the frames at positions i of the selection with i % N == K into parts,
// skipping frames whose part exists (a killed shard resumes; staging folders it left are removed). A frame
// that fails is logged and the others go on. Refuses (InputError) when `out` exists without --overwrite, or
// when an existing part was made for a different request (log, scenario, assets or render options).
SynthShardSummary RunSynthShard(const SynthRequest& request, const ShardSpec& shard);

// `synth --merge`: the parts of every selected frame -> `out`, exactly as a local run writes it. InputError,
// before anything is created, listing the frames that have no part, or naming a part of a different request.
// The parts folder is left in place.
SynthSummary MergeSynthParts(const SynthRequest& request);

// `synth --dry-run`: plans the selected frames (PlanSynthesis; --asset / bank assets optional: without them a
// category stands at its default size), renders nothing, and writes `out` (StagingDirectory) with plan.json
// (SynthPlanToJson) and plan.html (synth/report.h WritePlanReport). Works on logs whose sensor files are
// absent (only the poses and boxes are read).
struct DryRunSummary {
  std::filesystem::path out;
  SynthPlan plan;
  size_t objects = 0;
  std::vector<std::string> lines;  // human summary: per sequence and per arrangement / object request
};
DryRunSummary RunSynthDryRun(const SynthRequest& request);

}  // namespace sd
