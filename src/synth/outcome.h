#pragma once
// What synthesis did to one frame: the objects it inserted (placement, label, pixels and returns), the cameras
// it changed and the LiDAR model it used. SynthesizeFrame (synth/frame.h) makes it, a part (synth/parts.h)
// stores it, and the merge, synth.json and the report (synth/report.h) read it; this header sits below all of
// them so none reaches up into another's.
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/stage_times.h"
#include "core/image.h"
#include "core/pointcloud.h"
#include "datasets/writers.h"
#include "synth/ground.h"
#include "synth/lidar_model.h"
#include "synth/placement.h"

namespace sd {

// What happened to one inserted object in one frame, for labels, reports and verification.
struct ObjectOutcome {
  PlacedObject placement;
  int plan_object = -1;  // index into the SequencePlan's objects (world-fixed); -1: placed for this frame alone
  AddedObject label;
  int lidar_points = 0;
  double rendered_pixels = 0, visible_pixels = 0;
};

struct CameraOutcome {
  std::string channel;
  std::string light;  // for people: the light at the objects in this camera (sun visibility, scale), harmoniser
  ImageU8 before, after;  // only for cameras the objects touch
  std::vector<int> objects;  // indices into FrameOutcome::objects drawn in this camera
  // The camera's look as estimated from its image and applied (CameraLook::ToJson + the blur applied); null when
  // SynthOptions::camera_look is all off.
  nlohmann::json look;
};

// FrameOutcome::lidar_model of a frame that has no LiDAR sweep: nothing was read, simulated or written.
inline constexpr char kNoLidar[] = "absent: the frame has no LiDAR sweep (none read, none written)";

struct FrameOutcome {
  size_t frame_index = 0;
  FrameEdit edit;
  std::vector<ObjectOutcome> objects;
  std::vector<CameraOutcome> cameras;
  GroundModel ground;
  std::string sun_source;
  Eigen::Vector3d sun_direction_ego = Eigen::Vector3d::UnitZ();  // unit, towards the sun (the one the frame was lit by)
  std::string light;  // for people: the light model of the frame (environment map: sun, sun/sky split, seams)
  PointCloud sweep_before;  // sensor frame
  std::vector<std::pair<int, int>> lidar_object_points;  // (point index in edit.points, object index)
  // The LiDAR model the frame was simulated with: LidarModel::Summary(), or "off" (lidar_realism false, an
  // Argoverse 2 log, or a sweep the model cannot be fitted from: then the ideal sensor, with a warning).
  // Kept in parts and written per frame to synth.json.
  std::string lidar_model = "off";
  // Where the frame's road came from, one line: its LiDAR sweep, its cameras' stereo, or an assumed plane
  // (synth/frame.h EstimateCameraGround). Kept in parts and written per frame to synth.json.
  std::string road;
  std::optional<LidarModel> lidar_model_fit;  // the fitted model itself; in memory only (not in parts)
  bool lidar_ego_motion = false;              // rolling shutter from the neighbouring frames' ego poses
  // Seconds per stage of SynthesizeFrame ("read", "light", "camera render", ...; camera stages summed over the
  // cameras): where the frame's time went. The cameras and the LiDAR run at once, so their stages may add up to
  // more than the frame's wall time. In memory only; benchmarks and --verbose print it.
  StageTimes timings;
};

}  // namespace sd
