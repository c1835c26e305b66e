#pragma once
// Rigid transforms. Name every instance after the frames it connects: `T_parent_child` maps coordinates
// expressed in `child` into `parent` (so T_ego_lidar * p_lidar = p_ego, and T_a_b * T_b_c = T_a_c).
//
// Unit rotations: every way in renormalises its quaternion (file values, matrices, products and slerps drift
// off unit length) except FromUnitQuaternion, which stores it as given. Normalising is not idempotent in
// floating point (about a third of unit quaternions move in the last bit), so values read back from our own
// files go through FromUnitQuaternion to round-trip exactly.
#include <Eigen/Core>
#include <Eigen/Geometry>

namespace sd {

struct Rigid3d {
  Eigen::Quaterniond rotation = Eigen::Quaterniond::Identity();
  Eigen::Vector3d translation = Eigen::Vector3d::Zero();

  Rigid3d() = default;
  Rigid3d(const Eigen::Quaterniond& q, const Eigen::Vector3d& t) : rotation(q.normalized()), translation(t) {}
  Rigid3d(const Eigen::Matrix3d& R, const Eigen::Vector3d& t) : rotation(Eigen::Quaterniond(R).normalized()), translation(t) {}

  // From a homogeneous 4x4 (top-left 3x3 must be a rotation; it is re-orthonormalised through the quaternion).
  static Rigid3d FromMatrix(const Eigen::Matrix4d& m);
  // Quaternion in the w, x, y, z order that nuScenes, Lyft and Argoverse tables use.
  static Rigid3d FromWxyz(double w, double x, double y, double z, const Eigen::Vector3d& t);
  // Rotation about +z by `yaw` radians, then translation.
  static Rigid3d FromYaw(double yaw, const Eigen::Vector3d& t);
  // `q_unit` kept bit for bit: it must already be unit length (e.g. a rotation this type wrote out).
  static Rigid3d FromUnitQuaternion(const Eigen::Quaterniond& q_unit, const Eigen::Vector3d& t);

  Eigen::Matrix4d Matrix() const;
  Eigen::Matrix3d Rotation() const { return rotation.toRotationMatrix(); }
  Rigid3d Inverse() const;
  // Heading of the x axis in the parent's xy plane, radians in (-pi, pi].
  double Yaw() const;

  Eigen::Vector3d operator*(const Eigen::Vector3d& p) const { return rotation * p + translation; }
  Rigid3d operator*(const Rigid3d& other) const {
    return Rigid3d(rotation * other.rotation, rotation * other.translation + translation);
  }
};

// The pose a fraction `s` of the way from `a` (s = 0) to `b` (s = 1): rotation slerped the short way round
// (Eigen's slerp, so q and -q give the same path), translation (1 - s) * a + s * b. Outside [0, 1] it
// extrapolates at constant angular and linear velocity along the same great circle and line; the callers
// (pose tables, box tracks, a sweep's firing times) clamp or bracket, so none does.
Rigid3d Interpolate(const Rigid3d& a, const Rigid3d& b, double s);

}  // namespace sd
