// The plain-executable face of a fuzz target (any compiler, no libFuzzer): runs the target's seeds and every file
// given on the command line (its fuzz/regressions/<target>/ folder, as CTest passes it), each once, so a fixed
// crash stays fixed. A file that crashes or throws anything but InputError fails the test; the name of the input
// being run is printed first so the failure names it.
#include <algorithm>
#include <cstdint>
#include <filesystem>
#include <iostream>
#include <string>
#include <vector>

#include "fuzz/fuzz_support.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size);

namespace {

void Replay(const std::string& name, const std::string& bytes) {
  std::cerr << "replay " << name << " (" << bytes.size() << " B)\n";
  LLVMFuzzerTestOneInput(reinterpret_cast<const uint8_t*>(bytes.data()), bytes.size());
}

}  // namespace

int main(int argc, char** argv) {
  namespace fs = std::filesystem;
  int inputs = 0;
  for (const sd::fuzz::Seed& seed : sd::fuzz::FuzzSeeds()) {
    Replay("seed " + seed.name, seed.bytes);
    ++inputs;
  }
  for (int i = 1; i < argc; ++i) {
    const fs::path arg = argv[i];
    std::vector<fs::path> files;
    if (fs::is_directory(arg)) {
      for (const auto& e : fs::directory_iterator(arg))
        if (e.is_regular_file() && e.path().filename().string().front() != '.') files.push_back(e.path());
    } else if (fs::is_regular_file(arg)) {
      files.push_back(arg);
    }
    std::sort(files.begin(), files.end());
    for (const fs::path& file : files) {
      Replay(file.string(), sd::fuzz::ReadBytes(file));
      ++inputs;
    }
  }
  std::cout << "replayed " << inputs << " inputs without a crash\n";
  return inputs > 0 ? 0 : 1;
}
