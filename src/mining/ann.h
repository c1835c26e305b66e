#pragma once
// Approximate nearest-neighbour search for large mining indexes (docs/mining.md "Search at scale"): a FAISS
// IVF-PQ index over one kind of vector of the shards it was built on, kept in <index>/ann/<kind>.faiss with the
// list of shards it covers in <kind>.json. It only proposes candidates; their scores are recomputed exactly
// from the shards' memory-mapped vectors, and shards added after it was built are searched exactly, so a query
// always sees every row and every score it returns is the true cosine.
//
// Why IVF-PQ: its codes (dim / 4 bytes a vector) are small enough to load at open in a fraction of a second and
// to hold 10^8 vectors on one machine, while the exact vectors stay on disk, mapped, for the re-ranking. A flat
// IVF would copy every vector into memory again; HNSW would add a graph of about as many bytes as the vectors and
// build an order of magnitude slower.
#include <cstddef>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

namespace faiss {
struct Index;
}

namespace sd::mining {

// One shard's vectors of the kind indexed, in the index's row order.
struct AnnShard {
  std::string name;  // the shard folder's name
  size_t rows = 0;
  const float* vectors = nullptr;  // rows x dim, unit norm
};

struct AnnParams {
  int nlist = 0;   // inverted lists (coarse centroids)
  int m = 0;       // PQ sub-quantizers (bytes per code)
  int nprobe = 0;  // lists visited per query
  size_t train_rows = 0;
};
// By size: about sqrt(rows) lists (a power of two, at least 64), dim / 4 one-byte sub-quantizers, a 32nd of
// the lists probed (at least 32), trained on 40 vectors per list (at least 10k).
AnnParams ChooseAnnParams(size_t rows, int dim);

// Indexes with fewer vectors than this are searched exactly (20 ms at 100k on 2 cores, bench_mine).
constexpr size_t kAnnMinRows = 100000;

struct AnnBuildReport {
  size_t rows = 0;
  AnnParams params;
  double train_seconds = 0, add_seconds = 0;
};
// Trains and fills an IVF-PQ over every row of `shards` and writes <index_dir>/ann/<kind>.faiss and .json
// (each atomically, the table last, so a reader never sees a table of another build).
AnnBuildReport BuildAnn(const std::filesystem::path& index_dir, const std::string& kind, int dim,
                        const std::vector<AnnShard>& shards);

class AnnIndex {
 public:
  // The index's ANN for `kind`, matched against the index's current shards; null when there is none, or when it
  // covers a shard that is gone or has another row count (stale: logged, the index is then searched exactly
  // until `mine index` rebuilds it). InputError naming the file for a malformed one.
  static std::unique_ptr<AnnIndex> Load(const std::filesystem::path& index_dir, const std::string& kind, int dim,
                                        const std::vector<AnnShard>& current);
  ~AnnIndex();

  // Per current shard: whether its rows are in the ANN (the others must be searched exactly).
  const std::vector<bool>& covers() const { return covers_; }
  size_t covered_rows() const { return covered_rows_; }
  const AnnParams& params() const { return params_; }

  // Up to `kk` candidates per query, as (current shard, row in shard), best first by the codes' estimate.
  std::vector<std::vector<std::pair<size_t, size_t>>> Candidates(const float* queries, size_t nq, size_t kk) const;

 private:
  AnnIndex();
  std::unique_ptr<faiss::Index> index_;
  AnnParams params_;
  std::vector<bool> covers_;
  size_t covered_rows_ = 0;
  std::vector<size_t> label_begin_;   // per ANN shard: its first label
  std::vector<size_t> label_shard_;   // per ANN shard: the current shard it is
};

// Whether `mine index` should (re)build the ANN for `kind`: the index has kAnnMinRows rows or more and has none,
// a stale one, or one that leaves more than a quarter of its covered rows uncovered (shards added since).
bool AnnNeedsBuild(const std::filesystem::path& index_dir, const std::string& kind, int dim,
                   const std::vector<AnnShard>& current, size_t min_rows = kAnnMinRows);

}  // namespace sd::mining
