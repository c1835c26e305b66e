#pragma once
// Where a benchmark finds the repo's data/ and ../shared/data. Header-only, benchmarks only.
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <optional>
#include <vector>

namespace sd::bench {

// $SYNTHDRIVE_SOURCE_DIR, else the executable's build/bin/../../, whichever holds data/driving and data/assets.
inline std::optional<std::filesystem::path> FindRepoRoot() {
  namespace fs = std::filesystem;
  std::vector<fs::path> candidates;
  if (const char* env = std::getenv("SYNTHDRIVE_SOURCE_DIR"); env && *env) candidates.emplace_back(env);
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (!ec) candidates.push_back(exe.parent_path() / ".." / "..");
  for (const auto& c : candidates)
    if (fs::is_directory(c / "data" / "driving") && fs::is_directory(c / "data" / "assets")) return fs::canonical(c);
  return std::nullopt;
}

// FindRepoRoot, or nullopt after the one-line error a benchmark stops with (exit status 1).
inline std::optional<std::filesystem::path> RepoRootOrSay() {
  std::optional<std::filesystem::path> root = FindRepoRoot();
  if (!root) std::fprintf(stderr, "error: no repo root with data/ (set SYNTHDRIVE_SOURCE_DIR)\n");
  return root;
}

// ../shared/data/driving beside the repo (it may not exist: the benchmarks say what they skip).
inline std::filesystem::path SharedDriving(const std::filesystem::path& repo_root) {
  return repo_root / ".." / "shared" / "data" / "driving";
}

}  // namespace sd::bench
