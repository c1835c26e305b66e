#include "core/camera.h"

#include <cmath>
#include <limits>

#include "core/error.h"

namespace sd {

namespace {

// OpenCV's radial-tangential model: radial factor 1 + k1 r^2 + k2 r^4 + k3 r^6, tangential p1, p2.
Eigen::Vector2d DistortPoint(const Distortion& d, const Eigen::Vector2d& xy) {
  const double x = xy.x(), y = xy.y();
  const double r2 = x * x + y * y;
  const double radial = 1 + r2 * (d.k1 + r2 * (d.k2 + r2 * d.k3));
  return {x * radial + 2 * d.p1 * x * y + d.p2 * (r2 + 2 * x * x),
          y * radial + d.p1 * (r2 + 2 * y * y) + 2 * d.p2 * x * y};
}

// d DistortPoint / d(x, y); symmetric, since r2 depends on x and y alike.
Eigen::Matrix2d DistortPointJacobian(const Distortion& d, const Eigen::Vector2d& xy) {
  const double x = xy.x(), y = xy.y();
  const double r2 = x * x + y * y;
  const double radial = 1 + r2 * (d.k1 + r2 * (d.k2 + r2 * d.k3));
  const double dradial_dr2 = d.k1 + r2 * (2 * d.k2 + 3 * r2 * d.k3);
  const double off_diagonal = 2 * x * y * dradial_dr2 + 2 * d.p1 * x + 2 * d.p2 * y;
  Eigen::Matrix2d J;
  J(0, 0) = radial + 2 * x * x * dradial_dr2 + 2 * d.p1 * y + 6 * d.p2 * x;
  J(0, 1) = J(1, 0) = off_diagonal;
  J(1, 1) = radial + 2 * y * y * dradial_dr2 + 6 * d.p1 * y + 2 * d.p2 * x;
  return J;
}

struct Undistorted {
  Eigen::Vector2d xy;
  bool converged = false;
};

// Newton's method from the distorted point itself. Where a barrel (pincushion) lens's radial map is concave
// (convex) between that start and the root, the steps approach the root from the start's side and never
// overshoot into the fold; they need 2-4 steps over a 1600x900 image even at k1 = -0.3.
Undistorted NewtonUndistort(const Distortion& d, const Eigen::Vector2d& xy_distorted) {
  constexpr int kMaxSteps = 20;
  // A few ulps of |xy| are the best Distort's rounding allows; Newton gets there from 1e-8 in one step.
  const double tolerance = 1e-14 * (1 + xy_distorted.norm());
  Eigen::Vector2d xy = xy_distorted;
  Undistorted best{xy_distorted, false};
  double best_residual2 = std::numeric_limits<double>::infinity();
  for (int step = 0;; ++step) {
    const Eigen::Vector2d residual = DistortPoint(d, xy) - xy_distorted;
    const Eigen::Matrix2d J = DistortPointJacobian(d, xy);
    const double a = J(0, 0), b = J(0, 1), c = J(1, 1), det = a * c - b * b;
    // Past the fold (det <= 0) several points share one image: a root there is not the one a real image has.
    if (!(det > 0)) break;
    const double r2_residual = residual.squaredNorm();
    if (r2_residual < best_residual2) best_residual2 = r2_residual, best.xy = xy;
    if (r2_residual <= tolerance * tolerance) return {xy, true};
    if (step == kMaxSteps) break;
    xy -= Eigen::Vector2d(c * residual.x() - b * residual.y(), a * residual.y() - b * residual.x()) / det;
  }
  return best;
}

}  // namespace

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
  return DistortPoint(distortion, xy);
}

Eigen::Matrix2d PinholeCamera::DistortJacobian(const Eigen::Vector2d& xy) const {
  if (distortion.IsZero()) return Eigen::Matrix2d::Identity();
  return DistortPointJacobian(distortion, xy);
}

std::optional<Eigen::Vector2d> PinholeCamera::TryUndistort(const Eigen::Vector2d& xy_distorted) const {
  if (distortion.IsZero()) return xy_distorted;
  const Undistorted u = NewtonUndistort(distortion, xy_distorted);
  if (!u.converged) return std::nullopt;
  return u.xy;
}

Eigen::Vector2d PinholeCamera::Undistort(const Eigen::Vector2d& xy_distorted) const {
  if (distortion.IsZero()) return xy_distorted;
  return NewtonUndistort(distortion, xy_distorted).xy;
}

std::optional<Eigen::Vector2d> PinholeCamera::Project(const Eigen::Vector3d& p_cam, double min_depth) const {
  if (!(p_cam.z() > min_depth)) return std::nullopt;
  const Eigen::Vector2d xy = Distort(Eigen::Vector2d(p_cam.x() / p_cam.z(), p_cam.y() / p_cam.z()));
  return Eigen::Vector2d(fx * xy.x() + cx, fy * xy.y() + cy);
}

Eigen::Vector3d PinholeCamera::RayDirectionDistorted(const Eigen::Vector2d& xy_distorted) const {
  const Eigen::Vector2d xy = Undistort(xy_distorted);
  return Eigen::Vector3d(xy.x(), xy.y(), 1.0).normalized();
}

}  // namespace sd
