#pragma once
// The mining records the mining fuzz targets are seeded with: a log hit with every field set and a folder image,
// as the index and the mining run write them.
#include "mining/item.h"

namespace sd::fuzz {

inline mining::MinedItem SeedLogHit() {
  using sd::mining::MinedItem;
  MinedItem log_hit;
  log_hit.id = "3f9a0c1d2e4b5a69";
  log_hit.source = "data/driving/nuscenes-scene0061-kf0/mmdet3d_info/n015-2018-07-24-11-22-45+0800.json";
  log_hit.origin = "samples/CAM_FRONT/n015-2018-07-24-11-22-45+0800__CAM_FRONT__1532402927612460.jpg";
  log_hit.category = "traffic_cone";
  log_hit.dataset_category = "movable_object.trafficcone";
  log_hit.log_name = "n015-2018-07-24-11-22-45+0800";
  log_hit.frame_token = "e93e98b63d3b40209056d129dc53ceee";
  log_hit.camera = "CAM_FRONT";
  log_hit.annotation_token = "a1";
  Box3 box;
  box.T_frame_box = Rigid3d::FromYaw(0.3, Eigen::Vector3d(12.5, -3.1, 0.4));
  box.size = Eigen::Vector3d(0.4, 0.4, 0.7);
  log_hit.box_ego = box;
  log_hit.box_camera = box;
  PinholeCamera camera;
  camera.width = 1600;
  camera.height = 900;
  camera.fx = camera.fy = 1266.4;
  camera.cx = 816.3;
  camera.cy = 491.5;
  log_hit.camera_intrinsics = camera;
  log_hit.annotated_box2d = Box2{700, 400, 760, 480};
  log_hit.visibility_level = 4;
  log_hit.lidar_points = 35;
  log_hit.box2d = Box2{702.5, 401, 758.25, 479.5};
  log_hit.crop_rect = Box2{680, 380, 780, 500};
  log_hit.crop_width = log_hit.crop_height = 128;
  log_hit.truncation = 0;
  log_hit.occlusion = 0.1;
  log_hit.sharpness = 143.5;
  log_hit.phash = 0x8f3c00ff12345678ULL;
  log_hit.mask_source = "lidar";
  log_hit.crop_file = "crops/3f9a0c1d2e4b5a69.png";
  log_hit.mask_file = "crops/3f9a0c1d2e4b5a69.mask.png";
  return log_hit;
}

inline mining::MinedItem SeedFolderImage() {
  using sd::mining::MinedItem;
  MinedItem folder_image;
  folder_image.id = "77aa";
  folder_image.kind = mining::SourceKind::kFolder;
  folder_image.source = "data/images/roadanomaly-cones";
  folder_image.origin = "data/images/roadanomaly-cones/frames/a.jpg";
  folder_image.box2d = folder_image.crop_rect = Box2{0, 0, 640, 360};
  folder_image.crop_width = 640;
  folder_image.crop_height = 360;
  folder_image.crop_file = "crops/77aa.png";
  return folder_image;
}

}  // namespace sd::fuzz
