#pragma once
// One model of a driving log for every dataset we read (nuScenes tables, mmdetection3d infos, KITTI).
//
// Frames and conventions (converted once, at each reader; see the reader's header for its source
// convention and the test that pins it):
//  - ego: x forward, y left, z up, metres; the ego pose at the frame's LiDAR timestamp. For KITTI, which has
//    no ego frame, ego = the Velodyne frame (also x forward, y left, z up).
//  - world: the dataset's global/map frame (nuScenes "global"); KITTI object frames have none (identity).
//  - Camera extrinsics are T_ego_cam of the camera *as seen from the frame's ego pose*: camera motion
//    between the LiDAR and the camera timestamps is folded in (T_ego_cam = T_world_ego(t_lidar)^-1 *
//    T_world_ego(t_cam) * T_egocam_cam), so projecting ego-frame points through it is exact for static
//    objects. `T_egocam_cam` keeps the pure calibration.
//  - Annotation boxes are Box3 in the ego frame with the geometric centre and (length, width, height).
#include <filesystem>
#include <limits>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "core/box3.h"
#include "core/camera.h"
#include "core/pointcloud.h"
#include "core/rigid3.h"
#include "io/pointcloud_io.h"

namespace sd {

struct CameraSensor {
  std::string channel;        // "CAM_FRONT", "image_2", ...
  std::string token;          // dataset id of this image record (nuScenes sample_data token), may be empty
  std::filesystem::path image_path;  // absolute path of the image file
  std::string image_relpath;  // the path as the dataset's record writes it (for writers)
  double timestamp = 0;       // seconds
  PinholeCamera intrinsics;   // width/height filled from the record or the image header
  Rigid3d T_ego_cam;          // see the file comment: includes ego motion to the LiDAR time
  Rigid3d T_egocam_cam;       // pure calibration (camera -> ego at camera time)
  Rigid3d T_world_egocam;     // ego pose at the camera timestamp
};

// How a sweep file stores its points (ReadLidar reads both into the sensor frame).
enum class SweepFile {
  kFloat32Records,  // N x layout.num_features little-endian float32, sensor frame (nuScenes, KITTI, AV2)
  kPandaSetPickle,  // a pandas DataFrame pickle (.pkl.gz): x y z (world frame) i t (absolute s) d, float64
};

struct LidarSensor {
  std::string channel;        // "LIDAR_TOP", "velodyne"
  std::string token;
  std::filesystem::path path;  // absolute path of the sweep file
  std::string relpath;         // as written in the dataset's record
  PointLayout layout;          // record layout of the points ReadLidar returns (of the file for kFloat32Records)
  double timestamp = 0;        // seconds
  Rigid3d T_ego_lidar;
  SweepFile file = SweepFile::kFloat32Records;
  // kPandaSetPickle: the file's points are in the world frame; ReadLidar moves them by T_lidar_world into this
  // sensor's frame and stores per-point times relative to `timestamp` (float32 cannot hold Unix seconds).
  Rigid3d T_lidar_world;
  // Several LiDARs in one sweep (PandaSet: d = 0 the Pandar64, d = 1 the PandarGT): the feature holding each
  // point's sensor index, and each sensor's pose in this (the first) sensor's frame; a point's beam starts at
  // its own sensor. Empty: one sensor at this one's origin.
  std::string sensor_feature;
  std::vector<Rigid3d> T_lidar_sensors;
  // Facts about the sweep its reader knows, so synthesis need not know the dataset (docs/lidar.md):
  int spin_direction = 0;            // record order: +1 counter-clockwise seen from above, -1 clockwise, 0: inferred
  double start_azimuth = std::numeric_limits<double>::quiet_NaN();  // azimuth of the first record; NaN: inferred
  bool motion_compensated = true;    // de-skewed to one pose and stamped at the end of the turn (nuScenes), not raw (KITTI)
  bool one_beam_pattern = true;      // one spinning sensor's returns; false where several LiDARs are merged (AV2):
                                     // no beam model is fitted to such a sweep
};

struct Annotation {
  std::string category;           // the dataset's own class name ("traffic_cone", "Car", "movable_object.trafficcone");
                                  // empty when the source marks the box as outside its class list (mmdet3d label -1)
  Box3 box;                       // ego frame, geometric centre
  std::string token;              // annotation id, may be empty
  std::string instance_token;     // track id, may be empty
  int num_lidar_pts = -1;         // -1 when unknown
  Eigen::Vector2d velocity = Eigen::Vector2d::Constant(std::numeric_limits<double>::quiet_NaN());  // ego frame m/s
  int visibility = -1;            // dataset-specific level, -1 unknown (nuScenes 1..4; KITTI occluded 0..3)
  double truncation = -1;         // KITTI truncated 0..1, -1 unknown
  std::map<std::string, Box2> box2d_by_camera;  // the dataset's own 2D box per camera channel, where it annotates one (KITTI label bbox for image_2; mmdet3d v1 cam_instances)
  // A box SynthDrive's LiDAR detector made where the log has no labels (synth/detected_tracks.h), not the
  // dataset's: keep-out for placement and sequence planning only, never written as a label and never a real
  // object's reference (realism, colour cap, LiDAR intensity). Its category is "detected.<class>".
  bool detected = false;
};

struct Frame {
  std::string token;               // sample token / frame id ("000008")
  double timestamp = 0;            // seconds (LiDAR time)
  Rigid3d T_world_ego;             // at the LiDAR timestamp
  std::vector<CameraSensor> cameras;
  std::optional<LidarSensor> lidar;
  std::vector<Annotation> annotations;
  bool has_annotations = false;    // false when the source carries no boxes for this frame (unknown, not "empty")

  const CameraSensor* FindCamera(const std::string& channel) const;
};

struct GeoLocation {
  double latitude_deg = 0, longitude_deg = 0;
  std::string name;  // e.g. "singapore-onenorth"
};

// Each has one row in datasets/format.h (reader, writer, names). kArgoverse2 is read (for sequences: poses,
// tracks, sweeps) but not written: its tables are Arrow files.
enum class LogFormat { kNuScenesTables, kMmdet3dV1, kMmdet3dV0, kKitti, kArgoverse2, kPandaSet, kMmdet3dKitti };
const char* ToString(LogFormat f);

struct Log {
  LogFormat format = LogFormat::kMmdet3dV1;
  std::filesystem::path source;     // what the user passed (root directory or info file)
  std::filesystem::path data_root;  // the directory dataset-relative paths resolve against
  // Where the annotations were read from: the info file (mmdet3d), the tables' version directory
  // (nuScenes/Lyft) or the label_2 directory (KITTI). Writers use it to rewrite them.
  std::filesystem::path annotation_path;
  std::string name;                 // log/scene name if known
  std::string version;              // dataset version string if known ("v1.0-mini")
  std::vector<std::string> categories;  // the dataset's class list where it defines one (mmdet3d metainfo)
  std::optional<GeoLocation> location;
  std::vector<Frame> frames;
  // Facts about the frames their reader knows:
  bool sequential = true;            // frames are a time series with world poses (KITTI object frames are not)
  bool ego_origin_on_ground = true;  // the ego origin lies on the road (nuScenes' rear axle); KITTI's Velodyne frame does not
  // The road's height in the ego frame by the rig's convention: 0 where the ego origin lies on it, PandaSet's pose
  // reference -0.30 m, KITTI's Velodyne -1.73 m. Where no sweep measures the road, the cameras search around it.
  double nominal_road_z = 0;
  // What the reader assumed for optional fields the file left out, one line per kind ("ego2global missing in 3 of
  // 81 frames (first: <token>): ..."); OpenLog reports each once, so a run never rests on a silent default.
  std::vector<std::string> assumptions;
};

}  // namespace sd
