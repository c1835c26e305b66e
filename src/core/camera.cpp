#include "core/camera.h"

#include <cmath>

#include "core/error.h"

namespace sd {

PinholeCamera PinholeCamera::FromK(const Eigen::Matrix3d& K, int width, int height) {
  // The readers refuse skewed calibrations with the file named (datasets' SkewProblem); one reaching here is a bug.
  SD_CHECK(std::abs(K(0, 1)) <= 1e-3 * std::abs(K(0, 0)) && std::abs(K(1, 0)) <= 1e-6,
           << "a skewed camera matrix (K[0][1] = " << K(0, 1) << ") has no PinholeCamera");
  PinholeCamera c;
  c.width = width;
  c.height = height;
  c.fx = K(0, 0);
  c.fy = K(1, 1);
  c.cx = K(0, 2);
  c.cy = K(1, 2);
  return c;
}

Eigen::Matrix3d PinholeCamera::K() const {
  Eigen::Matrix3d K;
  K << fx, 0, cx, 0, fy, cy, 0, 0, 1;
  return K;
}

Eigen::Vector2d PinholeCamera::Distort(const Eigen::Vector2d& xy) const {
  if (distortion.IsZero()) return xy;
  const double x = xy.x(), y = xy.y();
  const double r2 = x * x + y * y;
  const auto& d = distortion;
  const double radial = 1 + r2 * (d.k1 + r2 * (d.k2 + r2 * d.k3));
  return {x * radial + 2 * d.p1 * x * y + d.p2 * (r2 + 2 * x * x),
          y * radial + d.p1 * (r2 + 2 * y * y) + 2 * d.p2 * x * y};
}

Eigen::Vector2d PinholeCamera::Undistort(const Eigen::Vector2d& xy_distorted) const {
  if (distortion.IsZero()) return xy_distorted;
  // Fixed-point iteration as in OpenCV's undistortPoints; converges in a few steps for automotive lenses.
  Eigen::Vector2d xy = xy_distorted;
  for (int it = 0; it < 20; ++it) {
    const Eigen::Vector2d err = Distort(xy) - xy_distorted;
    xy -= err;
    if (err.squaredNorm() < 1e-24) break;
  }
  return xy;
}

std::optional<Eigen::Vector2d> PinholeCamera::Project(const Eigen::Vector3d& p_cam, double min_depth) const {
  if (!(p_cam.z() > min_depth)) return std::nullopt;
  const Eigen::Vector2d xy = Distort(Eigen::Vector2d(p_cam.x() / p_cam.z(), p_cam.y() / p_cam.z()));
  return Eigen::Vector2d(fx * xy.x() + cx, fy * xy.y() + cy);
}

Eigen::Vector3d PinholeCamera::RayDirection(const Eigen::Vector2d& uv) const {
  const Eigen::Vector2d xy = Undistort(Eigen::Vector2d((uv.x() - cx) / fx, (uv.y() - cy) / fy));
  return Eigen::Vector3d(xy.x(), xy.y(), 1.0).normalized();
}

}  // namespace sd
