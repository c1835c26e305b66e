// Mining records (mining/item.h ItemFromJson), read line by line as the mining manifest (manifest.jsonl) and the
// index shards store them (io/json.h ForEachJsonLine). mining/item.cpp is compiled into the target on its own:
// the mining module's library pulls in FAISS, libcurl and the model runtime, which the record parser does not
// use. Seeds: records ToJson writes for a log hit and a folder image, as the mining run writes them.
#include "fuzz/fuzz_support.h"
#include "io/json.h"
#include "fuzz/mined_item_seeds.h"
#include "mining/item.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  return sd::fuzz::ExpectOnlyInputErrors([&] {
    const std::filesystem::path manifest = sd::fuzz::FreshCaseDir() / "manifest.jsonl";
    sd::fuzz::WriteBytes(manifest, sd::fuzz::AsText(data, size));
    sd::ForEachJsonLine(manifest, [](const nlohmann::json& value, const std::string& where) {
      sd::mining::ItemFromJson(value, where);
    });
  });
}

std::vector<sd::fuzz::Seed> sd::fuzz::FuzzSeeds() {
  const sd::mining::MinedItem log_hit = SeedLogHit(), folder_image = SeedFolderImage();
  const std::string manifest =
      sd::mining::ToJson(log_hit).dump() + "\n" + sd::mining::ToJson(folder_image).dump() + "\n";
  return {{"log-hit.jsonl", sd::mining::ToJson(log_hit).dump() + "\n"}, {"manifest.jsonl", manifest}};
}
