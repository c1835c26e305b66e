#pragma once
// Wall-clock seconds per named stage of a long computation (a synthesised frame: its light, render, shadows,
// occlusion, ...), summed over repeats, in the order the stages first ran. For benchmarks and --verbose logs:
// where a frame's time goes, per stage, without a profiler. Not thread-safe: one thread records.
#include <chrono>
#include <string>
#include <utility>
#include <vector>

namespace sd {

class StageTimes {
 public:
  void Add(const std::string& stage, double seconds);
  void Merge(const StageTimes& other);
  double Seconds(const std::string& stage) const;  // 0 when the stage never ran
  double Total() const;
  const std::vector<std::pair<std::string, double>>& entries() const { return entries_; }
  // "light 0.31 s, render 0.52 s, ..." (two decimals; stages under 5 ms left out).
  std::string Summary() const;

 private:
  std::vector<std::pair<std::string, double>> entries_;
};

// Adds the time from construction to destruction (or to Stop) to `times` under `stage`; a null `times` records
// nothing, so callers need not branch.
class ScopedStage {
 public:
  ScopedStage(StageTimes* times, std::string stage);
  ~ScopedStage() { Stop(); }
  ScopedStage(const ScopedStage&) = delete;
  ScopedStage& operator=(const ScopedStage&) = delete;
  void Stop();

 private:
  StageTimes* times_;
  std::string stage_;
  std::chrono::steady_clock::time_point start_;
};

}  // namespace sd
