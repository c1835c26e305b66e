#include "core/rigid3.h"

#include <cmath>

namespace sd {

Rigid3d Rigid3d::FromMatrix(const Eigen::Matrix4d& m) {
  return Rigid3d(Eigen::Matrix3d(m.topLeftCorner<3, 3>()), Eigen::Vector3d(m.topRightCorner<3, 1>()));
}

Rigid3d Rigid3d::FromWxyz(double w, double x, double y, double z, const Eigen::Vector3d& t) {
  return Rigid3d(Eigen::Quaterniond(w, x, y, z), t);
}

Rigid3d Rigid3d::FromYaw(double yaw, const Eigen::Vector3d& t) {
  return Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ())), t);
}

Rigid3d Rigid3d::FromUnitQuaternion(const Eigen::Quaterniond& q_unit, const Eigen::Vector3d& t) {
  Rigid3d T;
  T.rotation = q_unit;
  T.translation = t;
  return T;
}

Eigen::Matrix4d Rigid3d::Matrix() const {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  m.topLeftCorner<3, 3>() = rotation.toRotationMatrix();
  m.topRightCorner<3, 1>() = translation;
  return m;
}

Rigid3d Rigid3d::Inverse() const {
  // Renormalised although the conjugate of a unit quaternion is unit: skipping it would move about a third of
  // all inverses in the last bit, and every figure computed from them.
  const Eigen::Quaterniond inv = rotation.conjugate();
  return Rigid3d(inv, -(inv * translation));
}

double Rigid3d::Yaw() const {
  const Eigen::Vector3d x = rotation * Eigen::Vector3d::UnitX();
  return std::atan2(x.y(), x.x());
}

Rigid3d Interpolate(const Rigid3d& a, const Rigid3d& b, double s) {
  return Rigid3d(a.rotation.slerp(s, b.rotation), (1 - s) * a.translation + s * b.translation);
}

}  // namespace sd
