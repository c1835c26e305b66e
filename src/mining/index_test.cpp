#include "mining/index.h"

#include <gtest/gtest.h>

#include <atomic>
#include <fstream>
#include <map>
#include <random>
#include <set>
#include <thread>

#include <nlohmann/json.hpp>

#include "core/error.h"
#include "datasets/categories.h"
#include "io/files.h"
#include "io/image_io.h"
#include "io/json.h"
#include "mining/descriptor.h"
#include "mining/query.h"
#include "models/clip.h"
#include "testing/http_server.h"
#include "testing/testing.h"

namespace sd::mining {
namespace {

namespace fs = std::filesystem;
using sd::testing::TempDir;

// A coloured disc on a noisy grey background: sharp edges and texture, so it passes the quality filters, and
// a known dominant colour for the colour-space CLIP test model.
ImageU8 Disc(int size, const std::array<uint8_t, 3>& colour, uint32_t seed, bool alpha = false) {
  std::mt19937 rng(seed);
  std::uniform_int_distribution<int> noise(-20, 20);
  ImageU8 img(size, size, alpha ? 4 : 3);
  const double r = size * (0.25 + 0.1 * (seed % 3)), cx = size * 0.5 + seed % 7, cy = size * 0.5 - seed % 5;
  for (int y = 0; y < size; ++y)
    for (int x = 0; x < size; ++x) {
      const bool in = (x + 0.5 - cx) * (x + 0.5 - cx) + (y + 0.5 - cy) * (y + 0.5 - cy) < r * r;
      for (int c = 0; c < 3; ++c) {
        const int base = in ? colour[c] : 128;
        img.at(x, y, c) = static_cast<uint8_t>(std::clamp(base + noise(rng), 0, 255));
      }
      if (alpha) img.at(x, y, 3) = in ? 255 : 0;
    }
  return img;
}

// Crops of a real camera image: distinct content, for retrieval and duplicate tests.
std::vector<ImageU8> RealCrops(int n, int size) {
  const ImageU8 cam = ReadImage(sd::testing::RepoData("driving/nuscenes-scene0061-kf0/samples/CAM_FRONT") /
                                    fs::directory_iterator(sd::testing::RepoData(
                                        "driving/nuscenes-scene0061-kf0/samples/CAM_FRONT"))->path().filename(),
                                3);
  std::vector<ImageU8> crops;
  for (int i = 0; i < n; ++i) {
    const int x0 = (i * 97) % (cam.width() - size), y0 = 200 + (i * 53) % (cam.height() - size - 200);
    ImageU8 c(size, size, 3);
    for (int y = 0; y < size; ++y)
      for (int x = 0; x < size; ++x)
        for (int k = 0; k < 3; ++k) c.at(x, y, k) = cam.at(x0 + x, y0 + y, k);
    crops.push_back(c);
  }
  return crops;
}

void WriteFolder(const fs::path& dir, const std::vector<ImageU8>& images, const std::string& stem) {
  fs::create_directories(dir);
  for (size_t i = 0; i < images.size(); ++i)
    WriteImage(dir / (stem + std::to_string(100 + i) + ".png"), images[i]);
}

IndexBuildOptions FolderOptions(const std::vector<fs::path>& folders, int chunk = 4) {
  IndexBuildOptions o;
  for (const auto& f : folders) o.sources.push_back({SourceKind::kFolder, f});
  o.chunk_size = chunk;
  o.progress = false;
  return o;
}

std::set<std::string> Ids(const MiningIndex& index) {
  std::set<std::string> ids;
  for (size_t i = 0; i < index.size(); ++i) ids.insert(index.item(i).id);
  return ids;
}

TEST(MiningIndex, FolderRoundTripStoresCropsMasksAndSearchableVectors) {
  TempDir tmp;
  std::vector<ImageU8> images = RealCrops(9, 96);
  images.push_back(Disc(80, {220, 30, 30}, 1, /*alpha=*/true));
  WriteFolder(tmp / "imgs", images, "img");
  const IndexBuildReport report = BuildIndex(tmp / "index", FolderOptions({tmp / "imgs"}));
  EXPECT_EQ(report.chunks_total, 3u);  // 10 images in chunks of 4
  EXPECT_EQ(report.chunks_built, 3u);
  EXPECT_EQ(report.items, 10u);
  EXPECT_EQ(report.failures, 0u);

  const MiningIndex index = MiningIndex::Open(tmp / "index");
  ASSERT_EQ(index.size(), 10u);
  EXPECT_EQ(index.shard_count(), 3u);
  EXPECT_FALSE(index.has_clip());
  EXPECT_EQ(index.dim(VectorKind::kDescriptor), DescriptorDim());
  int with_alpha = 0;
  for (size_t row = 0; row < index.size(); ++row) {
    const MinedItem& item = index.item(row);
    EXPECT_EQ(item.kind, SourceKind::kFolder);
    const ImageU8 crop = ReadImage(index.ItemDir(row) / item.crop_file);
    EXPECT_EQ(crop.width(), item.crop_width);
    EXPECT_EQ(crop.height(), item.crop_height);
    EXPECT_GT(item.sharpness, 0);
    // The stored vector is the descriptor of the crop (before JPEG: within JPEG noise of the stored file).
    const ImageU8 mask = item.mask_file.empty() ? ImageU8() : ReadImage(index.ItemDir(row) / item.mask_file, 1);
    const std::vector<float> d = ImageDescriptor(crop, mask.empty() ? nullptr : &mask);
    const float* v = index.vector(VectorKind::kDescriptor, row);
    double dot = 0;
    for (int i = 0; i < DescriptorDim(); ++i) dot += d[i] * v[i];
    EXPECT_GT(dot, 0.97) << item.origin;
    EXPECT_LE(HammingDistance(item.phash, PerceptualHash(crop)), 4) << item.origin;
    // Each item is its own nearest neighbour, with cosine 1.
    const auto hits = index.Search(VectorKind::kDescriptor, v, 1, 3)[0];
    ASSERT_EQ(hits.size(), 3u);
    EXPECT_EQ(hits[0].row, row);
    EXPECT_NEAR(hits[0].score, 1.0, 1e-4);
    EXPECT_GE(hits[0].score, hits[1].score);
    if (item.mask_source == "alpha") {
      ++with_alpha;
      // The disc's alpha becomes the mask, and box2d is its bounding box.
      EXPECT_LT(item.box2d.x2 - item.box2d.x1, 80 * 0.85);
      EXPECT_GT(item.box2d.x2 - item.box2d.x1, 80 * 0.45);
    }
  }
  EXPECT_EQ(with_alpha, 1);
}

TEST(MiningIndex, GrowsIncrementallyResumesAndSplitsIntoShards) {
  TempDir tmp;
  WriteFolder(tmp / "a", RealCrops(6, 64), "a");
  WriteFolder(tmp / "b", RealCrops(5, 72), "b");
  BuildIndex(tmp / "index", FolderOptions({tmp / "a"}, 2));
  // Adding a folder embeds only its own chunks.
  const IndexBuildReport add = BuildIndex(tmp / "index", FolderOptions({tmp / "a", tmp / "b"}, 2));
  EXPECT_EQ(add.chunks_total, 6u);
  EXPECT_EQ(add.chunks_skipped, 3u);
  EXPECT_EQ(add.chunks_built, 3u);
  const std::set<std::string> all = Ids(MiningIndex::Open(tmp / "index"));
  EXPECT_EQ(all.size(), 11u);
  // The run log has one line per owned chunk and run: 3 built, then 3 skipped and 3 built.
  std::vector<std::string> built, skipped;
  ForEachJsonLine(tmp / "index" / "logs" / "index-0-of-1.jsonl", [&](const nlohmann::json& j, const std::string&) {
    (j["status"] == "done" ? built : skipped).push_back(j["chunk"].get<std::string>());
    EXPECT_TRUE(j["status"] == "done" || j["status"] == "skipped") << j.dump();
  });
  EXPECT_EQ(built.size(), 6u);
  EXPECT_EQ(skipped.size(), 3u);

  // A killed run: one shard missing, a staging folder left behind. The rerun rebuilds just that chunk, and an
  // open index never sees the staging folder.
  std::vector<fs::path> shards;
  for (const auto& e : fs::directory_iterator(tmp / "index" / "shards")) shards.push_back(e.path());
  std::sort(shards.begin(), shards.end());
  fs::rename(shards[1], fs::path(shards[1].string() + ".tmp-999999-0"));
  EXPECT_EQ(MiningIndex::Open(tmp / "index").size(), 11u - 2u);
  const IndexBuildReport resume = BuildIndex(tmp / "index", FolderOptions({tmp / "a", tmp / "b"}, 2));
  EXPECT_EQ(resume.chunks_built, 1u);
  EXPECT_EQ(resume.chunks_skipped, 5u);
  EXPECT_FALSE(fs::exists(shards[1].string() + ".tmp-999999-0"));
  EXPECT_EQ(Ids(MiningIndex::Open(tmp / "index")), all);

  // Two shard processes build the same index between them.
  for (int k = 0; k < 2; ++k) {
    IndexBuildOptions o = FolderOptions({tmp / "a", tmp / "b"}, 2);
    o.shard = ShardSpec{k, 2};
    const IndexBuildReport r = BuildIndex(tmp / "split", o);
    EXPECT_EQ(r.chunks_owned, 3u);
  }
  EXPECT_EQ(Ids(MiningIndex::Open(tmp / "split")), all);
}

// Shard processes started at the same moment all find no index yet: every one must succeed, with one header.
TEST(MiningIndex, ShardsCreatingTheSameNewIndexTogetherAllSucceed) {
  TempDir tmp;
  WriteFolder(tmp / "a", RealCrops(8, 48), "a");
  for (int round = 0; round < 5; ++round) {
    const fs::path out = tmp / ("index" + std::to_string(round));
    std::atomic<int> ready{0}, failed{0};
    std::vector<std::thread> shards;
    for (int k = 0; k < 4; ++k)
      shards.emplace_back([&, k] {
        IndexBuildOptions o = FolderOptions({tmp / "a"}, 2);
        o.shard = ShardSpec{k, 4};
        ++ready;
        while (ready < 4) std::this_thread::yield();
        try {
          BuildIndex(out, o);
        } catch (const std::exception& e) {
          ++failed;
          ADD_FAILURE() << "shard " << k << ": " << e.what();
        }
      });
    for (std::thread& t : shards) t.join();
    EXPECT_EQ(failed, 0);
    EXPECT_EQ(MiningIndex::Open(out).size(), 8u);
    for (const auto& e : fs::directory_iterator(out))
      EXPECT_TRUE(e.path().filename() == "index.json" || e.path().filename() == "shards" ||
                  e.path().filename() == "logs")
          << e.path();
  }
}

TEST(MiningIndex, BadInputIsRefusedWithoutPartialOutput) {
  TempDir tmp;
  WriteFolder(tmp / "a", RealCrops(3, 64), "a");
  // A missing source: nothing is created.
  IndexBuildOptions o = FolderOptions({tmp / "a", tmp / "missing"});
  EXPECT_THROW(BuildIndex(tmp / "index", o), InputError);
  EXPECT_FALSE(fs::exists(tmp / "index"));
  // A non-empty folder that is not an index is never written into.
  fs::create_directories(tmp / "busy");
  std::ofstream(tmp / "busy" / "notes.txt") << "mine";
  EXPECT_THROW(BuildIndex(tmp / "busy", FolderOptions({tmp / "a"})), InputError);
  // A corrupt image is recorded and the rest of the folder is indexed.
  std::ofstream(tmp / "a" / "broken.png") << "not a png";
  const IndexBuildReport r = BuildIndex(tmp / "index", FolderOptions({tmp / "a"}));
  EXPECT_EQ(r.items, 3u);
  EXPECT_EQ(r.failures, 1u);
  // A truncated vector file and a malformed record are named on open.
  fs::path shard;
  for (const auto& e : fs::directory_iterator(tmp / "index" / "shards")) shard = e.path();
  const std::string vectors = ReadFileToString(shard / "vectors-descriptor.f32");
  WriteFileAtomic(shard / "vectors-descriptor.f32", vectors.substr(0, vectors.size() - 4));
  try {
    MiningIndex::Open(tmp / "index");
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("vectors-descriptor.f32"), std::string::npos) << e.what();
  }
  WriteFileAtomic(shard / "vectors-descriptor.f32", vectors);
  const std::string items = ReadFileToString(shard / "items.jsonl");
  WriteFileAtomic(shard / "items.jsonl", items + "{\"id\": 3\n");
  try {
    MiningIndex::Open(tmp / "index");
    FAIL() << "expected InputError";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("items.jsonl:4"), std::string::npos) << e.what();
  }
  EXPECT_THROW(MiningIndex::Open(tmp / "nothing"), InputError);
}

// A URL list where some downloads fail: the good images are indexed, each failure is recorded in its chunk with
// the reason, and a rerun fetches nothing again (the chunks are done).
TEST(MiningIndex, UrlListFailuresAreRecordedWithoutLosingTheRest) {
  using sd::testing::LoopbackHttpServer;
  const std::vector<ImageU8> crops = RealCrops(4, 96);
  std::vector<std::string> bodies;
  for (const ImageU8& c : crops) bodies.push_back(EncodeImage(c, "png"));
  LoopbackHttpServer server([&](LoopbackHttpServer&, int fd, const std::string& target, int) {
    using L = LoopbackHttpServer;
    for (size_t i = 0; i < bodies.size(); ++i)
      if (target == "/img" + std::to_string(i) + ".png") {
        L::SendAll(fd, L::Response(200, "OK", "image/png", bodies[i]));
        return;
      }
    if (target == "/page") L::SendAll(fd, L::Response(200, "OK", "text/html", "<html></html>"));
    else if (target == "/hang") L::WaitForClose(fd);
    else if (target == "/garbage") L::SendAll(fd, L::Response(200, "OK", "image/png", "not a png"));
    else L::SendAll(fd, L::Response(404, "Not Found", "text/plain", "no"));
  });
  TempDir tmp;
  std::ofstream list(tmp / "urls.txt");
  list << "# test list\n";
  for (const char* t : {"/img0.png", "/missing", "/img1.png", "/page", "/hang", "/img2.png", "/garbage", "/img3.png"})
    list << server.Url(t) << "\n";
  list.close();
  IndexBuildOptions o;
  o.sources = {{SourceKind::kUrl, tmp / "urls.txt"}};
  o.chunk_size = 3;
  o.progress = false;
  o.fetch.stall_timeout_s = 0.5;
  o.fetch.total_timeout_s = 3;
  o.fetch.retries = 0;
  const IndexBuildReport r = BuildIndex(tmp / "index", o);
  EXPECT_EQ(r.chunks_built, 3u);
  EXPECT_EQ(r.items, 4u);
  EXPECT_EQ(r.failures, 4u);
  std::map<std::string, std::string> errors;
  for (const auto& e : fs::directory_iterator(tmp / "index" / "shards")) {
    const nlohmann::json chunk = ReadJsonFile(e.path() / "chunk.json");  // named: the loop must not outlive it
    for (const auto& f : chunk["failures"]) errors[f["origin"].get<std::string>()] = f["error"].get<std::string>();
  }
  EXPECT_EQ(errors[server.Url("/missing")], "HTTP 404");
  EXPECT_NE(errors[server.Url("/page")].find("content type text/html"), std::string::npos);
  EXPECT_NE(errors[server.Url("/hang")].find("no data for"), std::string::npos);
  EXPECT_EQ(errors[server.Url("/garbage")], "not a decodable image");
  const MiningIndex index = MiningIndex::Open(tmp / "index");
  ASSERT_EQ(index.size(), 4u);
  for (size_t row = 0; row < index.size(); ++row) {
    EXPECT_EQ(index.item(row).kind, SourceKind::kUrl);
    EXPECT_EQ(index.item(row).origin.rfind(server.Url("/img"), 0), 0u);
  }
  const int hits = server.Hits("/img0.png");
  EXPECT_EQ(BuildIndex(tmp / "index", o).chunks_built, 0u);
  EXPECT_EQ(server.Hits("/img0.png"), hits);
}

TEST(MiningQuery, PromptsNameCategories) {
  EXPECT_EQ(CategoryForPrompt("traffic cone"), "traffic_cone");
  EXPECT_EQ(CategoryForPrompt("orange traffic cone on a road"), "traffic_cone");
  EXPECT_EQ(CategoryForPrompt("movable_object.trafficcone"), "traffic_cone");
  EXPECT_EQ(CategoryForPrompt("Pedestrian"), "pedestrian");
  EXPECT_EQ(CategoryForPrompt("construction vehicle"), "construction_vehicle");
  EXPECT_EQ(CategoryForPrompt("a purple elephant"), "");
}

TEST(MiningQuery, ExampleModeDedupesAndKeepsDiversity) {
  TempDir tmp;
  std::vector<ImageU8> images = RealCrops(8, 96);
  const ImageU8 red = Disc(96, {230, 20, 20}, 4);
  images.push_back(red);
  images.push_back(red);  // an exact copy under another name: a near-duplicate
  images.push_back(Disc(96, {20, 20, 230}, 5));
  WriteFolder(tmp / "imgs", images, "img");
  BuildIndex(tmp / "index", FolderOptions({tmp / "imgs"}));
  const MiningIndex index = MiningIndex::Open(tmp / "index");
  WriteImage(tmp / "query.png", Disc(96, {235, 25, 25}, 6));

  QueryOptions o;
  o.examples = {tmp / "query.png"};
  o.k = 3;
  o.min_example_score = 0.0;
  o.min_size_px = 0;
  std::vector<PromptResult> r = RunQuery(index, o);
  ASSERT_EQ(r.size(), 1u);
  EXPECT_EQ(r[0].mode, QueryMode::kExample);
  ASSERT_EQ(r[0].hits.size(), 3u);
  // The red disc first, its copy removed as a duplicate, and the scores descending.
  EXPECT_EQ(fs::path(index.item(r[0].hits[0].row).origin).filename().string().substr(0, 6), "img108");
  EXPECT_GE(r[0].rejected_duplicate, 1u);
  for (size_t i = 1; i < r[0].hits.size(); ++i) EXPECT_LE(r[0].hits[i].score, r[0].hits[i - 1].score);
  for (const QueryHit& h : r[0].hits)
    EXPECT_NE(fs::path(index.item(h.row).origin).filename(), "img109.png");

  // Without dedupe the copy comes straight back at rank 2.
  o.max_hash_distance = -1;
  r = RunQuery(index, o);
  EXPECT_EQ(fs::path(index.item(r[0].hits[1].row).origin).filename(), "img109.png");

  // A prompt naming no category, on an index without CLIP vectors: a clear error.
  QueryOptions text;
  text.prompts = {"purple elephant"};
  EXPECT_THROW(RunQuery(index, text), InputError);
}

TEST(MiningQuery, RunFolderRoundTripsThroughTheManifest) {
  TempDir tmp;
  std::vector<ImageU8> images = RealCrops(4, 96);
  images.push_back(Disc(96, {230, 20, 20}, 2, true));
  WriteFolder(tmp / "imgs", images, "img");
  BuildIndex(tmp / "index", FolderOptions({tmp / "imgs"}));
  const MiningIndex index = MiningIndex::Open(tmp / "index");
  WriteImage(tmp / "query.png", Disc(96, {230, 20, 20}, 3, true));  // a cut-out: its alpha is the mask
  QueryOptions o;
  o.examples = {tmp / "query.png"};
  o.k = 2;
  o.min_example_score = 0;
  o.min_size_px = 0;
  const auto results = RunQuery(index, o);
  WriteMiningRun(tmp / "run", index, results, o, false);
  EXPECT_THROW(WriteMiningRun(tmp / "run", index, results, o, false), InputError);  // never overwritten silently
  const std::vector<ManifestEntry> entries = ReadManifest(tmp / "run" / "manifest.jsonl");
  ASSERT_EQ(entries.size(), results[0].hits.size());
  for (size_t i = 0; i < entries.size(); ++i) {
    const MinedItem& want = index.item(results[0].hits[i].row);
    EXPECT_EQ(entries[i].item.id, want.id);
    EXPECT_EQ(entries[i].rank, static_cast<int>(i) + 1);
    EXPECT_EQ(entries[i].mode, "example");
    EXPECT_TRUE(fs::exists(entries[i].item.crop_file));
    EXPECT_EQ(ReadFileToString(entries[i].item.crop_file),
              ReadFileToString(index.ItemDir(results[0].hits[i].row) / want.crop_file));
  }
  EXPECT_EQ(entries[0].item.mask_source, "alpha");
  EXPECT_TRUE(fs::exists(entries[0].item.mask_file));
  EXPECT_TRUE(fs::exists(tmp / "run" / "index.html"));
  const nlohmann::json run = ReadJsonFile(tmp / "run" / "run.json");
  EXPECT_EQ(run["prompts"][0]["hits"], entries.size());

  // A manifest naming a crop that is gone is refused with the file and line.
  fs::remove(entries[1].item.crop_file);
  try {
    ReadManifest(tmp / "run" / "manifest.jsonl");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("manifest.jsonl:2"), std::string::npos) << e.what();
  }
}

// Label mode on a real nuScenes keyframe: every hit is a box of the prompt's category, passes the filters, and
// no tracked object appears twice.
TEST(MiningQuery, LabelModeOnARealLogReturnsOnlyThatCategory) {
  TempDir tmp;
  IndexBuildOptions bo;
  bo.sources = {{SourceKind::kLog,
                 sd::testing::RepoData("driving/nuscenes-scene0061-kf0/mmdet3d_info/n015-2018-07-24-11-22-45+0800.json")}};
  bo.progress = false;
  const IndexBuildReport rep = BuildIndex(tmp / "index", bo);
  EXPECT_GT(rep.items, 50u);
  const MiningIndex index = MiningIndex::Open(tmp / "index");
  size_t total = 0;
  for (const std::string prompt : {"traffic cone", "car", "pedestrian", "barrier"}) {
    QueryOptions q;
    q.prompts = {prompt};
    q.k = 100;
    q.min_size_px = 20;
    const PromptResult r = RunQuery(index, q)[0];
    EXPECT_EQ(r.mode, QueryMode::kLabel);
    std::set<std::string> instances;
    for (const QueryHit& h : r.hits) {
      const MinedItem& item = index.item(h.row);
      const auto c = FindCategory(item.dataset_category);
      ASSERT_TRUE(c.has_value()) << item.dataset_category;
      EXPECT_EQ(c->name, r.category) << prompt;
      EXPECT_TRUE(item.box_ego.has_value());
      EXPECT_GE(ObjectSizePx(item), 20);
      EXPECT_LE(item.truncation, q.max_truncation);
      EXPECT_TRUE(item.occlusion < 0 || item.occlusion <= q.max_occlusion);
      EXPECT_TRUE(instances.insert(item.source + item.instance_token).second || item.instance_token.empty());
      if (h.rank > 1) {
        EXPECT_LE(h.quality, r.hits[h.rank - 2].quality + 1e-12);
      }
    }
    std::printf("%s: %zu hits of %zu candidates\n", prompt.c_str(), r.hits.size(), r.candidates);
    total += r.hits.size();
  }
  EXPECT_GT(total, 5u);
}

// CLIP mode end to end with a tiny model whose embedding space is colour (tools/testing/
// make_mining_test_models.py): "red ..." must find the red discs, "blue ..." the blue one.
TEST(MiningQuery, ClipModeRanksByTextImageSimilarity) {
  SD_REQUIRE_TEST_MODEL(dir, "clip_colour");
  const models::ClipEncoder clip = models::ClipEncoder::Load(dir);
  TempDir tmp;
  std::vector<ImageU8> images;
  for (uint32_t s = 0; s < 3; ++s) images.push_back(Disc(96, {230, 30, 30}, 10 + s));
  images.push_back(Disc(96, {30, 30, 230}, 20));
  images.push_back(Disc(96, {30, 200, 30}, 21));
  for (const ImageU8& c : RealCrops(4, 96)) images.push_back(c);
  WriteFolder(tmp / "imgs", images, "img");
  IndexBuildOptions bo = FolderOptions({tmp / "imgs"});
  bo.clip = &clip;
  BuildIndex(tmp / "index", bo);
  const MiningIndex index = MiningIndex::Open(tmp / "index");
  ASSERT_TRUE(index.has_clip());
  EXPECT_EQ(index.clip_model(), clip.Describe());
  EXPECT_EQ(index.dim(VectorKind::kClip), 4);

  QueryOptions o;
  o.prompts = {"red disc", "blue disc"};
  o.k = 3;
  o.min_clip_score = 0.5;
  o.min_size_px = 0;
  o.clip = &clip;
  const auto r = RunQuery(index, o);
  ASSERT_EQ(r.size(), 2u);
  EXPECT_EQ(r[0].mode, QueryMode::kClip);
  ASSERT_EQ(r[0].hits.size(), 3u);
  for (const QueryHit& h : r[0].hits) {
    const std::string name = fs::path(index.item(h.row).origin).filename().string();
    EXPECT_TRUE(name == "img100.png" || name == "img101.png" || name == "img102.png") << name;
    EXPECT_GT(h.score, 0.5);
  }
  ASSERT_GE(r[1].hits.size(), 1u);
  EXPECT_EQ(fs::path(index.item(r[1].hits[0].row).origin).filename(), "img103.png");

  // Vectors of another model cannot be added to, or searched with, this index.
  EXPECT_THROW(BuildIndex(tmp / "index", FolderOptions({tmp / "imgs"})), InputError);
}

}  // namespace
}  // namespace sd::mining
