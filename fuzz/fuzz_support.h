#pragma once
// What every fuzz target shares (docs/fuzzing.md). A target defines LLVMFuzzerTestOneInput and FuzzSeeds();
// the same source links either with libFuzzer (clang, SYNTHDRIVE_FUZZ) or with replay_main.cpp (any compiler,
// a CTest that replays the seeds and fuzz/regressions/<target>/).
//
// The contract a target checks: on any bytes the parser returns or throws sd::InputError (the project's tier for
// bad input, core/error.h). Any other exception, a crash, an SD_CHECK abort, a sanitizer report, a hang or
// unbounded memory is a bug.
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "core/error.h"

namespace sd::fuzz {

// One seed input: a name (for the corpus file) and its bytes.
struct Seed {
  std::string name;
  std::string bytes;
};

// The target's seed corpus, made at run time from the repo's data/ (defined by each target).
std::vector<Seed> FuzzSeeds();

// Runs `parse`; an InputError is the expected outcome for bad input and is swallowed. Everything else escapes,
// so libFuzzer (or the replay test) reports it.
template <typename Fn>
int ExpectOnlyInputErrors(Fn&& parse) {
  try {
    std::forward<Fn>(parse)();
  } catch (const InputError&) {
  }
  return 0;
}

inline std::string_view AsText(const uint8_t* data, size_t size) {
  return {reinterpret_cast<const char*>(data), size};
}

// A file of the repo (data/...), from the source tree this binary was configured from.
std::filesystem::path RepoPath(const std::string& relative);
// ../shared/data beside the repo, where the larger datasets live (may be absent: targets then seed less).
std::filesystem::path SharedDataPath(const std::string& relative);
std::string ReadBytes(const std::filesystem::path& path);

// A fresh, empty directory for this input, under one per-process scratch folder removed at exit. Parsers that
// only take paths read the input from files written here.
std::filesystem::path FreshCaseDir();
void WriteBytes(const std::filesystem::path& path, std::string_view bytes);

// Several files in one input, for readers of a directory layout (nuScenes tables, KITTI, PandaSet, OBJ + MTL,
// glTF + .bin). The text form keeps names and contents visible to the mutator:
//   "#@file:<relative path>\n<content>\n#@file:<next path>\n<content>..."
// A content ends at the next "\n#@file:". Unpacking ignores anything before the first marker and any file whose
// name is not a plain relative path (letters, digits, "._+-/", no "..", at most 4 levels).
using Archive = std::vector<std::pair<std::string, std::string>>;
std::string PackArchive(const Archive& files);
Archive UnpackArchive(std::string_view bytes);
// Writes the archive's files under `dir`; returns the paths written, in archive order.
std::vector<std::filesystem::path> WriteArchive(const Archive& files, const std::filesystem::path& dir);

// A copy of `image_file` shrunk to at most `max_side` pixels a side and encoded as `format` ("png" or "jpg"):
// real image content in a seed small enough to fuzz quickly.
std::string SmallImageFrom(const std::filesystem::path& image_file, int max_side, const std::string& format,
                           int channels = 0);

}  // namespace sd::fuzz
