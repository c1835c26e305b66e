// The geometry codec: what it writes reads back bit for bit, files of other writers read as before, and each
// refusal names the file and the key.
#include "io/geometry_json.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstring>
#include <random>
#include <string>

#include "core/error.h"
#include "testing/input_error.h"

namespace sd {
namespace {

using nlohmann::json;

using testing::InputErrorOf;

// Bit equality: == would let -0.0 stand for 0.0.
bool SameBits(const Eigen::Vector4d& a, const Eigen::Vector4d& b) { return std::memcmp(a.data(), b.data(), sizeof(double) * 4) == 0; }
bool SameBits(const Eigen::Vector3d& a, const Eigen::Vector3d& b) { return std::memcmp(a.data(), b.data(), sizeof(double) * 3) == 0; }

// Through text, as a file holds it.
json Reparsed(const json& j) { return ParseJsonText(j.dump(), "mem.json"); }

// Rotations as the rest of the code makes them: a random direction in R^4 through Rigid3d's normalising
// constructor; translations from millimetres to kilometres, so digits of every magnitude are exercised.
Rigid3d RandomPose(std::mt19937_64& rng) {
  std::normal_distribution<double> n(0, 1);
  std::uniform_real_distribution<double> exponent(-3, 3);
  const Eigen::Quaterniond q(n(rng), n(rng), n(rng), n(rng));
  const Eigen::Vector3d t(n(rng) * std::pow(10, exponent(rng)), n(rng) * std::pow(10, exponent(rng)), n(rng));
  return Rigid3d(q, t);
}

TEST(GeometryJson, PosesFromRandomQuaternionsRoundTripBitForBit) {
  std::mt19937_64 rng(7);
  int renormalising_would_move = 0;
  for (int i = 0; i < 20000; ++i) {
    const Rigid3d T = RandomPose(rng);
    const json j = Reparsed(Rigid3dJson(T));
    const Rigid3d back = ReadRigid3d(JsonReader(j, "pose.json"));
    ASSERT_TRUE(SameBits(back.rotation.coeffs(), T.rotation.coeffs())) << i << ": " << j.dump();
    ASSERT_TRUE(SameBits(back.translation, T.translation)) << i << ": " << j.dump();
    ASSERT_EQ(Rigid3dJson(back).dump(), j.dump());
    const Rigid3d renormalised = Rigid3d::FromWxyz(T.rotation.w(), T.rotation.x(), T.rotation.y(), T.rotation.z(), T.translation);
    renormalising_would_move += SameBits(renormalised.rotation.coeffs(), T.rotation.coeffs()) ? 0 : 1;
  }
  // Why unit quaternions are kept as written: normalising them again moves a share of them (core/rigid3.h).
  EXPECT_GT(renormalising_would_move, 1000);
}

TEST(GeometryJson, BoxesRoundTripBitForBit) {
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<double> side(0.01, 20);
  for (int i = 0; i < 5000; ++i) {
    Box3 b;
    b.T_frame_box = RandomPose(rng);
    b.size = Eigen::Vector3d(side(rng), side(rng), side(rng));
    const json j = Reparsed(Box3Json(b));
    const Box3 back = ReadBox3(JsonReader(j, "box.json"));
    ASSERT_TRUE(SameBits(back.T_frame_box.rotation.coeffs(), b.T_frame_box.rotation.coeffs())) << j.dump();
    ASSERT_TRUE(SameBits(back.center(), b.center())) << j.dump();
    ASSERT_TRUE(SameBits(back.size, b.size)) << j.dump();
  }
  const Box2 b2{0.5, 1.25, 1e-17, 1919.999999999999};
  const Box2 back2 = ReadBox2(JsonReader(Reparsed(Box2Json(b2)), "b.json"));
  EXPECT_TRUE(back2.x1 == b2.x1 && back2.y1 == b2.y1 && back2.x2 == b2.x2 && back2.y2 == b2.y2);
}

// The encodings are files' formats (mining items on users' disks, plan.json): pinned here.
TEST(GeometryJson, EncodingsArePinned) {
  Box3 b;
  b.T_frame_box = Rigid3d(Eigen::Quaterniond::Identity(), Eigen::Vector3d(1, 2, 3.5));
  b.size = Eigen::Vector3d(4, 2, 1.5);
  EXPECT_EQ(Box3Json(b).dump(), R"({"center":[1.0,2.0,3.5],"rotation_wxyz":[1.0,0.0,0.0,0.0],"size":[4.0,2.0,1.5]})");
  EXPECT_EQ(Rigid3dJson(b.T_frame_box).dump(), R"({"rotation_wxyz":[1.0,0.0,0.0,0.0],"translation":[1.0,2.0,3.5]})");
  EXPECT_EQ(Box2Json(Box2{1, 2, 30, 40.5}).dump(), "[1.0,2.0,30.0,40.5]");
}

// Files from other writers (a hand-edited item, a tool printing 4 digits) are normalised, as FromWxyz did before.
TEST(GeometryJson, LooseQuaternionsAreNormalised) {
  const json j = ParseJsonText(R"({"center": [10, -2, 0.4], "size": [0.4, 0.4, 0.8], "rotation_wxyz": [0.7071, 0, 0, 0.7071]})", "item.json");
  const Box3 b = ReadBox3(JsonReader(j, "item.json"));
  const Rigid3d expected = Rigid3d::FromWxyz(0.7071, 0, 0, 0.7071, Eigen::Vector3d(10, -2, 0.4));
  EXPECT_TRUE(SameBits(b.T_frame_box.rotation.coeffs(), expected.rotation.coeffs()));
  EXPECT_NEAR(b.T_frame_box.rotation.norm(), 1, 1e-15);
  EXPECT_NEAR(b.Yaw(), M_PI / 2, 1e-12);
  // Integers are numbers too.
  const json twice = ParseJsonText(R"({"translation": [1, 2, 3], "rotation_wxyz": [2, 0, 0, 0]})", "pose.json");
  EXPECT_TRUE(ReadRigid3d(JsonReader(twice, "pose.json")).rotation.coeffs().isApprox(Eigen::Vector4d(0, 0, 0, 1)));
}

TEST(GeometryJson, RefusalsNameTheFileAndTheKey) {
  const json good = Box3Json(Box3{Rigid3d::FromYaw(0.3, Eigen::Vector3d(1, 2, 3)), Eigen::Vector3d(1, 1, 1)});
  auto box_error = [&](const std::string& key, const json& value) {
    json j = {{"box", good}};
    j["box"][key] = value;
    return InputErrorOf([&] { ReadBox3(JsonReader(j, "part.json")["box"]); });
  };
  std::string m = box_error("size", {1.0, -0.5, 1.0});
  EXPECT_NE(m.find("part.json: .box.size: box sizes must be positive"), std::string::npos) << m;
  EXPECT_NE(box_error("size", {1.0, 0.0, 1.0}).find("must be positive"), std::string::npos);
  m = box_error("size", {1.0, 1.0});
  EXPECT_NE(m.find("part.json: .box.size: expected [length, width, height], found 2 values"), std::string::npos) << m;
  m = box_error("center", {1.0, 2.0, 3.0, 4.0});
  EXPECT_NE(m.find(".box.center: expected [x, y, z], found 4 values"), std::string::npos) << m;
  m = box_error("rotation_wxyz", {1.0, 0.0, 0.0});
  EXPECT_NE(m.find(".box.rotation_wxyz: expected [w, x, y, z], found 3 values"), std::string::npos) << m;
  m = box_error("rotation_wxyz", {0.0, 0.0, 0.0, 0.0});
  EXPECT_NE(m.find(".box.rotation_wxyz: is no rotation"), std::string::npos) << m;
  m = box_error("center", {1.0, nullptr, 3.0});
  EXPECT_NE(m.find(".box.center[1]: expected a number, found null"), std::string::npos) << m;
  m = box_error("size", "big");
  EXPECT_NE(m.find(".box.size: expected an array"), std::string::npos) << m;

  json no_center = good;
  no_center.erase("center");
  m = InputErrorOf([&] { ReadBox3(JsonReader(no_center, "item.json")); });
  EXPECT_NE(m.find("item.json: (root): missing required field 'center'"), std::string::npos) << m;
  // The old part encoding ({"q_wxyz", "t"}) is not this one: refused, never misread.
  const json old_pose = {{"q_wxyz", {1.0, 0.0, 0.0, 0.0}}, {"t", {1.0, 2.0, 3.0}}};
  EXPECT_NE(InputErrorOf([&] { ReadRigid3d(JsonReader(old_pose, "part.json")); }).find("missing required field 'translation'"),
            std::string::npos);
  const json box2 = {1.0, 2.0, 3.0};
  m = InputErrorOf([&] { ReadBox2(JsonReader(box2, "items.jsonl:7")); });
  EXPECT_NE(m.find("items.jsonl:7: (root): expected [x1, y1, x2, y2], found 3 values"), std::string::npos) << m;
}

}  // namespace
}  // namespace sd
