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
  std::vector<nlohmann::json> bank_queries;  // "assets_from_bank", resolved by the pipeline (synth/pipeline.h)
};

// InputError naming the file for malformed JSON, unknown fields' bad values, count < 1, empty ranges.
Scenario ReadScenario(const std::filesystem::path& path);

}  // namespace sd
