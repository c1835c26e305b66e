#include "io/batch.h"

#include <chrono>
#include <fstream>

#include "core/error.h"
#include "core/log.h"

namespace sd {
namespace fs = std::filesystem;

void RemoveStaleTemporaries(const fs::path& path) {
  const std::string prefix = path.filename().string() + ".tmp-";
  std::error_code ec;
  for (const auto& e : fs::directory_iterator(path.parent_path(), ec)) {
    if (e.path().filename().string().rfind(prefix, 0) != 0) continue;
    SD_LOG(Debug, "removing the unfinished " << e.path().string());
    fs::remove_all(e.path(), ec);
  }
}

BatchSummary RunBatch(const BatchJob& job, const BatchOptions& options) {
  SD_CHECK(job.run && job.complete && job.describe && job.name, << "batch job without its callbacks");
  BatchSummary summary;
  summary.run_log = options.run_log;
  std::vector<size_t> owned;
  for (size_t i = 0; i < job.size; ++i)
    if (options.shard.Owns(i)) owned.push_back(i);
  summary.owned = owned.size();
  if (owned.empty()) return summary;
  if (job.output)
    for (size_t i : owned)
      if (const fs::path out = job.output(i); !out.empty()) RemoveStaleTemporaries(out);

  std::error_code ec;
  fs::create_directories(options.run_log.parent_path(), ec);
  std::ofstream run_log(options.run_log, std::ios::app);
  if (!run_log) throw InputError(options.run_log, "cannot open for appending");
  std::unique_ptr<Progress> progress;
  if (options.show_progress) progress = std::make_unique<Progress>(options.label + " (shard " + options.shard.ToString() + ")", owned.size());
  for (size_t i : owned) {
    const auto start = std::chrono::steady_clock::now();
    nlohmann::json line = job.describe(i);
    if (job.complete(i)) {
      ++summary.skipped;
      line["status"] = "skipped";
      line["error"] = "";
    } else {
      try {
        job.run(i, &line);
        ++summary.done;
        line["status"] = "done";
        line["error"] = "";
      } catch (const std::exception& e) {
        summary.failures.push_back({i, e.what(), std::current_exception()});
        line["status"] = "failed";
        line["error"] = e.what();
        if (options.log_failures) {
          // InputErrors already name their file; the item's name goes first unless the message starts with it.
          const std::string name = job.name(i), what = e.what();
          SD_LOG(Error, (what.rfind(name, 0) == 0 ? what : name + ": " + what));
        }
      }
    }
    line["seconds"] = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    run_log << line.dump() << '\n' << std::flush;
    if (progress) progress->Advance();
  }
  if (progress) progress->Finish();
  return summary;
}

}  // namespace sd
