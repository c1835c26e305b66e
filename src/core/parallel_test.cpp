// ParallelForRethrow: every index runs, and the lowest throwing index's exception comes out.
#include "core/parallel.h"

#include <gtest/gtest.h>

#include <atomic>
#include <stdexcept>
#include <string>

namespace sd {
namespace {

TEST(ParallelForRethrow, EveryIndexRunsAndTheLowestThrowingIndexIsRethrown) {
  std::vector<std::atomic<int>> ran(1000);
  try {
    ParallelForRethrow(0, ran.size(), [&](size_t i) {
      ran[i] += 1;
      if (i == 700 || i == 300 || i == 999) throw std::runtime_error("index " + std::to_string(i));
    });
    FAIL() << "nothing was rethrown";
  } catch (const std::runtime_error& e) {
    EXPECT_STREQ(e.what(), "index 300");
  }
  for (size_t i = 0; i < ran.size(); ++i) ASSERT_EQ(ran[i].load(), 1) << "index " << i;
}

TEST(ParallelForRethrow, OffsetRangesAndEmptyRanges) {
  std::vector<int> seen(20, 0);
  ParallelForRethrow(5, 15, [&](size_t i) { seen[i] = 1; });
  for (size_t i = 0; i < seen.size(); ++i) EXPECT_EQ(seen[i], i >= 5 && i < 15 ? 1 : 0) << i;
  ParallelForRethrow(7, 7, [&](size_t) { FAIL(); });
  ParallelForRethrow(9, 3, [&](size_t) { FAIL(); });
  EXPECT_THROW(ParallelForRethrow(5, 6, [&](size_t) { throw std::logic_error("x"); }), std::logic_error);
}

}  // namespace
}  // namespace sd
