#include "fuzz/fuzz_support.h"

#include <unistd.h>

#include <algorithm>
#include <cctype>
#include <cstdlib>
#include <fstream>
#include <sstream>

#include "io/image_io.h"

namespace sd::fuzz {
namespace fs = std::filesystem;

namespace {

constexpr std::string_view kFileMarker = "#@file:";

// Removes the scratch folder when the process ends normally (libFuzzer's -max_total_time exits through exit()).
struct ScratchFolder {
  fs::path dir;
  ScratchFolder() {
    dir = fs::temp_directory_path() / ("synthdrive-fuzz-" + std::to_string(::getpid()));
    fs::remove_all(dir);
    fs::create_directories(dir);
  }
  ~ScratchFolder() {
    std::error_code ec;
    fs::remove_all(dir, ec);
  }
};

bool IsPlainRelativePath(std::string_view name) {
  if (name.empty() || name.size() > 200 || name.front() == '/') return false;
  const bool plain_chars = std::all_of(name.begin(), name.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) || c == '.' || c == '_' || c == '+' || c == '-' || c == '/';
  });
  if (!plain_chars) return false;
  int depth = 0;
  for (const auto& part : fs::path(name)) {
    if (part.empty() || part == "." || part == "..") return false;
    ++depth;
  }
  return depth <= 4;
}

}  // namespace

fs::path RepoPath(const std::string& relative) { return fs::path(SYNTHDRIVE_SOURCE_DIR) / relative; }

fs::path SharedDataPath(const std::string& relative) {
  return fs::path(SYNTHDRIVE_SOURCE_DIR).parent_path() / "shared" / "data" / relative;
}

std::string ReadBytes(const fs::path& path) {
  std::ifstream in(path, std::ios::binary);
  std::ostringstream out;
  out << in.rdbuf();
  return out.str();
}

fs::path FreshCaseDir() {
  static ScratchFolder scratch;
  const fs::path dir = scratch.dir / "case";
  fs::remove_all(dir);
  fs::create_directories(dir);
  return dir;
}

void WriteBytes(const fs::path& path, std::string_view bytes) {
  fs::create_directories(path.parent_path());
  std::ofstream out(path, std::ios::binary);
  out.write(bytes.data(), static_cast<std::streamsize>(bytes.size()));
}

std::string PackArchive(const Archive& files) {
  std::string out;
  for (const auto& [name, content] : files) {
    if (!out.empty()) out += '\n';
    out.append(kFileMarker).append(name).append("\n").append(content);
  }
  return out;
}

Archive UnpackArchive(std::string_view bytes) {
  Archive files;
  size_t at = bytes.substr(0, kFileMarker.size()) == kFileMarker ? 0 : bytes.find(std::string("\n").append(kFileMarker));
  if (at != 0 && at != std::string_view::npos) ++at;
  while (at != std::string_view::npos && at < bytes.size()) {
    const size_t name_begin = at + kFileMarker.size();
    const size_t name_end = bytes.find('\n', name_begin);
    if (name_end == std::string_view::npos) break;
    const size_t next = bytes.find(std::string("\n").append(kFileMarker), name_end);
    const size_t content_end = next == std::string_view::npos ? bytes.size() : next;
    const std::string_view name = bytes.substr(name_begin, name_end - name_begin);
    // The same name twice would make the later copy win silently; keeping the first makes inputs minimise well.
    const bool seen = std::any_of(files.begin(), files.end(), [&](const auto& f) { return f.first == name; });
    if (IsPlainRelativePath(name) && !seen && files.size() < 64)
      files.emplace_back(std::string(name), std::string(bytes.substr(name_end + 1, content_end - name_end - 1)));
    at = next == std::string_view::npos ? next : next + 1;
  }
  return files;
}

std::vector<fs::path> WriteArchive(const Archive& files, const fs::path& dir) {
  std::vector<fs::path> written;
  for (const auto& [name, content] : files) {
    const fs::path path = dir / name;
    std::error_code ec;
    // A name that is a prefix directory of another ("a" and "a/b") cannot be both: the later one is dropped.
    if (fs::exists(path, ec) || (fs::exists(path.parent_path(), ec) && !fs::is_directory(path.parent_path(), ec)))
      continue;
    fs::create_directories(path.parent_path(), ec);
    if (ec) continue;
    WriteBytes(path, content);
    written.push_back(path);
  }
  return written;
}

std::string SmallImageFrom(const fs::path& image_file, int max_side, const std::string& format, int channels) {
  const ImageU8 full = ReadImage(image_file, channels);
  const int step = std::max(1, (std::max(full.width(), full.height()) + max_side - 1) / max_side);
  ImageU8 small(std::max(1, full.width() / step), std::max(1, full.height() / step), full.channels());
  for (int y = 0; y < small.height(); ++y)
    for (int x = 0; x < small.width(); ++x)
      for (int c = 0; c < full.channels(); ++c) small.at(x, y, c) = full.at(x * step, y * step, c);
  return EncodeImage(small, format);
}

}  // namespace sd::fuzz
