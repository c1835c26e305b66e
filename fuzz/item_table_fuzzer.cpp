// An index shard's records as `MiningIndex::Open` reads them (mining/item_table.h ItemTable): its items.bin table
// and the items.jsonl lines it points into, then every row's summary and record. mining/item.cpp and
// item_table.cpp are compiled into the target on their own (the mining module's library pulls in FAISS, libcurl
// and the model runtime). Input: an archive of the two files (fuzz_support.h). Seeds: shards WriteItemTable
// writes for a log hit and a folder image, and the same lines without a table.
#include "fuzz/fuzz_support.h"
#include "fuzz/mined_item_seeds.h"
#include "mining/item_table.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  return sd::fuzz::ExpectOnlyInputErrors([&] {
    const std::filesystem::path dir = sd::fuzz::FreshCaseDir();
    sd::fuzz::WriteArchive(sd::fuzz::UnpackArchive(sd::fuzz::AsText(data, size)), dir);
    const sd::mining::ItemTable table = sd::mining::ItemTable::Open(dir);
    for (size_t row = 0; row < table.size(); ++row) {
      (void)table.summary(row);
      (void)table.item(row);
    }
  });
}

std::vector<sd::fuzz::Seed> sd::fuzz::FuzzSeeds() {
  const std::filesystem::path dir = FreshCaseDir();
  sd::mining::WriteItemTable(dir, {SeedLogHit(), SeedFolderImage()});
  const std::string lines = ReadBytes(dir / "items.jsonl"), table = ReadBytes(dir / "items.bin");
  return {{"shard.archive", PackArchive({{"items.jsonl", lines}, {"items.bin", table}})},
          {"lines-only.archive", PackArchive({{"items.jsonl", lines}})}};
}
