#pragma once
// Inserting objects into a real LiDAR sweep by casting the sweep's own beams.
//
//  - Every real return whose beam now meets an inserted object before its recorded range moves onto the
//    object's surface (the object blocks it); its other features (ring, ...) are kept, intensity is
//    re-simulated.
//  - Beams that returned nothing in the real sweep (sky, far range) are recovered from the scan pattern:
//    per ring, the elevation angle and azimuth step are measured from the sweep, and empty azimuth slots
//    across each object are cast too; hits are added as new points. Needs a ring feature (nuScenes); for
//    formats without one (KITTI) only the real returns are cast.
//  - Intensity = reference x |cos(incidence)| / 0.7, where the reference is the median intensity of real
//    points on annotated objects of the same category in this sweep, or the category's relative
//    reflectivity x the median intensity of the sweep's ground points. Clamped to the sweep's range.
// Points of the sweep that no object touches are returned bit-identical.
//
// Realism (opt-in, LidarSimInput::realism; off = the behaviour above, exactly): with a LidarModel fitted
// from the sweep (synth/lidar_model.h), returns on objects get the fitted range noise and dropout (seeded),
// intensity = the model's reflectivity(category) x cos^n, and each ray is cast from the sensor pose at its
// firing time (FiringTime(azimuth)), interpolated between the ego poses at sweep start and end, so inserted
// objects get the same rolling-shutter skew as the real ones. The sweep and the objects are given in the
// frame of the reference pose (the frame's ego pose, which is the LiDAR timestamp's); the stored point is
// range x beam direction in the sensor frame at firing time (raw, not de-skewed) unless
// `motion_compensated_output` (datasets that de-skew their sweeps). A real return that an object blocks and
// whose simulated return drops out is removed from the cloud (indices in object_points refer to the output).
#include <cstdint>
#include <string>
#include <utility>
#include <vector>

#include "core/pointcloud.h"
#include "core/rigid3.h"
#include "synth/lidar_model.h"
#include "synth/placement.h"

namespace sd {

struct LidarRealism {
  const LidarModel* model = nullptr;  // required when any switch below is on
  bool noise = false;
  bool dropout = false;
  bool intensity = false;   // model intensity instead of reference_intensity x |cos| / 0.7
  uint64_t seed = 0;
  // Ego motion during the sweep: ego poses at the sweep's first and last firing, in the reference ego frame
  // (T_ref_ego). Identity/identity = a static sensor.
  bool ego_motion = false;
  Rigid3d T_ref_ego_start, T_ref_ego_end;
  // Store hits in the reference frame (the sweep is de-skewed: nuScenes, AV2) instead of the raw sensor frame
  // at firing time (KITTI). nuScenes stamps a sweep at the end of its turn: reference_time = period.
  bool motion_compensated_output = false;
};

// Ego poses at sweep start/end (reference frame = the ego at reference_time seconds after the sweep start)
// for a constant velocity `v_ego` (m/s, ego frame) and yaw rate (rad/s) over a sweep of `period` seconds.
std::pair<Rigid3d, Rigid3d> ConstantVelocitySweepPoses(const Eigen::Vector3d& v_ego, double yaw_rate, double period,
                                                       double reference_time);

// The same from two logged ego poses around the frame (world frame, timestamps in seconds; e.g. the previous and
// next frames, or the frame and one neighbour): body velocity and yaw rate of the reference ego between them.
std::pair<Rigid3d, Rigid3d> SweepPosesFromEgoPoses(const Rigid3d& T_world_ego_ref, const Rigid3d& T_world_ego_a, double t_a,
                                                   const Rigid3d& T_world_ego_b, double t_b, double period,
                                                   double reference_time);

struct LidarSimInput {
  const PointCloud* sweep = nullptr;  // sensor frame, dataset layout
  Rigid3d T_ego_lidar;
  std::vector<const PlacedObject*> objects;
  // Per-object reference intensity (see file comment); computed by the caller from the sweep.
  std::vector<float> reference_intensity;
  float max_range = 120.0f;
  LidarRealism realism;  // default: all off
  // Several LiDARs in one sweep (PandaSet's Pandar64 and PandarGT): the feature holding each point's sensor
  // index and each sensor's pose in the sweep's frame (T_lidar_sensor; index 0 is normally the identity). A real
  // return is recast from its own sensor through its recorded point; the point moved onto an object is stored in
  // the sweep's frame. Empty / -1: one sensor at the sweep's origin. Not combined with realism.ego_motion (a
  // contract check): the rolling shutter is fitted to one spinning sensor.
  int sensor_feature = -1;
  std::vector<Rigid3d> T_lidar_sensors;
};

struct LidarSimResult {
  PointCloud cloud;
  int moved = 0, added = 0;
  int dropped = 0;  // realism.dropout: simulated returns on objects that returned nothing
  std::vector<int> points_on_object;  // per object
  // For verification: indices (into cloud) of every point that now lies on an object, and which object.
  std::vector<std::pair<int, int>> object_points;
};

LidarSimResult SimulateLidar(const LidarSimInput& input);

// Reference intensity per object (see file comment). `points_ego` is the sweep in the ego frame.
std::vector<float> ReferenceIntensities(const PointCloud& sweep, const std::vector<Eigen::Vector3d>& points_ego,
                                        const std::vector<int>& ground_indices,
                                        const std::vector<std::pair<std::string, Box3>>& annotated,  // category, box
                                        const std::vector<const PlacedObject*>& objects);

}  // namespace sd
