#pragma once
// Sequence planning for synth (docs/sequence_placement.md): the glue between a synth request and
// synth/sequence_plan.h. Used when the scenario has "arrangements" or says "world_fixed": true (then its plain
// "objects" are planned once too, distance_m / lateral_m read along the ego path), and always by --dry-run.
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
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "assetgen/asset.h"
#include "datasets/log.h"
#include "synth/scenario.h"
#include "synth/sequence_plan.h"

namespace sd {

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

// True when the scenario is planned once per sequence: it has arrangements, or says "world_fixed": true.
bool WorldFixedScenario(const Scenario& scenario);

// `need_assets`: every planned object must resolve to one of `assets` (InputError otherwise: rendering needs a
// mesh); false for dry runs, where a category without an asset stands at its default size. InputError naming
// `scenario_file` when the plan is impossible.
SynthPlan PlanSynthesis(const Log& log, const std::vector<size_t>& selected, const Scenario& scenario,
                        const std::vector<Asset>& assets, const std::filesystem::path& scenario_file, bool need_assets);
// {"sequences": [PlanToJson(plan) + {"surface", "surface_detail"}]}; plan.json is this plus "tool", "log" and
// "scenario" (the scenario file's JSON).
nlohmann::json SynthPlanToJson(const SynthPlan& plan);

}  // namespace sd
