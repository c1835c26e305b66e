// Linked into the libFuzzer binaries only. libFuzzer calls LLVMFuzzerInitialize before it reads its corpus
// folders, so with SYNTHDRIVE_FUZZ_SEEDS_OUT set the target's seeds land in the corpus it is about to read:
// scripts/fuzz.sh seeds every run from data/ this way and no corpus is committed.
#include <cstdlib>
#include <filesystem>

#include "fuzz/fuzz_support.h"

extern "C" int LLVMFuzzerInitialize(int* /*argc*/, char*** /*argv*/) {
  const char* out = std::getenv("SYNTHDRIVE_FUZZ_SEEDS_OUT");
  if (out == nullptr || *out == '\0') return 0;
  std::filesystem::create_directories(out);
  for (const sd::fuzz::Seed& seed : sd::fuzz::FuzzSeeds())
    sd::fuzz::WriteBytes(std::filesystem::path(out) / ("seed-" + seed.name), seed.bytes);
  return 0;
}
