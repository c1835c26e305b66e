#include "testing/testing.h"

#include <unistd.h>

#include <cstdlib>
#include <random>

namespace sd::testing {
namespace fs = std::filesystem;

static fs::path RepoRoot() {
  const char* env = std::getenv("SYNTHDRIVE_SOURCE_DIR");
  return env ? fs::path(env) : fs::current_path();
}

fs::path RepoData(const std::string& rel) { return RepoRoot() / "data" / rel; }

fs::path SharedData(const std::string& rel) {
  const fs::path p = RepoRoot().parent_path() / "shared" / "data" / rel;
  return fs::exists(p) ? p : fs::path();
}

fs::path TestModel(const std::string& rel) {
  const char* dir = std::getenv("SYNTHDRIVE_TEST_MODELS");
  if (!dir || !*dir) return {};
  const fs::path p = fs::path(dir) / rel;
  return fs::exists(p) ? p : fs::path();
}

TempDir::TempDir() {
  std::random_device rd;
  path_ = fs::temp_directory_path() / ("synthdrive-test-" + std::to_string(getpid()) + "-" + std::to_string(rd()));
  fs::create_directories(path_);
}

TempDir::~TempDir() {
  std::error_code ec;
  fs::remove_all(path_, ec);
}

}  // namespace sd::testing
