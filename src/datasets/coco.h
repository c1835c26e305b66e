#pragma once
// COCO "instances" JSON of the 2D boxes of a derivative dataset, for 2D detectors trained on COCO-style
// files: one image record per camera image of the edited frames, one annotation per box.
//
// What goes in:
//  - images[]: file_name = the image's path relative to the log's data_root, i.e. where WriteDerivative puts
//    the image under its output directory (for nuScenes tables and KITTI this is CameraSensor::image_relpath;
//    mmdet3d v1's bare names become samples/<CHANNEL>/<name>). width, height in pixels. id =
//    frame_index * C + camera_index + 1 with C the largest camera count of any frame of the log, so an image
//    keeps its id whichever frames are written (files of shards merge without clashes). Extra fields:
//    frame_token, frame_index, channel.
//  - annotations[]: the log's own 2D boxes (Annotation::box2d_by_camera: KITTI image_2 labels, mmdet3d v1
//    cam_instances) with "synthetic": false, "dataset_category" and "annotation_token" (where the dataset has
//    one), then the added objects' CameraBox with "synthetic": true, visible_fraction, truncation and
//    asset_id. bbox = [x, y, w, h] in pixels with x = x1, w = x2 - x1 (pixel-edge coordinates, as Box2);
//    area = w * h; iscrowd 0. ids 1.. in image order. Empty boxes (w or h <= 0) and real boxes of classes
//    without a canonical category (KITTI Misc, Lyft animal) are left out. x + w gives x2 back exactly for
//    pixel-grid values (integers, halves); for arbitrary decimals (KITTI's 599.41) to within one ulp.
//  - categories[]: the canonical categories (datasets/categories.h), id = position + 1, in that order.
// The output depends only on the inputs (images sorted by frame then camera, no dates), so the same log and
// edits give the same bytes, whatever the order of `edits`.
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "core/box3.h"
#include "datasets/log.h"
#include "datasets/writers.h"

namespace sd {

struct Coco2DOptions {
  bool real_boxes = true;   // also write the log's own 2D boxes ("synthetic": false)
  std::string description;  // info.description; default names the log
};

// Writes `file` atomically. InputError when an edit names a frame the log lacks or a camera the frame lacks,
// or an added object's category is not canonical.
void WriteCoco2D(const Log& log, const std::vector<FrameEdit>& edits, const std::filesystem::path& file,
                 const Coco2DOptions& options = {});

struct CocoImage {
  int64_t id = 0;
  std::string file_name;
  int width = 0, height = 0;
  std::string frame_token, channel;  // empty when the file lacks them (COCO files of other tools)
};

struct CocoCategory {
  int64_t id = 0;
  std::string name;
};

struct CocoAnnotation {
  int64_t id = 0, image_id = 0, category_id = 0;
  std::string category;      // the category's name
  Box2 box;                  // x1 y1 x2 y2 pixels (from COCO's x y w h)
  double area = 0;
  bool iscrowd = false;
  bool synthetic = false;
  double visible_fraction = -1, truncation = -1;  // -1 when absent
  std::string asset_id;
};

struct Coco2D {
  std::vector<CocoImage> images;
  std::vector<CocoAnnotation> annotations;
  std::vector<CocoCategory> categories;
};

// Reads a COCO instances file (ours or another tool's: extra fields optional). InputError naming the file and
// the JSON path for malformed content: not JSON, missing fields, a bbox that is not 4 numbers or has negative
// size, duplicate ids, an annotation naming an unknown image or category.
Coco2D ReadCoco2D(const std::filesystem::path& path);

}  // namespace sd
