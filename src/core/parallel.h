#pragma once
// The one place that picks the threading library (TBB). Kernels call ParallelFor and never see TBB.
#include <cstddef>
#include <exception>
#include <functional>
#include <vector>

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

// ParallelFor for a body that may throw (ParallelFor's must not): every index still runs, each index's exception
// is caught, and once all are done the exception of the lowest index that threw is rethrown, the one a serial
// loop would have met first.
template <typename F>
void ParallelForRethrow(size_t begin, size_t end, F&& body, size_t grain = 1) {
  if (end <= begin) return;
  std::vector<std::exception_ptr> errors(end - begin);
  ParallelFor(
      begin, end,
      [&](size_t i) {
        try {
          body(i);
        } catch (...) {
          errors[i - begin] = std::current_exception();
        }
      },
      grain);
  for (const std::exception_ptr& e : errors)
    if (e) std::rethrow_exception(e);
}

// ParallelForRethrow over the rows [y0, y1) of an image, with int row indices: for the loops that give each
// pixel of a row from their inputs alone, so that rows in any order give the same image.
template <typename Body>
void ParallelRows(int y0, int y1, const Body& body) {
  if (y1 <= y0) return;
  ParallelForRethrow(static_cast<size_t>(y0), static_cast<size_t>(y1), [&](size_t y) { body(static_cast<int>(y)); });
}

// Limits worker threads for the life of the process (0 = library default: all cores).
void SetMaxThreads(int n);
// The worker threads kernels may use now (the limit above, or all cores). For libraries with their own pools
// (LibTorch's intra-op threads), so they follow --threads too.
int MaxThreads();

}  // namespace sd
