#include "mining/ann.h"

#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <set>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "core/error.h"
#include "io/files.h"
#include "io/json.h"
#include "mining/descriptor.h"
#include "mining/index.h"
#include "mining/item_table.h"

namespace sd::mining {
namespace {

namespace fs = std::filesystem;

constexpr int kDim = 64;

// Unit vectors around 150 random directions (an embedding space has structure; uniform random vectors have no
// neighbours worth the name, and no approximate index finds them).
class ClusteredVectors {
 public:
  explicit ClusteredVectors(uint32_t seed) : rng_(seed) {
    for (int c = 0; c < 150; ++c) centres_.push_back(Unit(Gaussian(1.0)));
  }
  std::vector<float> Next() {
    std::vector<float> v = centres_[std::uniform_int_distribution<size_t>(0, centres_.size() - 1)(rng_)];
    const std::vector<float> noise = Gaussian(0.06);
    for (int i = 0; i < kDim; ++i) v[i] += noise[i];
    return Unit(v);
  }

 private:
  std::vector<float> Gaussian(double sigma) {
    std::normal_distribution<float> g(0, static_cast<float>(sigma));
    std::vector<float> v(kDim);
    for (float& x : v) x = g(rng_);
    return v;
  }
  static std::vector<float> Unit(std::vector<float> v) {
    double n = 0;
    for (float x : v) n += x * x;
    for (float& x : v) x = static_cast<float>(x / std::sqrt(n));
    return v;
  }
  std::mt19937 rng_;
  std::vector<std::vector<float>> centres_;
};

void WriteVectorFile(const fs::path& path, int dim, const std::vector<float>& rows) {
  std::string bytes(32 + rows.size() * sizeof(float), '\0');
  std::memcpy(bytes.data(), "SDVEC001", 8);
  const uint32_t d = static_cast<uint32_t>(dim);
  const uint64_t n = rows.size() / dim;
  std::memcpy(bytes.data() + 8, &d, 4);
  std::memcpy(bytes.data() + 16, &n, 8);
  std::memcpy(bytes.data() + 32, rows.data(), rows.size() * sizeof(float));
  WriteFileAtomic(path, bytes);
}

class AnnTest : public ::testing::Test {
 protected:
  void SetUp() override {
    dir_ = fs::temp_directory_path() / ("sd_ann_" + std::string(::testing::UnitTest::GetInstance()->current_test_info()->name()));
    fs::remove_all(dir_);
    fs::create_directories(dir_ / "shards");
    WriteJsonFile(dir_ / "index.json", {{"format", "synthdrive-mine-index/1"},
                                        {"descriptor", {{"version", kDescriptorVersion}, {"dim", DescriptorDim()}}},
                                        {"clip", {{"model", "synthetic"}, {"dim", kDim}}},
                                        {"chunk_size", 16}});
  }
  void TearDown() override { fs::remove_all(dir_); }

  // A shard of `rows` items in the index's on-disk format; its CLIP vectors are returned.
  std::vector<float> AddShard(const std::string& name, size_t rows) {
    const fs::path shard = dir_ / "shards" / name;
    fs::create_directories(shard);
    std::vector<MinedItem> items(rows);
    std::vector<float> clip, descriptor(rows * DescriptorDim(), 0.f);
    for (size_t i = 0; i < rows; ++i) {
      items[i].id = StableId(name + std::to_string(i));
      items[i].kind = SourceKind::kUrl;
      items[i].source = "synthetic";
      items[i].origin = "https://example.invalid/" + name + "/" + std::to_string(i);
      items[i].box2d = items[i].crop_rect = Box2{0, 0, 64, 64};
      items[i].crop_width = items[i].crop_height = 64;
      const std::vector<float> v = vectors_.Next();
      clip.insert(clip.end(), v.begin(), v.end());
      descriptor[i * DescriptorDim()] = 1.f;
    }
    WriteItemTable(shard, items);
    WriteVectorFile(shard / "vectors-clip.f32", kDim, clip);
    WriteVectorFile(shard / "vectors-descriptor.f32", DescriptorDim(), descriptor);
    WriteJsonFile(shard / "chunk.json", {{"source", "synthetic"}, {"kind", "url"}, {"begin", 0}, {"end", rows}, {"items", rows}});
    return clip;
  }

  fs::path dir_;
  ClusteredVectors vectors_{5};
};

TEST(AnnParams, GrowWithTheIndexAndFitTheDimension) {
  const AnnParams small = ChooseAnnParams(20000, 512), large = ChooseAnnParams(1000000, 512);
  EXPECT_EQ(small.m, 128);  // a byte of code per four floats
  EXPECT_EQ(512 % large.m, 0);
  EXPECT_EQ(ChooseAnnParams(100000, 380).m, 95);  // the descriptor's 380 = 95 x 4
  EXPECT_GE(small.nlist, 64);
  EXPECT_EQ(large.nlist, 1024);
  EXPECT_EQ(large.nprobe, 32);
  EXPECT_GE(large.train_rows, 10000u);
  EXPECT_LE(small.train_rows, 20000u);
}

TEST_F(AnnTest, FindsTheExactTopTenAndScoresExactlyAndSeesShardsAddedLater) {
  AddShard("a", 9000);
  AddShard("b", 7000);
  AddShard("c", 8000);
  {
    const MiningIndex index = MiningIndex::Open(dir_);
    EXPECT_EQ(index.ann(VectorKind::kClip), nullptr);
    EXPECT_TRUE(AnnNeedsBuild(dir_, "clip", kDim, index.ShardVectors(VectorKind::kClip), 10000));
    EXPECT_FALSE(AnnNeedsBuild(dir_, "clip", kDim, index.ShardVectors(VectorKind::kClip), 100000));  // small: exact
    const AnnBuildReport r = BuildAnn(dir_, "clip", kDim, index.ShardVectors(VectorKind::kClip));
    EXPECT_EQ(r.rows, 24000u);
    EXPECT_FALSE(AnnNeedsBuild(dir_, "clip", kDim, index.ShardVectors(VectorKind::kClip), 10000));
  }
  const MiningIndex index = MiningIndex::Open(dir_);
  ASSERT_NE(index.ann(VectorKind::kClip), nullptr);
  EXPECT_EQ(index.ann(VectorKind::kClip)->covered_rows(), 24000u);
  ClusteredVectors queries(99);
  double found = 0;
  const int nq = 100;
  std::vector<float> q;
  for (int i = 0; i < nq; ++i) {
    const auto v = queries.Next();
    q.insert(q.end(), v.begin(), v.end());
  }
  const auto approx = index.Search(VectorKind::kClip, q.data(), nq, 10);
  const auto exact = index.Search(VectorKind::kClip, q.data(), nq, 10, SearchMode::kExact);
  for (int i = 0; i < nq; ++i) {
    ASSERT_EQ(approx[i].size(), 10u);
    std::set<size_t> truth;
    for (const SearchHit& h : exact[i]) truth.insert(h.row);
    for (const SearchHit& h : approx[i]) {
      found += truth.count(h.row);
      // The returned score is the exact cosine of that row, not the codes' estimate.
      float dot = 0;
      for (int j = 0; j < kDim; ++j) dot += q[i * kDim + j] * index.vector(VectorKind::kClip, h.row)[j];
      EXPECT_NEAR(h.score, dot, 1e-5);
    }
  }
  const double recall = found / (10.0 * nq);
  EXPECT_GE(recall, 0.95) << recall;

  // A shard added after the build is searched exactly: its own vectors come back first.
  const std::vector<float> added = AddShard("d", 3000);
  const MiningIndex grown = MiningIndex::Open(dir_);
  ASSERT_NE(grown.ann(VectorKind::kClip), nullptr);
  EXPECT_FALSE(grown.ann(VectorKind::kClip)->covers()[3]);
  for (size_t row : {size_t{0}, size_t{1234}, size_t{2999}}) {
    const auto hit = grown.Search(VectorKind::kClip, added.data() + row * kDim, 1, 1)[0];
    ASSERT_EQ(hit.size(), 1u);
    EXPECT_EQ(grown.item(hit[0].row).id, StableId("d" + std::to_string(row)));
  }
  EXPECT_FALSE(AnnNeedsBuild(dir_, "clip", kDim, grown.ShardVectors(VectorKind::kClip), 10000));  // 3k of 24k
  AddShard("e", 4000);
  const MiningIndex more = MiningIndex::Open(dir_);
  EXPECT_TRUE(AnnNeedsBuild(dir_, "clip", kDim, more.ShardVectors(VectorKind::kClip), 10000));  // 7k of 24k
}

TEST_F(AnnTest, AStaleIndexIsIgnoredAndACorruptOneRefused) {
  AddShard("a", 6000);
  AddShard("b", 6000);
  {
    const MiningIndex index = MiningIndex::Open(dir_);
    BuildAnn(dir_, "clip", kDim, index.ShardVectors(VectorKind::kClip));
  }
  // A covered shard gone: the approximate index no longer describes the index; search is exact, and complete.
  fs::rename(dir_ / "shards" / "b", dir_ / "b-away");
  {
    const MiningIndex index = MiningIndex::Open(dir_);
    EXPECT_EQ(index.ann(VectorKind::kClip), nullptr);
    EXPECT_EQ(index.size(), 6000u);
    EXPECT_TRUE(AnnNeedsBuild(dir_, "clip", kDim, index.ShardVectors(VectorKind::kClip), 1000));
  }
  fs::rename(dir_ / "b-away", dir_ / "shards" / "b");
  // The codes cut short or altered: refused before FAISS reads them, naming the file.
  const std::string codes = ReadFileToString(dir_ / "ann" / "clip.faiss");
  for (const std::string& broken : {codes.substr(0, codes.size() / 2), std::string(codes).replace(100, 4, "XXXX")}) {
    WriteFileAtomic(dir_ / "ann" / "clip.faiss", broken);
    try {
      MiningIndex::Open(dir_);
      FAIL() << "corrupt codes were accepted";
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("clip.faiss"), std::string::npos) << e.what();
    }
  }
}

}  // namespace
}  // namespace sd::mining
