#include "testing/testing.h"

#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>

#include <cstdlib>
#include <fstream>
#include <random>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

namespace sd::testing {
namespace fs = std::filesystem;

// $SYNTHDRIVE_SOURCE_DIR (CTest sets it; so does a run on another machine), else the checkout these tests were
// built from.
static fs::path RepoRoot() {
  const char* env = std::getenv("SYNTHDRIVE_SOURCE_DIR");
  return env && *env ? fs::path(env) : fs::path(SYNTHDRIVE_SOURCE_DIR_DEFAULT);
}

fs::path RepoData(const std::string& rel) { return RepoRoot() / "data" / rel; }

fs::path SharedData(const std::string& rel) {
  const fs::path p = RepoRoot().parent_path() / "shared" / "data" / rel;
  return fs::exists(p) ? p : fs::path();
}

std::string PandasPython() {
  if (const char* env = std::getenv("SYNTHDRIVE_PANDAS_PYTHON")) return env;
  return SYNTHDRIVE_PANDAS_PYTHON_DEFAULT;
}

int RunPython(const std::string& script, const std::vector<std::string>& args, std::string* output) {
  auto quote = [](const std::string& s) {
    std::string q = "'";
    for (char c : s) q += c == '\'' ? std::string("'\\''") : std::string(1, c);
    return q + "'";
  };
  std::string cmd = quote(PandasPython());
  cmd.append(" ").append(quote((RepoRoot() / script).string()));
  for (const std::string& a : args) cmd.append(" ").append(quote(a));  // (not " " + ...: GCC 12 -Wrestrict, falsely)
  cmd.append(" 2>&1");
  FILE* p = popen(cmd.c_str(), "r");
  if (!p) return -1;
  char buf[4096];
  size_t n;
  output->clear();
  while ((n = fread(buf, 1, sizeof(buf), p)) > 0) output->append(buf, n);
  const int status = pclose(p);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

fs::path TestModel(const std::string& rel) {
  const char* dir = std::getenv("SYNTHDRIVE_TEST_MODELS");
  if (!dir || !*dir) return {};
  const fs::path p = fs::path(dir) / rel;
  return fs::exists(p) ? p : fs::path();
}

namespace {

template <typename T>
std::vector<T> ReadRaw(const fs::path& file, std::vector<int64_t>* shape) {
  std::ifstream meta(file.string() + ".json");
  const nlohmann::json j = nlohmann::json::parse(meta);
  size_t n = 1;
  for (const auto& d : j["shape"]) {
    shape->push_back(d.get<int64_t>());
    n *= static_cast<size_t>(d.get<int64_t>());
  }
  std::vector<T> values(n);
  std::ifstream in(file, std::ios::binary);
  in.read(reinterpret_cast<char*>(values.data()), static_cast<std::streamsize>(n * sizeof(T)));
  EXPECT_TRUE(in.good()) << file << " holds fewer than " << n << " values";
  return values;
}

}  // namespace

std::vector<float> ReadRawFloats(const fs::path& file, std::vector<int64_t>* shape) { return ReadRaw<float>(file, shape); }
std::vector<uint8_t> ReadRawBytes(const fs::path& file, std::vector<int64_t>* shape) {
  return ReadRaw<uint8_t>(file, shape);
}

ScopedEnv::ScopedEnv(const char* name, const std::string& value) : name_(name) {
  if (const char* old = std::getenv(name)) old_ = old;
  setenv(name, value.c_str(), 1);
}

ScopedEnv::~ScopedEnv() {
  if (old_) setenv(name_, old_->c_str(), 1);
  else unsetenv(name_);
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
