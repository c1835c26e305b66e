#pragma once
// The one place that picks the threading library (TBB). Kernels call ParallelFor and never see TBB.
#include <cstddef>
#include <functional>

namespace sd {

// Calls body(begin_i, end_i) on disjoint sub-ranges of [begin, end), in parallel. `grain` is the smallest
// sub-range worth a task. The body must not throw.
void ParallelForRange(size_t begin, size_t end, size_t grain, const std::function<void(size_t, size_t)>& body);

template <typename F>
void ParallelFor(size_t begin, size_t end, F&& body, size_t grain = 1) {
  ParallelForRange(begin, end, grain, [&](size_t b, size_t e) {
    for (size_t i = b; i < e; ++i) body(i);
  });
}

// Limits worker threads for the life of the process (0 = library default: all cores).
void SetMaxThreads(int n);
// The worker threads kernels may use now (the limit above, or all cores). For libraries with their own pools
// (LibTorch's intra-op threads), so they follow --threads too.
int MaxThreads();

}  // namespace sd
