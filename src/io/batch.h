#pragma once
// The one batch runner (DESIGN.md, batch commands): `synth`, `generate --manifest` and `mine index` hand it
// their work list and it does the rest the same way for all three:
//  - `--shard K/N`: the shard owns the items at positions i % N == K (core/shard.h);
//  - resume: an owned item whose output is complete is skipped, and what a killed run left half-written of an
//    owned item (StagingDirectory's "<output>.tmp-*" siblings) is removed first;
//  - a run log: one JSON line per owned item, appended and flushed as it happens, so a killed or failed shard
//    says what it did: the item's own fields, "status" (done | skipped | failed), "error", "seconds" (wall
//    clock), and whatever the item adds;
//  - failures: an item that throws is logged and the others go on; the caller decides the exit status.
#include <cstddef>
#include <exception>
#include <filesystem>
#include <functional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/shard.h"

namespace sd {

struct BatchJob {
  size_t size = 0;  // the work list: items 0 .. size-1, the same list in every shard
  // The fields that name item i in its run-log line, e.g. {"frame": 3, "token": "..."}.
  std::function<nlohmann::json(size_t)> describe;
  // Item i for people, in error messages ("frame 3 (token)", "manifest.jsonl:4").
  std::function<std::string(size_t)> name;
  // Item i's output folder or file, written through a StagingDirectory or a temporary sibling; empty: none.
  std::function<std::filesystem::path(size_t)> output;
  // True when item i's output is complete: it is skipped.
  std::function<bool(size_t)> complete;
  // Does item i; throws on failure. May add fields to the item's run-log line.
  std::function<void(size_t, nlohmann::json* line)> run;
};

struct BatchOptions {
  std::string label;               // the progress line's ("synthesising frames")
  ShardSpec shard;
  std::filesystem::path run_log;   // created with its folder when the shard owns an item
  bool show_progress = true;
  bool log_failures = true;        // each failure logged (Error) as it happens, "<name>: <error>"
};

struct BatchFailure {
  size_t item = 0;
  std::string error;
  std::exception_ptr exception;  // to rethrow (a local run rethrows the first)
};

struct BatchSummary {
  std::filesystem::path run_log;
  size_t owned = 0, done = 0, skipped = 0;
  std::vector<BatchFailure> failures;  // in work-list order
};

// Runs the shard's items of `job` in work-list order. InputError only for the run log itself (it cannot be
// opened); everything an item throws is a failure of that item.
BatchSummary RunBatch(const BatchJob& job, const BatchOptions& options);

// Removes what a killed writer of `path` left: its siblings named "<filename>.tmp-*" (io/files.h
// TemporarySibling). Only the process that owns an output writes it, so whatever is there is stale.
void RemoveStaleTemporaries(const std::filesystem::path& path);

}  // namespace sd
