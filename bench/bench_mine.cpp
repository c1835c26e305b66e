// bench_mine: asset mining (src/mining) — crawl + index throughput on real logs, label-mode retrieval
// correctness, and query latency / index size at scale on synthetic vectors.
//
//  1. Crawl + index: every log under ../shared/data/driving that has camera images (and the repo's data/driving)
//     is indexed into a fresh folder, `--repeat` times; the median seconds give crops/s (crop + mask + quality
//     figures + descriptor + files) and, with --clip DIR, CLIP embeddings/s for that model.
//  2. Label mode on those logs: for each prompt, every hit must be a box of the prompt's category (read back
//     from the log's own class name), and where the log has its own 2D box for that camera the crop's box2d is
//     compared with it (IoU).
//  3. Scale: synthetic embedding-like unit vectors (dimension --dim, default 512 as CLIP ViT-B/32; categories,
//     objects and views) written in the index's own on-disk format as shards of --shard-size rows, at each of
//     --sizes; reports bytes on disk, MiningIndex::Open seconds, and the median latency of one query and of a
//     batch of 16, top 10: exact (FAISS's inner-product kernel over the memory-mapped shards) and, from
//     kAnnMinRows vectors, through the approximate index (mining/ann.h: build seconds, size, recall@10 against
//     exact).
//
// Usage: bench_mine [--clip DIR] [--repeat N] [--sizes 10000,100000,1000000] [--dim 512] [--shard-size 50000]
//                   [--skip-crawl] [--skip-scale]
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <optional>
#include <random>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/log.h"
#include "datasets/categories.h"
#include "datasets/readers.h"
#include "io/files.h"
#include "io/json.h"
#include "mining/descriptor.h"
#include "mining/index.h"
#include "mining/item_table.h"
#include "mining/query.h"
#include "models/clip.h"

namespace {

namespace fs = std::filesystem;
using namespace sd;
using namespace sd::mining;
using Clock = std::chrono::steady_clock;

double Since(Clock::time_point t) { return std::chrono::duration<double>(Clock::now() - t).count(); }

double Median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
}

uint64_t DirBytes(const fs::path& dir) {
  uint64_t total = 0;
  for (const auto& e : fs::recursive_directory_iterator(dir))
    if (e.is_regular_file()) total += e.file_size();
  return total;
}

// The logs to crawl: each a path OpenLog accepts and whose first frame's camera images exist.
std::vector<fs::path> CrawlableLogs(const fs::path& root) {
  const std::vector<std::string> candidates = {
      "../shared/data/driving/nuscenes-scene0061-kf0/mmdet3d_info/n015-2018-07-24-11-22-45+0800.json",
      "../shared/data/driving/kitti-object-openpcdet",
      "../shared/data/driving/kitti-mmdet3d/tests/data/kitti/kitti_infos_train.json",
      "../shared/data/driving/lyft-mmdet3d-tests/lyft_infos.json",
      "data/driving/kitti-object",
      "data/driving/lyft-tables"};
  std::vector<fs::path> logs;
  for (const std::string& rel : candidates) {
    const fs::path p = root / rel;
    if (!fs::exists(p)) continue;
    try {
      const Log log = OpenLog(p);
      if (log.frames.empty() || log.frames[0].cameras.empty() || !fs::exists(log.frames[0].cameras[0].image_path))
        continue;
      logs.push_back(p);
    } catch (const InputError& e) {
      std::printf("  (skipped %s: %s)\n", rel.c_str(), e.what());
    }
  }
  return logs;
}

// Unit vectors with the structure of an embedding space: 200 categories, each of objects (one per 100 vectors
// of the index), each seen in many views. A view's cosine with its object's direction is about 0.9, objects of
// one category about 0.7, unrelated vectors about 0. Uniform random vectors, used before, have no neighbours
// worth the name: no approximate index finds their top 10 short of scanning them all.
class EmbeddingLikeVectors {
 public:
  EmbeddingLikeVectors(int dim, size_t objects, uint32_t seed) : dim_(dim), rng_(seed) {
    std::vector<std::vector<float>> categories;
    for (int c = 0; c < 200; ++c) categories.push_back(Unit(Noise(1.0 / std::sqrt(dim))));
    for (size_t o = 0; o < objects; ++o)
      objects_.push_back(Unit(Add(categories[o % categories.size()], Noise(1.0 / std::sqrt(dim)))));
  }
  // A view of a random object.
  void Next(float* out) {
    const auto& o = objects_[std::uniform_int_distribution<size_t>(0, objects_.size() - 1)(rng_)];
    const std::vector<float> v = Unit(Add(o, Noise(0.48 / std::sqrt(dim_))));
    std::copy(v.begin(), v.end(), out);
  }

 private:
  std::vector<float> Noise(double sigma) {
    std::normal_distribution<float> g(0, static_cast<float>(sigma));
    std::vector<float> v(dim_);
    for (float& x : v) x = g(rng_);
    return v;
  }
  static std::vector<float> Add(std::vector<float> a, const std::vector<float>& b) {
    for (size_t i = 0; i < a.size(); ++i) a[i] += b[i];
    return a;
  }
  static std::vector<float> Unit(std::vector<float> v) {
    double n = 0;
    for (float x : v) n += x * x;
    for (float& x : v) x = static_cast<float>(x / std::sqrt(n));
    return v;
  }
  int dim_;
  std::mt19937 rng_;
  std::vector<std::vector<float>> objects_;
};

// Writes `n` synthetic vectors into `dir` in the index's on-disk format (docs/mining.md), the vector files
// independently of index.cpp: shards of `shard_size` rows with minimal item records, embedding-like CLIP vectors
// and random descriptor vectors.
void WriteSyntheticIndex(const fs::path& dir, size_t n, int dim, size_t shard_size, EmbeddingLikeVectors& clip) {
  fs::create_directories(dir / "shards");
  WriteJsonFile(dir / "index.json", {{"format", "synthdrive-mine-index/1"},
                                     {"descriptor", {{"version", kDescriptorVersion}, {"dim", DescriptorDim()}}},
                                     {"clip", {{"model", "synthetic"}, {"dim", dim}}},
                                     {"chunk_size", 16}});
  std::mt19937 rng(7);
  std::normal_distribution<float> g;
  auto write_vectors = [](const fs::path& file, int d, size_t rows, const std::function<void(float*)>& next) {
    std::ofstream out(file, std::ios::binary);
    char header[32] = {'S', 'D', 'V', 'E', 'C', '0', '0', '1'};
    const uint32_t dd = d;
    const uint64_t nn = rows;
    std::memcpy(header + 8, &dd, 4);
    std::memcpy(header + 16, &nn, 8);
    out.write(header, 32);
    std::vector<float> row(d);
    for (size_t i = 0; i < rows; ++i) {
      next(row.data());
      out.write(reinterpret_cast<const char*>(row.data()), d * sizeof(float));
    }
  };
  auto random_unit = [&](float* row) {
    double norm = 0;
    for (int i = 0; i < DescriptorDim(); ++i) row[i] = g(rng), norm += row[i] * row[i];
    for (int i = 0; i < DescriptorDim(); ++i) row[i] = static_cast<float>(row[i] / std::sqrt(norm));
  };
  for (size_t first = 0, s = 0; first < n; first += shard_size, ++s) {
    const size_t rows = std::min(shard_size, n - first);
    char name[32];
    std::snprintf(name, sizeof name, "synthetic-%06zu", s);
    const fs::path shard = dir / "shards" / name;
    fs::create_directories(shard);
    std::vector<MinedItem> items;
    items.reserve(rows);
    for (size_t i = 0; i < rows; ++i) {
      MinedItem item;
      item.id = StableId(std::to_string(first + i));
      item.kind = SourceKind::kUrl;
      item.source = "synthetic";
      item.origin = "https://example.invalid/" + std::to_string(first + i) + ".jpg";
      item.box2d = item.crop_rect = Box2{0, 0, 256, 256};
      item.crop_width = item.crop_height = 256;
      item.crop_file = "crops/" + item.id + ".jpg";
      items.push_back(std::move(item));
    }
    WriteItemTable(shard, items);  // items.jsonl and its table, as `mine index` writes them
    write_vectors(shard / "vectors-clip.f32", dim, rows, [&](float* row) { clip.Next(row); });
    write_vectors(shard / "vectors-descriptor.f32", DescriptorDim(), rows, random_unit);
    WriteJsonFile(shard / "chunk.json", {{"source", "synthetic"}, {"kind", "url"}, {"begin", first}, {"end", first + rows},
                                         {"items", rows}, {"failures", nlohmann::json::array()}});
  }
}

}  // namespace

int main(int argc, char** argv) {
  std::string clip_dir;
  int repeat = 3, dim = 512;
  size_t shard_size = 50000;
  std::vector<size_t> sizes = {10000, 100000, 1000000};
  bool crawl = true, scale = true;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    auto next = [&]() -> std::string {
      if (i + 1 >= argc) {
        std::fprintf(stderr, "bench_mine: %s needs a value\n", a.c_str());
        std::exit(2);
      }
      return argv[++i];
    };
    if (a == "--clip") {
      clip_dir = next();
    } else if (a == "--repeat") {
      repeat = std::max(1, std::atoi(next().c_str()));
    } else if (a == "--dim") {
      dim = std::max(1, std::atoi(next().c_str()));
    } else if (a == "--shard-size") {
      shard_size = std::max(1, std::atoi(next().c_str()));
    } else if (a == "--sizes") {
      sizes.clear();
      std::stringstream ss(next());
      for (std::string s; std::getline(ss, s, ',');) sizes.push_back(std::stoull(s));
    } else if (a == "--skip-crawl") {
      crawl = false;
    } else if (a == "--skip-scale") {
      scale = false;
    } else {
      std::fprintf(stderr, "bench_mine: unknown argument %s\n", a.c_str());
      return 2;
    }
  }
  const char* env = std::getenv("SYNTHDRIVE_SOURCE_DIR");
  const fs::path root = env ? fs::path(env) : fs::weakly_canonical(fs::path(argv[0])).parent_path().parent_path().parent_path();
  SetLogLevel(LogLevel::kWarn);
  const fs::path work = fs::temp_directory_path() / ("bench_mine-" + std::to_string(::getpid()));
  fs::create_directories(work);
  nlohmann::json results;

  try {
    if (crawl) {
      std::optional<models::ClipEncoder> clip;
      if (!clip_dir.empty()) clip = models::ClipEncoder::Load(clip_dir);
      const std::vector<fs::path> logs = CrawlableLogs(root);
      std::printf("crawl + index (%d runs, median) over %zu logs:\n", repeat, logs.size());
      for (const fs::path& l : logs) std::printf("  %s\n", fs::relative(l, root).c_str());
      std::vector<double> total_s, crop_s, embed_s;
      size_t items = 0, frames = 0;
      for (const fs::path& l : logs) frames += OpenLog(l).frames.size();
      for (int r = 0; r < repeat; ++r) {
        fs::remove_all(work / "index");
        IndexBuildOptions o;
        for (const fs::path& l : logs) o.sources.push_back({SourceKind::kLog, l});
        o.progress = false;
        o.clip = clip ? &*clip : nullptr;
        const IndexBuildReport rep = BuildIndex(work / "index", o);
        total_s.push_back(rep.seconds);
        crop_s.push_back(rep.crop_seconds);
        embed_s.push_back(rep.embed_seconds);
        items = rep.items;
      }
      const uint64_t bytes = DirBytes(work / "index");
      std::printf("  %zu frames -> %zu object crops; total %.2f s (%.1f crops/s), crop+describe+write %.2f s "
                  "(%.1f crops/s)",
                  frames, items, Median(total_s), items / Median(total_s), Median(crop_s), items / Median(crop_s));
      if (clip) std::printf(", CLIP %.2f s (%.1f embeddings/s, %s)", Median(embed_s), items / Median(embed_s),
                            clip->Describe().c_str());
      std::printf("; index %.1f MB\n\n", bytes / 1e6);
      results["crawl"] = {{"logs", logs.size()}, {"frames", frames}, {"crops", items},
                          {"seconds", Median(total_s)}, {"crop_seconds", Median(crop_s)},
                          {"embed_seconds", Median(embed_s)}, {"bytes", bytes}};

      // Label-mode correctness.
      const MiningIndex index = MiningIndex::Open(work / "index");
      std::printf("label mode (no filters, k = all):\n%-16s %6s %8s %10s %14s\n", "prompt", "hits", "correct",
                  "with 2D", "IoU 2D median");
      for (const std::string prompt : {"traffic cone", "barrier", "pedestrian", "car", "bicycle"}) {
        QueryOptions q;
        q.prompts = {prompt};
        q.k = static_cast<int>(index.size());
        q.min_size_px = 0;
        q.max_truncation = 1;
        q.max_occlusion = 1;
        q.min_sharpness = 0;
        q.max_hash_distance = -1;
        q.max_per_frame = q.max_per_instance = 0;
        const PromptResult r = RunQuery(index, q)[0];
        size_t correct = 0;
        std::vector<double> ious;
        for (const QueryHit& h : r.hits) {
          const MinedItem& item = index.item(h.row);
          const auto c = FindCategory(item.dataset_category);
          correct += c && c->name == r.category && item.box_ego.has_value();
          if (item.annotated_box2d) ious.push_back(IoU(item.box2d, *item.annotated_box2d));
        }
        std::printf("%-16s %6zu %8zu %10zu %14.3f\n", prompt.c_str(), r.hits.size(), correct, ious.size(),
                    Median(ious));
        results["label"][prompt] = {{"hits", r.hits.size()}, {"correct", correct}, {"with_2d", ious.size()},
                                    {"iou_2d_median", Median(ious)}};
      }
      std::printf("\n");
    }

    if (scale) {
      std::printf("scale (synthetic embedding-like vectors, D = %d, shards of %zu, top 10; median of 20 after one "
                  "warm-up; recall@10 of the approximate search against the exact one over 200 queries):\n",
                  dim, shard_size);
      std::printf("%10s %8s %10s %10s | %9s %9s %9s | %8s %8s %8s %9s %9s %9s %8s\n", "vectors", "shards", "MB on disk",
                  "MB vectors", "exact open", "1 q ms", "16 q ms", "ANN build", "vec/s", "MB ANN", "open s", "1 q ms",
                  "16 q ms", "recall");
      for (size_t n : sizes) {
        const fs::path dir = work / ("scale-" + std::to_string(n));
        EmbeddingLikeVectors clip(dim, std::max<size_t>(1, n / 100), 7);
        WriteSyntheticIndex(dir, n, dim, shard_size, clip);
        uint64_t vec_bytes = 0;
        for (const auto& e : fs::recursive_directory_iterator(dir))
          if (e.path().filename() == "vectors-clip.f32") vec_bytes += e.file_size();
        // Queries: new views of the index's objects (a prompt or an example close to some of them).
        const int nq = 200;
        std::vector<float> q(static_cast<size_t>(nq) * dim);
        for (int i = 0; i < nq; ++i) clip.Next(q.data() + static_cast<size_t>(i) * dim);
        struct Timing {
          double open_s = 0, one_ms = 0, batch_ms = 0;
          std::vector<std::vector<SearchHit>> top10;
        };
        auto measure = [&](SearchMode mode) {
          Timing t;
          const auto t_open = Clock::now();
          const MiningIndex index = MiningIndex::Open(dir);
          t.open_s = Since(t_open);
          index.Search(VectorKind::kClip, q.data(), 1, 10, mode);  // page the vectors in once: steady-state latency
          std::vector<double> one, batch;
          for (int r = 0; r < 20; ++r) {
            auto t0 = Clock::now();
            index.Search(VectorKind::kClip, q.data() + (r % 16) * dim, 1, 10, mode);
            one.push_back(Since(t0) * 1e3);
            t0 = Clock::now();
            index.Search(VectorKind::kClip, q.data(), 16, 10, mode);
            batch.push_back(Since(t0) * 1e3);
          }
          t.one_ms = Median(one);
          t.batch_ms = Median(batch);
          t.top10 = index.Search(VectorKind::kClip, q.data(), nq, 10, mode);
          return t;
        };
        const Timing exact = measure(SearchMode::kExact);
        nlohmann::json row = {{"bytes", DirBytes(dir)}, {"vector_bytes", vec_bytes}, {"open_s", exact.open_s},
                              {"query_ms", exact.one_ms}, {"batch16_ms", exact.batch_ms}};
        std::printf("%10zu %8zu %10.1f %10.1f | %9.2f %9.2f %9.2f |", n, (n + shard_size - 1) / shard_size,
                    DirBytes(dir) / 1e6, vec_bytes / 1e6, exact.open_s, exact.one_ms, exact.batch_ms);
        if (n >= kAnnMinRows) {
          AnnBuildReport built;
          const auto t_build = Clock::now();
          {
            const MiningIndex index = MiningIndex::Open(dir);
            built = BuildAnn(dir, "clip", dim, index.ShardVectors(VectorKind::kClip));
          }
          const double build_s = Since(t_build);
          const uint64_t ann_bytes = fs::file_size(dir / "ann" / "clip.faiss");
          const Timing ann = measure(SearchMode::kAuto);
          double found = 0;
          for (int i = 0; i < nq; ++i)
            for (const SearchHit& h : ann.top10[i])
              found += std::count_if(exact.top10[i].begin(), exact.top10[i].end(), [&](const SearchHit& e) { return e.row == h.row; });
          const double recall = found / (10.0 * nq);
          std::printf(" %8.1f %8.0f %8.1f %8.2f %9.2f %9.2f %8.3f\n", build_s, n / build_s, ann_bytes / 1e6, ann.open_s,
                      ann.one_ms, ann.batch_ms, recall);
          row["ann"] = {{"type", "IVF-PQ"},        {"nlist", built.params.nlist}, {"m", built.params.m},
                        {"nprobe", built.params.nprobe}, {"train_rows", built.params.train_rows},
                        {"train_s", built.train_seconds}, {"add_s", built.add_seconds}, {"build_s", build_s},
                        {"bytes", ann_bytes},       {"open_s", ann.open_s},     {"query_ms", ann.one_ms},
                        {"batch16_ms", ann.batch_ms}, {"recall_at_10", recall}, {"queries", nq}};
        } else {
          std::printf(" (exact only below %zu vectors)\n", kAnnMinRows);
        }
        results["scale"][std::to_string(n)] = row;
        fs::remove_all(dir);
      }
    }
  } catch (const std::exception& e) {
    std::fprintf(stderr, "bench_mine: %s\n", e.what());
    fs::remove_all(work);
    return 1;
  }
  fs::remove_all(work);
  fs::create_directories(root / "bench" / "results");
  WriteJsonFile(root / "bench" / "results" / "mine.json", results);
  return 0;
}
