#include "datasets/annotation_json.h"

#include <climits>
#include <cmath>
#include <limits>

#include "io/geometry_json.h"

namespace sd {
using nlohmann::json;

namespace {

// nlohmann would dump NaN as null anyway; writing null here keeps the value in memory equal to the one read back.
json MaybeNumber(double v) { return std::isfinite(v) ? json(v) : json(nullptr); }
double ReadMaybeNumber(const JsonReader& r) {
  return r.raw().is_null() ? std::numeric_limits<double>::quiet_NaN() : r.Number();
}

int ReadInt(const JsonReader& r) { return static_cast<int>(r.IntegerIn(INT_MIN, INT_MAX)); }

}  // namespace

json AnnotationJson(const Annotation& a) {
  json box2d = json::object();
  for (const auto& [channel, b] : a.box2d_by_camera) box2d[channel] = Box2Json(b);
  return {{"category", a.category},
          {"box", Box3Json(a.box)},
          {"token", a.token},
          {"instance_token", a.instance_token},
          {"num_lidar_pts", a.num_lidar_pts},
          {"velocity", {MaybeNumber(a.velocity.x()), MaybeNumber(a.velocity.y())}},
          {"visibility", a.visibility},
          {"truncation", MaybeNumber(a.truncation)},
          {"box2d_by_camera", std::move(box2d)},
          {"detected", a.detected}};
}

Annotation ReadAnnotation(const JsonReader& r) {
  Annotation a;
  a.category = r["category"].String();
  a.box = ReadBox3(r["box"]);
  a.token = r["token"].String();
  a.instance_token = r["instance_token"].String();
  a.num_lidar_pts = ReadInt(r["num_lidar_pts"]);
  const JsonReader velocity = r["velocity"];
  if (velocity.Size() != 2) velocity.Fail("expected [vx, vy]");
  a.velocity = Eigen::Vector2d(ReadMaybeNumber(velocity[0]), ReadMaybeNumber(velocity[1]));
  a.visibility = ReadInt(r["visibility"]);
  a.truncation = ReadMaybeNumber(r["truncation"]);
  const JsonReader box2d = r["box2d_by_camera"];
  if (!box2d.raw().is_object()) box2d.Fail("expected an object of channel: [x1, y1, x2, y2]");
  for (const auto& [channel, b] : box2d.raw().items()) a.box2d_by_camera[channel] = ReadBox2(box2d[channel]);
  a.detected = r["detected"].Bool();
  return a;
}

}  // namespace sd
