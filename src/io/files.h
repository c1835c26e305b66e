#pragma once
// Files that never leave partial output behind: everything is written under a temporary name in the same
// directory and renamed into place when complete (rename is atomic on POSIX file systems).
#include <filesystem>
#include <string>
#include <string_view>
#include <vector>

namespace sd {

// Whole file as bytes; InputError naming the file when missing, unreadable, or not a regular file (a FIFO or a
// device is never read as data).
std::string ReadFileToString(const std::filesystem::path& path);
// Writes `bytes` to `path` via a temporary sibling + fsync + rename. Creates parent directories.
void WriteFileAtomic(const std::filesystem::path& path, std::string_view bytes);
// A temporary sibling name for `path` that no other process uses ("<name>.tmp-<pid>-<n>").
std::filesystem::path TemporarySibling(const std::filesystem::path& path);

// InputError naming `out` when writing it could destroy or change an input: `out` is one of `inputs`, holds one
// (replacing it with --overwrite would delete the input), or lies inside an input folder. Paths are compared
// after resolving symlinks and ".." (std::filesystem::weakly_canonical), so a link or another spelling of the
// same place does not slip past. Inputs that do not exist are skipped (their readers report them). Costs one
// canonicalisation per distinct input folder, so a log's thousands of sensor files are cheap to pass.
void RefuseOutputOverInputs(const std::filesystem::path& out, const std::vector<std::filesystem::path>& inputs);

// An output directory built under a temporary name and published by Commit():
//   StagingDirectory out(dir, overwrite);  ...write under out.path()...;  out.Commit();
// If the object dies without Commit() (error, exception), the temporary tree is removed and `dir` is left
// exactly as it was; what a killed writer of `dir` left ("<dir>.tmp-<pid>-*" of a process no longer running) is
// removed when the next one starts. An existing `dir` is refused (InputError) unless `overwrite`; with overwrite it is
// replaced only at Commit().
class StagingDirectory {
 public:
  StagingDirectory(const std::filesystem::path& final_dir, bool overwrite);
  ~StagingDirectory();
  StagingDirectory(const StagingDirectory&) = delete;
  StagingDirectory& operator=(const StagingDirectory&) = delete;

  const std::filesystem::path& path() const { return temp_; }
  const std::filesystem::path& final_path() const { return final_; }
  void Commit();

 private:
  std::filesystem::path final_, temp_;
  bool overwrite_ = false, committed_ = false;
};

}  // namespace sd
