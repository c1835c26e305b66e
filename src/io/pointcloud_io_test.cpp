#include "io/pointcloud_io.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>

#include "core/error.h"
#include "io/files.h"
#include "testing/testing.h"

namespace sd {
namespace {
namespace fs = std::filesystem;
using testing::RepoData;

const char* kNuScenesSweep =
    "driving/nuscenes-scene0061-kf0/samples/LIDAR_TOP/"
    "n015-2018-07-24-11-22-45+0800__LIDAR_TOP__1532402927647951.pcd.bin";

TEST(PointCloudIo, NuScenesSweep) {
  const PointCloud pc = ReadPointCloudBin(RepoData(kNuScenesSweep), PointLayout::NuScenes());
  EXPECT_EQ(pc.num_features, 5);
  EXPECT_EQ(pc.size(), 34688u);
  EXPECT_EQ(pc.FeatureIndex("ring"), 4);
  EXPECT_EQ(pc.FeatureIndex("intensity"), 3);
  EXPECT_EQ(pc.FeatureIndex("nope"), -1);
  float ring_min = 1e9f, ring_max = -1e9f, int_min = 1e9f, int_max = -1e9f;
  std::vector<bool> seen(32, false);
  for (size_t i = 0; i < pc.size(); ++i) {
    const float ring = pc.feature(i, 4), intensity = pc.feature(i, 3);
    ASSERT_EQ(ring, std::round(ring)) << i;  // integer ring ids stored as float
    ring_min = std::min(ring_min, ring), ring_max = std::max(ring_max, ring);
    int_min = std::min(int_min, intensity), int_max = std::max(int_max, intensity);
    if (ring >= 0 && ring < 32) seen[static_cast<int>(ring)] = true;
  }
  EXPECT_EQ(ring_min, 0.0f);
  EXPECT_EQ(ring_max, 31.0f);
  EXPECT_TRUE(std::all_of(seen.begin(), seen.end(), [](bool b) { return b; }));  // all 32 beams
  EXPECT_GE(int_min, 0.0f);
  EXPECT_LE(int_max, 255.0f);
  EXPECT_GT(int_max, 100.0f);  // 0..255 scale, not 0..1
}

TEST(PointCloudIo, KittiVelodyne) {
  const fs::path p = RepoData("driving/kitti-object/training/velodyne/000000.bin");
  const PointCloud pc = ReadPointCloudBin(p, PointLayout::Kitti());
  EXPECT_EQ(pc.num_features, 4);
  EXPECT_EQ(pc.size(), fs::file_size(p) / 16);
  EXPECT_EQ(pc.size(), 115384u);
  float rmax = 0;
  for (size_t i = 0; i < pc.size(); ++i) rmax = std::max(rmax, pc.feature(i, 3));
  EXPECT_LE(rmax, 1.0f);  // KITTI reflectance is 0..1
  EXPECT_GT(rmax, 0.5f);
}

TEST(PointCloudIo, TruncatedAndEmptyFilesAreErrors) {
  testing::TempDir tmp;
  const std::string bytes = ReadFileToString(RepoData(kNuScenesSweep));
  WriteFileAtomic(tmp / "cut.pcd.bin", std::string_view(bytes).substr(0, 1003));
  try {
    ReadPointCloudBin(tmp / "cut.pcd.bin", PointLayout::NuScenes());
    FAIL();
  } catch (const InputError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("cut.pcd.bin"), std::string::npos) << msg;
    EXPECT_NE(msg.find("1003"), std::string::npos) << msg;
  }
  WriteFileAtomic(tmp / "empty.bin", "");
  try {
    ReadPointCloudBin(tmp / "empty.bin", PointLayout::Kitti());
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("empty.bin"), std::string::npos);
  }
  EXPECT_THROW(ReadPointCloudBin(tmp / "missing.bin", PointLayout::Kitti()), InputError);
}

TEST(PointCloudIo, WriteReadIsByteIdentical) {
  const fs::path src = RepoData(kNuScenesSweep);
  const PointCloud pc = ReadPointCloudBin(src, PointLayout::NuScenes());
  testing::TempDir tmp;
  WritePointCloudBin(tmp / "copy.pcd.bin", pc);
  EXPECT_EQ(ReadFileToString(tmp / "copy.pcd.bin"), ReadFileToString(src));
  const PointCloud again = ReadPointCloudBin(tmp / "copy.pcd.bin", PointLayout::NuScenes());
  EXPECT_EQ(again.data, pc.data);
}

}  // namespace
}  // namespace sd
