#include "core/stage_times.h"

#include <thread>

#include <gtest/gtest.h>

namespace sd {
namespace {

TEST(StageTimes, SumsByStageInFirstSeenOrder) {
  StageTimes t;
  t.Add("render", 0.5);
  t.Add("light", 0.25);
  t.Add("render", 0.25);
  ASSERT_EQ(t.entries().size(), 2u);
  EXPECT_EQ(t.entries()[0].first, "render");
  EXPECT_DOUBLE_EQ(t.Seconds("render"), 0.75);
  EXPECT_DOUBLE_EQ(t.Seconds("missing"), 0.0);
  EXPECT_DOUBLE_EQ(t.Total(), 1.0);
  t.Add("tiny", 0.001);
  EXPECT_EQ(t.Summary(), "render 0.75 s, light 0.25 s");  // stages under 5 ms left out
  StageTimes other;
  other.Add("light", 1.0);
  other.Add("lidar", 0.5);
  t.Merge(other);
  EXPECT_DOUBLE_EQ(t.Seconds("light"), 1.25);
  EXPECT_EQ(t.entries().back().first, "lidar");
}

TEST(StageTimes, ScopedStageRecordsOnceAndNullRecordsNothing) {
  StageTimes t;
  {
    ScopedStage s(&t, "sleep");
    std::this_thread::sleep_for(std::chrono::milliseconds(20));
    s.Stop();
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }  // the destructor after Stop adds nothing
  EXPECT_GE(t.Seconds("sleep"), 0.015);
  EXPECT_LT(t.Seconds("sleep"), 0.065);
  { ScopedStage none(nullptr, "ignored"); }
  EXPECT_EQ(t.entries().size(), 1u);
}

}  // namespace
}  // namespace sd
