#pragma once
// One mined object image: the record every source (driving log, image folder, URL list) produces, that the
// index stores and that a mining run's manifest.jsonl carries, one JSON object per line.
//
// Pixels: a log item's boxes are in the pixels of the *source camera image*; `crop_rect` is the window of the
// source image the crop was cut from (before any downscaling, `crop_scale` = crop pixels per source pixel).
// Folder and URL items are the whole image (crop_rect = the image, crop_scale 1 unless downscaled).
#include <cstdint>
#include <optional>
#include <string>

#include <nlohmann/json_fwd.hpp>

#include "core/box3.h"
#include "core/camera.h"
#include "core/image.h"

namespace sd::mining {

enum class SourceKind { kLog, kFolder, kUrl };
const char* ToString(SourceKind kind);
SourceKind SourceKindFromString(const std::string& s);  // InputError on an unknown kind

struct MinedItem {
  std::string id;              // stable across runs: a hash of source, frame, camera and annotation (or URL)
  SourceKind kind = SourceKind::kLog;
  std::string source;          // the log path / image folder / URL list file as the user gave it
  std::string origin;          // the source image: absolute file path or URL

  // The object's category: canonical (datasets/categories.h) when the source's name maps to one, else the
  // source's own name; empty when unknown (folder and URL images).
  std::string category;
  std::string dataset_category;  // the log's own class name ("movable_object.trafficcone"), log items only

  // Log items only (empty / nullopt otherwise).
  std::string log_name, frame_token, camera, annotation_token, instance_token;
  std::optional<Box3> box_ego;         // the annotation's 3D box, ego frame, metres (metric scale for generate)
  std::optional<Box3> box_camera;      // the same box in the source camera's frame (OpenCV axes): which way the
                                       // object faces in the crop, so generate can put its front along +x
  std::optional<PinholeCamera> camera_intrinsics;
  std::optional<Box2> annotated_box2d;  // the dataset's own 2D box in this camera, where it has one
  int visibility_level = -1;            // the dataset's level (nuScenes 1..4, KITTI occluded 0..3), -1 unknown
  int lidar_points = -1;                // LiDAR returns inside the box, -1 unknown

  Box2 box2d;          // the object in the source image: projected 3D box clipped to the image (logs), the
                       // mask's bounding box (folder images with alpha) or the whole image
  Box2 crop_rect;      // the source-image window the crop was cut from (integer pixel edges)
  double crop_scale = 1;
  int crop_width = 0, crop_height = 0;  // pixels of the stored crop
  // Quality, 0..1 each where known, -1 unknown: the fraction of the projected box outside the image, and the
  // fraction of the object's image area hidden behind nearer LiDAR returns.
  double truncation = -1, occlusion = -1;
  double sharpness = -1;  // variance of the Laplacian of the crop's grey image, see descriptor.h; -1 unknown
  uint64_t phash = 0;     // 64-bit DCT perceptual hash of the crop (descriptor.h)
  std::string mask_source;  // "lidar" (projected returns), "box" (projected 3D box), "alpha", "" (no mask)

  // Files relative to the folder holding the record (an index shard or a mining run).
  std::string crop_file, mask_file;
};

// The image size a quality filter sees: the shorter side of the object's 2D box in source pixels.
double ObjectSizePx(const MinedItem& item);

nlohmann::json ToJson(const MinedItem& item);
// `where` names the file and line for the InputError on a malformed record.
MinedItem ItemFromJson(const nlohmann::json& j, const std::string& where);

// A short stable id: 16 hex digits of a 64-bit FNV-1a hash of `key`.
std::string StableId(const std::string& key);

}  // namespace sd::mining
