#pragma once
// A hit of a mining run (mining/query.h) as the input of `generate`: the crop, the object's box in it, the
// source's mask as a segmentation prior (generate.h SegmentationPrior), and, for crops cut from a driving log,
// the metric size and the facing that the log's 3D box gives.
//
// Facing: Zero123++ generates views around the object as if the input photo were taken from the rig's azimuth
// 0 (a camera on +x looking at the origin, so the photo's right is the rig's +y and its depth the rig's -x).
// The box in the source camera's frame says where the object's front (the box's +x) points relative to the
// ray through the object; turning that into the rig frame gives the direction Canonicalize puts on +x, so a
// mined car comes out facing +x with the box's length along it, and the box's (length, width, height) is the
// target size.
#include <optional>
#include <string>

#include <Eigen/Core>

#include "assetgen/generate.h"
#include "core/box3.h"
#include "core/image.h"
#include "mining/query.h"

namespace sd {

struct MinedObject {
  ImageU8 image;                                 // the crop, RGB
  Box2 box;                                      // the object in crop pixels
  std::optional<SegmentationPrior> prior;        // from the crop's mask, when it has one
  std::string category;                          // canonical category, may be empty (folder / URL images)
  std::optional<Eigen::Vector3d> size_lwh;       // metres, from the log's 3D box
  std::optional<Eigen::Vector3d> front_in_rig;   // unit, the rig (views) frame, from the log's 3D box
  std::string source;                            // provenance line: log, frame, camera, or the image's origin
};

// Reads the entry's crop and mask files (InputError naming a missing or unreadable file).
MinedObject LoadMinedObject(const mining::ManifestEntry& entry);

// Where the box's +x points in the Zero123++ rig frame when the photo was taken from a camera that sees the box
// at `box_camera` (OpenCV camera frame); horizontal, unit length.
Eigen::Vector3d RigFrontFromCameraBox(const Box3& box_camera);

}  // namespace sd
