#include "core/stage_times.h"

#include <algorithm>
#include <cstdio>

namespace sd {

void StageTimes::Add(const std::string& stage, double seconds) {
  const auto it = std::find_if(entries_.begin(), entries_.end(), [&](const auto& e) { return e.first == stage; });
  if (it == entries_.end()) entries_.emplace_back(stage, seconds);
  else it->second += seconds;
}

void StageTimes::Merge(const StageTimes& other) {
  for (const auto& [stage, seconds] : other.entries_) Add(stage, seconds);
}

double StageTimes::Seconds(const std::string& stage) const {
  for (const auto& [name, seconds] : entries_)
    if (name == stage) return seconds;
  return 0;
}

double StageTimes::Total() const {
  double total = 0;
  for (const auto& e : entries_) total += e.second;
  return total;
}

std::string StageTimes::Summary() const {
  std::string out;
  for (const auto& [stage, seconds] : entries_) {
    if (seconds < 0.005) continue;
    char buf[32];
    std::snprintf(buf, sizeof buf, " %.2f s", seconds);
    out += (out.empty() ? "" : ", ") + stage + buf;
  }
  return out;
}

ScopedStage::ScopedStage(StageTimes* times, std::string stage)
    : times_(times), stage_(std::move(stage)), start_(std::chrono::steady_clock::now()) {}

void ScopedStage::Stop() {
  if (!times_) return;
  times_->Add(stage_, std::chrono::duration<double>(std::chrono::steady_clock::now() - start_).count());
  times_ = nullptr;
}

}  // namespace sd
