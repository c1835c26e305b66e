#include "core/shard.h"

#include <cstdlib>

#include "core/error.h"

namespace sd {

ShardSpec ParseShard(const std::string& text) {
  const size_t slash = text.find('/');
  auto parse = [&](const std::string& part, long& out) {
    char* end = nullptr;
    out = std::strtol(part.c_str(), &end, 10);
    return !part.empty() && end && *end == '\0';
  };
  long k = -1, n = -1;
  if (slash == std::string::npos || !parse(text.substr(0, slash), k) || !parse(text.substr(slash + 1), n) ||
      n < 1 || k < 0 || k >= n || n > 1000000)
    throw InputError({}, Msg() << "--shard '" << text << "': expected K/N with 0 <= K < N (e.g. 0/4)");
  return ShardSpec{static_cast<int>(k), static_cast<int>(n)};
}

}  // namespace sd
