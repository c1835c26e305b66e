#pragma once
// Test support: where the repo's data/ and the optional ../shared/data are, and temporary directories.
#include <cstdint>
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

namespace sd::testing {

// <repo>/data/<rel>. The repo root comes from $SYNTHDRIVE_SOURCE_DIR (set by CTest), else it is the checkout the
// tests were built from.
std::filesystem::path RepoData(const std::string& rel);
// <repo>/../shared/data/<rel>, or an empty path when ../shared is absent (tests then GTEST_SKIP).
std::filesystem::path SharedData(const std::string& rel);
// <dir>/<rel> where dir is $SYNTHDRIVE_TEST_MODELS: the tiny TorchScript models tools/testing/make_test_models.py
// builds before the model tests run (a CTest fixture). Empty when they could not be built (no python3-torch).
std::filesystem::path TestModel(const std::string& rel);
// The raw little-endian tensors the tiny-model generators under tools/testing/ write: `file` holds the values,
// `file`.json {"shape": [...]}. The shape is appended to `shape`; a short file fails the test.
std::vector<float> ReadRawFloats(const std::filesystem::path& file, std::vector<int64_t>* shape);
std::vector<uint8_t> ReadRawBytes(const std::filesystem::path& file, std::vector<int64_t>* shape);

// Debian's python3 with numpy and pandas, the real consumers the format tests check our files against
// ($SYNTHDRIVE_PANDAS_PYTHON, else what CMake found); empty when there is none (tests then GTEST_SKIP).
std::string PandasPython();
// Runs `script` (a path under the repo, e.g. "tools/testing/pandaset_check.py") with PandasPython() and `args`
// (each shell-quoted here); returns the exit status and puts stdout + stderr in `output`.
int RunPython(const std::string& script, const std::vector<std::string>& args, std::string* output);

// Sets an environment variable for the life of the object, then restores it.
class ScopedEnv {
 public:
  ScopedEnv(const char* name, const std::string& value);
  ~ScopedEnv();
  ScopedEnv(const ScopedEnv&) = delete;
  ScopedEnv& operator=(const ScopedEnv&) = delete;

 private:
  const char* name_;
  std::optional<std::string> old_;
};

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

// Skips the current test with a clear message when there is no python3 with numpy and pandas.
#define SD_REQUIRE_PANDAS_PYTHON()                                                                     \
  if (::sd::testing::PandasPython().empty())                                                           \
  GTEST_SKIP() << "no python3 with numpy and pandas (SYNTHDRIVE_PANDAS_PYTHON): the consumer checks need it"

// Skips the current test with a clear message when the tiny test models were not built.
#define SD_REQUIRE_TEST_MODEL(var, rel)                                                        \
  const std::filesystem::path var = ::sd::testing::TestModel(rel);                             \
  if (var.empty()) GTEST_SKIP() << "tiny test model " << (rel) << " not built (needs python3 with torch)"
