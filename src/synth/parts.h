#pragma once
// A synth *part*: one frame's outcome on disk, `<out>.parts/<index>-<token>/`, written through a
// StagingDirectory so it exists complete or not at all. part.json holds the request fingerprint, the frame, the
// labels and everything synth.json and the report need; images/<n>.png the replacement images (lossless,
// re-encoded by WriteDerivative exactly as a local run encodes them); sweep.bin the replacement sweep in its
// record layout. The ground model, the original images and sweep are not stored: the merge recomputes or
// re-reads them from the log. Parts hold no wall-clock data and every double round-trips exactly, so the
// merge's bytes do not depend on which process made which part.
#include <filesystem>
#include <string>

#include <nlohmann/json.hpp>

#include "synth/outcome.h"
#include "synth/request.h"

namespace sd {

// The folder name of a frame's part: "<index>-<token>", the token made safe for a file name.
std::string PartName(const Log& log, size_t frame_index);

// What a part's bytes depend on: the log, the scenario, the assets, the render options, the harmoniser that
// resolved ("auto" is learned on one machine and classical on another) and the plan (every shard plans from the
// whole selection). Write options (JPEG quality, symlinks) and the frame selection apply at the merge, so parts
// stay valid across them. `in`: loaded but for its fingerprint.
nlohmann::json RequestFingerprint(const SynthRequest& request, const SynthInputs& in);

// Writes `outcome` into the (staging) folder `dir`.
void WritePart(const std::filesystem::path& dir, const FrameOutcome& outcome, const SynthInputs& in, const SynthOptions& options);

// InputError unless the part was made for the request `in` describes; names the first thing that differs.
void CheckPartRequest(const std::filesystem::path& part_json, const nlohmann::json& part, const SynthInputs& in);

// Reads a part back. `for_report`: also the original images, sweep and ground the report draws.
FrameOutcome ReadPart(const std::filesystem::path& dir, size_t frame_index, const SynthInputs& in, bool for_report);

}  // namespace sd
