// bench_mine: asset mining (src/mining) — crawl + index throughput on real logs, label-mode retrieval
// correctness, and query latency / index size at scale on synthetic vectors.
//
//  1. Crawl + index: every log under ../shared/data/driving that has camera images (and the repo's data/driving)
//     is indexed into a fresh folder, `--repeat` times; the median seconds give crops/s (crop + mask + quality
//     figures + descriptor + files) and, with --clip DIR, CLIP embeddings/s for that model.
//  2. Label mode on those logs: for each prompt, every hit must be a box of the prompt's category (read back
//     from the log's own class name), and where the log has its own 2D box for that camera the crop's box2d is
//     compared with it (IoU).
//  3. Scale: synthetic unit vectors (dimension --dim, default 512 as CLIP ViT-B/32) written in the index's own
//     on-disk format as shards of --shard-size rows, at each of --sizes; reports bytes on disk, MiningIndex::Open
//     seconds, and the median latency of one query and of a batch of 16 (exact FAISS inner-product search
//     over the memory-mapped shards, top 50).
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

// Writes `n` synthetic unit vectors into `dir` in the index's on-disk format (docs/mining.md), independently of
// index.cpp: shards of `shard_size` rows with minimal item records and descriptor vectors.
void WriteSyntheticIndex(const fs::path& dir, size_t n, int dim, size_t shard_size) {
  fs::create_directories(dir / "shards");
  WriteJsonFile(dir / "index.json", {{"format", "synthdrive-mine-index/1"},
                                     {"descriptor", {{"version", kDescriptorVersion}, {"dim", DescriptorDim()}}},
                                     {"clip", {{"model", "synthetic"}, {"dim", dim}}},
                                     {"chunk_size", 16}});
  std::mt19937 rng(7);
  std::normal_distribution<float> g;
  auto write_vectors = [](const fs::path& file, int d, size_t rows, std::mt19937& r, std::normal_distribution<float>& nd) {
    std::ofstream out(file, std::ios::binary);
    char header[32] = {'S', 'D', 'V', 'E', 'C', '0', '0', '1'};
    const uint32_t dd = d;
    const uint64_t nn = rows;
    std::memcpy(header + 8, &dd, 4);
    std::memcpy(header + 16, &nn, 8);
    out.write(header, 32);
    std::vector<float> row(d);
    for (size_t i = 0; i < rows; ++i) {
      double norm = 0;
      for (float& v : row) v = nd(r), norm += v * v;
      for (float& v : row) v = static_cast<float>(v / std::sqrt(norm));
      out.write(reinterpret_cast<const char*>(row.data()), d * sizeof(float));
    }
  };
  for (size_t first = 0, s = 0; first < n; first += shard_size, ++s) {
    const size_t rows = std::min(shard_size, n - first);
    char name[32];
    std::snprintf(name, sizeof name, "synthetic-%06zu", s);
    const fs::path shard = dir / "shards" / name;
    fs::create_directories(shard);
    std::ofstream items(shard / "items.jsonl");
    for (size_t i = 0; i < rows; ++i) {
      MinedItem item;
      item.id = StableId(std::to_string(first + i));
      item.kind = SourceKind::kUrl;
      item.source = "synthetic";
      item.origin = "https://example.invalid/" + std::to_string(first + i) + ".jpg";
      item.box2d = item.crop_rect = Box2{0, 0, 256, 256};
      item.crop_width = item.crop_height = 256;
      item.crop_file = "crops/" + item.id + ".jpg";
      items << ToJson(item).dump() << "\n";
    }
    write_vectors(shard / "vectors-clip.f32", dim, rows, rng, g);
    write_vectors(shard / "vectors-descriptor.f32", DescriptorDim(), rows, rng, g);
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
      std::printf("scale (synthetic unit vectors, D = %d, shards of %zu, exact search, top 50; median of 20):\n", dim,
                  shard_size);
      std::printf("%10s %8s %10s %10s %10s %12s %14s\n", "vectors", "shards", "MB on disk", "MB vectors", "open s",
                  "1 query ms", "16 queries ms");
      for (size_t n : sizes) {
        const fs::path dir = work / ("scale-" + std::to_string(n));
        WriteSyntheticIndex(dir, n, dim, shard_size);
        uint64_t vec_bytes = 0;
        for (const auto& e : fs::recursive_directory_iterator(dir))
          if (e.path().filename() == "vectors-clip.f32") vec_bytes += e.file_size();
        const auto t_open = Clock::now();
        const MiningIndex index = MiningIndex::Open(dir);
        const double open_s = Since(t_open);
        std::mt19937 rng(11);
        std::normal_distribution<float> g;
        std::vector<float> q(16 * dim);
        for (float& v : q) v = g(rng);
        for (int i = 0; i < 16; ++i) {
          double norm = 0;
          for (int j = 0; j < dim; ++j) norm += q[i * dim + j] * q[i * dim + j];
          for (int j = 0; j < dim; ++j) q[i * dim + j] = static_cast<float>(q[i * dim + j] / std::sqrt(norm));
        }
        index.Search(VectorKind::kClip, q.data(), 1, 50);  // page the vectors in once: steady-state latency
        std::vector<double> one, batch;
        for (int r = 0; r < 20; ++r) {
          auto t = Clock::now();
          index.Search(VectorKind::kClip, q.data() + (r % 16) * dim, 1, 50);
          one.push_back(Since(t) * 1e3);
          t = Clock::now();
          index.Search(VectorKind::kClip, q.data(), 16, 50);
          batch.push_back(Since(t) * 1e3);
        }
        const uint64_t bytes = DirBytes(dir);
        std::printf("%10zu %8zu %10.1f %10.1f %10.2f %12.2f %14.2f\n", n, index.shard_count(), bytes / 1e6,
                    vec_bytes / 1e6, open_s, Median(one), Median(batch));
        results["scale"][std::to_string(n)] = {{"bytes", bytes}, {"vector_bytes", vec_bytes}, {"open_s", open_s},
                                               {"query_ms", Median(one)}, {"batch16_ms", Median(batch)}};
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
