#include "datasets/writers.h"

#include <set>

#include "core/error.h"
#include "datasets/format.h"

namespace fs = std::filesystem;

namespace sd {

namespace {

void CheckEdits(const Log& log, const std::vector<FrameEdit>& edits) {
  std::set<size_t> seen;
  for (const FrameEdit& e : edits) {
    if (e.frame_index >= log.frames.size())
      throw InputError(log.source, Msg() << "edit names frame " << e.frame_index << " but the log has " << log.frames.size());
    if (!seen.insert(e.frame_index).second) throw InputError(log.source, Msg() << "frame " << e.frame_index << " edited twice");
  }
}

}  // namespace

std::vector<fs::path> WriteDerivative(const Log& log, const std::vector<FrameEdit>& edits, const fs::path& out_dir,
                                      const WriteOptions& options) {
  if (!fs::is_directory(out_dir)) throw InputError(out_dir, "output directory does not exist");
  CheckEdits(log, edits);
  const LogFormatInfo& format = FormatInfo(log.format);
  if (!format.write) throw InputError(log.source, format.read_only_message);
  return format.write(log, edits, out_dir, options);
}

}  // namespace sd
