// An index shard's records as `MiningIndex::Open` reads them (mining/item_table.h ItemTable): its items.bin table
// and the items.jsonl lines it points into, then every row's summary and record. mining/item.cpp and
// item_table.cpp are compiled into the target on their own (the mining module's library pulls in FAISS, libcurl
// and the model runtime). Input: an archive of the two files (fuzz_support.h). Seeds: shards WriteItemTable
// writes for a log hit and a folder image, and the same lines without a table.
#include "fuzz/fuzz_support.h"
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
  using sd::mining::MinedItem;
  MinedItem log_hit;
  log_hit.id = "3f9a0c1d2e4b5a69";
  log_hit.source = "data/driving/nuscenes-scene0061-kf0/mmdet3d_info/n015-2018-07-24-11-22-45+0800.json";
  log_hit.origin = "samples/CAM_FRONT/n015-2018-07-24-11-22-45+0800__CAM_FRONT__1532402927612460.jpg";
  log_hit.category = "traffic_cone";
  log_hit.dataset_category = "movable_object.trafficcone";
  log_hit.camera = "CAM_FRONT";
  log_hit.box2d = Box2{702.5, 401, 758.25, 479.5};
  log_hit.crop_rect = Box2{680, 380, 780, 500};
  log_hit.crop_width = log_hit.crop_height = 128;
  log_hit.truncation = 0;
  log_hit.occlusion = 0.1;
  log_hit.sharpness = 143.5;
  log_hit.crop_file = "crops/3f9a0c1d2e4b5a69.jpg";
  MinedItem folder_image;
  folder_image.id = "77aa";
  folder_image.kind = sd::mining::SourceKind::kFolder;
  folder_image.source = "data/images/roadanomaly-cones";
  folder_image.origin = "data/images/roadanomaly-cones/frames/a.jpg";
  folder_image.box2d = folder_image.crop_rect = Box2{0, 0, 640, 360};
  folder_image.crop_width = 640;
  folder_image.crop_height = 360;
  folder_image.crop_file = "crops/77aa.jpg";
  const std::filesystem::path dir = FreshCaseDir();
  sd::mining::WriteItemTable(dir, {log_hit, folder_image});
  const std::string lines = ReadBytes(dir / "items.jsonl"), table = ReadBytes(dir / "items.bin");
  return {{"shard.archive", PackArchive({{"items.jsonl", lines}, {"items.bin", table}})},
          {"lines-only.archive", PackArchive({{"items.jsonl", lines}})}};
}
