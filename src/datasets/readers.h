#pragma once
// Opening driving logs. Each reader converts its dataset's conventions into datasets/log.h once; each lives
// with its writer in one file per format, and the format table (datasets/format.h, which says how to add one)
// is what OpenLog probes and dispatches through.
#include <filesystem>
#include <optional>

#include "core/pointcloud.h"
#include "datasets/log.h"

namespace sd {

struct OpenLogOptions {
  std::optional<LogFormat> format;      // force a reader instead of probing
  std::filesystem::path data_root;      // where dataset-relative paths resolve; default: probed
};

// `path`: a dataset root directory (nuScenes tables, KITTI object layout, a PandaSet sequence) or an info file
// (mmdet3d .pkl, .pkl.gz or .json). Probes the format unless forced: *.json, *.pkl, *.pkl.gz -> ReadMmdet3dInfo; a directory holding sample.json, or a
// version directory (or, Lyft, version/version) that does -> ReadNuScenesTables; calib/ + label_2/ (or
// training/) -> ReadKitti; a directory holding city_SE3_egovehicle.json and annotations.json ->
// ReadArgoverse2; camera/, lidar/ and annotations/cuboids/ -> ReadPandaSet. InputError (naming the path) when no reader recognises it. docs/datasets.md
// tabulates every format's conventions. Every log is then checked for what synthesis must trust, whatever its
// format: finite poses, sensors mounted within 100 m of the ego, cameras with positive focal lengths and the
// principal point near the image's centre, each sample and each sensor file once, sensor paths under the data
// root, one image size per camera calibration: InputError naming the log, the frame and the sensor otherwise. The optional
// fields the reader defaulted (Log::assumptions) are logged once each (Warn).
Log OpenLog(const std::filesystem::path& path, const OpenLogOptions& options = {});

// nuScenes devkit tables (also Lyft Level 5, which uses the nuScenes schema). `path` is the dataset root
// (holding v1.0-*/ or a version directory with sample.json) or the version directory itself. Missing
// optional tables (sample_annotation, instance, log, map) are tolerated: frames then have
// has_annotations = false. Keyframes (samples) become frames, in timestamp order. Boxes: global
// translation/rotation (wxyz) and size (w, l, h) -> ego at the LiDAR time, (l, w, h). The lidar is
// LIDAR_TOP where there are several. Log::location only for the four nuScenes maps (approximate
// map-origin coordinates); velocities are NaN (not derived from prev/next).
Log ReadNuScenesTables(const std::filesystem::path& path, const OpenLogOptions& options = {});
// mmdetection3d info file, the converters' pickle (read as data: io/pickle.h, never executed) or its JSON
// conversion, v1.x (`data_list`, `instances`, boxes [x y z l w h yaw] in the LiDAR frame) or
// v0.x (`infos`, `gt_boxes` [x y z w l h yaw_old] with yaw_old = -yaw - pi/2). Image and LiDAR paths are
// resolved against data_root (probed: the nearest ancestor of the info file holding samples/ or training/);
// v1 bare file names live in samples/<CHANNEL>/, other paths are cut to their first samples/ or sweeps/
// component. Python NaN/Infinity literals read as null. v1 boxes with label -1 are kept with an empty
// category. Sweeps are read as 5 float32 per point. KITTI-flavoured infos (v0.x list of
// image/point_cloud/calib/annos dicts; v1.x with camera-frame boxes and images.R0_rect) read through the KITTI
// calibration they carry, as ReadKitti does; their cam_instances (2D-only labels) are not read.
Log ReadMmdet3dInfo(const std::filesystem::path& info_json, const OpenLogOptions& options = {});
// KITTI 3D object layout: <root>/{image_2,velodyne,calib,label_2}/NNNNNN.* (or <root>/training/...).
// ego = Velodyne frame; one camera "image_2" with T_ego_cam = inv(T_cam2_rect0 * R0_rect * Tr_velo_to_cam);
// labels (bottom centre in rectified cam0, h w l, rotation_y) -> geometric-centre boxes (l, w, h) in the
// Velodyne frame; DontCare skipped; truncation and occlusion kept.
Log ReadKitti(const std::filesystem::path& root, const OpenLogOptions& options = {});

// Argoverse 2 sensor log directory, from the JSON / float32 conversions of its Arrow tables
// (city_SE3_egovehicle.json, annotations.json, sensors/lidar/<ts_ns>.xyzil.f32.bin: N x 5 float32 x y z
// intensity laser_number, already in the ego frame, so T_ego_lidar = identity). Frames: every sweep on disk and
// every annotated timestamp, in time order (token = the timestamp in ns; frames without a sweep file have
// lidar = nullopt). T_world_ego (world = city) is interpolated from the ~170 Hz poses at the frame time
// (translation linear, rotation slerp). Boxes: centre in the ego frame, (length, width, height), rotation
// ego <- object; category = the AV2 name (REGULAR_VEHICLE, ...; datasets/categories.h maps them),
// instance_token = track_uuid, num_lidar_pts = num_interior_pts. No cameras (no images are converted).
Log ReadArgoverse2(const std::filesystem::path& log_dir, const OpenLogOptions& options = {});

// PandaSet sequence folder (<seq>/camera, lidar, annotations, meta; docs/datasets.md "PandaSet"): ego = the
// lidar/poses.json pose turned to x forward, y left, z up (origin 0.30 m above the road); the Pandar64 and the
// PandarGT, at the rig's calibration, in one sweep (LidarSensor::sensor_feature, T_lidar_sensors); the six
// cameras with their per-frame poses; cuboids (heading = yaw + pi/2, dimensions width, length, height) with
// tracks (instance_token = uuid), per-LiDAR duplicates folded, velocities from the track.
Log ReadPandaSet(const std::filesystem::path& sequence_dir, const OpenLogOptions& options = {});
// A PandaSet sweep (lidar/NN.pkl.gz): x y z in the Pandar64 frame, intensity, time relative to the sweep's
// stamp (s), sensor (0 Pandar64, 1 PandarGT).
PointCloud ReadPandaSetSweep(const LidarSensor& lidar);

// Reads the frame's sweep in its own layout (sensor frame). InputError naming the file when it is missing or
// not a whole number of records.
PointCloud ReadLidar(const LidarSensor& lidar);

}  // namespace sd
