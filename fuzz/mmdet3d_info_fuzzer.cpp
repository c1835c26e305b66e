// mmdetection3d info files through OpenLog (datasets/readers.h): the reader (v1.x and v0.x, nuScenes- and
// KITTI-flavoured, JSON or pickle) and the sensor-geometry checks every log gets. The bytes are an info file,
// named .pkl when they start like a binary pickle (PROTO, 0x80) and .json otherwise; the data root is the repo's
// nuScenes keyframe, so the camera checks read real image headers.
#include "datasets/readers.h"
#include "fuzz/fuzz_support.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  return sd::fuzz::ExpectOnlyInputErrors([&] {
    const bool pickle = size > 0 && data[0] == 0x80;
    const std::filesystem::path info = sd::fuzz::FreshCaseDir() / (pickle ? "info.pkl" : "info.json");
    sd::fuzz::WriteBytes(info, sd::fuzz::AsText(data, size));
    sd::OpenLogOptions options;
    options.data_root = sd::fuzz::RepoPath("data/driving/nuscenes-scene0061-kf0");
    sd::OpenLog(info, options);
  });
}

std::vector<sd::fuzz::Seed> sd::fuzz::FuzzSeeds() {
  std::vector<Seed> seeds;
  for (const char* file : {"data/driving/nuscenes-scene0061-kf0/mmdet3d_info/n015-2018-07-24-11-22-45+0800.json",
                           "data/driving/nuscenes-scene0061-kf0/mmdet3d_info/n015-2018-07-24-11-22-45+0800.pkl",
                           "data/driving/nuscenes-scene0061-kf0/bevfusion_demo_info/nuscenes_infos_test.json",
                           "data/driving/nuscenes-scene0061-kf0/bevfusion_demo_info/nuscenes_infos_test.pkl",
                           "data/driving/kitti-mmdet3d-pkl-000008/v0x_format/kitti_000008_infos.pkl",
                           "data/driving/kitti-mmdet3d-pkl-000008/v1x_format/000008.pkl"})
    seeds.push_back({std::filesystem::path(file).filename().string(), ReadBytes(RepoPath(file))});
  return seeds;
}
