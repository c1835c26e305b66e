#include "io/files.h"

#include <fcntl.h>
#include <signal.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <cstring>
#include <fstream>
#include <map>
#include <sstream>

#include "core/error.h"

namespace sd {
namespace fs = std::filesystem;

std::string ReadFileToString(const fs::path& path) {
  std::error_code ec;
  if (!fs::exists(path, ec)) throw InputError(path, "file not found");
  if (fs::is_directory(path, ec)) throw InputError(path, "is a directory, expected a file");
  // Data is read from regular files only: a FIFO blocks for ever and /dev/zero or /dev/urandom never end (they
  // ended in std::bad_alloc with no file named).
  if (!fs::is_regular_file(path, ec))
    throw InputError(path, "is not a regular file (a FIFO, device or socket): not read as data");
  std::ifstream in(path, std::ios::binary);
  if (!in) throw InputError(path, std::string("cannot open: ") + std::strerror(errno));
  // One read into a string of the file's size: a stringstream's doubling and final copy cost a second for
  // the 140 MB of a million-vector search index's codes.
  const uintmax_t size = fs::file_size(path, ec);
  std::string bytes(ec ? 0 : static_cast<size_t>(size), '\0');
  in.read(bytes.data(), static_cast<std::streamsize>(bytes.size()));
  bytes.resize(static_cast<size_t>(in.gcount()));
  if (in.bad()) throw InputError(path, "read error");
  if (!in.eof()) {  // the file grew since it was measured: the rest too
    std::ostringstream rest;
    rest << in.rdbuf();
    if (in.bad()) throw InputError(path, "read error");
    bytes += rest.str();
  }
  return bytes;
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

namespace {

// The canonical spelling of `p`: symlinks and ".." resolved as far as the path exists, the rest lexical.
fs::path Resolved(const fs::path& p) {
  std::error_code ec;
  fs::path r = fs::weakly_canonical(fs::absolute(p), ec);
  if (ec) r = fs::absolute(p).lexically_normal();
  if (r.filename().empty() && r.has_parent_path() && r != r.root_path()) r = r.parent_path();
  return r;
}

// True when `inner` is `outer` or lies below it (component-wise, so /a/bc is not inside /a/b).
bool IsWithin(const fs::path& inner, const fs::path& outer) {
  auto i = inner.begin();
  for (auto o = outer.begin(); o != outer.end(); ++o, ++i) {
    if (o->empty()) continue;  // a trailing separator
    if (i == inner.end() || *i != *o) return false;
  }
  return true;
}

}  // namespace

void RefuseOutputOverInputs(const fs::path& out, const std::vector<fs::path>& inputs) {
  const fs::path target = Resolved(out);
  // Files are checked through their folder: the folder's canonical form is computed once, however many of a
  // log's sensor files sit in it.
  std::map<fs::path, fs::path> resolved_dirs;
  for (const fs::path& input : inputs) {
    if (input.empty()) continue;
    std::error_code ec;
    const fs::file_status st = fs::status(input, ec);
    if (ec || !fs::exists(st)) continue;
    if (fs::is_directory(st)) {
      const fs::path dir = Resolved(input);
      if (dir == target) throw InputError(out, "is the input folder " + input.string() + "; choose another output");
      if (IsWithin(dir, target))
        throw InputError(out, "holds the input " + input.string() + " (replacing it would delete that); choose another output");
      if (IsWithin(target, dir))
        throw InputError(out, "lies inside the input folder " + input.string() + "; choose an output outside it");
      continue;
    }
    const fs::path parent = fs::absolute(input).parent_path();
    auto it = resolved_dirs.find(parent);
    if (it == resolved_dirs.end()) it = resolved_dirs.emplace(parent, Resolved(parent)).first;
    const fs::path file = it->second / Resolved(input).filename();
    if (file == target) throw InputError(out, "is the input file " + input.string() + "; choose another output");
    if (IsWithin(it->second, target))
      throw InputError(out, "holds the input " + input.string() + " (replacing it would delete that); choose another output");
  }
}

namespace {

// A "<name>.tmp-<pid>-<n>" sibling of `path` whose writer is no longer running on this machine: what a killed
// run (SIGKILL, a crash, a power cut) left. A live writer's (another run writing the same output) is left alone.
bool IsDeadWritersTemporary(const fs::path& candidate, const fs::path& path) {
  const std::string prefix = path.filename().string() + ".tmp-";
  const std::string name = candidate.filename().string();
  if (name.rfind(prefix, 0) != 0) return false;
  const size_t dash = name.find('-', prefix.size());
  if (dash == std::string::npos || dash == prefix.size()) return false;
  const std::string pid_text = name.substr(prefix.size(), dash - prefix.size());
  if (pid_text.find_first_not_of("0123456789") != std::string::npos || pid_text.size() > 9) return false;
  const pid_t pid = static_cast<pid_t>(std::stol(pid_text));
  return pid != getpid() && ::kill(pid, 0) != 0 && errno == ESRCH;
}

void RemoveDeadWritersTemporaries(const fs::path& path) {
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(path.parent_path(), ec))
    if (IsDeadWritersTemporary(e.path(), path)) fs::remove_all(e.path(), ec);
}

}  // namespace

StagingDirectory::StagingDirectory(const fs::path& final_dir, bool overwrite)
    : final_(fs::absolute(final_dir).lexically_normal()), overwrite_(overwrite) {
  if (final_.filename().empty()) final_ = final_.parent_path();
  RemoveDeadWritersTemporaries(final_);
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
