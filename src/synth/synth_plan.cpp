#include "synth/synth_plan.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <memory>
#include <set>

#include "core/log.h"
#include "datasets/categories.h"
#include "synth/realism.h"
#include "synth/road_surface.h"

namespace sd {
namespace fs = std::filesystem;
using nlohmann::json;

bool WorldFixedScenario(const Scenario& scenario) { return !scenario.arrangements.empty() || scenario.world_fixed; }

const SequencePlan* SynthPlan::ForFrame(size_t frame_index) const {
  for (const auto& s : sequences)
    for (const PlannedFrame& f : s.plan.frames)
      if (f.frame_index == frame_index) return &s.plan;
  return nullptr;
}

namespace {

// Frames a < b of one sequence: every step between them within the planner's time gap.
bool OneSequence(const Log& log, size_t a, size_t b, double max_gap_s) {
  if (!log.sequential) return false;  // object frames: no world pose, no time order
  for (size_t k = a; k < b; ++k) {
    const double gap = log.frames[k + 1].timestamp - log.frames[k].timestamp;
    if (!(gap >= 0 && gap <= max_gap_s)) return false;
  }
  return true;
}

double Median(std::vector<double> v) {
  SD_CHECK(!v.empty(), << "median of nothing");
  std::nth_element(v.begin(), v.begin() + static_cast<long>(v.size() / 2), v.end());
  return v[v.size() / 2];
}

// Where no sweep measured the road: horizontal at the height of the nearest ego origin plus `ground_offset`
// (the road's height in the ego frame: 0 in nuScenes and Argoverse 2, whose ego origin is on the ground; about
// -1.73 m for KITTI's Velodyne frame), drivable everywhere (nothing is known there; the plan's lane geometry
// and the annotated boxes still apply).
class EgoPoseSurface final : public SurfaceModel {
 public:
  EgoPoseSurface(std::vector<Rigid3d> poses, double ground_offset) : poses_(std::move(poses)), offset_(ground_offset) {
    SD_CHECK(!poses_.empty(), << "no poses");
  }
  std::optional<SurfacePoint> At(const Eigen::Vector2d& xy) const override {
    double best = std::numeric_limits<double>::infinity(), z = 0;
    for (const Rigid3d& T : poses_) {
      const double d = (T.translation.head<2>() - xy).squaredNorm();
      if (d < best) {
        best = d;
        z = T.translation.z();
      }
    }
    return SurfacePoint{z + offset_, Eigen::Vector3d::UnitZ(), false};
  }
  bool IsDrivable(const Eigen::Vector2d&) const override { return true; }

 private:
  std::vector<Rigid3d> poses_;
  double offset_;
};

// How far from a sweep's sensor its road surface decides. RoadSurface keeps points to 50 m, but beyond about
// 30 m the ground rings are too sparse for an unmeasured cell to mean "no road" (one Argoverse 2 log with 2 of
// its 156 sweeps refused every lane closure ahead at 50 m, "off the surface"; at 30 m it plans).
constexpr double kSweepCoverage = 30.0;

// The LiDAR road surface within `coverage` of some sweep's sensor (there it alone decides: a hole is a
// building or an occlusion shadow, not missing data), the ego poses' height beyond it.
class CoveredRoadSurface final : public SurfaceModel {
 public:
  CoveredRoadSurface(RoadSurface road, const std::vector<SweepInWorld>& sweeps, std::vector<Rigid3d> poses, double coverage)
      : road_(std::move(road)), poses_(poses, GroundUnderEgo(road_, poses)), coverage2_(coverage * coverage) {
    for (const auto& s : sweeps) sensors_.push_back(s.sensor_origin.head<2>());
  }
  // The measured road's height under the ego origins, relative to them (median).
  static double GroundUnderEgo(const RoadSurface& road, const std::vector<Rigid3d>& poses) {
    std::vector<double> dz;
    for (const Rigid3d& T : poses)
      if (const auto p = road.At(T.translation.head<2>())) dz.push_back(p->height - T.translation.z());
    return dz.empty() ? 0.0 : Median(dz);
  }
  const RoadSurface& road() const { return road_; }
  std::optional<SurfacePoint> At(const Eigen::Vector2d& xy) const override { return Covered(xy) ? road_.At(xy) : poses_.At(xy); }
  bool IsDrivable(const Eigen::Vector2d& xy) const override { return Covered(xy) ? road_.IsDrivable(xy) : true; }

 private:
  bool Covered(const Eigen::Vector2d& xy) const {
    for (const auto& s : sensors_)
      if ((s - xy).squaredNorm() <= coverage2_) return true;
    return false;
  }
  RoadSurface road_;
  EgoPoseSurface poses_;
  double coverage2_;
  std::vector<Eigen::Vector2d> sensors_;
};

}  // namespace

SynthPlan PlanSynthesis(const Log& log, const std::vector<size_t>& selected, const Scenario& scenario,
                        const std::vector<Asset>& assets, const fs::path& scenario_file, bool need_assets) {
  SequencePlanOptions options;
  for (const Asset& a : assets) {
    options.assets.push_back(PlanAsset{a.info.id, CanonicalCategory(a.info.category), a.info.extent});
  }
  std::vector<size_t> sorted = selected;
  std::sort(sorted.begin(), sorted.end());
  std::vector<std::pair<size_t, size_t>> ranges;  // [first, last] selected frames of each sequence
  for (size_t fi : sorted) {
    if (!ranges.empty() && OneSequence(log, ranges.back().second, fi, options.max_frame_gap_s)) ranges.back().second = fi;
    else ranges.push_back({fi, fi});
  }
  SynthPlan out;
  for (const auto& [first, last] : ranges) {
    SynthPlanSequence seq;
    std::vector<Rigid3d> poses;
    for (size_t k = first; k <= last; ++k) poses.push_back(log.frames[k].T_world_ego);
    // The sweeps on disk, read by runs of consecutive frames that have one (info files may list sweeps that
    // were never downloaded; Argoverse 2 test logs hold a few of their sweeps).
    std::vector<SweepInWorld> sweeps;
    for (size_t k = first; k <= last;) {
      auto on_disk = [&](size_t i) {
        std::error_code ec;
        return log.frames[i].lidar && fs::is_regular_file(log.frames[i].lidar->path, ec);
      };
      if (!on_disk(k)) { ++k; continue; }
      size_t e = k;
      while (e <= last && on_disk(e)) ++e;
      for (SweepInWorld& sw : SweepsFromLog(log, k, e)) sweeps.push_back(std::move(sw));
      k = e;
    }
    std::unique_ptr<SurfaceModel> surface;
    if (!sweeps.empty()) {
      auto road = std::make_unique<CoveredRoadSurface>(RoadSurface::Build(sweeps), sweeps, poses, kSweepCoverage);
      const RoadSurface::Stats& st = road->road().stats();
      seq.surface = "road_surface";
      seq.surface_detail = Msg() << sweeps.size() << " of " << last - first + 1 << " frames' LiDAR sweeps, " << st.observed_cells
                                 << " observed + " << st.filled_cells << " filled cells, " << st.drivable_cells
                                 << " drivable; beyond " << kSweepCoverage << " m of every sweep: the ego poses' height";
      surface = std::move(road);
    } else {
      seq.surface = "ego_poses";
      seq.surface_detail = "no LiDAR files on disk: the height of the nearest ego origin (on the ground in nuScenes and "
                           "Argoverse 2), drivable everywhere";
      // The road under the ego origin: on it by convention, except where the ego frame is a sensor's (KITTI's
      // Velodyne): there the boxes say.
      std::vector<double> bottoms;
      if (!log.ego_origin_on_ground)
        for (size_t k = first; k <= last; ++k)
          for (const auto& a : log.frames[k].annotations) bottoms.push_back(a.box.center().z() - 0.5 * a.box.size.z());
      surface = std::make_unique<EgoPoseSurface>(poses, bottoms.empty() ? 0.0 : Median(bottoms));
    }
    try {
      seq.plan = PlanSequence(log, scenario, *surface, FrameRange{first, last + 1}, options);
    } catch (const InputError& e) {
      if (!e.where().empty()) throw;
      throw InputError(scenario_file, e.what());
    }
    if (need_assets)
      for (const PlannedObject& o : seq.plan.objects)
        if (o.asset_id.empty())
          throw InputError(scenario_file, Msg() << o.source << " places a " << o.category << " (" << o.role
                                                << "), and no asset of that category was given: rendering needs one "
                                                   "(--asset or assets_from_bank; --dry-run plans without)");
    if (need_assets && !seq.plan.objects.empty()) {
      std::set<std::string> categories;
      for (const PlannedObject& o : seq.plan.objects) categories.insert(CanonicalCategory(o.category));
      std::vector<size_t> frames;
      for (size_t k = first; k <= last; ++k) frames.push_back(k);
      seq.plan.colour_reference = RealSaturation(log, frames, categories);
    }
    SD_LOG(Info, "plan of frames " << first << ".." << last << ": " << seq.plan.objects.size() << " world-fixed object(s), surface: "
                                   << seq.surface << " (" << seq.surface_detail << ")");
    out.sequences.push_back(std::move(seq));
  }
  return out;
}

json SynthPlanToJson(const SynthPlan& plan) {
  json seqs = json::array();
  for (const auto& s : plan.sequences) {
    json j = PlanToJson(s.plan);
    j["surface"] = s.surface;
    j["surface_detail"] = s.surface_detail;
    seqs.push_back(std::move(j));
  }
  return {{"sequences", std::move(seqs)}};
}

}  // namespace sd
