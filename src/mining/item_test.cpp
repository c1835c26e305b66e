#include "mining/item.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <string>

#include "core/error.h"

namespace sd::mining {
namespace {

MinedItem LogItem() {
  MinedItem item;
  item.id = StableId("log|frame|CAM_FRONT|ann");
  item.kind = SourceKind::kLog;
  item.source = "/data/nuscenes";
  item.origin = "/data/nuscenes/samples/CAM_FRONT/x.jpg";
  item.category = "traffic_cone";
  item.dataset_category = "movable_object.trafficcone";
  item.frame_token = "f0";
  item.camera = "CAM_FRONT";
  item.annotation_token = "a0";
  item.instance_token = "i0";
  Box3 box;
  box.T_frame_box = Rigid3d::FromYaw(0.3, {10, -2, 0.4});
  box.size = {0.4, 0.4, 0.8};
  item.box_ego = box;
  item.box_camera = box.Transformed(Rigid3d::FromYaw(1.0, {0, 0, 1}));
  item.camera_intrinsics = PinholeCamera::FromK(Eigen::Matrix3d::Identity() * 1000, 1600, 900);
  item.annotated_box2d = Box2{1, 2, 30, 40};
  item.box2d = Box2{0.5, 1.5, 31, 41};
  item.crop_rect = Box2{0, 0, 40, 50};
  item.crop_scale = 1;
  item.crop_width = 40;
  item.crop_height = 50;
  item.truncation = 0.1;
  item.occlusion = 0.2;
  item.sharpness = 150;
  item.phash = 0xfedcba9876543210ull;  // above 2^53: must survive JSON exactly
  item.mask_source = "lidar";
  item.crop_file = "crops/a.jpg";
  item.mask_file = "masks/a.png";
  return item;
}

TEST(MinedItem, JsonRoundTripKeepsEveryField) {
  const MinedItem a = LogItem();
  const MinedItem b = ItemFromJson(nlohmann::json::parse(ToJson(a).dump()), "items.jsonl:1");
  EXPECT_EQ(b.id, a.id);
  EXPECT_EQ(b.kind, SourceKind::kLog);
  EXPECT_EQ(b.category, "traffic_cone");
  EXPECT_EQ(b.dataset_category, a.dataset_category);
  EXPECT_EQ(b.instance_token, "i0");
  ASSERT_TRUE(b.box_ego.has_value());
  EXPECT_NEAR(b.box_ego->Yaw(), 0.3, 1e-12);
  EXPECT_NEAR((b.box_ego->center() - a.box_ego->center()).norm(), 0, 1e-12);
  EXPECT_EQ(b.box_ego->size, a.box_ego->size);
  ASSERT_TRUE(b.box_camera.has_value());
  EXPECT_NEAR((b.box_camera->center() - a.box_camera->center()).norm(), 0, 1e-12);
  EXPECT_NEAR(b.box_camera->T_frame_box.rotation.angularDistance(a.box_camera->T_frame_box.rotation), 0, 1e-12);
  ASSERT_TRUE(b.camera_intrinsics.has_value());
  EXPECT_EQ(b.camera_intrinsics->width, 1600);
  EXPECT_DOUBLE_EQ(b.camera_intrinsics->fx, 1000);
  ASSERT_TRUE(b.annotated_box2d.has_value());
  EXPECT_DOUBLE_EQ(b.annotated_box2d->y2, 40);
  EXPECT_DOUBLE_EQ(b.box2d.x2, 31);
  EXPECT_EQ(b.phash, a.phash);
  EXPECT_EQ(b.crop_width, 40);
  EXPECT_DOUBLE_EQ(ObjectSizePx(b), 30.5);
  EXPECT_EQ(b.mask_file, "masks/a.png");
}

TEST(MinedItem, MalformedRecordNamesTheLine) {
  nlohmann::json j = ToJson(LogItem());
  j["box2d"] = {1, 2, 3};
  try {
    ItemFromJson(j, "shard/items.jsonl:7");
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("items.jsonl:7"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("box2d"), std::string::npos) << e.what();
  }
  j = ToJson(LogItem());
  j["kind"] = "ftp";
  EXPECT_THROW(ItemFromJson(j, "x"), InputError);
}

// A line of items.jsonl as the build before the shared geometry codec (io/geometry_json.h) wrote it: indexes on
// users' disks hold such lines. It reads to the same values, and writing the item again gives the same bytes.
TEST(MinedItem, ReadsALineTheEarlierBuildWrote) {
  const std::string line =
      R"({"annotated_box2d":[700.0,400.0,760.0,480.0],"annotation":"a1","box2d":[702.5,401.0,758.25,479.5],"box_camera":{"center":[0.5000000000000003,-11.0,2.9000000000000004],"rotation_wxyz":[0.5691046052048208,-0.41966647273122154,0.5691046052048208,-0.41966647273122154],"size":[0.4,0.4,0.7]},"box_ego":{"center":[12.5,-3.1,0.4],"rotation_wxyz":[0.9887710779360424,0.0,0.0,0.14943813247359924],"size":[0.4,0.4,0.7]},"camera":"CAM_FRONT","category":"traffic_cone","crop_file":"crops/a.png","crop_rect":[680.0,380.0,780.0,500.0],"crop_scale":1.0,"crop_size":[128,128],"dataset_category":"movable_object.trafficcone","frame":"e93e98b6","id":"e3f7116f2c922241","instance":"i1","intrinsics":{"cx":816.3,"cy":491.5,"fx":1266.4,"fy":1266.4,"height":900,"width":1600},"kind":"log","lidar_points":35,"log_name":"n015","mask_file":"crops/a.mask.png","mask_source":"lidar","occlusion":0.1,"origin":"/data/nuscenes/samples/CAM_FRONT/x.jpg","phash":"8f3c00ff12345678","sharpness":143.5,"source":"/data/nuscenes","truncation":0.0,"visibility_level":4})";
  const MinedItem item = ItemFromJson(nlohmann::json::parse(line), "index/shard-0/items.jsonl:1");
  EXPECT_EQ(ToJson(item).dump(), line);
  ASSERT_TRUE(item.box_ego.has_value() && item.box_camera.has_value());
  EXPECT_EQ(item.box_ego->center(), Eigen::Vector3d(12.5, -3.1, 0.4));
  EXPECT_EQ(item.box_ego->size, Eigen::Vector3d(0.4, 0.4, 0.7));
  EXPECT_EQ(item.box_ego->T_frame_box.rotation.coeffs(), Eigen::Vector4d(0.0, 0.0, 0.14943813247359924, 0.9887710779360424));
  // That build normalised on reading (FromWxyz); the value kept is within an ulp of that one.
  const Eigen::Quaterniond renormalised = Rigid3d::FromWxyz(0.5691046052048208, -0.41966647273122154, 0.5691046052048208,
                                                            -0.41966647273122154, Eigen::Vector3d::Zero()).rotation;
  EXPECT_LT((item.box_camera->T_frame_box.rotation.coeffs() - renormalised.coeffs()).cwiseAbs().maxCoeff(), 2e-16);
  EXPECT_NEAR(item.box_ego->Yaw(), 0.3, 1e-15);
  EXPECT_EQ(item.box_camera->center(), Eigen::Vector3d(0.5000000000000003, -11.0, 2.9000000000000004));
  EXPECT_EQ(item.lidar_points, 35);
  EXPECT_EQ(item.phash, 0x8f3c00ff12345678ull);
  EXPECT_DOUBLE_EQ(item.box2d.x2, 758.25);
}

TEST(MinedItem, NonPositiveBoxSizeNamesTheLineAndKey) {
  nlohmann::json j = ToJson(LogItem());
  j["box_ego"]["size"][1] = -0.4;
  try {
    ItemFromJson(j, "shard/items.jsonl:3");
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("shard/items.jsonl:3: .box_ego.size: box sizes must be positive"), std::string::npos)
        << e.what();
  }
}

TEST(MinedItem, StableIdIsDeterministicAndSpreads) {
  EXPECT_EQ(StableId("abc"), StableId("abc"));
  EXPECT_NE(StableId("abc"), StableId("abd"));
  EXPECT_EQ(StableId("").size(), 16u);
}

}  // namespace
}  // namespace sd::mining
