#include "io/files.h"

#include <fcntl.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <sstream>

#include "core/error.h"

namespace sd {
namespace fs = std::filesystem;

std::string ReadFileToString(const fs::path& path) {
  std::error_code ec;
  if (!fs::exists(path, ec)) throw InputError(path, "file not found");
  if (fs::is_directory(path, ec)) throw InputError(path, "is a directory, expected a file");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, std::string("cannot open: ") + std::strerror(errno));
  std::ostringstream ss;
  ss << in.rdbuf();
  if (in.bad()) throw InputError(path, "read error");
  return ss.str();
}

fs::path TemporarySibling(const fs::path& path) {
  static std::atomic<int> counter{0};
  return path.parent_path() / (path.filename().string() + ".tmp-" + std::to_string(getpid()) + "-" +
                               std::to_string(counter++));
}

void WriteFileAtomic(const fs::path& path, std::string_view bytes) {
  if (path.has_parent_path()) fs::create_directories(path.parent_path());
  const fs::path tmp = TemporarySibling(path);
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) throw InputError(path, std::string("cannot write: ") + std::strerror(errno));
  size_t done = 0;
  while (done < bytes.size()) {
    const ssize_t n = ::write(fd, bytes.data() + done, bytes.size() - done);
    if (n < 0) {
      if (errno == EINTR) continue;
      const std::string err = std::strerror(errno);
      ::close(fd);
      ::unlink(tmp.c_str());
      throw InputError(path, "write failed: " + err);
    }
    done += static_cast<size_t>(n);
  }
  if (::fsync(fd) != 0 || ::close(fd) != 0) {
    ::unlink(tmp.c_str());
    throw InputError(path, "write failed while flushing");
  }
  std::error_code ec;
  fs::rename(tmp, path, ec);
  if (ec) {
    fs::remove(tmp);
    throw InputError(path, "cannot rename into place: " + ec.message());
  }
}

StagingDirectory::StagingDirectory(const fs::path& final_dir, bool overwrite)
    : final_(fs::absolute(final_dir).lexically_normal()), overwrite_(overwrite) {
  if (final_.filename().empty()) final_ = final_.parent_path();
  std::error_code ec;
  if (fs::exists(final_, ec) && !overwrite_)
    throw InputError(final_, "output already exists (pass --overwrite to replace it)");
  fs::create_directories(final_.parent_path(), ec);
  if (ec) throw InputError(final_.parent_path(), "cannot create directory: " + ec.message());
  temp_ = TemporarySibling(final_);
  fs::create_directories(temp_, ec);
  if (ec) throw InputError(temp_, "cannot create directory: " + ec.message());
}

StagingDirectory::~StagingDirectory() {
  if (!committed_) {
    std::error_code ec;
    fs::remove_all(temp_, ec);
  }
}

void StagingDirectory::Commit() {
  std::error_code ec;
  fs::path old;
  if (fs::exists(final_, ec)) {
    if (!overwrite_) throw InputError(final_, "output appeared while we were writing; refusing to replace it");
    // Move the old tree aside first so a failure in between never loses both.
    old = TemporarySibling(final_);
    fs::rename(final_, old, ec);
    if (ec) throw InputError(final_, "cannot move old output aside: " + ec.message());
  }
  fs::rename(temp_, final_, ec);
  if (ec) {
    if (!old.empty()) fs::rename(old, final_);
    throw InputError(final_, "cannot publish output: " + ec.message());
  }
  committed_ = true;
  if (!old.empty()) fs::remove_all(old, ec);
}

}  // namespace sd
