#include "datasets/writers.h"

#include <gtest/gtest.h>

#include "core/error.h"
#include "datasets/categories.h"
#include "datasets/internal.h"
#include "datasets/readers.h"
#include "io/image_io.h"
#include "io/json.h"
#include "testing/testing.h"

namespace sd {
namespace {

namespace fs = std::filesystem;
using nlohmann::json;
using sd::testing::RepoData;
using sd::testing::TempDir;

// A warning tripod placed at T_ego_box, seen by `channel` with a plausible 2D box. Each format stores only
// yaw about its box frame's up axis (mmdet3d: LiDAR z; KITTI: rectified cam0 -y), so tests place the object
// with a rotation the format can represent; the writers drop the rest (see writers.h).
AddedObject Tripod(const std::string& channel, const Rigid3d& T_ego_box) {
  AddedObject obj;
  obj.category = "warning_tripod";
  obj.asset_id = "tripod-001";
  const Eigen::Vector3d size = FindCategory("warning_tripod")->default_size;
  obj.annotation.box.size = size;
  obj.annotation.box.T_frame_box = T_ego_box;
  obj.annotation.num_lidar_pts = 42;
  CameraBox cb;
  cb.channel = channel;
  cb.box = {500, 300, 560, 350};
  cb.visible_fraction = 0.9;
  cb.truncation = 0.0;
  obj.camera_boxes.push_back(cb);
  return obj;
}

void ExpectSameBox(const Box3& a, const Box3& b, double tol = 1e-4) {
  const auto ca = a.Corners(), cb = b.Corners();
  for (int k = 0; k < 8; ++k) EXPECT_LT((ca[k] - cb[k]).norm(), tol) << "corner " << k;
  EXPECT_LT((a.size - b.size).cwiseAbs().maxCoeff(), tol);
}

void ExpectSameAnnotations(const std::vector<Annotation>& got, const std::vector<Annotation>& want) {
  ASSERT_GE(got.size(), want.size());
  for (size_t i = 0; i < want.size(); ++i) {
    EXPECT_EQ(got[i].category, want[i].category);
    EXPECT_EQ(got[i].num_lidar_pts, want[i].num_lidar_pts);
    ExpectSameBox(got[i].box, want[i].box, 1e-9);
  }
}

TEST(WriteDerivative, Mmdet3dV1RoundTrip) {
  const Log log = OpenLog(RepoData("driving/nuscenes-scene0061-kf0/mmdet3d_info/n015-2018-07-24-11-22-45+0800.json"));
  const Frame& f = log.frames[0];
  TempDir out;
  FrameEdit edit;
  // LiDAR frame: x right, y forward; the ground is ~1.84 m below the sensor.
  edit.added.push_back(Tripod("CAM_FRONT", f.lidar->T_ego_lidar * Rigid3d::FromYaw(0.4, Eigen::Vector3d(1.5, 8.0, -1.6))));
  const ImageU8 grey(1600, 900, 3, 128);
  edit.images["CAM_FRONT"] = grey;
  PointCloud points = ReadLidar(*f.lidar);
  const size_t n_points = points.size();
  points.data.resize(points.data.size() - 5 * 10);  // drop 10 points, as a LiDAR simulation might occlude them
  edit.points = points;
  const auto written = WriteDerivative(log, {edit}, out.path());
  ASSERT_EQ(written.size(), 1u);
  EXPECT_EQ(written[0], out / "mmdet3d_info/n015-2018-07-24-11-22-45+0800.json");

  const Log back = OpenLog(written[0]);
  ASSERT_EQ(back.frames.size(), 1u);
  const Frame& b = back.frames[0];
  EXPECT_EQ(b.token, f.token);
  ASSERT_EQ(b.annotations.size(), f.annotations.size() + 1);
  ExpectSameAnnotations(b.annotations, f.annotations);
  EXPECT_EQ(b.annotations.back().category, "warning_tripod");
  EXPECT_EQ(back.categories.size(), 11u);
  EXPECT_EQ(b.annotations.back().num_lidar_pts, 42);
  ExpectSameBox(b.annotations.back().box, edit.added[0].annotation.box);
  // Sensor files at the same data_root-relative paths; replaced ones replaced.
  EXPECT_EQ(ReadLidar(*b.lidar).size(), n_points - 10);
  ASSERT_EQ(b.cameras.size(), 6u);
  for (const CameraSensor& c : b.cameras) {
    ASSERT_TRUE(fs::exists(c.image_path)) << c.image_path;
    EXPECT_EQ(c.intrinsics.width, 1600);
    EXPECT_LT((c.T_ego_cam.Matrix() - f.FindCamera(c.channel)->T_ego_cam.Matrix()).cwiseAbs().maxCoeff(), 1e-9);
  }
  const ImageU8 front = ReadImage(b.FindCamera("CAM_FRONT")->image_path);
  EXPECT_NEAR(front.at(800, 450, 1), 128, 3);

  // The added cam_instance follows the dataset's camera-box convention (pinned in readers_test).
  const json j = ReadJsonFile(written[0]);
  const json& ci = j["data_list"][0]["cam_instances"]["CAM_FRONT"].back();
  const CameraSensor& cam = *b.FindCamera("CAM_FRONT");
  const Box3 bc = edit.added[0].annotation.box.Transformed(cam.T_ego_cam.Inverse());
  const auto uv = cam.intrinsics.Project(bc.center());
  ASSERT_TRUE(uv);
  EXPECT_NEAR(ci["center_2d"][0].get<double>(), uv->x(), 1e-6);
  EXPECT_NEAR(ci["center_2d"][1].get<double>(), uv->y(), 1e-6);
  EXPECT_NEAR(ci["depth"].get<double>(), bc.center().z(), 1e-9);
  EXPECT_NEAR(ci["bbox_3d"][4].get<double>(), bc.size.z(), 1e-12);  // l h w order
  EXPECT_EQ(ci["bbox_label_3d"].get<int>(), 10);
  EXPECT_EQ(j["metainfo"]["categories"]["warning_tripod"].get<int>(), 10);
}

TEST(WriteDerivative, Mmdet3dV0RoundTrip) {
  SD_REQUIRE_SHARED(info, "driving/nuscenes-mini-val-infos/nuscenes_infos_val.json");
  const Log log = OpenLog(info);
  TempDir out;
  FrameEdit edit;
  edit.frame_index = 5;
  const Rigid3d& T_ego_lidar = log.frames[5].lidar->T_ego_lidar;
  edit.added.push_back(Tripod("CAM_FRONT", T_ego_lidar * Rigid3d::FromYaw(-0.7, Eigen::Vector3d(-1.0, 9.0, -1.6))));
  WriteOptions options;
  EXPECT_THROW(WriteDerivative(log, {edit}, out.path(), options), InputError);  // sensor files absent
  options.require_sensor_files = false;
  const auto written = WriteDerivative(log, {edit}, out.path(), options);
  ASSERT_EQ(written.size(), 1u);
  const Log back = OpenLog(written[0], {.format = {}, .data_root = out.path()});
  EXPECT_EQ(back.format, LogFormat::kMmdet3dV0);
  ASSERT_EQ(back.frames.size(), 1u);
  const Frame& b = back.frames[0];
  const Frame& f = log.frames[5];
  EXPECT_EQ(b.token, f.token);
  ASSERT_EQ(b.annotations.size(), f.annotations.size() + 1);
  ExpectSameAnnotations(b.annotations, f.annotations);
  EXPECT_EQ(b.annotations.back().category, "warning_tripod");
  ExpectSameBox(b.annotations.back().box, edit.added[0].annotation.box);
}

TEST(WriteDerivative, NuScenesTablesRoundTrip) {
  const Log log = OpenLog(RepoData("driving/nuscenes-scene0061-kf0"));
  TempDir out;
  FrameEdit edit;
  edit.added.push_back(Tripod("CAM_FRONT", Rigid3d::FromYaw(0.4, Eigen::Vector3d(8.0, 1.5, 0.2))));
  const auto written = WriteDerivative(log, {edit}, out.path(), {.unchanged = UnchangedFiles::kSymlink});
  EXPECT_EQ(written.size(), 3u);  // sample_annotation, instance, category (a new class)
  const Log back = OpenLog(out.path());
  ASSERT_EQ(back.frames.size(), 1u);
  const Frame& b = back.frames[0];
  EXPECT_TRUE(b.has_annotations);
  ASSERT_EQ(b.annotations.size(), 1u);
  EXPECT_EQ(b.annotations[0].category, "movable_object.warning_tripod");
  EXPECT_EQ(b.annotations[0].visibility, 4);  // 90 % visible
  EXPECT_EQ(b.annotations[0].num_lidar_pts, 42);
  EXPECT_EQ(b.annotations[0].token.size(), 32u);
  ExpectSameBox(b.annotations[0].box, edit.added[0].annotation.box);
  EXPECT_TRUE(fs::is_symlink(b.lidar->path));
  EXPECT_EQ(ReadLidar(*b.lidar).size(), 34688u);
}

TEST(WriteDerivative, LyftTablesKeepOldAnnotations) {
  const Log log = OpenLog(RepoData("driving/lyft-tables/v1.01-train"));
  TempDir out;
  FrameEdit edit;
  AddedObject car = Tripod("CAM_FRONT", Rigid3d::FromYaw(2.0, Eigen::Vector3d(12.0, -3.0, 0.9)));
  car.category = "car";
  car.annotation.box.size = FindCategory("car")->default_size;
  edit.added.push_back(car);
  WriteOptions options;
  options.require_sensor_files = false;  // the fixture ships tables only
  const auto written = WriteDerivative(log, {edit}, out.path(), options);
  EXPECT_EQ(written.size(), 2u);  // Lyft's own "car" category record is reused, category.json unchanged
  const Log back = OpenLog(out.path());
  ASSERT_EQ(back.frames[0].annotations.size(), 5u);
  ExpectSameAnnotations(back.frames[0].annotations, log.frames[0].annotations);
  EXPECT_EQ(back.frames[0].annotations.back().category, "car");
  ExpectSameBox(back.frames[0].annotations.back().box, car.annotation.box);
}

TEST(WriteDerivative, KittiRoundTrip) {
  const Log log = OpenLog(RepoData("driving/kitti-object"));
  TempDir out;
  FrameEdit edit;
  edit.frame_index = 1;
  // A rotation KITTI can hold: yaw about rectified cam0's y, i.e. an existing label's rotation.
  edit.added.push_back(Tripod("image_2", Rigid3d(log.frames[1].annotations[0].box.T_frame_box.rotation, Eigen::Vector3d(10.0, 1.5, -1.5))));
  const auto written = WriteDerivative(log, {edit}, out.path());
  ASSERT_EQ(written.size(), 1u);
  EXPECT_EQ(written[0], out / "label_2/000001.txt");
  const Log back = OpenLog(out.path());
  ASSERT_EQ(back.frames.size(), 1u);
  const Frame& b = back.frames[0];
  EXPECT_EQ(b.token, "000001");
  const Frame& f = log.frames[1];
  ASSERT_EQ(b.annotations.size(), f.annotations.size() + 1);
  ExpectSameAnnotations(b.annotations, f.annotations);
  EXPECT_EQ(b.annotations.back().category, "WarningTripod");
  EXPECT_EQ(b.annotations.back().visibility, 0);  // 90 % visible -> fully visible
  ExpectSameBox(b.annotations.back().box, edit.added[0].annotation.box);
  EXPECT_EQ(ReadLidar(*b.lidar).size(), ReadLidar(*f.lidar).size());
  EXPECT_EQ(b.cameras[0].intrinsics.width, f.cameras[0].intrinsics.width);
}

TEST(WriteDerivative, RejectsBadEdits) {
  const Log log = OpenLog(RepoData("driving/kitti-object"));
  TempDir out;
  FrameEdit edit;
  edit.frame_index = 7;
  EXPECT_THROW(WriteDerivative(log, {edit}, out.path()), InputError);
  edit.frame_index = 0;
  edit.images["image_2"] = ImageU8(10, 10, 3);  // wrong size
  EXPECT_THROW(WriteDerivative(log, {edit}, out.path()), InputError);
  EXPECT_THROW(WriteDerivative(log, {}, out / "missing"), InputError);
}

}  // namespace
}  // namespace sd
