#pragma once
// `synthdrive synth`: insert assets into a real driving log, camera and LiDAR, with labels, written as a
// derivative dataset in the input's own format.
//
// A batch command (DESIGN.md): the work list is the selected frames. Each frame is synthesised into a *part*,
// `<out>.parts/<index>-<token>/` (written through a StagingDirectory, so it exists complete or not at all), and
// the merge turns the parts of every selected frame into the derivative dataset. A local run is exactly
// "shard 0/1, then merge" (RunSynth), so shards + merge write the same bytes as a local run by construction.
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include "assetgen/asset.h"
#include "core/image.h"
#include "core/shard.h"
#include "datasets/readers.h"
#include "datasets/writers.h"
#include "synth/ground.h"
#include "synth/placement.h"
#include "synth/scenario.h"

namespace sd {

struct SynthOptions {
  int samples_per_pixel = 4;
  int ao_samples = 16;
  std::vector<std::string> frames;  // frame tokens or indices to synthesise; empty = all frames
  WriteOptions write;
  bool overwrite = false;
  bool report = true;
  // Tests only: called while a part is half written (its images and sweep are in the staging folder, its
  // part.json is not), so a test can kill the process mid-part.
  std::function<void(size_t frame_index, const std::filesystem::path& staging)> part_written_hook;
};

struct SynthRequest {
  std::filesystem::path log;            // dataset root or info file
  OpenLogOptions log_options;
  std::vector<std::filesystem::path> assets;  // asset folders
  std::filesystem::path scenario;
  std::filesystem::path out;
  SynthOptions options;
};

// What happened to one inserted object in one frame, for labels, reports and verification.
struct ObjectOutcome {
  PlacedObject placement;
  AddedObject label;
  int lidar_points = 0;
  double rendered_pixels = 0, visible_pixels = 0;
};

struct CameraOutcome {
  std::string channel;
  ImageU8 before, after;  // only for cameras the objects touch
  std::vector<int> objects;  // indices into FrameOutcome::objects drawn in this camera
};

struct FrameOutcome {
  size_t frame_index = 0;
  FrameEdit edit;
  std::vector<ObjectOutcome> objects;
  std::vector<CameraOutcome> cameras;
  GroundModel ground;
  std::string sun_source;
  PointCloud sweep_before;  // sensor frame
  std::vector<std::pair<int, int>> lidar_object_points;  // (point index in edit.points, object index)
};

// Synthesises one frame in memory (no files written).
FrameOutcome SynthesizeFrame(const Log& log, size_t frame_index, const std::vector<Asset>& assets,
                             const Scenario& scenario, const SynthOptions& options);

struct SynthSummary {
  std::filesystem::path out, report;
  size_t frames = 0, objects = 0;
};

// The whole command: loads everything, synthesises the selected frames, writes the derivative dataset,
// synth.json (placements and provenance) and report.html into `out` atomically. It is RunSynthShard(0/1)
// followed by MergeSynthParts; the parts folder is removed once the output is committed (and kept when a
// frame failed and others have parts, so a rerun resumes). A frame's failure does not stop the others; the
// first failure is rethrown at the end.
SynthSummary RunSynth(const SynthRequest& request);

// Where the parts of `out` live: "<out>.parts" (a sibling, so the output folder itself only ever appears
// complete). Besides one folder per frame it holds each shard's run log, log-<K>-of-<N>.jsonl: one line per
// frame, {"frame", "token", "status": done|skipped|failed, "error", "seconds"} (seconds: wall clock).
std::filesystem::path SynthPartsDir(const std::filesystem::path& out);

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

}  // namespace sd
