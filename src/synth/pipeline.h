#pragma once
// `synthdrive synth`: insert assets into a real driving log, camera and LiDAR, with labels, written as a
// derivative dataset in the input's own format.
//
// A batch command (DESIGN.md): the work list is the selected frames. Each frame is synthesised into a *part*,
// `<out>.parts/<index>-<token>/` (written through a StagingDirectory, so it exists complete or not at all), and
// the merge turns the parts of every selected frame into the derivative dataset. A local run is exactly
// "shard 0/1, then merge" (RunSynth), so shards + merge write the same bytes as a local run by construction.
#include <filesystem>
#include <functional>
#include <memory>
#include <optional>
#include <string>
#include <vector>

#include "assetgen/asset.h"
#include "core/image.h"
#include "core/shard.h"
#include "datasets/readers.h"
#include "datasets/writers.h"
#include "synth/ground.h"
#include "synth/lidar_model.h"
#include "synth/placement.h"
#include "synth/scenario.h"
#include "synth/sequence_plan.h"

namespace sd {
namespace models {
class Harmonizer;
}

struct SynthOptions {
  int samples_per_pixel = 4;
  int ao_samples = 16;
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
  // Tests only: called while a part is half written (its images and sweep are in the staging folder, its
  // part.json is not), so a test can kill the process mid-part.
  std::function<void(size_t frame_index, const std::filesystem::path& staging)> part_written_hook;
};

struct SynthRequest {
  std::filesystem::path log;            // dataset root or info file
  OpenLogOptions log_options;
  std::vector<std::filesystem::path> assets;  // asset folders
  std::filesystem::path scenario;
  std::filesystem::path out;
  SynthOptions options;
};

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
};

struct FrameOutcome {
  size_t frame_index = 0;
  FrameEdit edit;
  std::vector<ObjectOutcome> objects;
  std::vector<CameraOutcome> cameras;
  GroundModel ground;
  std::string sun_source;
  std::string light;  // for people: the light model of the frame (environment map: sun, sun/sky split, seams)
  PointCloud sweep_before;  // sensor frame
  std::vector<std::pair<int, int>> lidar_object_points;  // (point index in edit.points, object index)
  // The LiDAR model the frame was simulated with: LidarModel::Summary(), or "off" (lidar_realism false, an
  // Argoverse 2 log, or a sweep the model cannot be fitted from: then the ideal sensor, with a warning).
  // Kept in parts and written per frame to synth.json.
  std::string lidar_model = "off";
  std::optional<LidarModel> lidar_model_fit;  // the fitted model itself; in memory only (not in parts)
  bool lidar_ego_motion = false;              // rolling shutter from the neighbouring frames' ego poses
};

// Synthesises one frame in memory (no files written). Without a plan, objects are placed for this frame alone
// (synth/placement.h, ego frame, the frame's GroundModel). With a plan (which must cover the frame), the
// plan's world-fixed objects within its range gate (PlannedView::in_range) are rendered at their ego-frame
// pose PlannedView::T_ego_object, so every frame shows the same objects where the world has them; an object
// that ends up with neither a LiDAR point nor a labelable camera box (>= 4 visible pixels) gets no label.
// LiDAR (options.lidar_realism): the model is fitted from the frame's sweep (KITTI: clockwise, sweep boundary
// behind); the simulation's seed is derived from the scenario seed and the frame index only, so the result does
// not depend on which shard synthesises the frame; ego motion from the previous and next log frames where they
// are of the same sequence (nuScenes: the sweep's timestamp is the end of its turn; output de-skewed as
// nuScenes' own sweeps are), none for KITTI object frames.
FrameOutcome SynthesizeFrame(const Log& log, size_t frame_index, const std::vector<Asset>& assets,
                             const Scenario& scenario, const SynthOptions& options, const SequencePlan* plan = nullptr);

// Sequence planning for synth (docs/sequence_placement.md). Used when the scenario has "arrangements" or
// says "world_fixed": true (then its plain "objects" are planned once too, distance_m / lateral_m read along
// the ego path), and always by --dry-run.
//  - Sequences: the selected frames, sorted, are cut where consecutive log frames are more than
//    SequencePlanOptions::max_frame_gap_s apart (nuScenes info files hold several scenes); each sequence is
//    planned over the log frames [first selected, last selected] of it (unselected frames in between count as
//    obstacles and path). KITTI object frames have no world pose: each is its own sequence.
//  - Surface: RoadSurface::Build over the sequence's sweeps that are on disk; it alone decides within
//    RoadSurfaceOptions::max_range (50 m) of some sweep's sensor. Beyond that, and everywhere when no sweep
//    is on disk (info files without the sensor data), the height of the nearest planned ego origin (on the
//    ground in nuScenes and Argoverse 2), horizontal, drivable everywhere ("ego_poses").
// Deterministic: the plan depends only on the log, the selection, the scenario and the assets, so every shard
// computes the same plan (its hash is part of the parts' request fingerprint).
struct SynthPlanSequence {
  std::string surface;         // "road_surface" (LiDAR, ego poses beyond its reach) | "ego_poses" (no sweep on disk)
  std::string surface_detail;  // for people: sweeps and cells used
  SequencePlan plan;
};
struct SynthPlan {
  std::vector<SynthPlanSequence> sequences;
  // The plan covering `frame_index`, or nullptr.
  const SequencePlan* ForFrame(size_t frame_index) const;
};
// `need_assets`: every planned object must resolve to one of `assets` (InputError otherwise: rendering needs a
// mesh); false for dry runs, where a category without an asset stands at its default size. InputError naming
// `scenario_file` when the plan is impossible.
SynthPlan PlanSynthesis(const Log& log, const std::vector<size_t>& selected, const Scenario& scenario,
                        const std::vector<Asset>& assets, const std::filesystem::path& scenario_file, bool need_assets);
// {"sequences": [PlanToJson(plan) + {"surface", "surface_detail"}]}; plan.json is this plus "tool", "log" and
// "scenario" (the scenario file's JSON).
nlohmann::json SynthPlanToJson(const SynthPlan& plan);

struct SynthSummary {
  std::filesystem::path out, report;
  size_t frames = 0, objects = 0;
};

// The whole command: loads everything, synthesises the selected frames, writes the derivative dataset,
// synth.json (placements and provenance) and report.html into `out` atomically (world-fixed scenarios: also
// plan.json and plan.html, as --dry-run writes them; --coco: coco_2d.json). It is RunSynthShard(0/1)
// followed by MergeSynthParts; the parts folder is removed once the output is committed (and kept when a
// frame failed and others have parts, so a rerun resumes). A frame's failure does not stop the others; the
// first failure is rethrown at the end.
SynthSummary RunSynth(const SynthRequest& request);

// Where the parts of `out` live: "<out>.parts" (a sibling, so the output folder itself only ever appears
// complete). Besides one folder per frame it holds each shard's run log, log-<K>-of-<N>.jsonl: one line per
// frame, {"frame", "token", "status": done|skipped|failed, "error", "seconds"} (seconds: wall clock).
std::filesystem::path SynthPartsDir(const std::filesystem::path& out);

struct SynthShardSummary {
  std::filesystem::path parts, run_log;
  size_t owned = 0, done = 0, skipped = 0;  // skipped: its part was already there
  std::vector<size_t> failed;               // frame indices whose synthesis failed (errors are in the run log)
};

// `synth --shard K/N`: synthesises the frames at positions i of the selection with i % N == K into parts,
// skipping frames whose part exists (a killed shard resumes; staging folders it left are removed). A frame
// that fails is logged and the others go on. Refuses (InputError) when `out` exists without --overwrite, or
// when an existing part was made for a different request (log, scenario, assets or render options).
SynthShardSummary RunSynthShard(const SynthRequest& request, const ShardSpec& shard);

// `synth --merge`: the parts of every selected frame -> `out`, exactly as a local run writes it. InputError,
// before anything is created, listing the frames that have no part, or naming a part of a different request.
// The parts folder is left in place.
SynthSummary MergeSynthParts(const SynthRequest& request);

// `synth --dry-run`: plans the selected frames (PlanSynthesis; --asset / bank assets optional: without them a
// category stands at its default size), renders nothing, and writes `out` (StagingDirectory) with plan.json
// (SynthPlanToJson) and plan.html (synth/report.h WritePlanReport). Works on logs whose sensor files are
// absent (only the poses and boxes are read).
struct DryRunSummary {
  std::filesystem::path out;
  SynthPlan plan;
  size_t objects = 0;
  std::vector<std::string> lines;  // human summary: per sequence and per arrangement / object request
};
DryRunSummary RunSynthDryRun(const SynthRequest& request);

}  // namespace sd
