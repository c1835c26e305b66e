#include "mining/item.h"

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

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

TEST(MinedItem, StableIdIsDeterministicAndSpreads) {
  EXPECT_EQ(StableId("abc"), StableId("abc"));
  EXPECT_NE(StableId("abc"), StableId("abd"));
  EXPECT_EQ(StableId("").size(), 16u);
}

}  // namespace
}  // namespace sd::mining
