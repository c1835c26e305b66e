// PandaSet sequence folders through OpenLog (datasets/readers.h: ReadPandaSet's poses, intrinsics, GPS and cuboid
// DataFrame pickles, then the sensor-geometry checks). The input is an archive (fuzz_support.h) of the folder's
// files. Seeds come from the PandaSet frames in ../shared/data when present (the repo's data/ holds none): one
// frame (44) with the front camera, the cuboids stored unzipped (the reader gunzips by magic, and the mutator
// gets at the pickle) and an empty placeholder sweep (sweeps are read later, by ReadLidar).
#include "datasets/readers.h"
#include "fuzz/fuzz_support.h"
#include "io/gzip.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  return sd::fuzz::ExpectOnlyInputErrors([&] {
    const std::filesystem::path root = sd::fuzz::FreshCaseDir();
    sd::fuzz::WriteArchive(sd::fuzz::UnpackArchive(sd::fuzz::AsText(data, size)), root);
    sd::OpenLogOptions options;
    options.format = sd::LogFormat::kPandaSet;
    sd::OpenLog(root, options);
  });
}

std::vector<sd::fuzz::Seed> sd::fuzz::FuzzSeeds() {
  const auto sequence = SharedDataPath("driving/pandaset-002-f44-55");
  if (!std::filesystem::exists(sequence / "lidar" / "poses.json")) return {};
  const std::string cuboids = sd::ReadMaybeGzipFile(sequence / "annotations/cuboids/44.pkl.gz", size_t(16) << 20);
  Archive frame = {{"lidar/poses.json", ReadBytes(sequence / "lidar/poses.json")},
                   {"lidar/timestamps.json", ReadBytes(sequence / "lidar/timestamps.json")},
                   {"lidar/44.pkl.gz", ""},
                   {"camera/front_camera/poses.json", ReadBytes(sequence / "camera/front_camera/poses.json")},
                   {"camera/front_camera/timestamps.json", ReadBytes(sequence / "camera/front_camera/timestamps.json")},
                   {"camera/front_camera/intrinsics.json", ReadBytes(sequence / "camera/front_camera/intrinsics.json")},
                   {"annotations/cuboids/44.pkl.gz", cuboids}};
  std::vector<Seed> seeds = {{"frame-44", PackArchive(frame)}};
  frame.push_back({"meta/gps.json", ReadBytes(sequence / "meta/gps.json")});
  seeds.push_back({"frame-44-gps", PackArchive(frame)});
  return seeds;
}
