#pragma once
// Object crops from driving logs: every annotated object, cut from every camera that sees it, with a mask from
// the LiDAR returns inside its 3D box and the box's projection.
//
// For one frame and one camera, an annotation yields a crop when its 3D box projects into the image:
//  - The box's 8 corners (and, for boxes crossing the camera's z = near plane, the edges clipped against it)
//    project through the camera's T_ego_cam and intrinsics (with distortion); `box2d` is their bounding box
//    clipped to the image, and `truncation` = 1 - area(clipped) / area(unclipped).
//  - The mask ("lidar"): the frame's LiDAR returns inside the box (grown by `box_margin_m`, ground returns
//    below `ground_clearance_m` removed) that are not hidden behind nearer returns, projected and splatted with
//    a radius that follows the sensor's angular spacing at their depth, closed and hole-filled, then clipped to
//    the polygon of the projected box. With fewer than `min_mask_points` visible returns the mask is that
//    polygon itself ("box"). Every mask pixel lies inside the projected box.
//  - `occlusion`: of the LiDAR returns that project into the box polygon, the fraction lying in front of the
//    box (nearer than its nearest corner by more than `box_margin_m` and outside it) — the part of the object
//    a camera at the LiDAR's position cannot see.
//  - The crop window is box2d grown by `context` of its size on each side, clipped to the image; crops larger
//    than `max_crop_px` on their longer side are downscaled (area filter).
#include <functional>
#include <vector>

#include "core/image.h"
#include "core/pointcloud.h"
#include "datasets/log.h"
#include "mining/item.h"

namespace sd::mining {

struct LogCropOptions {
  std::vector<std::string> cameras;  // channels to crop from; empty = every camera of the frame
  std::vector<std::string> categories;  // canonical categories to keep; empty = all annotated objects
  std::function<bool(const Annotation&)> select;  // when set, only the annotations it accepts (one track, say)
  double context = 0.1;           // margin around box2d, fraction of its width / height per side
  int min_box_px = 12;            // skip objects whose clipped box2d is smaller on its shorter side
  double max_truncation = 0.75;   // skip objects mostly outside the image
  int max_crop_px = 512;          // downscale crops whose longer side is larger
  double box_margin_m = 0.1;      // grow the box by this when collecting its LiDAR returns
  double ground_clearance_m = 0.05;  // drop returns this close to the box's bottom face (road under it)
  int min_mask_points = 8;        // fewer visible returns -> the mask is the projected box polygon
  double near_m = 0.5;            // camera near plane for the box projection
};

struct ObjectCrop {
  MinedItem item;  // everything but `id`, `source`, crop_file / mask_file (the caller names those)
  ImageU8 image;   // RGB crop (item.crop_width × item.crop_height)
  ImageU8 mask;    // 1 channel, 255 = object, same size as `image`
};

// The crops of one frame. `sweep_ego` holds the frame's LiDAR points in the ego frame (positions only are
// used); pass an empty cloud when the frame has no sweep (masks are then "box" and occlusion unknown).
// Camera images are read from disk (InputError naming the file when one is missing or unreadable).
std::vector<ObjectCrop> CropFrameObjects(const Frame& frame, const std::vector<Eigen::Vector3d>& sweep_ego,
                                         const LogCropOptions& options);

// The frame's sweep in the ego frame (ReadLidar + T_ego_lidar); empty when the frame has no LiDAR.
std::vector<Eigen::Vector3d> SweepInEgo(const Frame& frame);

}  // namespace sd::mining
