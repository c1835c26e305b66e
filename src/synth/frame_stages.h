#pragma once
// The stages of SynthesizeFrame (synth/frame.h) and what they hand each other; internal to synth/frame.cpp and
// synth/frame_camera.cpp. The data flow is the one of docs/architecture.md: inputs -> placement -> the frame's
// light -> the object scene -> each camera -> the LiDAR.
#include <map>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/image.h"
#include "datasets/log.h"
#include "render/ray_scene.h"
#include "synth/environment.h"
#include "synth/frame.h"
#include "synth/outcome.h"
#include "synth/placement.h"
#include "synth/sequence_plan.h"

namespace sd {
namespace models {
class Harmonizer;
}
namespace frame_stages {

// What the frame brings: its sweep in the ego frame, the annotated boxes, the ground (the sweep and the ground
// are kept in the FrameOutcome), and the camera images, each read on first use.
struct FrameInputs {
  const Log* log = nullptr;
  const Frame* frame = nullptr;
  size_t index = 0;
  FrameSeeds seeds;
  const PointCloud* sweep = nullptr;  // sensor frame
  const GroundModel* ground = nullptr;
  std::vector<Eigen::Vector3d> points_ego;
  std::vector<uint8_t> is_ground;  // parallel to points_ego
  std::vector<Box3> real_boxes;
  std::vector<std::pair<std::string, Box3>> annotated;  // (category, box), for the LiDAR's reference intensities
  // Camera k's photograph (sRGB), read and checked against its calibration the first time it is asked for. Safe
  // from several threads for different k only.
  const ImageU8& Image(size_t k) const;
  // Camera k's JPEG quality, from its file's quantisation table; nullopt for other formats.
  std::optional<int> JpegQuality(size_t k) const;
  mutable std::vector<ImageU8> images;  // empty until read
};
FrameInputs ReadFrameInputs(const Log& log, size_t frame_index, const Scenario& scenario, FrameOutcome* out);

// The frame's light: the sun, the environment map (kEnvironment with objects to light), and the sun's
// visibility at each object, decided once from every camera that sees its road.
struct FrameLight {
  Eigen::Vector3d sun_dir = Eigen::Vector3d::UnitZ();
  std::optional<EnvironmentMap> env;
  std::vector<Eigen::Vector3d> road_points;                  // drivable ground near all objects
  std::vector<std::vector<Eigen::Vector3d>> road_points_of;  // each object's own road (kOwnRoadMargins)
  std::optional<double> sun_at_objects;                      // over all objects' road
  std::vector<std::optional<double>> sun_at_object;          // each object's verdict, else sun_at_objects
  std::vector<bool> own_verdict;                             // the object's own road gave its verdict
};

// The objects in the ego frame with one receiver mesh for their shadows.
struct ObjectScene {
  RayScene scene;                          // meshes 0..n-1: the objects; then the receiver
  std::shared_ptr<TriangleMesh> receiver;  // a square of road under each object
  std::vector<size_t> receiver_faces_end;  // object k's patch: faces [end of k - 1, end of k) of the receiver
  int receiver_id = -1;
  std::vector<Eigen::Vector3d> extent_points;  // everything a camera may need to redraw: boxes and receivers
  std::vector<std::vector<Eigen::Vector3d>> extent_of;  // the same per object: its box and its receiver patch
};
// Each object's receiver patch is a rectangle on its local ground that holds its sun shadow (the shadow of its box
// for the sun `sun_dir` in the ego frame, at least 15 degrees up) and a margin of its height (at least 1 m) round its
// footprint for the sky it hides.
ObjectScene BuildObjectScene(const std::vector<PlacedObject>& placed, const Eigen::Vector3d& sun_dir);

// What every camera shares.
struct CameraStageInput {
  const FrameInputs* in = nullptr;
  const std::vector<PlacedObject>* placed = nullptr;
  const FrameLight* light = nullptr;
  const ObjectScene* scene = nullptr;
  const models::Harmonizer* harmonizer = nullptr;  // null: no harmonisation
  const SynthOptions* options = nullptr;
  // The camera look's colour reference (ColourReference); null when the look's colour step is off.
  const std::map<std::string, SaturationReference>* colour_reference = nullptr;
  bool sequence = false;  // that reference is a planned sequence's
  StageTimes* times = nullptr;  // where the camera stages add their seconds (the camera's own: not thread-safe)
};

// The colour reference of a frame's inserts: per category placed, its most saturated real object (realism.h
// RealSaturation) over the planned sequence's frames when there is a plan (one reference for all of them, so an
// object's colour does not change from frame to frame), else over the frame's own images (the rig's cameras
// share their colour processing).
std::map<std::string, SaturationReference> ColourReference(const FrameInputs& in, const std::vector<PlacedObject>& placed,
                                                           const SequencePlan* plan);

// What one camera adds to an object's outcome: its pixels, and its 2D box where it is labelable.
struct CameraObjectView {
  double rendered_pixels = 0, visible_pixels = 0;
  std::optional<CameraBox> box;
};

// One camera: its light at the objects, the render and the soft shadows, the receiver's depth, occlusion by the
// real scene, the composite in linear light, harmonisation, and the objects' 2D boxes. Fills `views` (one per
// placed object; they are added to the frame's objects by AddCameraViews, in camera order) and returns nullopt
// when the objects do not touch the camera's image. Reads only what the frame's earlier stages made, so the
// cameras of a frame run concurrently; `stage.times` must be the camera's own.
std::optional<CameraOutcome> SynthesizeCamera(const CameraStageInput& stage, size_t cam_index, std::vector<CameraObjectView>* views);
void AddCameraViews(const std::vector<CameraObjectView>& views, std::vector<ObjectOutcome>* objects);

// Drivable ground points within `margin_m` of the objects' footprints (their bounding circles).
std::vector<Eigen::Vector3d> RoadPointsNear(const GroundModel& ground, const std::vector<PlacedObject>& objects, double margin_m = 6.0);

// The road that decides whether an object stands in the sun: within 1.5 m of its footprint. Shade boundaries
// are sharp; the 6 m the level of the light is read from would mix a shaded spot with the sunlit road beside it.
// Where no camera shows road that close (a cone whose near road its neighbours and the parked cars hide), the
// nearest wider ring that has road, before the road of all objects: over a sequence the closest road comes and
// goes as the view changes, and jumping to the frame-wide level made a cone's brightness change by 70 % from one
// frame to the next (PandaSet 002, bench_sequence).
constexpr double kOwnRoadMargins[] = {1.5, 3.0, 6.0};

}  // namespace frame_stages
}  // namespace sd
