#pragma once
// Test support: where the repo's data/ and the optional ../shared/data are, and temporary directories.
#include <filesystem>
#include <string>

namespace sd::testing {

// <repo>/data/<rel>. The repo root comes from $SYNTHDRIVE_SOURCE_DIR (set by CTest).
std::filesystem::path RepoData(const std::string& rel);
// <repo>/../shared/data/<rel>, or an empty path when ../shared is absent (tests then GTEST_SKIP).
std::filesystem::path SharedData(const std::string& rel);
// A fresh, empty directory removed when the object dies.
class TempDir {
 public:
  TempDir();
  ~TempDir();
  const std::filesystem::path& path() const { return path_; }
  std::filesystem::path operator/(const std::string& rel) const { return path_ / rel; }

 private:
  std::filesystem::path path_;
};

}  // namespace sd::testing

// Skips the current test with a clear message when ../shared/data/<rel> is not present.
#define SD_REQUIRE_SHARED(var, rel)                                                            \
  const std::filesystem::path var = ::sd::testing::SharedData(rel);                             \
  if (var.empty()) GTEST_SKIP() << "../shared/data/" << (rel) << " not present (needs the shared data beside the repo)"
