// nuScenes / Lyft devkit tables through OpenLog (datasets/readers.h: ReadNuScenesTables, then the sensor-geometry
// checks). The input is an archive (fuzz_support.h) of the version folder's tables; the data root is the repo's
// nuScenes keyframe, so camera checks read its real image headers.
#include <algorithm>

#include "datasets/readers.h"
#include "fuzz/fuzz_support.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  return sd::fuzz::ExpectOnlyInputErrors([&] {
    const std::filesystem::path root = sd::fuzz::FreshCaseDir();
    sd::fuzz::WriteArchive(sd::fuzz::UnpackArchive(sd::fuzz::AsText(data, size)), root);
    sd::OpenLogOptions options;
    options.format = sd::LogFormat::kNuScenesTables;
    options.data_root = sd::fuzz::RepoPath("data/driving/nuscenes-scene0061-kf0");
    sd::OpenLog(root, options);
  });
}

namespace {

sd::fuzz::Seed TablesOf(const std::string& name, const std::filesystem::path& version_dir) {
  sd::fuzz::Archive files;
  for (const auto& e : std::filesystem::directory_iterator(version_dir))
    if (e.path().extension() == ".json")
      files.emplace_back(version_dir.filename().string() + "/" + e.path().filename().string(),
                         sd::fuzz::ReadBytes(e.path()));
  std::sort(files.begin(), files.end());
  return {name, sd::fuzz::PackArchive(files)};
}

}  // namespace

std::vector<sd::fuzz::Seed> sd::fuzz::FuzzSeeds() {
  return {TablesOf("nuscenes-kf0", RepoPath("data/driving/nuscenes-scene0061-kf0/v1.0-subset")),
          TablesOf("lyft", RepoPath("data/driving/lyft-tables/v1.01-train/v1.01-train"))};
}
