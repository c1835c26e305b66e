#include "core/box3.h"

#include <algorithm>
#include <cmath>

namespace sd {

std::array<Eigen::Vector3d, 8> Box3::Corners() const {
  const Eigen::Vector3d h = 0.5 * size;
  static const double kSign[4][2] = {{1, 1}, {-1, 1}, {-1, -1}, {1, -1}};
  std::array<Eigen::Vector3d, 8> out;
  for (int z = 0; z < 2; ++z)
    for (int i = 0; i < 4; ++i)
      out[z * 4 + i] = T_frame_box * Eigen::Vector3d(kSign[i][0] * h.x(), kSign[i][1] * h.y(), (z ? 1 : -1) * h.z());
  return out;
}

bool Box3::Contains(const Eigen::Vector3d& p, double margin) const { return BoxContainment(*this, margin).Contains(p); }

Box3 Box3::Transformed(const Rigid3d& T_new_frame) const {
  return Box3{T_new_frame * T_frame_box, size};
}

namespace {
// Projects the box footprint rectangle on `axis` and returns [min, max].
std::pair<double, double> ProjectFootprint(const Box3& b, const Eigen::Vector2d& axis, double margin) {
  const Eigen::Vector3d ex3 = b.T_frame_box.rotation * Eigen::Vector3d::UnitX();
  const Eigen::Vector3d ey3 = b.T_frame_box.rotation * Eigen::Vector3d::UnitY();
  const Eigen::Vector2d ex = ex3.head<2>().normalized(), ey = ey3.head<2>().normalized();
  const double c = b.center().head<2>().dot(axis);
  const double r = (0.5 * b.size.x() + margin) * std::abs(ex.dot(axis)) + (0.5 * b.size.y() + margin) * std::abs(ey.dot(axis));
  return {c - r, c + r};
}
}  // namespace

bool BoxesOverlap(const Box3& a, const Box3& b, double margin) {
  // z overlap, using each box's vertical extent (boxes are near-upright in driving data).
  // `margin` is a clearance: each box grows by half of it, so boxes closer than `margin` overlap.
  const double m = 0.5 * margin;
  const double az = 0.5 * a.size.z() + m, bz = 0.5 * b.size.z() + m;
  if (a.center().z() + az < b.center().z() - bz || b.center().z() + bz < a.center().z() - az) return false;
  // Separating axis theorem on the 4 edge normals of the two footprints (same half-margin growth as in z).
  for (const Box3* box : {&a, &b}) {
    for (int k = 0; k < 2; ++k) {
      const Eigen::Vector3d e = box->T_frame_box.rotation * (k == 0 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY());
      const Eigen::Vector2d axis = e.head<2>().normalized();
      const auto [a0, a1] = ProjectFootprint(a, axis, m);
      const auto [b0, b1] = ProjectFootprint(b, axis, m);
      if (a1 < b0 || b1 < a0) return false;
    }
  }
  return true;
}

double IoU(const Box2& a, const Box2& b) {
  const Box2 inter{std::max(a.x1, b.x1), std::max(a.y1, b.y1), std::min(a.x2, b.x2), std::min(a.y2, b.y2)};
  const double i = inter.Area();
  const double u = a.Area() + b.Area() - i;
  return u > 0 ? i / u : 0.0;
}

}  // namespace sd
