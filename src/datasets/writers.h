#pragma once
// Writing a derivative dataset: the input log with some images and sweeps replaced and objects added, in
// the input's own format and layout, so training code that read the input reads the output unchanged.
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "core/box3.h"
#include "core/image.h"
#include "core/pointcloud.h"
#include "datasets/log.h"

namespace sd {

struct CameraBox {
  std::string channel;
  Box2 box;                    // tight box of the visible rendered mask, pixels
  double visible_fraction = 1; // visible mask pixels / unoccluded mask pixels
  double truncation = 0;       // fraction of the unoccluded projection outside the image (KITTI semantics)
};

struct AddedObject {
  std::string category;         // canonical category (see datasets/categories.h)
  Annotation annotation;        // box in the ego frame; num_lidar_pts, visibility filled by synthesis
  std::vector<CameraBox> camera_boxes;
  std::string asset_id;         // provenance, written where the format has room for it
};

struct FrameEdit {
  size_t frame_index = 0;
  std::map<std::string, ImageU8> images;  // channel -> replacement image (same size as the original)
  std::optional<PointCloud> points;       // replacement sweep (same layout as the original)
  std::vector<AddedObject> added;
  // (point index in `points`, index into `added`) of every return that lies on an added object, for formats
  // that label points (PandaSet's semantic classes).
  std::vector<std::pair<int, int>> point_objects;
};

enum class UnchangedFiles { kCopy, kSymlink };

struct WriteOptions {
  UnchangedFiles unchanged = UnchangedFiles::kCopy;
  int jpeg_quality = 95;
  // Unchanged sensor files the log references but that are missing on disk: InputError when true; skipped
  // with a warning when false (infos shipped without their sensor files, e.g. the Lyft table fixture).
  bool require_sensor_files = true;
};

// Writes into `out_dir` (which must exist and is normally a StagingDirectory): every file the edited frames
// reference, at the same relative path as in the input, plus the annotation files of the format. Only the
// frames named in `edits` are written. Returns the written annotation/info file(s).
// Box rotations: nuScenes tables keep the full rotation; mmdet3d infos keep only yaw about LiDAR +z and
// KITTI labels only rotation_y about rectified cam0's y axis, so any tilt of an added box relative to
// that axis (the sensor's mounting tilt, about 0.3-1.4 degrees) is dropped on writing.
// Byte identity: annotation files are edited as text, so every record the edit does not touch (other tables,
// other samples' annotations, every existing field and list element of an edited frame's record, existing
// KITTI label lines) keeps its exact bytes; added records are laid out like their neighbours
// (docs/datasets.md, "Byte identity of derivatives").
std::vector<std::filesystem::path> WriteDerivative(const Log& log, const std::vector<FrameEdit>& edits,
                                                   const std::filesystem::path& out_dir, const WriteOptions& options = {});

}  // namespace sd
