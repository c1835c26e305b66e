// KITTI object layout through OpenLog (datasets/readers.h: ReadKitti's calib and label parsers, then the
// sensor-geometry checks). The input is an archive (fuzz_support.h) of calib/, label_2/ and image_2/ files; the
// seeds carry the repo's real calib and label text and a flat PNG of KITTI's image size (only its header is read).
#include "core/image.h"
#include "datasets/readers.h"
#include "fuzz/fuzz_support.h"
#include "io/image_io.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  return sd::fuzz::ExpectOnlyInputErrors([&] {
    const std::filesystem::path root = sd::fuzz::FreshCaseDir();
    sd::fuzz::WriteArchive(sd::fuzz::UnpackArchive(sd::fuzz::AsText(data, size)), root);
    // The layout's folders exist even when the archive holds no file in them (an error code, not an
    // exception, when the archive made a file of that name).
    std::error_code ec;
    std::filesystem::create_directories(root / "calib", ec);
    std::filesystem::create_directories(root / "label_2", ec);
    sd::OpenLogOptions options;
    options.format = sd::LogFormat::kKitti;
    sd::OpenLog(root, options);
  });
}

std::vector<sd::fuzz::Seed> sd::fuzz::FuzzSeeds() {
  const std::string flat_png = EncodeImage(ImageU8(1242, 375, 3, 128), "png");
  const auto training = RepoPath("data/driving/kitti-object/training");
  std::vector<Seed> seeds;
  Archive all_frames;
  for (const std::string id : {"000000", "000001", "000002"}) {
    const Archive frame = {{"calib/" + id + ".txt", ReadBytes(training / "calib" / (id + ".txt"))},
                           {"label_2/" + id + ".txt", ReadBytes(training / "label_2" / (id + ".txt"))},
                           {"image_2/" + id + ".png", flat_png}};
    seeds.push_back({"frame-" + id, PackArchive(frame)});
    all_frames.insert(all_frames.end(), frame.begin(), frame.end());
  }
  seeds.push_back({"three-frames", PackArchive(all_frames)});
  return seeds;
}
