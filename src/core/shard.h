#pragma once
// `--shard K/N`: the one way a batch command splits its work list across processes (Slurm job arrays, xargs,
// several machines). Items are dealt round-robin, so every shard gets a similar mix of small and large items
// and the split does not depend on how many items are already done.
#include <cstddef>
#include <string>

namespace sd {

struct ShardSpec {
  int index = 0;  // K, 0-based (Slurm: $SLURM_ARRAY_TASK_ID with --array=0-(N-1))
  int count = 1;  // N
  bool Owns(size_t item) const { return static_cast<int>(item % static_cast<size_t>(count)) == index; }
  std::string ToString() const { return std::to_string(index) + "/" + std::to_string(count); }
};

// Parses "K/N" with 0 <= K < N; InputError naming the text otherwise.
ShardSpec ParseShard(const std::string& text);

}  // namespace sd
