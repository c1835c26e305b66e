#pragma once
// Two error tiers (STYLE.md habit 9):
//  - InputError: bad input, config or IO. Located (names the file) and catchable; the CLI turns it into one
//    line on stderr and a non-zero exit.
//  - SD_CHECK: a broken contract inside the program (a bug). Prints the location and aborts.
#include <filesystem>
#include <sstream>
#include <stdexcept>
#include <string>

namespace sd {

class InputError : public std::runtime_error {
 public:
  InputError(const std::filesystem::path& where, const std::string& what)
      : std::runtime_error(where.empty() ? what : where.string() + ": " + what), where_(where) {}
  const std::filesystem::path& where() const { return where_; }

 private:
  std::filesystem::path where_;
};

// Builds a message with stream syntax: throw InputError(path, Msg() << "bad size " << n);
class Msg {
 public:
  template <typename T>
  Msg& operator<<(const T& v) {
    os_ << v;
    return *this;
  }
  operator std::string() const { return os_.str(); }
  std::string str() const { return os_.str(); }

 private:
  std::ostringstream os_;
};

// `v` with `digits` decimals ("%.*f", C locale), for messages and text records (KITTI labels, reports).
std::string Fixed(double v, int digits);

[[noreturn]] void CheckFailed(const char* file, int line, const char* cond, const std::string& msg);

}  // namespace sd

#define SD_CHECK(cond, ...)                                                         \
  do {                                                                              \
    if (!(cond)) ::sd::CheckFailed(__FILE__, __LINE__, #cond, (::sd::Msg() __VA_ARGS__).str()); \
  } while (0)
