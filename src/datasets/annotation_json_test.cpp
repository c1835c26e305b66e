// The annotation codec: unknown values (NaN velocity and truncation, -1 counts) survive, every double reads back
// bit for bit, and a bad box is named by file and key.
#include "datasets/annotation_json.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <limits>
#include <string>

#include "core/error.h"

namespace sd {
namespace {

using nlohmann::json;

bool SameBits(double a, double b) { return std::memcmp(&a, &b, sizeof a) == 0; }

Annotation Cone() {
  Annotation a;
  a.category = "movable_object.trafficcone";
  a.box.T_frame_box = Rigid3d(Eigen::Quaterniond(0.3, -0.1, 0.05, 0.9), Eigen::Vector3d(12.345678901234567, -3.1, 0.35));
  a.box.size = Eigen::Vector3d(0.41, 0.39, 0.7);
  a.token = "synth-0-0";
  a.instance_token = "plan-3";
  a.num_lidar_pts = 17;
  a.velocity = Eigen::Vector2d(std::numeric_limits<double>::quiet_NaN(), 0.1);
  a.visibility = 4;
  a.truncation = std::numeric_limits<double>::quiet_NaN();
  a.box2d_by_camera["CAM_FRONT"] = Box2{700.25, 400, 760, 480.5};
  a.box2d_by_camera["CAM_FRONT_LEFT"] = Box2{1, 2, 3, 4};
  return a;
}

TEST(AnnotationJson, RoundTripsBitForBitWithUnknowns) {
  Annotation unknowns;  // every field at its "unknown" default, but a box (a zero size is refused)
  unknowns.box = Cone().box;
  for (const Annotation& a : {Cone(), unknowns}) {
    const json written = AnnotationJson(a);
    const json j = ParseJsonText(written.dump(), "part.json");
    EXPECT_EQ(j, written);  // NaN is written as null, so the value in memory is the one a reader sees
    const Annotation b = ReadAnnotation(JsonReader(j, "part.json"));
    EXPECT_EQ(b.category, a.category);
    EXPECT_EQ(b.token, a.token);
    EXPECT_EQ(b.instance_token, a.instance_token);
    EXPECT_EQ(b.num_lidar_pts, a.num_lidar_pts);
    EXPECT_EQ(b.visibility, a.visibility);
    for (int k = 0; k < 2; ++k) EXPECT_TRUE(SameBits(b.velocity[k], a.velocity[k]) || (std::isnan(b.velocity[k]) && std::isnan(a.velocity[k])));
    EXPECT_TRUE(SameBits(b.truncation, a.truncation) || (std::isnan(b.truncation) && std::isnan(a.truncation)));
    EXPECT_EQ(b.box.T_frame_box.rotation.coeffs(), a.box.T_frame_box.rotation.coeffs());
    EXPECT_EQ(b.box.center(), a.box.center());
    EXPECT_EQ(b.box.size, a.box.size);
    ASSERT_EQ(b.box2d_by_camera.size(), a.box2d_by_camera.size());
    for (const auto& [channel, box] : a.box2d_by_camera) {
      const Box2& got = b.box2d_by_camera.at(channel);
      EXPECT_TRUE(got.x1 == box.x1 && got.y1 == box.y1 && got.x2 == box.x2 && got.y2 == box.y2) << channel;
    }
    EXPECT_EQ(b.detected, a.detected);
    EXPECT_EQ(AnnotationJson(b).dump(), written.dump());
  }
  const json j = AnnotationJson(Cone());
  EXPECT_TRUE(j["velocity"][0].is_null());
  EXPECT_TRUE(j["truncation"].is_null());
  EXPECT_EQ(j["box"].size(), 3u);  // the geometry codec's Box3: center, size, rotation_wxyz
}

TEST(AnnotationJson, RefusalsNameTheKey) {
  auto error_of = [](const json& j) {
    try {
      ReadAnnotation(JsonReader(j, "parts/0-a/part.json", ".objects[0].label.annotation"));
    } catch (const InputError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  json j = AnnotationJson(Cone());
  j["box"]["size"][2] = -0.7;
  std::string m = error_of(j);
  EXPECT_NE(m.find("parts/0-a/part.json: .objects[0].label.annotation.box.size: box sizes must be positive"), std::string::npos) << m;
  j = AnnotationJson(Cone());
  j["velocity"] = {0.0};
  EXPECT_NE(error_of(j).find(".annotation.velocity: expected [vx, vy]"), std::string::npos) << error_of(j);
  j = AnnotationJson(Cone());
  j["box2d_by_camera"]["CAM_FRONT"] = {1.0, 2.0};
  EXPECT_NE(error_of(j).find(".box2d_by_camera.CAM_FRONT: expected [x1, y1, x2, y2]"), std::string::npos) << error_of(j);
  j = AnnotationJson(Cone());
  j["num_lidar_pts"] = 1e12;
  EXPECT_NE(error_of(j).find(".num_lidar_pts: integer"), std::string::npos) << error_of(j);
}

}  // namespace
}  // namespace sd
