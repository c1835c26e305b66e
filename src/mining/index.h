#pragma once
// The mining index: every object image of the crawled sources, with its crop, mask, quality figures and
// embedding vectors, in a folder that grows incrementally and is searched through memory-mapped shards.
//
// Layout (docs/mining.md):
//   <index>/index.json                 format, the descriptor version and the CLIP model every vector came from
//   <index>/shards/<chunk>/chunk.json  the work item this shard holds (source, kind, range) and its failures
//                          items.jsonl one MinedItem per line; line i is row i of every vector file
//                          items.bin   the lines' table: byte ranges, categories, quality (mining/item_table.h)
//                          vectors-descriptor.f32, vectors-clip.f32 (when CLIP ran): header + rows of float32
//                          crops/<id>.jpg, masks/<id>.png
// The work list is the sources cut into chunks (`chunk_size` frames, images or URLs); a chunk is one shard,
// written under a temporary name and renamed when complete. A chunk whose shard exists is done, so a killed
// run resumes where it stopped, `--shard K/N` processes build disjoint chunks of the same index, and adding a
// log later embeds only that log's chunks.
//
// Search runs FAISS's exact inner-product kernel over each shard's memory-mapped vectors and merges the
// per-shard top-k; an index of kAnnMinRows vectors or more also gets an approximate index (mining/ann.h) whose
// candidates are re-scored exactly, so opening an index reads no vectors and processes share the page cache; a record is parsed
// from its JSON line only when asked for.
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "core/shard.h"
#include "mining/http.h"
#include "mining/item.h"
#include "mining/ann.h"
#include "mining/item_table.h"
#include "mining/log_crops.h"

namespace sd::models {
class ClipEncoder;
}

namespace sd::mining {

struct IndexSource {
  SourceKind kind = SourceKind::kLog;
  std::filesystem::path path;  // a log (any format OpenLog reads), an image folder, or a URL list file
};

struct IndexBuildOptions {
  std::vector<IndexSource> sources;
  int chunk_size = 16;             // frames, images or URLs per shard
  ShardSpec shard;                 // build only the chunks this process owns
  LogCropOptions crops;
  FetchOptions fetch;
  int fetch_concurrency = 8;
  int max_image_px = 1024;         // folder and URL images larger than this on their longer side are downscaled
  int jpeg_quality = 92;           // stored crops
  const models::ClipEncoder* clip = nullptr;  // null: descriptor vectors only (label / example search)
  bool progress = true;
  // After the chunks, (re)build the approximate index of each vector kind that needs it (AnnNeedsBuild). Only a
  // run that owns the whole work list does: after a `--shard K/N` array, one plain `mine index` finishes the index.
  bool build_ann = true;
  size_t ann_min_rows = kAnnMinRows;
};

struct IndexBuildReport {
  size_t chunks_total = 0;     // of the whole work list (all shards)
  size_t chunks_owned = 0;     // this process's share
  size_t chunks_built = 0;
  size_t chunks_skipped = 0;   // already done by an earlier run
  size_t items = 0;            // object images added by this run
  size_t failures = 0;         // images that could not be read or fetched (recorded in chunk.json)
  std::vector<std::string> failed_chunks;  // "<chunk>: <error>" of chunks that failed as a whole (in the run log)
  std::vector<std::string> ann_built;      // the vector kinds whose approximate index this run (re)built
  double seconds = 0, crop_seconds = 0, embed_seconds = 0, ann_seconds = 0;
};

// Creates `index_dir` (or checks an existing index was built with the same descriptor version and CLIP model:
// InputError otherwise, since vectors from different models cannot be compared) and builds the owned chunks
// not yet present, through the batch runner (io/batch.h: shard, resume, run log logs/index-K-of-N.jsonl).
// InputError naming the source for a source that cannot be opened (before any chunk is written); per-image
// failures inside a chunk are recorded in its chunk.json, and a chunk that fails as a whole is reported in
// `failed_chunks` while the others go on.
IndexBuildReport BuildIndex(const std::filesystem::path& index_dir, const IndexBuildOptions& options);

enum class VectorKind { kDescriptor, kClip };
const char* ToString(VectorKind kind);

// kAuto: through the approximate index where the index has one (candidates re-scored exactly; shards it does not
// cover searched exactly); kExact: every vector scanned, the reference.
enum class SearchMode { kAuto, kExact };

struct SearchHit {
  size_t row = 0;   // index into MiningIndex::item()
  float score = 0;  // inner product of unit vectors (cosine)
};

class MiningIndex {
 public:
  // Reads index.json and every complete shard's item table; maps the vector files and the JSON lines. InputError
  // naming the file for a missing index, a shard whose items and vectors disagree, a malformed table, or (for a
  // shard without a table) a malformed record.
  static MiningIndex Open(const std::filesystem::path& index_dir);

  MiningIndex(MiningIndex&&) noexcept;
  MiningIndex& operator=(MiningIndex&&) noexcept;
  ~MiningIndex();

  const std::filesystem::path& dir() const { return dir_; }
  size_t size() const { return rows_; }
  size_t shard_count() const;
  // The row's record, parsed from its shard's items.jsonl (InputError naming the line when it is malformed).
  MinedItem item(size_t row) const;
  // What label mode ranks by, from the shard's table: no parse.
  ItemSummary summary(size_t row) const;
  // The folder the item's crop_file / mask_file are relative to.
  std::filesystem::path ItemDir(size_t row) const;

  bool has_clip() const { return clip_dim_ > 0; }
  const std::string& clip_model() const { return clip_model_; }  // ClipEncoder::Describe() at build time
  int dim(VectorKind kind) const;
  const float* vector(VectorKind kind, size_t row) const;

  // Top-k rows by inner product with each of `nq` query vectors (row-major nq × dim(kind)), best first. Scores
  // are exact in both modes; kAuto may miss a row the exact scan ranks in the top k (recall in bench/RESULTS.md).
  std::vector<std::vector<SearchHit>> Search(VectorKind kind, const float* queries, size_t nq, size_t k,
                                             SearchMode mode = SearchMode::kAuto) const;
  // The approximate index Search uses for `kind` (null: exact only).
  const AnnIndex* ann(VectorKind kind) const;
  // Each shard's name, rows and mapped vectors of `kind`, in row order (what an approximate index is built on).
  std::vector<AnnShard> ShardVectors(VectorKind kind) const;

 private:
  struct Shard;
  MiningIndex();
  const Shard& ShardOf(size_t row, size_t* local) const;
  std::filesystem::path dir_;
  size_t rows_ = 0;
  std::vector<std::unique_ptr<Shard>> shards_;  // in row order
  std::unique_ptr<AnnIndex> ann_descriptor_, ann_clip_;
  std::string clip_model_;
  int clip_dim_ = 0, descriptor_dim_ = 0;
};

}  // namespace sd::mining
