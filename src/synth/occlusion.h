#pragma once
// Hiding inserted objects behind real scene geometry seen by the LiDAR.
//
// The sweep is projected into the camera (ego-motion-compensated extrinsics, see datasets/log.h). A
// rendered pixel at depth d is hidden when real, non-ground geometry is nearer than d - tol(d): between
// the sparse LiDAR rings, each pixel takes the verdict of the nearest projected point above and below it
// in a narrow column strip (so an occluder's edge falls midway between the rings that bound it). Ground
// points never occlude (the object stands on the ground) but do count as "nothing in front" evidence.
#include <vector>

#include <Eigen/Core>

#include "core/camera.h"
#include "core/image.h"
#include "core/rigid3.h"

namespace sd {

struct ProjectedPoint {
  float u, v, depth;  // pixels, metres along the camera z axis
  bool ground;
};

// Projects ego-frame points into the camera. `is_ground[i]` marks ground points (may be empty).
std::vector<ProjectedPoint> ProjectPoints(const std::vector<Eigen::Vector3d>& points_ego, const std::vector<uint8_t>& is_ground,
                                          const PinholeCamera& camera, const Rigid3d& T_cam_ego);

struct OcclusionOptions {
  int column_half_width = 3;  // pixels either side of the pixel's column searched for LiDAR points
  int max_gap = 48;           // pixels: farther points above/below say nothing
  double tol_abs = 0.4, tol_rel = 0.04;  // an occluder must be nearer than d - max(tol_abs, tol_rel * d)
};

// Visibility (1 visible, 0 hidden) of each pixel where `object_depth` is finite; 1 elsewhere.
ImageF ComputeVisibility(const std::vector<ProjectedPoint>& points, const ImageF& object_depth,
                         const OcclusionOptions& options = {});

}  // namespace sd
