// PNG / JPEG decoding as the program uses it (io/image_io.h): DecodeImage with each channel count the callers ask
// for, and EstimateJpegQuality (the camera-look stage reads every JPEG's quantisation table). Seeds: the repo's
// real photos and textures, shrunk and re-encoded, grey, RGB and RGBA.
#include "fuzz/fuzz_support.h"
#include "io/image_io.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  const std::string_view bytes = sd::fuzz::AsText(data, size);
  sd::EstimateJpegQuality(bytes);
  for (const int channels : {0, 1, 3, 4})
    sd::fuzz::ExpectOnlyInputErrors([&] { sd::DecodeImage(bytes, "fuzz image", channels); });
  return 0;
}

std::vector<sd::fuzz::Seed> sd::fuzz::FuzzSeeds() {
  const auto photo = RepoPath("data/driving/kitti-object/training/image_2/000000.png");
  const auto texture = RepoPath("data/assets/metadrive_traffic_cone/textures/cone_baseColor.jpeg");
  return {{"kitti-rgb.png", SmallImageFrom(photo, 48, "png", 3)},
          {"kitti-grey.png", SmallImageFrom(photo, 48, "png", 1)},
          {"kitti-rgba.png", SmallImageFrom(photo, 48, "png", 4)},
          {"kitti.jpg", SmallImageFrom(photo, 48, "jpg", 3)},
          {"cone-texture.jpg", SmallImageFrom(texture, 32, "jpg", 3)},
          {"cone-texture-grey.jpg", SmallImageFrom(texture, 32, "jpg", 1)}};
}
