// JSON text: ParseJsonText (io/json.h), the one parser behind every JSON file and JSON line, then the raw-text
// scanner (io/raw_json.h) the dataset writers splice derivatives with, walked over what the parser accepted
// (the writers only splice text that parsed).
#include <functional>

#include "fuzz/fuzz_support.h"
#include "io/json.h"
#include "io/raw_json.h"

namespace {

void WalkRaw(const sd::RawJson& raw, sd::Span value, int depth) {
  if (depth > sd::kMaxJsonDepth) return;
  if (raw.IsArray(value)) {
    for (const sd::Span element : raw.Elements(value)) WalkRaw(raw, element, depth + 1);
  } else if (raw.IsObject(value)) {
    for (const sd::RawMember& member : raw.Members(value)) WalkRaw(raw, member.value, depth + 1);
    raw.Member(value, "data_list");
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  return sd::fuzz::ExpectOnlyInputErrors([&] {
    const std::string_view text = sd::fuzz::AsText(data, size);
    sd::ParseJsonText(text, "fuzz.json");
    const sd::RawJson raw{std::string(text), "fuzz.json"};
    const sd::Span root = raw.Root();
    WalkRaw(raw, root, 0);
    const sd::JsonStyle style = raw.Style();
    if (raw.IsArray(root) || raw.IsObject(root))
      sd::ApplySplices(raw, root, {sd::AppendItems(raw, root, {{"fuzz", sd::ojson{{"added", 1}}}}, style)});
  });
}

std::vector<sd::fuzz::Seed> sd::fuzz::FuzzSeeds() {
  std::vector<Seed> seeds;
  for (const char* file : {"data/scenarios/demo.json", "data/scenarios/pandaset_closure.json",
                           "data/driving/nuscenes-scene0061-kf0/v1.0-subset/calibrated_sensor.json",
                           "data/driving/nuscenes-scene0061-kf0/v1.0-subset/sample_data.json",
                           "data/driving/lyft-tables/v1.01-train/v1.01-train/sample_annotation.json",
                           "data/assets/metadrive_traffic_cone/scene.gltf"})
    seeds.push_back({std::filesystem::path(file).filename().string(), ReadBytes(RepoPath(file))});
  return seeds;
}
