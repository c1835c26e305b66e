#include "core/parallel.h"

#include <memory>

#include <tbb/blocked_range.h>
#include <tbb/global_control.h>
#include <tbb/parallel_for.h>

namespace sd {

void ParallelForRange(size_t begin, size_t end, size_t grain, const std::function<void(size_t, size_t)>& body) {
  if (end <= begin) return;
  tbb::parallel_for(tbb::blocked_range<size_t>(begin, end, grain == 0 ? 1 : grain),
                    [&](const tbb::blocked_range<size_t>& r) { body(r.begin(), r.end()); });
}

void SetMaxThreads(int n) {
  static std::unique_ptr<tbb::global_control> control;
  control.reset();
  if (n > 0) control = std::make_unique<tbb::global_control>(tbb::global_control::max_allowed_parallelism, n);
}

int MaxThreads() {
  return static_cast<int>(tbb::global_control::active_value(tbb::global_control::max_allowed_parallelism));
}

}  // namespace sd
