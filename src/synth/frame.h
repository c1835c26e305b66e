#pragma once
// One frame of `synthdrive synth`, in memory: read the frame's inputs, place, light the frame, build the
// object scene, then each camera (its light, render, receiver depth, occlusion, composite, harmonisation, 2D
// boxes) and the LiDAR. No files are written here; synth/batch.h turns frames into parts and parts into the
// derivative dataset.
#include <cstdint>
#include <filesystem>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "assetgen/asset.h"
#include "datasets/log.h"
#include "datasets/writers.h"
#include "synth/camera_look.h"
#include "synth/camera_road.h"
#include "synth/ground.h"
#include "synth/outcome.h"
#include "synth/scenario.h"
#include "synth/sequence_plan.h"

namespace sd {
namespace models {
class Harmonizer;
}

struct SynthOptions {
  int samples_per_pixel = 4;
  int ao_samples = 16;
  // The objects' sky (render/camera_render.h CameraRenderOptions::sky_filter_radius): > 0, a pixel's sky is shared
  // by its sub-samples and denoised over this radius, and under the environment map's light the objects' render
  // traces ao_samples sky rays per pixel (spread over its sub-samples) instead of per sub-sample (under the road's
  // light, whose render also shades the road, still per sub-sample). 0: every sub-sample's own ao_samples rays.
  int sky_filter_radius = 3;
  std::vector<std::string> frames;  // frame tokens or indices to synthesise; empty = all frames
  WriteOptions write;
  bool overwrite = false;
  bool report = true;
  bool coco = false;  // also write coco_2d.json (datasets/coco.h WriteCoco2D) into the output
  // LiDAR realism (docs/lidar.md): a sensor model is fitted from each frame's own sweep and inserted objects get
  // its range noise, dropout, intensity and (where neighbouring frames give the ego's motion) rolling-shutter
  // skew. false (`--no-lidar-realism`): the ideal sensor, byte for byte what synth wrote before realism existed.
  bool lidar_realism = true;
  // Light on the objects (docs/lighting.md). kEnvironment: an HDR environment map stitched from the frame's
  // cameras (sun from the images or the ephemeris, fitted sky, each camera's exposure and white balance), the
  // level and the shade at the objects from the real road next to them (synth/object_light.h), soft sun shadows
  // and radiance-weighted ambient occlusion on the road. kRoad: one sun and one uniform sky per camera from the
  // road next to the objects (synth/lighting.h), hard shadows; faster (no map).
  enum class Light { kEnvironment, kRoad };
  Light light = Light::kEnvironment;
  // Occlusion by real geometry (docs/occlusion.md). true: dense, edge-aware depth per camera from the sweep with
  // the annotated boxes and the ground as priors, occluder edges matted from the photograph. false: the sparse
  // per-ring test (ComputeVisibility).
  bool dense_occlusion = true;
  // Harmonisation after compositing (models/harmonization.h): "none", "classical", "auto" (the installed
  // learned model when there is one, else classical) or a TorchScript file. The classical path moves the colour
  // cast and a little chroma only: the light already sets the object's exposure, and a lightness transfer
  // cannot tell exposure from albedo (it would grey a white car on dark asphalt).
  std::string harmonizer = "classical";
  // The resolved harmoniser (RunSynth resolves `harmonizer` once per run, so a model loads once). Null: the
  // frame resolves `harmonizer` itself.
  std::shared_ptr<const models::Harmonizer> harmonizer_model;
  // The camera's own look given to inserted pixels (synth/camera_look.h, docs/camera_look.md): the image's edge
  // rise (blur), noise and JPEG quality, estimated per camera and recorded in synth.json. All off: the render
  // composited as it is, as synth wrote before.
  CameraLookOptions camera_look;
  // Tests only: called while a part is half written (its images and sweep are in the staging folder, its
  // part.json is not), so a test can kill the process mid-part.
  std::function<void(size_t frame_index, const std::filesystem::path& staging)> part_written_hook;
};

// Synthesises one frame in memory (no files written). Without a plan, objects are placed for this frame alone
// (synth/placement.h, ego frame, the frame's GroundModel). With a plan (which must cover the frame), the
// plan's world-fixed objects within its range gate (PlannedView::in_range) are rendered at their ego-frame
// pose PlannedView::T_ego_object, so every frame shows the same objects where the world has them; an object
// that ends up with neither a LiDAR point nor a labelable camera box (>= 4 visible pixels) gets no label.
// LiDAR (options.lidar_realism): the model is fitted from the frame's sweep (KITTI: clockwise, sweep boundary
// behind); ego motion from the previous and next log frames where they are of the same sequence (nuScenes: the
// sweep's timestamp is the end of its turn; output de-skewed as nuScenes' own sweeps are), none for KITTI object
// frames. A frame without a sweep (a camera-only log) gets its road from EstimateCameraGround, its camera images
// and labels, and no sweep (FrameOutcome::lidar_model says so). Every random draw comes from FrameSeedsOf, so the result does not depend on which shard synthesises
// the frame.
FrameOutcome SynthesizeFrame(const Log& log, size_t frame_index, const std::vector<Asset>& assets,
                             const Scenario& scenario, const SynthOptions& options, const SequencePlan* plan = nullptr);

// The harmoniser a SynthOptions::harmonizer choice names ("classical", "auto" or a TorchScript file); "classical"
// moves the colour cast and a little chroma, never the lightness. InputError naming a file that does not exist.
models::Harmonizer ResolveSynthHarmonizer(const std::string& choice);

// The seeds of a frame's random streams, from the scenario seed and the frame index alone (never the
// shard, the process or the time).
struct FrameSeeds {
  uint32_t placement = 0;  // candidate positions and yaws (synth/placement.h), per-frame scenarios only
  uint32_t render = 0;     // anti-aliasing jitter, AO and soft-shadow rays (render/camera_render.h)
  uint64_t lidar = 0;      // range noise and dropout (synth/lidar_sim.h)
  uint64_t sensor = 0;     // camera noise on inserted pixels (synth/camera_look.h), mixed with the camera index
};
FrameSeeds FrameSeedsOf(uint32_t scenario_seed, size_t frame_index);

// The frame's sweep in the ego frame, and the one ground estimate of a frame: synthesis places on it and the
// merge recomputes it for the report, so it depends on nothing but the frame and the scenario.
std::vector<Eigen::Vector3d> PointsInEgo(const Frame& frame, const PointCloud& sweep);
// 1 for each return of a second LiDAR merged into the sweep (LidarSensor::sensor_feature), which the road fit
// leaves out; empty when the sweep holds one sensor.
std::vector<uint8_t> SecondSensorReturns(const Frame& frame, const PointCloud& sweep);
GroundModel EstimateFrameGround(const Frame& frame, const PointCloud& sweep, const std::vector<Eigen::Vector3d>& points_ego,
                                const Scenario& scenario);

// The road of a frame without a LiDAR sweep (docs/camera_only.md). From plane-sweep stereo of its cameras against
// the same cameras in the neighbouring frames (synth/camera_road.h), searched around RoadPriorHeight; where the
// stereo finds too little road (one frame, no texture, no neighbour in time), a level plane at that height,
// drivable everywhere within range. `source` says which, in one line, for synth.json and the report.
// `points_ego`: what the stereo measured, the road points first (GroundModel::ground_indices index them), then the
// scene points: the frame's stand-in for a sweep's points in placement and occlusion, never written. Empty for
// the plane.
struct CameraGround {
  GroundModel ground;
  std::string source;
  bool from_stereo = false;
  std::vector<Eigen::Vector3d> points_ego;
};
// The stereo synthesis runs: CameraRoadOptions' defaults with the scene points on.
CameraRoadOptions SynthCameraRoadOptions();
CameraGround EstimateCameraGround(const Log& log, size_t frame_index, const Scenario& scenario,
                                  const CameraRoadOptions& options = SynthCameraRoadOptions());
// The road's height in a frame's ego frame before anything measures it: the median bottom of its annotated boxes
// (they stand on the road), else the rig's convention (Log::nominal_road_z).
double RoadPriorHeight(const Log& log, const Frame& frame);

}  // namespace sd
