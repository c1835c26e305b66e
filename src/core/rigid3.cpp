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

Eigen::Matrix4d Rigid3d::Matrix() const {
  Eigen::Matrix4d m = Eigen::Matrix4d::Identity();
  m.topLeftCorner<3, 3>() = rotation.toRotationMatrix();
  m.topRightCorner<3, 1>() = translation;
  return m;
}

Rigid3d Rigid3d::Inverse() const {
  const Eigen::Quaterniond inv = rotation.conjugate();
  return Rigid3d(inv, -(inv * translation));
}

double Rigid3d::Yaw() const {
  const Eigen::Vector3d x = rotation * Eigen::Vector3d::UnitX();
  return std::atan2(x.y(), x.x());
}

}  // namespace sd
