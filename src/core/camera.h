#pragma once
// Pinhole camera with optional OpenCV (Brown-Conrady) distortion.
//
// Frames: the camera frame is OpenCV's (x right, y down, z forward), metres.
// Pixels: continuous image coordinates (u, v) in pixels; pixel (i, j) covers [i, i+1) x [j, j+1), so its
// centre is (i + 0.5, j + 0.5). Intrinsics read from datasets are used as given (u = fx*x/z + cx).
#include <optional>

#include <Eigen/Core>

namespace sd {

struct Distortion {
  double k1 = 0, k2 = 0, p1 = 0, p2 = 0, k3 = 0;  // OpenCV order
  bool IsZero() const { return k1 == 0 && k2 == 0 && p1 == 0 && p2 == 0 && k3 == 0; }
};

struct PinholeCamera {
  int width = 0, height = 0;  // pixels
  double fx = 0, fy = 0, cx = 0, cy = 0;
  Distortion distortion;

  // K must have no skew (SD_CHECK: the readers refuse skewed calibrations with the file named).
  static PinholeCamera FromK(const Eigen::Matrix3d& K, int width, int height);
  Eigen::Matrix3d K() const;

  // Projects a point in the camera frame. Empty when the point is not in front of the camera
  // (z <= min_depth). The result may lie outside the image; see InImage().
  std::optional<Eigen::Vector2d> Project(const Eigen::Vector3d& p_cam, double min_depth = 1e-3) const;
  // Unit-length ray direction in the camera frame through image point `uv` (undoes distortion with Undistort).
  // Inline for the undistorted camera: the renderers call it for every sub-sample.
  Eigen::Vector3d RayDirection(const Eigen::Vector2d& uv) const {
    const Eigen::Vector2d xy((uv.x() - cx) / fx, (uv.y() - cy) / fy);
    if (distortion.IsZero()) return Eigen::Vector3d(xy.x(), xy.y(), 1.0).normalized();
    return RayDirectionDistorted(xy);
  }
  bool InImage(const Eigen::Vector2d& uv) const { return uv.x() >= 0 && uv.y() >= 0 && uv.x() < width && uv.y() < height; }

  // Normalised image plane <-> distorted normalised plane.
  Eigen::Vector2d Distort(const Eigen::Vector2d& xy) const;
  // d Distort / d xy (2x2, symmetric); its determinant turns <= 0 past a strong lens's fold.
  Eigen::Matrix2d DistortJacobian(const Eigen::Vector2d& xy) const;
  // The xy with Distort(xy) = xy_distorted, by Newton's method (at most 20 steps, from xy_distorted). Empty when
  // no xy within |Distort(xy) - xy_distorted| <= 1e-14 (1 + |xy_distorted|) was found where Distort is still
  // invertible (Jacobian determinant > 0): points past the edge of a strong barrel lens's image, whose rays
  // would have to come from beyond its fold.
  std::optional<Eigen::Vector2d> TryUndistort(const Eigen::Vector2d& xy_distorted) const;
  // TryUndistort for callers that cannot fail. Where it finds nothing, the step with the smallest residual that
  // stayed inside the fold (at worst xy_distorted itself). Without distortion, xy_distorted as given.
  Eigen::Vector2d Undistort(const Eigen::Vector2d& xy_distorted) const;

 private:
  // RayDirection's distorted case, from the distorted normalised point.
  Eigen::Vector3d RayDirectionDistorted(const Eigen::Vector2d& xy_distorted) const;
};

}  // namespace sd
