#include "io/geometry_json.h"

#include <cmath>
#include <string>

#include "core/error.h"

namespace sd {
using nlohmann::json;

namespace {

json Vec3Json(const Eigen::Vector3d& v) { return json::array({v.x(), v.y(), v.z()}); }

// `r` must be an array of exactly `n` numbers; `shape` ("[x, y, z]") is what the refusal says it expected.
void CheckLength(const JsonReader& r, size_t n, const char* shape) {
  if (r.Size() != n) r.Fail(Msg() << "expected " << shape << ", found " << r.Size() << " values");
}

Eigen::Vector3d ReadVec3(const JsonReader& r, const char* shape) {
  CheckLength(r, 3, shape);
  return {r[0].Number(), r[1].Number(), r[2].Number()};
}

json RotationJson(const Eigen::Quaterniond& q) { return json::array({q.w(), q.x(), q.y(), q.z()}); }

Rigid3d ReadPose(const JsonReader& rotation, const Eigen::Vector3d& translation) {
  CheckLength(rotation, 4, "[w, x, y, z]");
  const Eigen::Quaterniond q(rotation[0].Number(), rotation[1].Number(), rotation[2].Number(), rotation[3].Number());
  const double length = q.norm();
  if (!(length >= 1e-6)) rotation.Fail(Msg() << "is no rotation: the quaternion's length is " << length);
  if (std::abs(length - 1) <= kUnitQuaternionTolerance) return Rigid3d::FromUnitQuaternion(q, translation);
  return Rigid3d::FromWxyz(q.w(), q.x(), q.y(), q.z(), translation);
}

}  // namespace

json Rigid3dJson(const Rigid3d& T) {
  return {{"translation", Vec3Json(T.translation)}, {"rotation_wxyz", RotationJson(T.rotation)}};
}

Rigid3d ReadRigid3d(const JsonReader& r) {
  const Eigen::Vector3d translation = ReadVec3(r["translation"], "[x, y, z]");
  return ReadPose(r["rotation_wxyz"], translation);
}

json Box3Json(const Box3& box) {
  return {{"center", Vec3Json(box.center())},
          {"size", Vec3Json(box.size)},
          {"rotation_wxyz", RotationJson(box.T_frame_box.rotation)}};
}

Box3 ReadBox3(const JsonReader& r) {
  Box3 box;
  const Eigen::Vector3d center = ReadVec3(r["center"], "[x, y, z]");
  box.T_frame_box = ReadPose(r["rotation_wxyz"], center);
  const JsonReader size = r["size"];
  box.size = ReadVec3(size, "[length, width, height]");
  if (!(box.size.minCoeff() > 0)) size.Fail("box sizes must be positive");
  return box;
}

json Box2Json(const Box2& box) { return json::array({box.x1, box.y1, box.x2, box.y2}); }

Box2 ReadBox2(const JsonReader& r) {
  CheckLength(r, 4, "[x1, y1, x2, y2]");
  return Box2{r[0].Number(), r[1].Number(), r[2].Number(), r[3].Number()};
}

}  // namespace sd
