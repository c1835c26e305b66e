// `.bin` / `.pcd.bin` sweeps (io/pointcloud_io.h ReadPointCloudBin). The first byte picks the record layout
// (nuScenes 5 floats, KITTI 4 floats), the rest is the file. Seeds: the first records of the repo's real sweeps
// (a whole sweep is hundreds of kB of the same structure).
#include "fuzz/fuzz_support.h"
#include "io/pointcloud_io.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size == 0) return 0;
  return sd::fuzz::ExpectOnlyInputErrors([&] {
    const std::filesystem::path sweep = sd::fuzz::FreshCaseDir() / "sweep.pcd.bin";
    sd::fuzz::WriteBytes(sweep, sd::fuzz::AsText(data + 1, size - 1));
    sd::ReadPointCloudBin(sweep, data[0] % 2 == 0 ? sd::PointLayout::NuScenes() : sd::PointLayout::Kitti());
  });
}

std::vector<sd::fuzz::Seed> sd::fuzz::FuzzSeeds() {
  const std::string nuscenes = ReadBytes(RepoPath(
      "data/driving/nuscenes-scene0061-kf0/samples/LIDAR_TOP/"
      "n015-2018-07-24-11-22-45+0800__LIDAR_TOP__1532402927647951.pcd.bin"));
  const std::string kitti = ReadBytes(RepoPath("data/driving/kitti-object/training/velodyne/000000.bin"));
  // Appended rather than `std::string(1, c) + ...`: gcc 12 reports a false -Wrestrict on that operator+.
  const auto with_layout_byte = [](char layout, const std::string& sweep, size_t bytes) {
    std::string seed(1, layout);
    seed.append(sweep, 0, bytes);
    return seed;
  };
  return {{"nuscenes-64-points", with_layout_byte('\0', nuscenes, 64 * 20)},
          {"kitti-64-points", with_layout_byte('\1', kitti, 64 * 16)}};
}
