#include "core/log.h"

#include <unistd.h>

#include <cstdio>

namespace sd {
namespace {
std::atomic<LogLevel> g_level{LogLevel::kInfo};
std::mutex g_log_mutex;
}  // namespace

void SetLogLevel(LogLevel level) { g_level = level; }
LogLevel GetLogLevel() { return g_level; }

void LogLine(LogLevel level, const std::string& line) {
  static const char* kPrefix[] = {"debug: ", "", "warning: ", "error: ", ""};
  std::lock_guard<std::mutex> lock(g_log_mutex);
  std::fprintf(stderr, "%s%s\n", kPrefix[static_cast<int>(level)], line.c_str());
}

Progress::Progress(std::string label, size_t total)
    : label_(std::move(label)), total_(total), start_(std::chrono::steady_clock::now()) {
  tty_ = isatty(fileno(stderr)) != 0;
  last_draw_ = start_;
}

Progress::~Progress() { Finish(); }

void Progress::Advance(size_t n) {
  const size_t done = done_.fetch_add(n) + n;
  if (GetLogLevel() > LogLevel::kInfo) return;
  std::unique_lock<std::mutex> lock(mutex_, std::try_to_lock);
  if (!lock.owns_lock()) return;
  Draw(done, false);
}

void Progress::Finish() {
  std::lock_guard<std::mutex> lock(mutex_);
  if (finished_) return;
  finished_ = true;
  if (GetLogLevel() > LogLevel::kInfo) return;
  Draw(done_.load(), true);
}

void Progress::Draw(size_t done, bool final) {
  const auto now = std::chrono::steady_clock::now();
  const double secs = std::chrono::duration<double>(now - start_).count();
  const double frac = total_ ? static_cast<double>(done) / static_cast<double>(total_) : 1.0;
  std::lock_guard<std::mutex> lock(g_log_mutex);
  if (tty_) {
    if (!final && now - last_draw_ < std::chrono::milliseconds(100)) return;
    last_draw_ = now;
    const int width = 30;
    const int filled = static_cast<int>(frac * width + 0.5);
    std::fprintf(stderr, "\r%-22s [%s%s] %zu/%zu %.1fs", label_.c_str(), std::string(filled, '#').c_str(),
                 std::string(width - filled, ' ').c_str(), done, total_, secs);
    if (final) std::fputc('\n', stderr);
  } else {
    const int decile = static_cast<int>(frac * 10);
    if (decile == last_decile_ && !final) return;
    if (final && decile == last_decile_ && decile == 10) return;
    last_decile_ = decile;
    std::fprintf(stderr, "%s: %zu/%zu (%.0f%%, %.1fs)\n", label_.c_str(), done, total_, frac * 100, secs);
  }
  std::fflush(stderr);
}

}  // namespace sd
