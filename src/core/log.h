#pragma once
// Logging to stderr and a progress bar for long loops. Library code reports through these, never printf,
// so the CLI decides verbosity in one place.
#include <atomic>
#include <chrono>
#include <cstddef>
#include <mutex>
#include <string>

#include "core/error.h"

namespace sd {

enum class LogLevel { kDebug = 0, kInfo = 1, kWarn = 2, kError = 3, kQuiet = 4 };

void SetLogLevel(LogLevel level);
LogLevel GetLogLevel();
void LogLine(LogLevel level, const std::string& line);

// Usage: SD_LOG(Info, "placed " << n << " objects");
#define SD_LOG(level, stream_expr)                                                       \
  do {                                                                                   \
    if (::sd::LogLevel::k##level >= ::sd::GetLogLevel())                                 \
      ::sd::LogLine(::sd::LogLevel::k##level, (::sd::Msg() << stream_expr).str());      \
  } while (0)

// Thread-safe progress reporter: `Progress p("rendering", n); ... p.Advance();`. Redraws at most ~10 times
// a second on a terminal; writes a plain line every 10% when stderr is not a terminal (CI logs stay short).
class Progress {
 public:
  Progress(std::string label, size_t total);
  ~Progress();
  void Advance(size_t n = 1);
  void Finish();

 private:
  void Draw(size_t done, bool final);
  std::string label_;
  size_t total_;
  std::atomic<size_t> done_{0};
  std::mutex mutex_;
  std::chrono::steady_clock::time_point start_, last_draw_;
  int last_decile_ = -1;
  bool tty_ = false;
  bool finished_ = false;
};

}  // namespace sd
