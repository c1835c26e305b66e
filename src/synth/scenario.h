#pragma once
// Scenario files: what to insert where. JSON, for example
//   {
//     "seed": 7,
//     "margin_m": 0.5,
//     "sun": {"azimuth_deg": 120, "elevation_deg": 55},     // optional; "auto" or absent = from the log
//     "location": {"latitude_deg": 1.2966, "longitude_deg": 103.787},  // optional; for the sun ephemeris
//                                                       // when the log does not say where it was recorded
//     "objects": [
//       {"category": "traffic_cone", "count": 3, "distance_m": [8, 25], "lateral_m": [-5, 5], "yaw": "random"},
//       {"asset": "torcs_p406", "count": 1, "distance_m": [10, 30], "yaw": "aligned"}
//     ]
//   }
// An object names either an asset id (one of the --asset folders) or a category (any --asset of that
// category, picked by the seed). The assets can also come from the bank instead of (or besides) --asset:
//     "assets_from_bank": {"bank": "bank.sqlite", "category": "traffic_cone", "min_quality": {...}, "limit": 5}
// (one query or a list of them, in the JSON shape of bank/bank.h BankQueryFromJson; a relative bank path is
// relative to the scenario file, no "bank" means $SYNTHDRIVE_BANK or ./bank.sqlite). distance_m is along the ego x axis (ahead), lateral_m along ego y (left).
// yaw: "aligned" (along the ego heading, +-10 deg), "random", or a number in degrees in the ego frame.
// By default each keyframe places its own objects; "world_fixed": true plans them once per sequence instead
// (distances then along the ego path, as for arrangements), so an object stays put across the frames.
//
// Arrangements: scenes placed ONCE in the world frame for a whole sequence (synth/sequence_plan.h,
// docs/sequence_placement.md), positioned along the ego path of the planned frames: distances are metres of
// arc length along the path from the first planned frame's ego position (beyond the path's ends it continues
// straight), lateral offsets are metres left (+) of the path. The ego lane is centred on the path.
//     "arrangements": [
//       {"type": "lane_closure", "category": "traffic_cone", "count": 6, "spacing_m": 3, "distance_m": [20, 40],
//        "lane_width_m": 3.5, "lane_offset_m": 0, "side": "right"},
//       {"type": "ego_lane_object", "category": "debris", "distance_m": [30, 60], "lateral_m": [-0.5, 0.5], "yaw": "random"},
//       {"type": "roadside_clutter", "categories": ["traffic_cone", "debris"], "count": 5, "distance_m": [5, 60],
//        "lateral_m": [2.5, 6], "side": "both"},
//       {"type": "breakdown", "vehicle": "car", "warning": "warning_tripod", "position": "shoulder", "side": "right",
//        "distance_m": [30, 60], "setting": "city"}
//     ]
// Objects are canonical categories (datasets/categories.h; any dataset spelling is accepted and normalised) or,
// as {"asset": "id"}, asset ids. "objects" may be empty when "arrangements" is not (the per-frame pipeline then
// inserts nothing by itself).
#include <filesystem>
#include <optional>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "datasets/log.h"

namespace sd {

struct ObjectRequest {
  std::string asset_id;   // exactly one of asset_id / category is set
  std::string category;
  int count = 1;
  double distance_min = 6, distance_max = 30;  // metres ahead (ego x)
  double lateral_min = -6, lateral_max = 6;    // metres left (ego y)
  enum class Yaw { kAligned, kRandom, kFixed } yaw_mode = Yaw::kAligned;
  double yaw_deg = 0;
};

// One thing to place: an asset id or a canonical category (exactly one is set).
struct ObjectSpec {
  std::string asset_id;
  std::string category;
  std::string Describe() const;  // "category 'car'" / "asset 'x'"
};

// A sequence-level arrangement (see the file comment for the JSON). Lengths in metres, along / left of the ego
// path of the planned frames.
struct Arrangement {
  enum class Kind { kLaneClosure, kEgoLaneObject, kRoadsideClutter, kBreakdown };
  enum class Side { kLeft, kRight, kBoth };
  Kind kind = Kind::kEgoLaneObject;
  // lane_closure: {cone}; ego_lane_object: {object}; roadside_clutter: the pool, one drawn per object by the seed;
  // breakdown: {vehicle, warning}.
  std::vector<ObjectSpec> objects;
  int count = 1;  // lane_closure: cones (>= 2, default 6); roadside_clutter: objects (default 5); otherwise 1
  // Arc length from the first planned frame's ego position: lane_closure: the first cone; ego_lane_object: the
  // object; roadside_clutter: every object; breakdown: the vehicle's centre.
  double distance_min = 20, distance_max = 40;
  // ego_lane_object: centre offset from the lane centre (default +-0.5); roadside_clutter: |offset| of the
  // object's centre from the path (default 2.5..6, each object also clear of the ego lane).
  double lateral_min = 0, lateral_max = 0;
  double lane_width_m = 3.5;
  double lane_offset_m = 0;  // the lane's centre left of the path (3.5: the lane to the left of the ego's)
  double spacing_m = 3.0;    // lane_closure: arc length between consecutive cones
  // lane_closure: the lane edge the taper starts from (it ends at the other edge; traffic is pushed to the
  // other side). roadside_clutter: which side(s). breakdown: the shoulder side. kBoth only for clutter.
  Side side = Side::kRight;
  bool in_lane = false;  // breakdown: vehicle stopped in the lane (true) or on the shoulder beside it (false)
  // breakdown: from the vehicle's rear to the warning, back along the traffic direction (the ego's direction
  // of travel). "setting": "city" -> 10..50 m, "highway" -> 30..100 m (typical regulations), or explicit.
  double warning_distance_min = 10, warning_distance_max = 50;
  bool allow_shoulder = false;  // may stand where the surface exists but is not drivable (kerb, shoulder)
  ObjectRequest::Yaw yaw_mode = ObjectRequest::Yaw::kAligned;  // relative to the path heading
  double yaw_deg = 0;
};
const char* ToString(Arrangement::Kind kind);  // the JSON "type"

struct SunSpec {
  double azimuth_deg = 0;    // in the ego frame, counter-clockwise from ego +x (forward)
  double elevation_deg = 0;  // above the horizon
};

struct Scenario {
  uint32_t seed = 1;
  double margin_m = 0.5;  // clearance to real objects and between inserted ones
  std::optional<SunSpec> sun;
  std::optional<GeoLocation> location;  // overrides the log's location for the sun ephemeris
  std::vector<ObjectRequest> objects;
  std::vector<Arrangement> arrangements;  // sequence planning only (synth/sequence_plan.h)
  // "world_fixed": true plans plain objects once per sequence too (as arrangements always are): each is placed
  // once in the world frame and appears at that place in every frame (synth/synth_plan.h PlanSynthesis).
  bool world_fixed = false;
  std::vector<nlohmann::json> bank_queries;  // "assets_from_bank", resolved with the request (synth/request.h)
};

// InputError naming the file for malformed JSON, unknown fields' bad values, count < 1, empty ranges, neither
// objects nor arrangements, unknown arrangement types / categories / sides.
Scenario ReadScenario(const std::filesystem::path& path);

}  // namespace sd
