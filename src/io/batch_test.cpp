#include "io/batch.h"

#include <gtest/gtest.h>

#include <set>
#include <stdexcept>

#include "core/error.h"
#include "io/files.h"
#include "io/json.h"
#include "testing/testing.h"

namespace sd {
namespace {
namespace fs = std::filesystem;

// A job over `n` items whose output is a file <dir>/item-<i>; the items in `fail` throw.
BatchJob FileJob(const fs::path& dir, size_t n, std::set<size_t> fail, std::vector<size_t>* ran) {
  BatchJob job;
  job.size = n;
  job.describe = [](size_t i) { return nlohmann::json{{"item", i}}; };
  job.name = [](size_t i) { return "item " + std::to_string(i); };
  job.output = [dir](size_t i) { return dir / ("item-" + std::to_string(i)); };
  job.complete = [dir](size_t i) { return fs::exists(dir / ("item-" + std::to_string(i))); };
  job.run = [dir, fail, ran](size_t i, nlohmann::json* line) {
    ran->push_back(i);
    if (fail.count(i)) throw InputError(dir / ("item-" + std::to_string(i)), "broken on purpose");
    WriteFileAtomic(dir / ("item-" + std::to_string(i)), "x");
    (*line)["bytes"] = 1;
  };
  return job;
}

std::vector<nlohmann::json> Lines(const fs::path& file) {
  std::vector<nlohmann::json> out;
  ForEachJsonLine(file, [&](const nlohmann::json& j, const std::string&) { out.push_back(j); });
  return out;
}

TEST(Batch, ShardsSplitTheWorkListRoundRobinAndTogetherDoItAll) {
  testing::TempDir tmp;
  std::vector<size_t> ran0, ran1;
  BatchOptions o;
  o.show_progress = false;
  o.shard = {0, 2};
  o.run_log = tmp / "logs/run-0.jsonl";
  const BatchSummary s0 = RunBatch(FileJob(tmp.path(), 5, {}, &ran0), o);
  o.shard = {1, 2};
  o.run_log = tmp / "logs/run-1.jsonl";
  const BatchSummary s1 = RunBatch(FileJob(tmp.path(), 5, {}, &ran1), o);
  EXPECT_EQ(ran0, (std::vector<size_t>{0, 2, 4}));
  EXPECT_EQ(ran1, (std::vector<size_t>{1, 3}));
  EXPECT_EQ(s0.owned + s1.owned, 5u);
  EXPECT_EQ(s0.done + s1.done, 5u);
  const auto lines = Lines(tmp / "logs/run-0.jsonl");
  ASSERT_EQ(lines.size(), 3u);
  EXPECT_EQ(lines[1]["item"], 2);
  EXPECT_EQ(lines[1]["status"], "done");
  EXPECT_EQ(lines[1]["bytes"], 1);  // the item's own fields
  EXPECT_TRUE(lines[1]["seconds"].is_number());
}

TEST(Batch, AFailureIsLoggedAndTheOthersGoOnAndARerunResumes) {
  testing::TempDir tmp;
  // What a killed writer of item 3 left behind.
  WriteFileAtomic(tmp / "item-3.tmp-999999-0/half", "half");
  std::vector<size_t> ran;
  BatchOptions o;
  o.show_progress = false;
  o.log_failures = false;
  o.run_log = tmp / "run.jsonl";
  const BatchSummary first = RunBatch(FileJob(tmp.path(), 4, {1}, &ran), o);
  EXPECT_EQ(ran, (std::vector<size_t>{0, 1, 2, 3}));
  EXPECT_EQ(first.done, 3u);
  ASSERT_EQ(first.failures.size(), 1u);
  EXPECT_EQ(first.failures[0].item, 1u);
  EXPECT_NE(first.failures[0].error.find("broken on purpose"), std::string::npos);
  EXPECT_THROW(std::rethrow_exception(first.failures[0].exception), InputError);
  EXPECT_FALSE(fs::exists(tmp / "item-3.tmp-999999-0"));  // the stale half-write is gone

  ran.clear();
  const BatchSummary second = RunBatch(FileJob(tmp.path(), 4, {}, &ran), o);
  EXPECT_EQ(ran, (std::vector<size_t>{1}));  // only what failed
  EXPECT_EQ(second.skipped, 3u);
  EXPECT_EQ(second.done, 1u);
  EXPECT_TRUE(second.failures.empty());
  const auto lines = Lines(tmp / "run.jsonl");  // appended: both runs
  ASSERT_EQ(lines.size(), 8u);
  EXPECT_EQ(lines[1]["status"], "failed");
  EXPECT_NE(lines[1]["error"].get<std::string>().find("broken on purpose"), std::string::npos);
  EXPECT_EQ(lines[4]["status"], "skipped");
  EXPECT_EQ(lines[5]["status"], "done");
}

TEST(Batch, AShardThatOwnsNothingWritesNoLog) {
  testing::TempDir tmp;
  std::vector<size_t> ran;
  BatchOptions o;
  o.show_progress = false;
  o.shard = {2, 3};
  o.run_log = tmp / "run.jsonl";
  const BatchSummary s = RunBatch(FileJob(tmp.path(), 2, {}, &ran), o);
  EXPECT_EQ(s.owned, 0u);
  EXPECT_TRUE(ran.empty());
  EXPECT_FALSE(fs::exists(tmp / "run.jsonl"));
}

TEST(Batch, AnUnwritableRunLogIsAnInputError) {
  testing::TempDir tmp;
  WriteFileAtomic(tmp / "file", "x");
  std::vector<size_t> ran;
  BatchOptions o;
  o.show_progress = false;
  o.run_log = tmp / "file" / "run.jsonl";  // its folder is a file
  EXPECT_THROW(RunBatch(FileJob(tmp.path(), 1, {}, &ran), o), InputError);
  EXPECT_TRUE(ran.empty());
}

}  // namespace
}  // namespace sd
