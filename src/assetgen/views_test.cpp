#include "assetgen/views.h"

#include <cmath>
#include <fstream>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "geometry/test_meshes.h"
#include "io/image_io.h"
#include "io/json.h"
#include "testing/testing.h"

namespace sd {
namespace {

constexpr double kPi = 3.14159265358979323846;

TEST(Zero123PlusPlusRig, SixViewsAtTheDocumentedAnglesLookingAtTheOrigin) {
  const std::vector<ViewCamera> rig = Zero123PlusPlusRig(320);
  ASSERT_EQ(rig.size(), 6u);
  for (int i = 0; i < 6; ++i) {
    const ViewCamera& v = rig[i];
    const Eigen::Vector3d eye = v.T_world_cam.translation;
    EXPECT_NEAR(eye.norm(), kRigDistance, 1e-9);
    const double azimuth = std::atan2(eye.y(), eye.x()) * 180 / kPi;
    const double elevation = std::asin(eye.z() / eye.norm()) * 180 / kPi;
    EXPECT_NEAR(std::remainder(azimuth - (30.0 + 60.0 * i), 360.0), 0.0, 1e-9) << i;
    EXPECT_NEAR(elevation, i % 2 == 0 ? 20.0 : -10.0, 1e-9) << i;
    // The origin projects to the image centre; +z is up in the image (smaller v).
    const Rigid3d T_cam_world = v.T_world_cam.Inverse();
    const auto centre = v.camera.Project(T_cam_world * Eigen::Vector3d::Zero());
    ASSERT_TRUE(centre.has_value());
    EXPECT_NEAR(centre->x(), 160.0, 1e-9);
    EXPECT_NEAR(centre->y(), 160.0, 1e-9);
    const auto above = v.camera.Project(T_cam_world * Eigen::Vector3d(0, 0, 0.5));
    ASSERT_TRUE(above.has_value());
    EXPECT_LT(above->y(), 160.0 - 10.0);
    // 30 degrees vertical field of view.
    EXPECT_NEAR(2 * std::atan(0.5 * v.camera.height / v.camera.fy) * 180 / kPi, 30.0, 1e-9);
  }
}

TEST(NormalizeIntoSphere, FarthestVertexOnTheSphere) {
  TriangleMesh m = geometry::testing::Cube(Eigen::Vector3f(1, 2, 3), Eigen::Vector3f(3, 3, 7));
  const SphereNormalization n = NormalizeIntoSphere(m, 1.0f);
  n.Apply(&m);
  float r = 0;
  for (const auto& p : m.positions) r = std::max(r, p.norm());
  EXPECT_NEAR(r, 1.0f, 1e-6f);
  n.Undo(&m);
  EXPECT_NEAR(m.positions[0].x(), 1.0f, 1e-5f);
  EXPECT_THROW(NormalizeIntoSphere(TriangleMesh{}), InputError);
}

// Oracle views of a sphere against the analytic picture: the silhouette is a disc whose angular radius is
// asin(r / d), and the normal at the image centre points back at the camera.
TEST(RenderOracleViews, SphereSilhouetteAndNormalsMatchAnalyticValues) {
  const float r = 0.8f;
  const TriangleMesh sphere = geometry::testing::Icosphere(5, r);
  const std::vector<ViewCamera> rig = Zero123PlusPlusRig(160);
  const MultiViewSet views = RenderOracleViews(sphere, rig, 2);
  ASSERT_EQ(views.size(), 6u);
  for (const MultiView& v : views) {
    double area = 0;
    for (int y = 0; y < 160; ++y)
      for (int x = 0; x < 160; ++x) area += v.mask.at(x, y);
    // Disc radius in pixels: f * tan(asin(r/d)).
    const double rpx = v.view.camera.fy * std::tan(std::asin(r / kRigDistance));
    EXPECT_NEAR(area, kPi * rpx * rpx, 0.01 * kPi * rpx * rpx) << v.view.name;
    const Eigen::Vector3f n(v.normals.pixel(80, 80));
    const Eigen::Vector3f towards_camera = v.view.T_world_cam.translation.cast<float>().normalized();
    EXPECT_GT(n.dot(towards_camera), std::cos(2.0f * static_cast<float>(kPi) / 180.0f)) << v.view.name;
    EXPECT_EQ(v.mask.at(0, 0), 0.0f);
  }
}

TEST(Views, SaveAndLoadRoundTripInBothNormalFrames) {
  const TriangleMesh sphere = geometry::testing::Icosphere(3, 0.9f);
  MultiViewSet views = RenderOracleViews(sphere, Zero123PlusPlusRig(64), 1);
  // One view cut by an image border: its known-pixel mask travels with it; the others stay whole.
  views[1].known = ImageF(64, 64, 1, 1.0f);
  for (int y = 0; y < 64; ++y)
    for (int x = 50; x < 64; ++x) views[1].known.at(x, y) = 0.0f;
  for (const std::string frame : {"camera", "world"}) {
    testing::TempDir tmp;
    SaveViews(views, tmp / "views", frame, false);
    const MultiViewSet back = LoadViews(tmp / "views");
    ASSERT_EQ(back.size(), views.size());
    for (size_t i = 0; i < views.size(); ++i) {
      EXPECT_EQ(back[i].view.name, views[i].view.name);
      EXPECT_NEAR((back[i].view.T_world_cam.Matrix() - views[i].view.T_world_cam.Matrix()).norm(), 0.0, 1e-9);
      EXPECT_DOUBLE_EQ(back[i].view.camera.fx, views[i].view.camera.fx);
      EXPECT_EQ(back[i].known.vector(), views[i].known.vector()) << i;
      EXPECT_EQ(IsWhole(back[i]), i != 1);
      double worst_normal = 0, worst_mask = 0;
      for (int y = 0; y < 64; ++y)
        for (int x = 0; x < 64; ++x) {
          worst_mask = std::max(worst_mask, double(std::abs(back[i].mask.at(x, y) - views[i].mask.at(x, y))));
          if (views[i].mask.at(x, y) < 1.0f) continue;
          const Eigen::Vector3f a(views[i].normals.pixel(x, y)), b(back[i].normals.pixel(x, y));
          worst_normal = std::max(worst_normal, double((a - b).norm()));
        }
      // Colour (an untextured mesh renders white where covered) survives the sRGB PNG.
      ASSERT_FALSE(back[i].color.empty());
      double worst_color = 0;
      for (size_t k = 0; k < views[i].color.size(); ++k)
        worst_color = std::max(worst_color, double(std::abs(back[i].color.data()[k] - views[i].color.data()[k])));
      EXPECT_LT(worst_color, 0.01) << frame;
      // 8-bit quantisation: half a step per channel (1/255 of the [-1, 1] range), then re-normalised.
      EXPECT_LT(worst_normal, 0.012) << frame;
      EXPECT_LE(worst_mask, 0.5 / 255 + 1e-6) << frame;
    }
    // The folder is not overwritten by accident.
    EXPECT_THROW(SaveViews(views, tmp / "views", frame, false), InputError);
  }
}

class ViewsBadInput : public ::testing::Test {
 protected:
  void SetUp() override {
    SaveViews(RenderOracleViews(geometry::testing::Icosphere(2, 0.9f), Zero123PlusPlusRig(32), 1), dir_, "camera", false);
    json_ = ReadJsonFile(dir_ / "cameras.json");
  }
  void Write(const nlohmann::json& j) { std::ofstream(dir_ / "cameras.json") << j.dump(); }
  void ExpectError(const std::string& fragment) {
    try {
      LoadViews(dir_);
      FAIL() << "no error; expected one mentioning " << fragment;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
    }
  }
  testing::TempDir tmp_;
  std::filesystem::path dir_ = tmp_ / "views";
  nlohmann::json json_;
};

TEST_F(ViewsBadInput, MissingCamerasJson) {
  std::filesystem::remove(dir_ / "cameras.json");
  ExpectError("cameras.json: missing");
}
TEST_F(ViewsBadInput, BrokenJson) {
  std::ofstream(dir_ / "cameras.json") << "{\"views\": [";
  ExpectError("cameras.json");
}
TEST_F(ViewsBadInput, NoViews) {
  json_["views"] = nlohmann::json::array();
  Write(json_);
  ExpectError("no views");
}
TEST_F(ViewsBadInput, CameraMissingIntrinsics) {
  json_["views"][2].erase("fx");
  Write(json_);
  ExpectError("views[2]");
}
TEST_F(ViewsBadInput, ImageSizeDisagreesWithCamera) {
  WriteImage(dir_ / "mask_03.png", ImageU8(40, 32, 1));
  ExpectError("mask_03.png: image is 40x32");
}
TEST_F(ViewsBadInput, ViewsOfDifferentSizes) {
  json_["views"][1]["width"] = 64;
  json_["views"][1]["height"] = 64;
  Write(json_);
  WriteImage(dir_ / "mask_01.png", ImageU8(64, 64, 1));
  WriteImage(dir_ / "normal_01.png", ImageU8(64, 64, 3));
  ExpectError("one size");
}
TEST_F(ViewsBadInput, NonRigidPose) {
  json_["views"][0]["T_world_cam"][0][0] = 2.0;
  Write(json_);
  ExpectError("not a rigid transform");
}
TEST_F(ViewsBadInput, UnknownNormalFrame) {
  json_["normal_frame"] = "object";
  Write(json_);
  ExpectError("normal_frame");
}
TEST_F(ViewsBadInput, ColourImageSizeDisagreesWithCamera) {
  WriteImage(dir_ / "image_05.png", ImageU8(20, 32, 3));
  ExpectError("image_05.png: image is 20x32");
}
TEST_F(ViewsBadInput, MissingImage) {
  std::filesystem::remove(dir_ / "normal_04.png");
  ExpectError("normal_04.png");
}

}  // namespace
}  // namespace sd
