#include "core/rigid3.h"

#include <gtest/gtest.h>

#include <cmath>

namespace sd {
namespace {

constexpr double kPi = 3.14159265358979323846;

Rigid3d Example(double angle, const Eigen::Vector3d& axis, const Eigen::Vector3d& t) {
  return Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(angle, axis.normalized())), t);
}

TEST(Rigid3, ComposeMatchesMatrixProduct) {
  const Rigid3d T_a_b = Example(0.7, {1, 2, 3}, {1, -2, 0.5});
  const Rigid3d T_b_c = Example(-1.9, {0, 1, -1}, {-3, 0.25, 2});
  const Rigid3d T_a_c = T_a_b * T_b_c;
  EXPECT_TRUE(T_a_c.Matrix().isApprox(T_a_b.Matrix() * T_b_c.Matrix(), 1e-12));
  const Eigen::Vector3d p_c(0.3, -4, 7);
  EXPECT_TRUE((T_a_c * p_c).isApprox(T_a_b * (T_b_c * p_c), 1e-12));
}

TEST(Rigid3, InverseUndoes) {
  const Rigid3d T = Example(2.1, {-1, 0.5, 0.2}, {10, -20, 3});
  const Rigid3d I = T * T.Inverse();
  EXPECT_TRUE(I.Matrix().isApprox(Eigen::Matrix4d::Identity(), 1e-12));
  EXPECT_TRUE(T.Inverse().Matrix().isApprox(T.Matrix().inverse(), 1e-12));
  const Eigen::Vector3d p(1, 2, 3);
  EXPECT_TRUE((T.Inverse() * (T * p)).isApprox(p, 1e-12));
}

TEST(Rigid3, MatrixRoundTrip) {
  const Rigid3d T = Example(-0.4, {0.3, -0.2, 1}, {0.5, 0.5, -7});
  const Rigid3d back = Rigid3d::FromMatrix(T.Matrix());
  EXPECT_TRUE(back.Matrix().isApprox(T.Matrix(), 1e-12));
  EXPECT_TRUE(back.translation.isApprox(T.translation));
  EXPECT_EQ(T.Matrix()(3, 3), 1.0);
  EXPECT_EQ(T.Matrix().row(3).head<3>().norm(), 0.0);
}

TEST(Rigid3, FromWxyzAgainstHandComputedRotations) {
  // 90 degrees about +z: w = cos 45, z = sin 45. x -> y, y -> -x.
  const double s = std::sqrt(0.5);
  const Rigid3d Rz = Rigid3d::FromWxyz(s, 0, 0, s, {1, 2, 3});
  Eigen::Matrix3d expected;
  expected << 0, -1, 0, 1, 0, 0, 0, 0, 1;
  EXPECT_TRUE(Rz.Rotation().isApprox(expected, 1e-12));
  EXPECT_TRUE((Rz * Eigen::Vector3d(1, 0, 0)).isApprox(Eigen::Vector3d(1, 3, 3), 1e-12));
  // (0.5, 0.5, 0.5, 0.5): 120 degrees about (1, 1, 1), the cyclic permutation x -> y -> z -> x.
  const Rigid3d Rc = Rigid3d::FromWxyz(0.5, 0.5, 0.5, 0.5, Eigen::Vector3d::Zero());
  expected << 0, 0, 1, 1, 0, 0, 0, 1, 0;
  EXPECT_TRUE(Rc.Rotation().isApprox(expected, 1e-12));
  // Unnormalised input is normalised (w, x, y, z order, not Eigen's x, y, z, w storage).
  const Rigid3d Rn = Rigid3d::FromWxyz(2 * s, 0, 0, 2 * s, Eigen::Vector3d::Zero());
  EXPECT_TRUE(Rn.Rotation().isApprox(Rz.Rotation(), 1e-12));
}

TEST(Rigid3, Yaw) {
  for (double yaw : {0.0, 0.3, 1.5, -2.0, 3.0, -3.1, kPi}) {
    const Rigid3d T = Rigid3d::FromYaw(yaw, {1, 2, 3});
    EXPECT_NEAR(T.Yaw(), yaw, 1e-12) << yaw;
    EXPECT_TRUE((T * Eigen::Vector3d::UnitX() - T.translation).isApprox(Eigen::Vector3d(std::cos(yaw), std::sin(yaw), 0), 1e-12));
  }
  EXPECT_NEAR(Rigid3d::FromYaw(2 * kPi + 0.5, Eigen::Vector3d::Zero()).Yaw(), 0.5, 1e-12);  // wrapped into (-pi, pi]
  // Pitch does not change the heading of the x axis in the xy plane.
  const Rigid3d pitched = Rigid3d::FromYaw(0.8, Eigen::Vector3d::Zero()) * Example(0.3, Eigen::Vector3d::UnitY(), Eigen::Vector3d::Zero());
  EXPECT_NEAR(pitched.Yaw(), 0.8, 1e-12);
}

TEST(Rigid3, InterpolateEndpointsAndMidpoint) {
  const Rigid3d a = Rigid3d::FromYaw(0.0, {0, 0, 0});
  const Rigid3d b = Rigid3d::FromYaw(kPi / 2, {2, 4, -6});
  EXPECT_TRUE(Interpolate(a, b, 0.0).Matrix().isApprox(a.Matrix(), 1e-15));
  EXPECT_TRUE(Interpolate(a, b, 1.0).Matrix().isApprox(b.Matrix(), 1e-15));
  EXPECT_EQ(Interpolate(a, b, 0.0).translation, a.translation);
  EXPECT_EQ(Interpolate(a, b, 1.0).translation, b.translation);
  // Half of a 90-degree turn about +z is 45 degrees; the translation is the average.
  const Rigid3d mid = Interpolate(a, b, 0.5);
  EXPECT_NEAR(mid.Yaw(), kPi / 4, 1e-15);
  EXPECT_TRUE(mid.Rotation().isApprox(Rigid3d::FromYaw(kPi / 4, {0, 0, 0}).Rotation(), 1e-15));
  EXPECT_TRUE(mid.translation.isApprox(Eigen::Vector3d(1, 2, -3), 1e-15));
  EXPECT_NEAR(mid.rotation.norm(), 1.0, 1e-15);
  // Past the end it extrapolates along the same turn (no caller does): s = 2 is a half turn.
  EXPECT_NEAR(std::abs(Interpolate(a, b, 2.0).Yaw()), kPi, 1e-12);
}

TEST(Rigid3, InterpolateTakesTheShortWayForQuaternionsOfOppositeSign) {
  // -q is the same rotation as q; interpolating towards it must not swing the long way (225 degrees) round.
  const Rigid3d a = Rigid3d::FromYaw(0.0, {0, 0, 0});
  const Rigid3d b = Rigid3d::FromYaw(kPi / 2, {0, 0, 0});
  const Rigid3d b_negated = Rigid3d::FromUnitQuaternion(Eigen::Quaterniond(-b.rotation.coeffs()), b.translation);
  ASSERT_LT(a.rotation.dot(b_negated.rotation), 0.0);
  ASSERT_TRUE(b_negated.Rotation().isApprox(b.Rotation(), 1e-15));
  for (double s : {0.25, 0.5, 0.75}) {
    EXPECT_NEAR(Interpolate(a, b_negated, s).Yaw(), s * kPi / 2, 1e-12) << s;
    EXPECT_TRUE(Interpolate(a, b_negated, s).Rotation().isApprox(Interpolate(a, b, s).Rotation(), 1e-12)) << s;
  }
}

TEST(Rigid3, FromUnitQuaternionKeepsEveryBitTheConstructorNormalises) {
  // Normalising a unit quaternion again can move its last bit; find such a quaternion to show the difference.
  Eigen::Quaterniond q_unit = Eigen::Quaterniond::Identity();
  bool moves = false;
  for (int i = 1; i < 1000 && !moves; ++i) {
    q_unit = Eigen::Quaterniond(Eigen::AngleAxisd(0.001 * i, Eigen::Vector3d(1, 2, 3).normalized())).normalized();
    moves = q_unit.normalized().coeffs() != q_unit.coeffs();
  }
  ASSERT_TRUE(moves);
  const Eigen::Vector3d t(1, 2, 3);
  EXPECT_EQ(Rigid3d::FromUnitQuaternion(q_unit, t).rotation.coeffs(), q_unit.coeffs());
  EXPECT_EQ(Rigid3d::FromUnitQuaternion(q_unit, t).translation, t);
  EXPECT_NE(Rigid3d(q_unit, t).rotation.coeffs(), q_unit.coeffs());
}

TEST(Rigid3, CompositionStaysUnit) {
  // A long chain of products would drift off unit length without the renormalisation in operator*.
  const Rigid3d step = Example(0.0123, {0.3, -1, 2}, {0.1, 0, 0});
  Rigid3d T;
  for (int i = 0; i < 10000; ++i) T = T * step;
  EXPECT_NEAR(T.rotation.norm(), 1.0, 1e-15);
}

}  // namespace
}  // namespace sd
