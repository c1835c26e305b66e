#include "synth/sequence_plan.h"

#include <algorithm>
#include <cmath>
#include <map>
#include <optional>
#include <random>
#include <unordered_map>

#include "core/error.h"
#include "core/log.h"
#include "datasets/categories.h"
#include "io/geometry_json.h"

namespace sd {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDeg = kPi / 180.0;

double WrapAngle(double a) { return std::atan2(std::sin(a), std::cos(a)); }

// Footprint-only copy of a box: same xy pose and extent, z flattened, so BoxesOverlap tests the footprints.
Box3 Flat(const Box3& b) {
  const double yaw = b.Yaw();
  return Box3{Rigid3d::FromYaw(yaw, Eigen::Vector3d(b.center().x(), b.center().y(), 0)),
              Eigen::Vector3d(b.size.x(), b.size.y(), 1.0)};
}

// Boxes binned on a 4 m grid by their footprint's bounding square; every box sits in each cell it touches, so
// a query only looks at the cells its own grown footprint touches.
class BoxGrid {
 public:
  void Add(const Box3& box) {
    const int idx = static_cast<int>(boxes_.size());
    boxes_.push_back(Flat(box));
    ForCells(box, 0.0, [&](int64_t key) { cells_[key].push_back(idx); });
  }
  bool AnyOverlap(const Box3& box, double margin) const {
    const Box3 flat = Flat(box);
    bool hit = false;
    ForCells(box, margin, [&](int64_t key) {
      if (hit) return;
      auto it = cells_.find(key);
      if (it == cells_.end()) return;
      for (int i : it->second)
        if (BoxesOverlap(flat, boxes_[static_cast<size_t>(i)], margin)) { hit = true; return; }
    });
    return hit;
  }
  size_t size() const { return boxes_.size(); }

 private:
  template <typename F>
  void ForCells(const Box3& box, double margin, F&& f) const {
    const double r = 0.5 * box.size.head<2>().norm() + margin;
    const auto lo = [&](double v) { return static_cast<int64_t>(std::floor((v - r) / kCell)); };
    const auto hi = [&](double v) { return static_cast<int64_t>(std::floor((v + r) / kCell)); };
    const double cx = box.center().x(), cy = box.center().y();
    for (int64_t y = lo(cy); y <= hi(cy); ++y)
      for (int64_t x = lo(cx); x <= hi(cx); ++x) f((x << 32) ^ (y & 0xffffffff));
  }
  static constexpr double kCell = 4.0;
  std::vector<Box3> boxes_;
  std::unordered_map<int64_t, std::vector<int>> cells_;
};

// Boxes between two poses of one object (exclusive of both ends), at most `step` apart.
std::vector<Box3> Between(const Box3& a, const Box3& b, double step) {
  const double dist = (b.center() - a.center()).head<2>().norm();
  // A turning box sweeps its corners too: count the arc of the far corner.
  const double turn = a.T_frame_box.rotation.angularDistance(b.T_frame_box.rotation) * 0.5 * a.size.head<2>().norm();
  const int n = std::min(400, static_cast<int>(std::ceil(std::max(dist, turn) / step)));
  std::vector<Box3> out;
  for (int i = 1; i < n; ++i) {
    const double t = static_cast<double>(i) / n;
    out.push_back(Box3{Interpolate(a.T_frame_box, b.T_frame_box, t), (1 - t) * a.size + t * b.size});
  }
  return out;
}

double Unit(std::mt19937& rng) { return rng() * (1.0 / 4294967296.0); }
double Uniform(std::mt19937& rng, double lo, double hi) { return lo + Unit(rng) * (hi - lo); }

struct Resolved {
  std::string category, asset_id;
  Eigen::Vector3d extent;
};

Resolved Resolve(const ObjectSpec& spec, const std::vector<PlanAsset>& assets, std::mt19937& rng,
                 const std::string& source) {
  if (!spec.asset_id.empty()) {
    for (const auto& a : assets)
      if (a.id == spec.asset_id) return {a.category, a.id, a.extent};
    throw InputError("", Msg() << source << " asks for asset '" << spec.asset_id
                               << "' but no asset of that id was given (its size is needed to plan)");
  }
  std::vector<const PlanAsset*> pool;
  for (const auto& a : assets)
    if (a.category == spec.category) pool.push_back(&a);
  if (!pool.empty()) {
    const PlanAsset* a = pool[static_cast<size_t>(Unit(rng) * static_cast<double>(pool.size())) % pool.size()];
    return {a->category, a->id, a->extent};
  }
  const auto c = FindCategory(spec.category);
  if (!c) throw InputError("", Msg() << source << " asks for category '" << spec.category << "', which is neither canonical nor any given asset's");
  return {c->name, "", c->default_size};
}

// One object of a candidate: what and where, in path coordinates.
struct Slot {
  const Resolved* what;
  std::string role;
  double s, lateral, yaw;  // yaw: world
};

class Planner {
 public:
  Planner(const Log& log, const Scenario& scenario, const SurfaceModel& surface, size_t begin, size_t end,
          const SequencePlanOptions& options, const EgoPath& path)
      : log_(log), scenario_(scenario), surface_(surface), begin_(begin), end_(end), opt_(options), path_(path) {}

  void BuildObstacles(SequencePlan* plan) {
    std::map<std::string, std::vector<Box3>> tracks;  // ordered: deterministic
    for (size_t k = begin_; k < end_; ++k) {
      const Frame& f = log_.frames[k];
      const Box3 ego = opt_.ego_box.Transformed(f.T_world_ego);
      ego_.Add(ego);
      if (k + 1 < end_)
        for (const Box3& b : Between(ego, opt_.ego_box.Transformed(log_.frames[k + 1].T_world_ego), opt_.sweep_step_m)) ego_.Add(b);
      if (!f.has_annotations) {
        plan->unannotated_frames.push_back(k);
        continue;
      }
      for (const Annotation& a : f.annotations) {
        const Box3 w = a.box.Transformed(f.T_world_ego);
        real_.Add(w);
        ++plan->annotated_boxes;
        if (!a.instance_token.empty()) {
          tracks[a.instance_token].push_back(w);
        } else if (k + 1 < end_ && a.velocity.allFinite()) {
          // No track id: sweep along the annotated velocity until the next keyframe.
          const double dt = log_.frames[k + 1].timestamp - f.timestamp;
          const Eigen::Vector3d v = f.T_world_ego.rotation * Eigen::Vector3d(a.velocity.x(), a.velocity.y(), 0);
          Box3 moved = w;
          moved.T_frame_box.translation += v * dt;
          if ((v * dt).norm() > opt_.sweep_step_m) {
            for (const Box3& b : Between(w, moved, opt_.sweep_step_m)) { real_.Add(b); ++plan->swept_boxes; }
            real_.Add(moved);
            ++plan->swept_boxes;
          }
        }
      }
    }
    plan->tracks = tracks.size();
    for (const auto& [token, boxes] : tracks)
      for (size_t i = 0; i + 1 < boxes.size(); ++i)
        for (const Box3& b : Between(boxes[i], boxes[i + 1], opt_.sweep_step_m)) { real_.Add(b); ++plan->swept_boxes; }
  }

  // Builds the world objects of a candidate and checks them all; true (and appends to `out`) when valid.
  bool Try(const std::vector<Slot>& slots, const Arrangement* arr, PlanStats* st, std::vector<PlannedObject>* out) {
    ++st->candidates;
    std::vector<PlannedObject> objs;
    bool off_surface = false, off_drivable = false;
    const bool allow_shoulder = arr && arr->allow_shoulder;
    for (const Slot& sl : slots) {
      const Eigen::Vector3d& e = sl.what->extent;
      const Eigen::Vector2d xy = path_.At(sl.s, sl.lateral);
      const auto sp = surface_.At(xy);
      if (!sp) { off_surface = true; break; }
      const Eigen::Vector3d up = sp->normal.normalized();
      Eigen::Vector3d fwd(std::cos(sl.yaw), std::sin(sl.yaw), 0);
      fwd = (fwd - fwd.dot(up) * up).normalized();
      Eigen::Matrix3d R;
      R.col(0) = fwd;
      R.col(1) = up.cross(fwd);
      R.col(2) = up;
      PlannedObject o;
      o.role = sl.role;
      o.category = sl.what->category;
      o.asset_id = sl.what->asset_id;
      o.T_world_object = Rigid3d(R, Eigen::Vector3d(xy.x(), xy.y(), sp->height));
      o.box = Box3{Rigid3d(R, o.T_world_object * Eigen::Vector3d(0, 0, 0.5 * e.z())), e};
      o.path_s = sl.s;
      o.path_lateral = sl.lateral;
      // Footprint samples: centre, edge midpoints and corners.
      for (int i = -1; i <= 1 && !off_surface && !off_drivable; ++i)
        for (int j = -1; j <= 1; ++j) {
          const Eigen::Vector2d p = (o.T_world_object * Eigen::Vector3d(0.5 * i * e.x(), 0.5 * j * e.y(), 0)).head<2>();
          if (!surface_.At(p)) { off_surface = true; break; }
          if (!allow_shoulder && !surface_.IsDrivable(p)) { off_drivable = true; break; }
        }
      if (off_surface || off_drivable) break;
      objs.push_back(std::move(o));
    }
    if (off_surface) { ++st->off_surface; return false; }
    if (off_drivable) { ++st->off_drivable; return false; }
    const double m = scenario_.margin_m;
    for (const auto& o : objs)
      if (ego_.AnyOverlap(o.box, m)) { ++st->hits_ego_path; return false; }
    for (const auto& o : objs)
      if (real_.AnyOverlap(o.box, m)) { ++st->overlaps_real; return false; }
    for (size_t i = 0; i < objs.size(); ++i) {
      if (placed_.AnyOverlap(objs[i].box, m)) { ++st->overlaps_placed; return false; }
      for (size_t j = 0; j < i; ++j)
        if (FootprintsOverlap(objs[i].box, objs[j].box, m)) { ++st->overlaps_placed; return false; }
    }
    if (opt_.require_visible)
      for (const auto& o : objs) {
        bool seen = false;
        for (size_t k = begin_; k < end_ && !seen; ++k) seen = View(log_.frames[k], o).visible;
        if (!seen) { ++st->never_visible; return false; }
      }
    for (auto& o : objs) {
      placed_.Add(o.box);
      out->push_back(std::move(o));
    }
    return true;
  }

  PlannedView View(const Frame& f, const PlannedObject& o) const {
    PlannedView v;
    const Rigid3d T_ego_world = f.T_world_ego.Inverse();
    v.T_ego_object = T_ego_world * o.T_world_object;
    v.box_ego = o.box.Transformed(T_ego_world);
    v.distance_m = v.box_ego.center().head<2>().norm();
    v.in_range = v.distance_m <= opt_.range_m;
    for (const CameraSensor& cam : f.cameras) {
      const auto uv = cam.intrinsics.Project(cam.T_ego_cam.Inverse() * v.box_ego.center(), 0.5);
      if (uv && cam.intrinsics.InImage(*uv)) v.cameras.push_back(cam.channel);
    }
    v.visible = v.in_range && (f.cameras.empty() || !v.cameras.empty());
    return v;
  }

  // How far the ego gets: the largest arc length its box front reaches.
  double EgoReach() const { return path_.length() + opt_.ego_box.center().x() + 0.5 * opt_.ego_box.size.x(); }

 private:
  const Log& log_;
  const Scenario& scenario_;
  const SurfaceModel& surface_;
  size_t begin_, end_;
  const SequencePlanOptions& opt_;
  const EgoPath& path_;
  BoxGrid real_, ego_, placed_;
};

double DrawYaw(std::mt19937& rng, ObjectRequest::Yaw mode, double fixed_deg, double heading, double aligned_jitter_deg) {
  switch (mode) {
    case ObjectRequest::Yaw::kAligned: return heading + Uniform(rng, -aligned_jitter_deg, aligned_jitter_deg) * kDeg;
    case ObjectRequest::Yaw::kRandom: return Uniform(rng, -kPi, kPi);
    case ObjectRequest::Yaw::kFixed: return heading + fixed_deg * kDeg;
  }
  return heading;
}

double SideSign(Arrangement::Side side, std::mt19937& rng) {
  if (side == Arrangement::Side::kBoth) return Unit(rng) < 0.5 ? 1.0 : -1.0;
  return side == Arrangement::Side::kLeft ? 1.0 : -1.0;
}

}  // namespace

EgoPath::EgoPath(const std::vector<Rigid3d>& T_world_ego) {
  SD_CHECK(!T_world_ego.empty());
  knots_.push_back(T_world_ego.front().translation.head<2>());
  for (const auto& T : T_world_ego) {
    const Eigen::Vector2d p = T.translation.head<2>();
    if ((p - knots_.back()).norm() >= 1.0) knots_.push_back(p);
  }
  s_.push_back(0);
  if (knots_.size() == 1) {
    const double yaw = T_world_ego.front().Yaw();
    dir_.push_back(Eigen::Vector2d(std::cos(yaw), std::sin(yaw)));
    return;
  }
  for (size_t i = 0; i + 1 < knots_.size(); ++i) {
    const Eigen::Vector2d d = knots_[i + 1] - knots_[i];
    s_.push_back(s_.back() + d.norm());
    dir_.push_back(d.normalized());
  }
}

size_t EgoPath::Segment(double s) const {
  // Segment i spans [s_[i], s_[i+1]]; before the start: the first, beyond the end: the last (extended).
  const auto it = std::upper_bound(s_.begin(), s_.end(), s);
  const size_t i = it == s_.begin() ? 0 : static_cast<size_t>(it - s_.begin()) - 1;
  return std::min(i, dir_.size() - 1);
}

Eigen::Vector2d EgoPath::At(double s, double lateral) const {
  const size_t i = Segment(s);
  const Eigen::Vector2d& d = dir_[i];
  return knots_[i] + (s - s_[i]) * d + lateral * Eigen::Vector2d(-d.y(), d.x());
}

double EgoPath::Heading(double s) const {
  const Eigen::Vector2d& d = dir_[Segment(s)];
  return std::atan2(d.y(), d.x());
}

Eigen::Vector2d EgoPath::Project(const Eigen::Vector2d& xy) const {
  double best = std::numeric_limits<double>::infinity();
  Eigen::Vector2d out(0, 0);
  for (size_t i = 0; i < dir_.size(); ++i) {
    const Eigen::Vector2d& d = dir_[i];
    double t = (xy - knots_[i]).dot(d);
    const double len = i + 1 < s_.size() ? s_[i + 1] - s_[i] : 0.0;
    if (i > 0) t = std::max(t, 0.0);                 // the first segment extends backwards
    if (i + 1 < dir_.size()) t = std::min(t, len);   // the last extends forwards
    const Eigen::Vector2d foot = knots_[i] + t * d;
    const double dist = (xy - foot).norm();
    if (dist < best) {
      best = dist;
      const Eigen::Vector2d r = xy - foot;
      out = Eigen::Vector2d(s_[i] + t, d.x() * r.y() - d.y() * r.x());
    }
  }
  return out;
}

bool FootprintsOverlap(const Box3& a, const Box3& b, double margin) { return BoxesOverlap(Flat(a), Flat(b), margin); }

std::string PlanStats::Summary() const {
  return Msg() << candidates << " candidates tried: " << off_surface << " off the surface, " << off_drivable
               << " off the drivable area, " << in_ego_lane << " inside the ego lane, " << hits_ego_path
               << " in the ego vehicle's swept path, " << overlaps_real << " overlapping annotated objects (any frame), "
               << overlaps_placed << " overlapping inserted objects, " << never_visible << " seen in no frame";
}

SequencePlan PlanSequence(const Log& log, const Scenario& scenario, const SurfaceModel& surface, FrameRange range,
                          const SequencePlanOptions& options) {
  const size_t end = std::min(range.end, log.frames.size());
  if (range.begin >= end)
    throw InputError(log.source, Msg() << "empty frame range [" << range.begin << ", " << range.end << ") for a log of "
                                       << log.frames.size() << " frames");
  for (size_t k = range.begin; k + 1 < end; ++k) {
    const double gap = log.frames[k + 1].timestamp - log.frames[k].timestamp;
    if (!(gap >= 0 && gap <= options.max_frame_gap_s))
      throw InputError(log.source, Msg() << "frames " << k << " and " << k + 1 << " are " << gap
                                         << " s apart: not one sequence; plan a frame range within one sequence");
  }
  std::vector<Rigid3d> poses;
  for (size_t k = range.begin; k < end; ++k) poses.push_back(log.frames[k].T_world_ego);
  const EgoPath path(poses);

  SequencePlan plan;
  plan.frame_begin = range.begin;
  plan.frame_end = end;
  plan.seed = scenario.seed;
  plan.margin_m = scenario.margin_m;
  plan.ego_path_length_m = path.length();
  Planner planner(log, scenario, surface, range.begin, end, options, path);
  planner.BuildObstacles(&plan);
  if (!plan.unannotated_frames.empty())
    SD_LOG(Warn, plan.unannotated_frames.size() << " planned frames carry no boxes: placements are not checked against them");

  auto fail = [&](const std::string& what, const PlanStats& st) {
    throw InputError("", Msg() << "impossible scenario: " << st.source << " (" << what << ") has no valid placement: "
                               << st.Summary() << ". The ego travels " << path.length() << " m along its path in frames "
                               << range.begin << ".." << end - 1 << " (its front reaches s = " << planner.EgoReach()
                               << " m): objects in its lane must stand beyond that");
  };

  for (size_t ai = 0; ai < scenario.arrangements.size(); ++ai) {
    const Arrangement& a = scenario.arrangements[ai];
    PlanStats st;
    st.source = Msg() << "arrangements[" << ai << "]";
    std::seed_seq seq{scenario.seed, 1u, static_cast<uint32_t>(ai)};
    std::mt19937 rng(seq);
    const size_t first = plan.objects.size();
    using K = Arrangement::Kind;
    const double half_lane = 0.5 * a.lane_width_m;
    auto run = [&](const std::string& what, auto&& draw) {
      for (int t = 0; t < options.max_candidates; ++t) {
        std::vector<Slot> slots;
        if (!draw(&slots)) { ++st.candidates; ++st.in_ego_lane; continue; }
        if (planner.Try(slots, &a, &st, &plan.objects)) { ++st.placed; return; }
      }
      fail(what, st);
    };
    switch (a.kind) {
      case K::kLaneClosure: {
        const Resolved cone = Resolve(a.objects[0], options.assets, rng, st.source);
        const double start = a.lane_offset_m + (a.side == Arrangement::Side::kRight ? -half_lane : half_lane);
        const double stop = a.lane_offset_m + (a.side == Arrangement::Side::kRight ? half_lane : -half_lane);
        run(Msg() << "lane_closure of " << a.count << " " << a.objects[0].Describe(), [&](std::vector<Slot>* slots) {
          const double s0 = Uniform(rng, a.distance_min, a.distance_max);
          for (int i = 0; i < a.count; ++i) {
            const double s = s0 + i * a.spacing_m, t = static_cast<double>(i) / (a.count - 1);
            slots->push_back({&cone, "cone", s, (1 - t) * start + t * stop, DrawYaw(rng, a.yaw_mode, a.yaw_deg, path.Heading(s), 10)});
          }
          return true;
        });
        break;
      }
      case K::kEgoLaneObject: {
        const Resolved obj = Resolve(a.objects[0], options.assets, rng, st.source);
        run(Msg() << "ego_lane_object " << a.objects[0].Describe(), [&](std::vector<Slot>* slots) {
          const double s = Uniform(rng, a.distance_min, a.distance_max);
          slots->push_back({&obj, "object", s, a.lane_offset_m + Uniform(rng, a.lateral_min, a.lateral_max),
                            DrawYaw(rng, a.yaw_mode, a.yaw_deg, path.Heading(s), 10)});
          return true;
        });
        break;
      }
      case K::kRoadsideClutter: {
        for (int n = 0; n < a.count; ++n) {
          const Resolved what = Resolve(a.objects[static_cast<size_t>(Unit(rng) * static_cast<double>(a.objects.size())) % a.objects.size()],
                                        options.assets, rng, st.source);
          run(Msg() << "roadside_clutter object " << n + 1 << " of " << a.count << ", " << what.category, [&](std::vector<Slot>* slots) {
            const double s = Uniform(rng, a.distance_min, a.distance_max);
            const double lat = SideSign(a.side, rng) * Uniform(rng, a.lateral_min, a.lateral_max);
            const double heading = path.Heading(s);
            const double yaw = DrawYaw(rng, a.yaw_mode, a.yaw_deg, heading, 10);
            // The footprint's half extent across the path must clear the ego lane.
            const double rel = yaw - heading;
            const double half_across = 0.5 * (what.extent.x() * std::abs(std::sin(rel)) + what.extent.y() * std::abs(std::cos(rel)));
            if (std::abs(lat) - half_across < half_lane) return false;
            slots->push_back({&what, "clutter", s, lat, yaw});
            return true;
          });
        }
        break;
      }
      case K::kBreakdown: {
        const Resolved vehicle = Resolve(a.objects[0], options.assets, rng, st.source);
        const Resolved warning = Resolve(a.objects[1], options.assets, rng, st.source);
        const double sign = a.side == Arrangement::Side::kLeft ? 1.0 : -1.0;
        run(Msg() << "breakdown: " << a.objects[0].Describe() << " + " << a.objects[1].Describe(), [&](std::vector<Slot>* slots) {
          const double s = Uniform(rng, a.distance_min, a.distance_max);
          const double lat = a.lane_offset_m + (a.in_lane ? Uniform(rng, -0.3, 0.3)
                                                          : sign * (half_lane + 0.5 * vehicle.extent.y() + Uniform(rng, 0.1, 0.8)));
          slots->push_back({&vehicle, "vehicle", s, lat, DrawYaw(rng, a.yaw_mode, a.yaw_deg, path.Heading(s), 3)});
          // Behind = back along the traffic direction (the ego's), measured from the vehicle's rear.
          const double sw = s - 0.5 * vehicle.extent.x() - Uniform(rng, a.warning_distance_min, a.warning_distance_max);
          slots->push_back({&warning, "warning", sw, lat + Uniform(rng, -0.3, 0.3), WrapAngle(path.Heading(sw) + kPi)});
          return true;
        });
        break;
      }
    }
    for (size_t i = first; i < plan.objects.size(); ++i) {
      plan.objects[i].source = st.source;
      plan.objects[i].arrangement = static_cast<int>(ai);
    }
    plan.stats.push_back(st);
  }

  for (size_t ri = 0; ri < scenario.objects.size(); ++ri) {
    const ObjectRequest& req = scenario.objects[ri];
    PlanStats st;
    st.source = Msg() << "objects[" << ri << "]";
    std::seed_seq seq{scenario.seed, 2u, static_cast<uint32_t>(ri)};
    std::mt19937 rng(seq);
    const ObjectSpec spec{req.asset_id, req.category};
    for (int n = 0; n < req.count; ++n) {
      const size_t first = plan.objects.size();
      const Resolved what = Resolve(spec, options.assets, rng, st.source);
      bool done = false;
      for (int t = 0; t < options.max_candidates && !done; ++t) {
        const double s = Uniform(rng, req.distance_min, req.distance_max);
        const double lat = Uniform(rng, req.lateral_min, req.lateral_max);
        const std::vector<Slot> slots{{&what, "object", s, lat, DrawYaw(rng, req.yaw_mode, req.yaw_deg, path.Heading(s), 10)}};
        done = planner.Try(slots, nullptr, &st, &plan.objects);
      }
      if (!done) fail(Msg() << spec.Describe() << " #" << n + 1, st);
      ++st.placed;
      plan.objects[first].source = st.source;
      plan.objects[first].request = static_cast<int>(ri);
    }
    plan.stats.push_back(st);
  }

  for (size_t k = range.begin; k < end; ++k) {
    const Frame& f = log.frames[k];
    PlannedFrame pf;
    pf.frame_index = k;
    pf.token = f.token;
    pf.timestamp = f.timestamp;
    for (const auto& o : plan.objects) pf.objects.push_back(planner.View(f, o));
    plan.frames.push_back(std::move(pf));
  }
  return plan;
}

namespace {
// The pose codec's encoding plus its heading for people reading plan.json; readers of the pose ignore the extra key.
nlohmann::json PoseJson(const Rigid3d& T) {
  nlohmann::json j = Rigid3dJson(T);
  j["yaw_deg"] = T.Yaw() / kDeg;
  return j;
}
}  // namespace

nlohmann::json PlanToJson(const SequencePlan& plan) {
  nlohmann::json j;
  j["frames"] = {plan.frame_begin, plan.frame_end};
  j["seed"] = plan.seed;
  j["margin_m"] = plan.margin_m;
  j["ego_path_length_m"] = plan.ego_path_length_m;
  j["obstacles"] = {{"annotated_boxes", plan.annotated_boxes}, {"tracks", plan.tracks}, {"swept_boxes", plan.swept_boxes},
                    {"unannotated_frames", plan.unannotated_frames}};
  nlohmann::json objects = nlohmann::json::array();
  for (size_t i = 0; i < plan.objects.size(); ++i) {
    const PlannedObject& o = plan.objects[i];
    nlohmann::json jo = {{"index", i}, {"source", o.source}, {"role", o.role}, {"category", o.category},
                         {"asset", o.asset_id}, {"T_world_object", PoseJson(o.T_world_object)},
                         {"size", {o.box.size.x(), o.box.size.y(), o.box.size.z()}},
                         {"path_s_m", o.path_s}, {"path_lateral_m", o.path_lateral}};
    int frames_visible = 0;
    for (const auto& f : plan.frames) frames_visible += f.objects[i].visible ? 1 : 0;
    jo["frames_visible"] = frames_visible;
    objects.push_back(std::move(jo));
  }
  j["objects"] = std::move(objects);
  nlohmann::json frames = nlohmann::json::array();
  for (const PlannedFrame& f : plan.frames) {
    nlohmann::json views = nlohmann::json::array();
    for (size_t i = 0; i < f.objects.size(); ++i) {
      const PlannedView& v = f.objects[i];
      views.push_back({{"object", i}, {"T_ego_object", PoseJson(v.T_ego_object)}, {"distance_m", v.distance_m},
                       {"in_range", v.in_range}, {"cameras", v.cameras}, {"visible", v.visible}});
    }
    frames.push_back({{"frame", f.frame_index}, {"token", f.token}, {"timestamp", f.timestamp}, {"objects", std::move(views)}});
  }
  j["per_frame"] = std::move(frames);
  nlohmann::json stats = nlohmann::json::array();
  for (const PlanStats& s : plan.stats)
    stats.push_back({{"source", s.source}, {"placed", s.placed}, {"candidates", s.candidates}, {"off_surface", s.off_surface},
                     {"off_drivable", s.off_drivable}, {"in_ego_lane", s.in_ego_lane}, {"hits_ego_path", s.hits_ego_path},
                     {"overlaps_real", s.overlaps_real}, {"overlaps_placed", s.overlaps_placed},
                     {"never_visible", s.never_visible}});
  j["rejections"] = std::move(stats);
  return j;
}

}  // namespace sd
