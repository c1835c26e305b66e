// Scenario files (synth/scenario.h ReadScenario): keys, ranges, arrangements, bank queries as data.
// synth/scenario.cpp is compiled into the target on its own: the synth module's library links every stage
// (Embree, LibTorch, SQLite), and the scenario parser uses only core, io and datasets' categories. Seeds: the
// repo's scenarios and one using the keys they leave out (documented in scenario.h).
#include "fuzz/fuzz_support.h"
#include "synth/scenario.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  return sd::fuzz::ExpectOnlyInputErrors([&] {
    const std::filesystem::path scenario = sd::fuzz::FreshCaseDir() / "scenario.json";
    sd::fuzz::WriteBytes(scenario, sd::fuzz::AsText(data, size));
    sd::ReadScenario(scenario);
  });
}

std::vector<sd::fuzz::Seed> sd::fuzz::FuzzSeeds() {
  std::vector<Seed> seeds;
  for (const auto& e : std::filesystem::directory_iterator(RepoPath("data/scenarios")))
    if (e.path().extension() == ".json") seeds.push_back({e.path().filename().string(), ReadBytes(e.path())});
  seeds.push_back({"every-key.json", R"({
  "_comment": "keys the repo's scenarios leave out",
  "seed": 3, "margin_m": 1.5, "world_fixed": true,
  "sun": {"azimuth_deg": 120, "elevation_deg": 55},
  "assets_from_bank": [{"bank": "bank.sqlite", "category": "traffic_cone", "limit": 5}],
  "objects": [{"asset": "torcs_p406", "count": 1, "distance_m": [10, 30], "lateral_m": [-2, 2], "yaw": 90}],
  "arrangements": [
    {"type": "ego_lane_object", "category": "debris", "distance_m": [30, 60], "lateral_m": [-0.5, 0.5], "yaw": "random"},
    {"type": "roadside_clutter", "categories": ["traffic_cone", "debris"], "count": 5, "distance_m": [5, 60],
     "lateral_m": [2.5, 6], "side": "both"},
    {"type": "lane_closure", "category": "traffic_cone", "count": 6, "spacing_m": 3, "distance_m": [20, 40],
     "lane_width_m": 3.5, "lane_offset_m": 0, "side": "right"},
    {"type": "breakdown", "vehicle": "car", "warning": "warning_tripod", "position": "shoulder", "side": "right",
     "distance_m": [30, 60], "setting": "city"}]
})"});
  return seeds;
}
