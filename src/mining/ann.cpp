#include "mining/ann.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstring>
#include <map>

#include <faiss/IndexFlat.h>
#include <faiss/IndexIVFPQ.h>
#include <faiss/impl/FaissException.h>
#include <faiss/impl/io.h>
#include <faiss/index_io.h>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/log.h"
#include "io/files.h"
#include "io/json.h"

namespace sd::mining {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

constexpr const char* kAnnFormat = "synthdrive-mine-ann/1";

fs::path CodesPath(const fs::path& index_dir, const std::string& kind) { return index_dir / "ann" / (kind + ".faiss"); }
fs::path TablePath(const fs::path& index_dir, const std::string& kind) { return index_dir / "ann" / (kind + ".json"); }

// FNV-1a over 64-bit words (then the tail bytes): the codes file is checked against its table before FAISS,
// which trusts its input, reads it. Word-wise, as a byte loop would take half a second at 10^6 vectors' codes.
uint64_t Fnv64(std::string_view bytes) {
  uint64_t h = 1469598103934665603ull;
  size_t i = 0;
  for (; i + 8 <= bytes.size(); i += 8) {
    uint64_t w;
    std::memcpy(&w, bytes.data() + i, 8);
    h = (h ^ w) * 1099511628211ull;
  }
  for (; i < bytes.size(); ++i) h = (h ^ static_cast<unsigned char>(bytes[i])) * 1099511628211ull;
  return h;
}

// FAISS's reader over bytes already in memory (its VectorIOReader would copy them once more).
struct BytesReader : faiss::IOReader {
  explicit BytesReader(std::string_view b) : bytes(b) {}
  size_t operator()(void* ptr, size_t size, size_t nitems) override {
    if (size == 0) return 0;
    const size_t n = std::min(nitems, (bytes.size() - at) / size);
    std::memcpy(ptr, bytes.data() + at, n * size);
    at += n * size;
    return n;
  }
  std::string_view bytes;
  size_t at = 0;
};

double Seconds(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

// The covered shards of a table, with its parameters; InputError naming the file when malformed.
struct AnnTable {
  AnnParams params;
  int dim = 0;
  uint64_t bytes = 0, fnv64 = 0;
  std::vector<std::pair<std::string, size_t>> shards;
};

AnnTable ReadTable(const fs::path& file) {
  const json j = ReadJsonFile(file);
  const JsonReader r(j, file);
  if (r["format"].String() != kAnnFormat) r["format"].Fail(std::string("expected ") + kAnnFormat);
  AnnTable t;
  t.dim = static_cast<int>(r["dim"].Number());
  t.params.nlist = static_cast<int>(r["nlist"].Number());
  t.params.m = static_cast<int>(r["m"].Number());
  t.params.nprobe = static_cast<int>(r["nprobe"].Number());
  t.params.train_rows = static_cast<size_t>(r["train_rows"].Number());
  t.bytes = static_cast<uint64_t>(r["bytes"].Number());
  t.fnv64 = std::stoull(r["fnv64"].String(), nullptr, 16);
  if (t.params.nlist < 1 || t.params.m < 1 || t.params.nprobe < 1 || t.dim < 1) r.Fail("non-positive parameters");
  for (size_t i = 0; i < r["shards"].Size(); ++i) {
    const JsonReader s = r["shards"][i];
    const double rows = s["rows"].Number();
    if (rows < 0) s["rows"].Fail("negative");
    t.shards.emplace_back(s["name"].String(), static_cast<size_t>(rows));
  }
  return t;
}

// The table's shards matched to the current ones: per table shard the current index, or npos when it is gone
// or has changed size.
std::vector<size_t> MatchShards(const AnnTable& t, const std::vector<AnnShard>& current) {
  std::map<std::string, size_t> by_name;
  for (size_t i = 0; i < current.size(); ++i) by_name[current[i].name] = i;
  std::vector<size_t> out;
  for (const auto& [name, rows] : t.shards) {
    auto it = by_name.find(name);
    out.push_back(it != by_name.end() && current[it->second].rows == rows ? it->second : std::string::npos);
  }
  return out;
}

}  // namespace

AnnParams ChooseAnnParams(size_t rows, int dim) {
  AnnParams p;
  p.nlist = static_cast<int>(std::clamp<double>(std::round(std::sqrt(static_cast<double>(rows))), 64, 65536));
  // A power of two near it keeps the lists' sizes even across index sizes that differ a little.
  p.nlist = 1 << static_cast<int>(std::round(std::log2(p.nlist)));
  p.m = 1;
  // A byte per four dimensions (128-byte codes for CLIP's 512): at a byte per eight, the codes' estimate could
  // not tell an object's near neighbours apart well enough for the re-ranking to reach recall@10 0.95. The
  // largest divisor of dim that is at most dim / 4: FAISS needs M to divide the dimension.
  for (int m = std::max(1, dim / 4); m >= 1; --m)
    if (dim % m == 0) {
      p.m = m;
      break;
    }
  p.nprobe = std::max(32, p.nlist / 32);
  p.train_rows = std::min(rows, std::max<size_t>(10000, static_cast<size_t>(p.nlist) * 40));
  return p;
}

AnnBuildReport BuildAnn(const fs::path& index_dir, const std::string& kind, int dim, const std::vector<AnnShard>& shards) {
  AnnBuildReport report;
  for (const AnnShard& s : shards) report.rows += s.rows;
  if (report.rows == 0) throw InputError(index_dir, "no " + kind + " vectors to build an approximate index over");
  report.params = ChooseAnnParams(report.rows, dim);
  const AnnParams& p = report.params;
  // Training sample: rows spread evenly over the whole index (every source and period, not the first shards).
  std::vector<float> sample(p.train_rows * static_cast<size_t>(dim));
  {
    std::vector<size_t> begin;
    size_t total = 0;
    for (const AnnShard& s : shards) begin.push_back(total), total += s.rows;
    size_t shard = 0;
    for (size_t i = 0; i < p.train_rows; ++i) {
      const size_t row = static_cast<size_t>((static_cast<double>(i) + 0.5) * total / p.train_rows);
      while (shard + 1 < shards.size() && begin[shard + 1] <= row) ++shard;
      std::memcpy(sample.data() + i * dim, shards[shard].vectors + (row - begin[shard]) * dim, dim * sizeof(float));
    }
  }
  auto t0 = std::chrono::steady_clock::now();
  faiss::IndexIVFPQ index(new faiss::IndexFlatIP(dim), dim, p.nlist, p.m, 8, faiss::METRIC_INNER_PRODUCT);
  index.own_fields = true;
  index.cp.seed = 1234;  // the same index from the same vectors
  index.verbose = false;
  try {
    index.train(static_cast<faiss::Index::idx_t>(p.train_rows), sample.data());
    report.train_seconds = Seconds(t0);
    t0 = std::chrono::steady_clock::now();
    for (const AnnShard& s : shards)
      if (s.rows > 0) index.add(static_cast<faiss::Index::idx_t>(s.rows), s.vectors);  // labels: rows in shard order
    report.add_seconds = Seconds(t0);
  } catch (const faiss::FaissException& e) {
    throw InputError(index_dir, std::string("building the approximate index failed: ") + e.what());
  }
  index.nprobe = static_cast<size_t>(p.nprobe);
  faiss::VectorIOWriter writer;
  faiss::write_index(&index, &writer);
  const std::string_view bytes(reinterpret_cast<const char*>(writer.data.data()), writer.data.size());
  json shard_list = json::array();
  for (const AnnShard& s : shards) shard_list.push_back({{"name", s.name}, {"rows", s.rows}});
  char hash[17];
  std::snprintf(hash, sizeof hash, "%016llx", static_cast<unsigned long long>(Fnv64(bytes)));
  fs::create_directories(index_dir / "ann");
  WriteFileAtomic(CodesPath(index_dir, kind), bytes);
  WriteJsonFile(TablePath(index_dir, kind), {{"format", kAnnFormat},
                                             {"kind", kind},
                                             {"type", "IVF-PQ"},
                                             {"dim", dim},
                                             {"rows", report.rows},
                                             {"nlist", p.nlist},
                                             {"m", p.m},
                                             {"nprobe", p.nprobe},
                                             {"train_rows", p.train_rows},
                                             {"bytes", bytes.size()},
                                             {"fnv64", hash},
                                             {"train_seconds", report.train_seconds},
                                             {"add_seconds", report.add_seconds},
                                             {"shards", shard_list}});
  return report;
}

AnnIndex::AnnIndex() = default;
AnnIndex::~AnnIndex() = default;

std::unique_ptr<AnnIndex> AnnIndex::Load(const fs::path& index_dir, const std::string& kind, int dim,
                                         const std::vector<AnnShard>& current) {
  const fs::path table_file = TablePath(index_dir, kind), codes_file = CodesPath(index_dir, kind);
  if (!fs::is_regular_file(table_file)) return nullptr;
  const AnnTable t = ReadTable(table_file);
  if (t.dim != dim) throw InputError(table_file, Msg() << "vectors of dimension " << t.dim << ", the index has " << dim);
  const std::vector<size_t> match = MatchShards(t, current);
  if (std::count(match.begin(), match.end(), std::string::npos) > 0) {
    SD_LOG(Warn, table_file.string() << ": covers shards that are gone or changed; searching exactly until `mine index` "
                                        "rebuilds it");
    return nullptr;
  }
  const std::string bytes = ReadFileToString(codes_file);
  if (bytes.size() != t.bytes || Fnv64(bytes) != t.fnv64)
    throw InputError(codes_file, "does not match its table " + table_file.filename().string() +
                                     " (size or checksum): delete the ann folder and run `mine index` again");
  auto ann = std::unique_ptr<AnnIndex>(new AnnIndex());
  try {
    BytesReader reader(bytes);
    ann->index_.reset(faiss::read_index(&reader));
  } catch (const faiss::FaissException& e) {
    throw InputError(codes_file, std::string("not a FAISS index: ") + e.what());
  }
  auto* ivf = dynamic_cast<faiss::IndexIVFPQ*>(ann->index_.get());
  size_t covered = 0;
  for (const auto& [name, rows] : t.shards) covered += rows;
  if (!ivf || ivf->d != dim || static_cast<size_t>(ivf->ntotal) != covered)
    throw InputError(codes_file, Msg() << "holds " << (ivf ? ivf->ntotal : 0) << " vectors where its table lists " << covered);
  ivf->nprobe = static_cast<size_t>(t.params.nprobe);
  ann->params_ = t.params;
  ann->covers_.assign(current.size(), false);
  size_t label = 0;
  for (size_t i = 0; i < t.shards.size(); ++i) {
    ann->covers_[match[i]] = true;
    ann->label_begin_.push_back(label);
    ann->label_shard_.push_back(match[i]);
    label += t.shards[i].second;
  }
  ann->covered_rows_ = covered;
  return ann;
}

std::vector<std::vector<std::pair<size_t, size_t>>> AnnIndex::Candidates(const float* queries, size_t nq, size_t kk) const {
  std::vector<std::vector<std::pair<size_t, size_t>>> out(nq);
  if (nq == 0 || kk == 0 || covered_rows_ == 0) return out;
  kk = std::min(kk, covered_rows_);
  std::vector<float> scores(nq * kk);
  std::vector<faiss::Index::idx_t> labels(nq * kk);
  index_->search(static_cast<faiss::Index::idx_t>(nq), queries, static_cast<faiss::Index::idx_t>(kk), scores.data(), labels.data());
  for (size_t q = 0; q < nq; ++q)
    for (size_t j = 0; j < kk; ++j) {
      const faiss::Index::idx_t l = labels[q * kk + j];
      if (l < 0) continue;
      const size_t label = static_cast<size_t>(l);
      const size_t s = static_cast<size_t>(std::upper_bound(label_begin_.begin(), label_begin_.end(), label) - label_begin_.begin()) - 1;
      out[q].emplace_back(label_shard_[s], label - label_begin_[s]);
    }
  return out;
}

bool AnnNeedsBuild(const fs::path& index_dir, const std::string& kind, int dim, const std::vector<AnnShard>& current,
                   size_t min_rows) {
  size_t rows = 0;
  for (const AnnShard& s : current) rows += s.rows;
  if (rows < min_rows) return false;
  const fs::path table_file = TablePath(index_dir, kind);
  if (!fs::is_regular_file(table_file)) return true;
  AnnTable t;
  try {
    t = ReadTable(table_file);
  } catch (const InputError&) {
    return true;  // a broken table is replaced
  }
  if (t.dim != dim) return true;
  const std::vector<size_t> match = MatchShards(t, current);
  if (std::count(match.begin(), match.end(), std::string::npos) > 0) return true;
  size_t covered = 0;
  for (const auto& [name, n] : t.shards) covered += n;
  return rows - covered > covered / 4;
}

}  // namespace sd::mining
