#pragma once
// Cameras of the synth tests' synthetic scenes (header-only; tests only, not part of the library).
#include <Eigen/Core>

#include "core/rigid3.h"
#include "datasets/log.h"

namespace sd::testing {

// An 800x600 camera, focal length 450 px, `height_m` above the ego origin looking straight down (image x along
// ego +x, image y along ego -y): every ground point near the ego is seen, none hidden behind another's base.
inline CameraSensor TopDownCamera(double height_m = 12) {
  CameraSensor cam;
  cam.channel = "CAM_FRONT";
  cam.intrinsics.width = 800;
  cam.intrinsics.height = 600;
  cam.intrinsics.fx = cam.intrinsics.fy = 450;
  cam.intrinsics.cx = 400;
  cam.intrinsics.cy = 300;
  Eigen::Matrix3d R;
  R << 1, 0, 0, 0, -1, 0, 0, 0, -1;
  cam.T_ego_cam = Rigid3d(R, Eigen::Vector3d(0, 0, height_m));
  return cam;
}

}  // namespace sd::testing
