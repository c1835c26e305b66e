#pragma once
// Helpers shared by the dataset readers and writers; not part of the module's public interface.
#include <array>
#include <filesystem>
#include <string>

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include "core/rigid3.h"

namespace sd::datasets_internal {

// KITTI object calib file (P0..P3 3x4, R0_rect 3x3, Tr_velo_to_cam 3x4). Throws InputError naming the file
// and line when a required key is missing or has the wrong number of values.
struct KittiCalib {
  Eigen::Matrix<double, 3, 4> P2;
  Eigen::Matrix3d R0_rect;
  Eigen::Matrix<double, 3, 4> Tr_velo_to_cam;
  // Rectified cam0 <- Velodyne: R0_rect * Tr_velo_to_cam (rigid up to R0_rect's rounding).
  Rigid3d T_rect0_velo() const;
  // Camera 2 <- rectified cam0: P2 = K [I | t], t = K^-1 P2[:,3].
  Rigid3d T_cam2_rect0() const;
  Eigen::Matrix3d K2() const { return P2.leftCols<3>(); }
};
KittiCalib ReadKittiCalib(const std::filesystem::path& path);

// `path` relative to `root` when it lies under it, else its file name.
std::string RelativePath(const std::filesystem::path& path, const std::filesystem::path& root);

// Deterministic 32-hex-digit token from a seed string (FNV-1a based), nuScenes token style.
std::string HexToken(const std::string& seed);

// Parses a JSON file written by Python (NaN / Infinity literals read as null); InputError naming the file.
nlohmann::json ReadPythonJson(const std::filesystem::path& path);

// Image width/height from a PNG IHDR or JPEG SOF header; {0, 0} when the file is missing or unrecognised.
std::array<int, 2> ImageSizeFromHeader(const std::filesystem::path& path);

// Yaw of a box in mmdetection3d camera coordinates: rotation about camera +y (down), measured so that the
// box x axis is (cos yaw, 0, -sin yaw). Pinned in datasets readers_test against the nuScenes cam_instances.
double CameraYaw(const Eigen::Matrix3d& R_cam_box);

}  // namespace sd::datasets_internal
