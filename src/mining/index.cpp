#include "mining/index.h"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <exception>
#include <cctype>
#include <chrono>
#include <cstring>
#include <fstream>
#include <mutex>

#include <faiss/utils/distances.h>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "core/log.h"
#include "core/parallel.h"
#include "datasets/readers.h"
#include "io/batch.h"
#include "io/files.h"
#include "io/image_io.h"
#include "io/json.h"
#include "mining/descriptor.h"
#include "mining/item_table.h"
#include "models/clip.h"
#include "models/resample.h"

namespace sd::mining {

namespace fs = std::filesystem;
using nlohmann::json;

namespace {

constexpr const char* kIndexFormat = "synthdrive-mine-index/1";
constexpr int kDefaultChunkSize = 16;

double Seconds(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

// --- Vector files: a 32-byte header ("SDVEC001", dim u32, reserved u32, count u64, reserved u64), then
// count × dim little-endian float32. A plain layout rather than a serialised faiss::Index, because FAISS 1.7
// cannot memory-map a flat index and its search kernels take raw row pointers anyway.
constexpr char kVectorMagic[8] = {'S', 'D', 'V', 'E', 'C', '0', '0', '1'};
constexpr size_t kVectorHeader = 32;

void WriteVectors(const fs::path& path, int dim, const std::vector<float>& rows) {
  SD_CHECK(dim > 0 && rows.size() % dim == 0, << dim << " " << rows.size());
  std::string bytes(kVectorHeader + rows.size() * sizeof(float), '\0');
  std::memcpy(bytes.data(), kVectorMagic, 8);
  const uint32_t d = static_cast<uint32_t>(dim);
  const uint64_t n = rows.size() / dim;
  std::memcpy(bytes.data() + 8, &d, 4);
  std::memcpy(bytes.data() + 16, &n, 8);
  if (!rows.empty()) std::memcpy(bytes.data() + kVectorHeader, rows.data(), rows.size() * sizeof(float));
  WriteFileAtomic(path, bytes);
}

class MappedVectors {
 public:
  MappedVectors(const fs::path& path, int expected_dim) {
    fd_ = ::open(path.c_str(), O_RDONLY | O_CLOEXEC);
    if (fd_ < 0) throw InputError(path, Msg() << "cannot open vector file: " << std::strerror(errno));
    struct stat st {};
    ::fstat(fd_, &st);
    size_ = static_cast<size_t>(st.st_size);
    if (size_ < kVectorHeader) Fail(path, "shorter than its header");
    map_ = ::mmap(nullptr, size_, PROT_READ, MAP_SHARED, fd_, 0);
    if (map_ == MAP_FAILED) {
      map_ = nullptr;
      Fail(path, std::string("cannot map: ") + std::strerror(errno));
    }
    const char* p = static_cast<const char*>(map_);
    if (std::memcmp(p, kVectorMagic, 8) != 0) Fail(path, "not a SynthDrive vector file (bad magic)");
    uint32_t d = 0;
    std::memcpy(&d, p + 8, 4);
    std::memcpy(&count_, p + 16, 8);
    dim_ = static_cast<int>(d);
    if (dim_ != expected_dim) Fail(path, Msg() << "vectors of dimension " << dim_ << ", the index says " << expected_dim);
    if (size_ != kVectorHeader + count_ * dim_ * sizeof(float))
      Fail(path, Msg() << "truncated: " << size_ << " bytes for " << count_ << " vectors of " << dim_);
  }
  ~MappedVectors() {
    if (map_) ::munmap(map_, size_);
    if (fd_ >= 0) ::close(fd_);
  }
  MappedVectors(const MappedVectors&) = delete;
  MappedVectors& operator=(const MappedVectors&) = delete;

  size_t count() const { return count_; }
  const float* data() const {
    return reinterpret_cast<const float*>(static_cast<const char*>(map_) + kVectorHeader);
  }

 private:
  [[noreturn]] void Fail(const fs::path& path, const std::string& what) {
    if (map_) ::munmap(map_, size_);
    if (fd_ >= 0) ::close(fd_);
    map_ = nullptr;
    fd_ = -1;
    throw InputError(path, what);
  }
  int fd_ = -1;
  void* map_ = nullptr;
  size_t size_ = 0;
  uint64_t count_ = 0;
  int dim_ = 0;
};

// FAISS answers a batch of queries with one BLAS matrix product once it holds this many (its default is 20);
// below that it scans the vectors once per query. A query of a few prompts is already cheaper as a product
// (the vectors are read once instead of once per prompt), so the product starts at 4.
[[maybe_unused]] const int kBlasFromQueries = [] {
  faiss::distance_compute_blas_threshold = 4;
  return 4;
}();

const char* VectorFileName(VectorKind kind) {
  return kind == VectorKind::kClip ? "vectors-clip.f32" : "vectors-descriptor.f32";
}

// --- index.json

struct IndexHeader {
  int descriptor_version = kDescriptorVersion;
  int descriptor_dim = 0;
  std::string clip_model;
  int clip_dim = 0;
  int chunk_size = kDefaultChunkSize;
};

IndexHeader ReadHeader(const fs::path& file) {
  const json j = ReadJsonFile(file);
  const JsonReader r(j, file);
  if (r["format"].String() != kIndexFormat)
    r["format"].Fail(Msg() << "expected \"" << kIndexFormat << "\" (an index written by another version?)");
  IndexHeader h;
  h.descriptor_version = static_cast<int>(r["descriptor"]["version"].Integer());
  h.descriptor_dim = static_cast<int>(r["descriptor"]["dim"].Integer());
  if (r.Has("clip")) {
    h.clip_model = r["clip"]["model"].String();
    h.clip_dim = static_cast<int>(r["clip"]["dim"].Integer());
  }
  h.chunk_size = static_cast<int>(r["chunk_size"].Integer());
  if (h.chunk_size < 1) r["chunk_size"].Fail("must be at least 1");
  return h;
}

json HeaderJson(const IndexHeader& h) {
  json j = {{"format", kIndexFormat},
            {"descriptor", {{"version", h.descriptor_version}, {"dim", h.descriptor_dim}}},
            {"chunk_size", h.chunk_size}};
  j["clip"] = h.clip_model.empty() ? json(nullptr) : json{{"model", h.clip_model}, {"dim", h.clip_dim}};
  return j;
}

// Creates index.json or checks that this run's vectors are comparable with those already stored. Returns the
// header in force (an existing index keeps its chunk size: chunk names depend on it).
IndexHeader EnsureIndexHeader(const fs::path& dir, const IndexBuildOptions& options) {
  IndexHeader wanted;
  wanted.descriptor_dim = DescriptorDim();
  if (options.clip) {
    wanted.clip_model = options.clip->Describe();
    wanted.clip_dim = options.clip->embed_dim();
  }
  if (options.chunk_size > 0) wanted.chunk_size = options.chunk_size;
  const fs::path file = dir / "index.json";
  if (!fs::exists(file)) {
    if (fs::exists(dir) && !fs::is_directory(dir)) throw InputError(dir, "exists and is not an index folder");
    // Shard processes started together all get here: besides shards/, logs/ and index.json temporaries (another
    // process creating the index right now), anything in the folder means it is not ours to write into.
    if (fs::exists(dir))
      for (const auto& e : fs::directory_iterator(dir)) {
        const std::string name = e.path().filename().string();
        if (name != "shards" && name != "logs" && name != "index.json" && name.rfind("index.json.tmp-", 0) != 0)
          throw InputError(dir, "exists, is not empty and holds no index.json: refusing to write an index into it");
      }
    fs::create_directories(dir / "shards");
    // Create-if-absent in one step: a complete temporary file hard-linked to index.json. link() fails when
    // another process got there first, and then that header (read below) must agree with this run.
    const fs::path tmp = TemporarySibling(file);
    WriteJsonFile(tmp, HeaderJson(wanted));
    const int linked = ::link(tmp.c_str(), file.c_str());
    const int link_errno = errno;
    fs::remove(tmp);
    if (linked != 0 && link_errno != EEXIST)
      throw InputError(file, Msg() << "cannot create: " << std::strerror(link_errno));
    if (linked == 0) return wanted;
  }
  IndexHeader have = ReadHeader(file);
  if (have.descriptor_version != wanted.descriptor_version || have.descriptor_dim != wanted.descriptor_dim)
    throw InputError(file, Msg() << "built with image descriptor v" << have.descriptor_version << " ("
                                 << have.descriptor_dim << " floats); this build writes v" << wanted.descriptor_version
                                 << ": rebuild the index in a new folder");
  if (have.clip_model != wanted.clip_model)
    throw InputError(file, Msg() << "built with CLIP model '" << (have.clip_model.empty() ? "none" : have.clip_model)
                                 << "', this run has '" << (wanted.clip_model.empty() ? "none" : wanted.clip_model)
                                 << "': embeddings of different models cannot be searched together (use the same "
                                    "--clip, or another --out)");
  if (options.chunk_size > 0 && options.chunk_size != have.chunk_size)
    SD_LOG(Warn, file.string() << ": keeps its chunk size " << have.chunk_size << " (asked " << options.chunk_size
                               << "): chunk names depend on it");
  return have;
}

// --- Planning: the sources cut into chunks, the same list in every shard process.

struct SourceState {
  IndexSource source;
  std::string key;                  // kind|absolute path: names the chunks and the item ids
  std::optional<Log> log;           // kLog
  std::vector<fs::path> images;     // kFolder, sorted
  std::vector<std::string> urls;    // kUrl
  size_t size() const { return log ? log->frames.size() : !images.empty() ? images.size() : urls.size(); }
};

struct Chunk {
  size_t source = 0;
  size_t begin = 0, end = 0;
  std::string name;
};

bool IsImageFile(const fs::path& p) {
  std::string ext = p.extension().string();
  std::transform(ext.begin(), ext.end(), ext.begin(), [](unsigned char c) { return std::tolower(c); });
  return ext == ".png" || ext == ".jpg" || ext == ".jpeg";
}

SourceState OpenSource(const IndexSource& source) {
  SourceState s;
  s.source = source;
  std::error_code ec;
  const fs::path abs = fs::weakly_canonical(fs::absolute(source.path), ec);
  s.key = std::string(ToString(source.kind)) + "|" + (ec ? source.path.string() : abs.string());
  switch (source.kind) {
    case SourceKind::kLog:
      s.log = OpenLog(source.path);
      break;
    case SourceKind::kFolder: {
      if (!fs::is_directory(source.path)) throw InputError(source.path, "image folder not found");
      for (const auto& e : fs::recursive_directory_iterator(source.path, fs::directory_options::skip_permission_denied))
        if (e.is_regular_file() && IsImageFile(e.path())) s.images.push_back(e.path());
      std::sort(s.images.begin(), s.images.end());
      if (s.images.empty()) SD_LOG(Warn, source.path.string() << ": no .png / .jpg images");
      break;
    }
    case SourceKind::kUrl:
      s.urls = ReadUrlList(source.path);
      break;
  }
  return s;
}

std::vector<Chunk> PlanChunks(const std::vector<SourceState>& sources, int chunk_size) {
  std::vector<Chunk> chunks;
  for (size_t s = 0; s < sources.size(); ++s) {
    const std::string stem = std::string(ToString(sources[s].source.kind)) + "-" + StableId(sources[s].key);
    for (size_t b = 0; b < sources[s].size(); b += chunk_size) {
      char suffix[32];
      std::snprintf(suffix, sizeof suffix, "-%06zu", b);
      chunks.push_back({s, b, std::min(sources[s].size(), b + chunk_size), stem + suffix});
    }
  }
  return chunks;
}

ImageU8 DownscaleToFit(const ImageU8& image, int max_px, double& scale) {
  scale = 1;
  const int longer = std::max(image.width(), image.height());
  if (max_px <= 0 || longer <= max_px) return image;
  scale = static_cast<double>(max_px) / longer;
  const int w = std::max(1, static_cast<int>(std::lround(image.width() * scale)));
  const int h = std::max(1, static_cast<int>(std::lround(image.height() * scale)));
  ImageF f(image.width(), image.height(), image.channels());
  for (size_t i = 0; i < image.size(); ++i) f.data()[i] = image.data()[i];
  const ImageF r = models::ResizeLinear(f, w, h);
  ImageU8 out(w, h, image.channels());
  for (size_t i = 0; i < out.size(); ++i)
    out.data()[i] = static_cast<uint8_t>(std::clamp(std::lround(r.data()[i]), 0l, 255l));
  return out;
}

// A folder or URL image is one item: the whole picture, its alpha channel (if any) as the mask.
ObjectCrop WholeImageCrop(const ImageU8& decoded, SourceKind kind, const std::string& origin, int max_px) {
  ObjectCrop c;
  MinedItem& item = c.item;
  item.kind = kind;
  item.origin = origin;
  const int W = decoded.width(), H = decoded.height();
  item.crop_rect = Box2{0, 0, static_cast<double>(W), static_cast<double>(H)};
  item.box2d = item.crop_rect;
  double scale = 1;
  const ImageU8 small = DownscaleToFit(decoded, max_px, scale);
  item.crop_scale = scale;
  const int w = small.width(), h = small.height(), ch = small.channels();
  c.image = ImageU8(w, h, 3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int k = 0; k < 3; ++k) c.image.at(x, y, k) = small.at(x, y, ch >= 3 ? k : 0);
  if (ch == 4 || ch == 2) {
    c.mask = ImageU8(w, h, 1);
    int x1 = w, y1 = h, x2 = -1, y2 = -1;
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        if (small.at(x, y, ch - 1) > 127) {
          c.mask.at(x, y) = 255;
          x1 = std::min(x1, x), y1 = std::min(y1, y), x2 = std::max(x2, x), y2 = std::max(y2, y);
        }
    if (x2 < 0) {
      c.mask = ImageU8();  // fully transparent: no usable mask, keep the picture
    } else {
      item.mask_source = "alpha";
      item.box2d = Box2{x1 / scale, y1 / scale, (x2 + 1) / scale, (y2 + 1) / scale};
    }
  }
  item.crop_width = w;
  item.crop_height = h;
  return c;
}

struct ChunkOutput {
  std::vector<MinedItem> items;
  std::vector<float> descriptors, clip;
  json failures = json::array();
  double crop_seconds = 0, embed_seconds = 0;
};

void AddFailure(ChunkOutput& out, std::mutex& m, const std::string& origin, const std::string& error) {
  std::lock_guard<std::mutex> lock(m);
  out.failures.push_back({{"origin", origin}, {"error", error}});
  // InputError messages already start with the file they name.
  if (error.rfind(origin, 0) == 0) SD_LOG(Warn, error);
  else SD_LOG(Warn, origin << ": " << error);
}

std::vector<ObjectCrop> CropLogChunk(const SourceState& s, const Chunk& chunk, const IndexBuildOptions& options,
                                     ChunkOutput& out) {
  std::vector<ObjectCrop> crops;
  std::mutex m;
  for (size_t f = chunk.begin; f < chunk.end; ++f) {
    const Frame& frame = s.log->frames[f];
    std::vector<Eigen::Vector3d> sweep;
    try {
      sweep = SweepInEgo(frame);
    } catch (const InputError& e) {
      AddFailure(out, m, frame.lidar ? frame.lidar->path.string() : frame.token,
                 std::string(e.what()) + " (masks from boxes only)");
    }
    try {
      for (ObjectCrop& c : CropFrameObjects(frame, sweep, options.crops)) {
        c.item.log_name = s.log->name;
        c.item.id = StableId(s.key + "|" + frame.token + "|" + c.item.camera + "|" +
                             (c.item.annotation_token.empty() ? std::to_string(crops.size()) : c.item.annotation_token));
        crops.push_back(std::move(c));
      }
    } catch (const InputError& e) {
      AddFailure(out, m, frame.token, e.what());
    }
  }
  return crops;
}

std::vector<ObjectCrop> CropImageChunk(const SourceState& s, const Chunk& chunk, const IndexBuildOptions& options,
                                       ChunkOutput& out) {
  const size_t n = chunk.end - chunk.begin;
  std::vector<std::optional<ObjectCrop>> slots(n);
  std::mutex m;
  if (s.source.kind == SourceKind::kFolder) {
    ParallelFor(0, n, [&](size_t i) {
      const fs::path& file = s.images[chunk.begin + i];
      try {
        slots[i] = WholeImageCrop(ReadImage(file), SourceKind::kFolder, fs::absolute(file).string(),
                                  options.max_image_px);
      } catch (const InputError& e) {
        AddFailure(out, m, file.string(), e.what());
      }
    });
  } else {
    const std::vector<std::string> urls(s.urls.begin() + chunk.begin, s.urls.begin() + chunk.end);
    std::vector<FetchedImage> fetched = FetchImages(urls, options.fetch, options.fetch_concurrency);
    for (size_t i = 0; i < n; ++i) {
      if (!fetched[i].error.empty()) {
        AddFailure(out, m, urls[i], fetched[i].error);
        continue;
      }
      slots[i] = WholeImageCrop(fetched[i].image, SourceKind::kUrl, urls[i], options.max_image_px);
    }
  }
  std::vector<ObjectCrop> crops;
  for (size_t i = 0; i < n; ++i)
    if (slots[i]) {
      slots[i]->item.id = StableId(s.key + "|" + slots[i]->item.origin);
      crops.push_back(std::move(*slots[i]));
    }
  return crops;
}

// Crops, quality figures, files and vectors of one chunk, written into `dir` (the staging folder).
ChunkOutput BuildChunk(const SourceState& s, const Chunk& chunk, const IndexBuildOptions& options, const fs::path& dir) {
  ChunkOutput out;
  auto t0 = std::chrono::steady_clock::now();
  std::vector<ObjectCrop> crops = s.source.kind == SourceKind::kLog ? CropLogChunk(s, chunk, options, out)
                                                                    : CropImageChunk(s, chunk, options, out);
  const int D = DescriptorDim();
  out.descriptors.assign(crops.size() * D, 0.f);
  fs::create_directories(dir / "crops");
  fs::create_directories(dir / "masks");
  ParallelForRethrow(0, crops.size(), [&](size_t i) {
    ObjectCrop& c = crops[i];
    MinedItem& item = c.item;
    item.source = s.source.path.string();
    // A mask with no object pixels (a sliver lost to downscaling) describes nothing: use the whole crop.
    const bool has_mask = !c.mask.empty() && std::any_of(c.mask.vector().begin(), c.mask.vector().end(),
                                                         [](uint8_t v) { return v > 127; });
    if (!has_mask) {
      c.mask = ImageU8();
      item.mask_source.clear();
    }
    const ImageU8* mask = has_mask ? &c.mask : nullptr;
    item.sharpness = Sharpness(c.image, mask);
    item.phash = PerceptualHash(c.image);
    const std::vector<float> d = ImageDescriptor(c.image, mask);
    std::copy(d.begin(), d.end(), out.descriptors.begin() + i * D);
    item.crop_file = "crops/" + item.id + ".jpg";
    WriteImage(dir / item.crop_file, c.image, options.jpeg_quality);
    if (mask) {
      item.mask_file = "masks/" + item.id + ".png";
      WriteImage(dir / item.mask_file, c.mask);
    }
  });
  out.crop_seconds = Seconds(t0);
  if (options.clip && !crops.empty()) {
    t0 = std::chrono::steady_clock::now();
    std::vector<ImageU8> images;
    images.reserve(crops.size());
    for (const ObjectCrop& c : crops) images.push_back(c.image);
    for (const auto& e : options.clip->EmbedImages(images)) out.clip.insert(out.clip.end(), e.begin(), e.end());
    out.embed_seconds = Seconds(t0);
  }
  for (ObjectCrop& c : crops) out.items.push_back(std::move(c.item));
  return out;
}

void WriteChunk(const SourceState& s, const Chunk& chunk, const IndexHeader& header, const ChunkOutput& out,
                const fs::path& dir) {
  WriteItemTable(dir, out.items);
  WriteVectors(dir / VectorFileName(VectorKind::kDescriptor), header.descriptor_dim, out.descriptors);
  if (header.clip_dim > 0) WriteVectors(dir / VectorFileName(VectorKind::kClip), header.clip_dim, out.clip);
  WriteJsonFile(dir / "chunk.json", {{"source", s.source.path.string()},
                                     {"kind", ToString(s.source.kind)},
                                     {"begin", chunk.begin},
                                     {"end", chunk.end},
                                     {"items", out.items.size()},
                                     {"failures", out.failures},
                                     {"crop_seconds", out.crop_seconds},
                                     {"embed_seconds", out.embed_seconds}});
}

}  // namespace

const char* ToString(VectorKind kind) { return kind == VectorKind::kClip ? "clip" : "descriptor"; }

IndexBuildReport BuildIndex(const fs::path& index_dir, const IndexBuildOptions& options) {
  const auto t0 = std::chrono::steady_clock::now();
  if (options.sources.empty()) throw InputError({}, "mine index: no sources (give --log, --images or --urls)");
  if (options.clip && options.clip->embed_dim() <= 0) throw InputError({}, "CLIP model has no embedding size");
  // Open every source before writing anything: a typo in the last --log must not leave a half-made index.
  std::vector<SourceState> sources;
  for (const IndexSource& src : options.sources) sources.push_back(OpenSource(src));
  const IndexHeader header = EnsureIndexHeader(index_dir, options);
  const std::vector<Chunk> chunks = PlanChunks(sources, header.chunk_size);

  IndexBuildReport report;
  report.chunks_total = chunks.size();
  const fs::path shards = index_dir / "shards";
  auto chunk_dir = [&](size_t i) { return shards / chunks[i].name; };
  BatchJob job;
  job.size = chunks.size();
  job.describe = [&](size_t i) {
    const Chunk& c = chunks[i];
    return json{{"chunk", c.name}, {"source", sources[c.source].source.path.string()}, {"begin", c.begin}, {"end", c.end}};
  };
  job.name = [&](size_t i) { return "chunk " + chunks[i].name; };
  job.output = chunk_dir;
  job.complete = [&](size_t i) { return fs::exists(chunk_dir(i) / "chunk.json"); };
  job.run = [&](size_t i, json* line) {
    const Chunk& chunk = chunks[i];
    StagingDirectory staging(chunk_dir(i), /*overwrite=*/false);
    const SourceState& s = sources[chunk.source];
    const ChunkOutput out = BuildChunk(s, chunk, options, staging.path());
    WriteChunk(s, chunk, header, out, staging.path());
    staging.Commit();
    // Per-image failures are the chunk's own (its chunk.json lists them); the chunk itself is done.
    (*line)["items"] = out.items.size();
    (*line)["failures"] = out.failures.size();
    report.items += out.items.size();
    report.failures += out.failures.size();
    report.crop_seconds += out.crop_seconds;
    report.embed_seconds += out.embed_seconds;
  };
  size_t owned = 0, complete = 0;
  for (size_t i = 0; i < chunks.size(); ++i)
    if (options.shard.Owns(i)) ++owned, complete += job.complete(i) ? 1 : 0;
  SD_LOG(Info, "mine index: " << chunks.size() << " chunks from " << sources.size() << " sources; shard "
                              << options.shard.ToString() << " owns " << owned << ", " << complete
                              << " already done; vectors: descriptor"
                              << (options.clip ? " + CLIP" : " only (no CLIP model: label and example search)"));
  BatchOptions batch;
  batch.label = "mine index";
  batch.shard = options.shard;
  batch.run_log = index_dir / "logs" / ("index-" + std::to_string(options.shard.index) + "-of-" +
                                        std::to_string(options.shard.count) + ".jsonl");
  batch.show_progress = options.progress;
  const BatchSummary run = RunBatch(job, batch);
  report.chunks_owned = run.owned;
  report.chunks_built = run.done;
  report.chunks_skipped = run.skipped;
  for (const BatchFailure& f : run.failures) report.failed_chunks.push_back(chunks[f.item].name + ": " + f.error);
  if (options.build_ann && options.shard.count == 1 && report.failed_chunks.empty()) {
    const auto t_ann = std::chrono::steady_clock::now();
    const MiningIndex index = MiningIndex::Open(index_dir);
    for (VectorKind kind : {VectorKind::kDescriptor, VectorKind::kClip}) {
      if (kind == VectorKind::kClip && !index.has_clip()) continue;
      const std::vector<AnnShard> shards = index.ShardVectors(kind);
      if (!AnnNeedsBuild(index_dir, ToString(kind), index.dim(kind), shards, options.ann_min_rows)) continue;
      SD_LOG(Info, "mine index: building the approximate " << ToString(kind) << " index over " << index.size() << " vectors");
      const AnnBuildReport ann = BuildAnn(index_dir, ToString(kind), index.dim(kind), shards);
      SD_LOG(Info, "mine index: " << ToString(kind) << " IVF-PQ (" << ann.params.nlist << " lists, " << ann.params.m
                                  << "-byte codes) trained in " << ann.train_seconds << " s, filled in " << ann.add_seconds << " s");
      report.ann_built.push_back(ToString(kind));
    }
    report.ann_seconds = Seconds(t_ann);
  }
  report.seconds = Seconds(t0);
  return report;
}

// --- MiningIndex

struct MiningIndex::Shard {
  fs::path dir;
  size_t first_row = 0, rows = 0;
  ItemTable items;
  std::unique_ptr<MappedVectors> descriptor, clip;
  const MappedVectors* Vectors(VectorKind kind) const { return kind == VectorKind::kClip ? clip.get() : descriptor.get(); }
};

MiningIndex::MiningIndex() = default;
MiningIndex::MiningIndex(MiningIndex&&) noexcept = default;
MiningIndex& MiningIndex::operator=(MiningIndex&&) noexcept = default;
MiningIndex::~MiningIndex() = default;

size_t MiningIndex::shard_count() const { return shards_.size(); }
const MiningIndex::Shard& MiningIndex::ShardOf(size_t row, size_t* local) const {
  if (row >= rows_) throw std::out_of_range("MiningIndex: row " + std::to_string(row) + " of " + std::to_string(rows_));
  // The last shard starting at or before `row`: never an empty one, whose successor starts at the same row.
  const auto it = std::upper_bound(shards_.begin(), shards_.end(), row,
                                   [](size_t r, const std::unique_ptr<Shard>& s) { return r < s->first_row; });
  const Shard& s = **std::prev(it);
  *local = row - s.first_row;
  return s;
}

MinedItem MiningIndex::item(size_t row) const {
  size_t local = 0;
  const Shard& s = ShardOf(row, &local);
  return s.items.item(local);
}

ItemSummary MiningIndex::summary(size_t row) const {
  size_t local = 0;
  const Shard& s = ShardOf(row, &local);
  return s.items.summary(local);
}

fs::path MiningIndex::ItemDir(size_t row) const {
  size_t local = 0;
  return ShardOf(row, &local).dir;
}

const AnnIndex* MiningIndex::ann(VectorKind kind) const {
  return kind == VectorKind::kClip ? ann_clip_.get() : ann_descriptor_.get();
}

std::vector<AnnShard> MiningIndex::ShardVectors(VectorKind kind) const {
  std::vector<AnnShard> out;
  for (const auto& s : shards_) {
    const MappedVectors* v = s->Vectors(kind);
    out.push_back({s->dir.filename().string(), s->rows, v ? v->data() : nullptr});
  }
  return out;
}

int MiningIndex::dim(VectorKind kind) const { return kind == VectorKind::kClip ? clip_dim_ : descriptor_dim_; }

const float* MiningIndex::vector(VectorKind kind, size_t row) const {
  size_t local = 0;
  const Shard& s = ShardOf(row, &local);
  const MappedVectors* v = s.Vectors(kind);
  SD_CHECK(v != nullptr, << "no " << ToString(kind) << " vectors in this index");
  return v->data() + local * dim(kind);
}

MiningIndex MiningIndex::Open(const fs::path& index_dir) {
  const fs::path file = index_dir / "index.json";
  if (!fs::exists(file)) throw InputError(index_dir, "not a mining index (no index.json; build one with `mine index`)");
  const IndexHeader header = ReadHeader(file);
  if (header.descriptor_version != kDescriptorVersion || header.descriptor_dim != DescriptorDim())
    throw InputError(file, Msg() << "built with image descriptor v" << header.descriptor_version
                                 << "; this build reads v" << kDescriptorVersion << ": rebuild the index");
  MiningIndex index;
  index.dir_ = index_dir;
  index.clip_model_ = header.clip_model;
  index.clip_dim_ = header.clip_dim;
  index.descriptor_dim_ = header.descriptor_dim;

  std::vector<fs::path> dirs;
  if (fs::is_directory(index_dir / "shards"))
    for (const auto& e : fs::directory_iterator(index_dir / "shards")) {
      const std::string name = e.path().filename().string();
      // Staging folders of running or killed builds are not part of the index until renamed.
      if (e.is_directory() && name.find(".tmp-") == std::string::npos && fs::exists(e.path() / "chunk.json"))
        dirs.push_back(e.path());
    }
  std::sort(dirs.begin(), dirs.end());
  // Shards open in parallel (a shard written before items.bin existed parses its JSON lines), then join in name
  // order.
  std::vector<std::unique_ptr<Shard>> shards(dirs.size());
  // One shard's records and vector maps (a lambda: Shard is private to MiningIndex).
  auto load_shard = [&header](const fs::path& dir, std::unique_ptr<Shard>& out) {
    auto shard = std::make_unique<Shard>();
    shard->dir = dir;
    shard->items = ItemTable::Open(dir);
    shard->rows = shard->items.size();
    shard->descriptor = std::make_unique<MappedVectors>(dir / VectorFileName(VectorKind::kDescriptor), header.descriptor_dim);
    if (header.clip_dim > 0)
      shard->clip = std::make_unique<MappedVectors>(dir / VectorFileName(VectorKind::kClip), header.clip_dim);
    for (const MappedVectors* v : {shard->descriptor.get(), shard->clip.get()})
      if (v && v->count() != shard->rows)
        throw InputError(dir, Msg() << "holds " << shard->rows << " items but " << v->count()
                                    << " vectors: the shard is corrupt (delete it and run `mine index` again)");
    out = std::move(shard);
  };
  ParallelForRethrow(0, dirs.size(), [&](size_t s) { load_shard(dirs[s], shards[s]); });  // first shard's error first
  for (size_t s = 0; s < dirs.size(); ++s) {
    shards[s]->first_row = index.rows_;
    index.rows_ += shards[s]->rows;
    index.shards_.push_back(std::move(shards[s]));
  }
  index.ann_descriptor_ = AnnIndex::Load(index_dir, ToString(VectorKind::kDescriptor), index.descriptor_dim_,
                                         index.ShardVectors(VectorKind::kDescriptor));
  if (index.has_clip())
    index.ann_clip_ = AnnIndex::Load(index_dir, ToString(VectorKind::kClip), index.clip_dim_, index.ShardVectors(VectorKind::kClip));
  return index;
}

std::vector<std::vector<SearchHit>> MiningIndex::Search(VectorKind kind, const float* queries, size_t nq, size_t k,
                                                        SearchMode mode) const {
  if (kind == VectorKind::kClip && !has_clip())
    throw InputError(dir_, "has no CLIP embeddings (built without a CLIP model)");
  const size_t d = static_cast<size_t>(dim(kind));
  std::vector<std::vector<SearchHit>> hits(nq);
  if (k == 0) return hits;
  const AnnIndex* approx = mode == SearchMode::kAuto ? ann(kind) : nullptr;
  // Candidates from the approximate index, re-scored exactly from the mapped vectors: many times k, because the
  // codes' estimate is coarser than the differences between an object's near neighbours (re-scoring 256 rows
  // reads half a megabyte of mapped vectors at 512 floats, a fraction of a millisecond).
  if (approx) {
    const size_t kk = std::max<size_t>(16 * k, 256);
    const auto candidates = approx->Candidates(queries, nq, kk);
    for (size_t q = 0; q < nq; ++q)
      for (const auto& [shard, local] : candidates[q]) {
        const Shard& s = *shards_[shard];
        const MappedVectors* v = s.Vectors(kind);
        const float score = faiss::fvec_inner_product(queries + q * d, v->data() + local * d, d);
        hits[q].push_back({s.first_row + local, score});
      }
  }
  // One exact top-k per shard the approximate index does not cover (all of them without one), shards in
  // parallel (a single query is memory-bound in one thread), then merged.
  std::vector<std::vector<std::vector<SearchHit>>> per_shard(shards_.size());
  ParallelFor(0, shards_.size(), [&](size_t s) {
    if (approx && approx->covers()[s]) return;
    const Shard& shard = *shards_[s];
    const MappedVectors* v = shard.Vectors(kind);
    if (!v || v->count() == 0) return;
    const size_t kk = std::min(k, v->count());
    std::vector<float> scores(nq * kk, 0.f);
    std::vector<int64_t> labels(nq * kk, -1);
    faiss::knn_inner_product(queries, v->data(), d, nq, v->count(), kk, scores.data(), labels.data());
    per_shard[s].resize(nq);
    for (size_t q = 0; q < nq; ++q)
      for (size_t j = 0; j < kk; ++j)
        if (labels[q * kk + j] >= 0)
          per_shard[s][q].push_back({shard.first_row + static_cast<size_t>(labels[q * kk + j]), scores[q * kk + j]});
  });
  for (const auto& shard_hits : per_shard)
    for (size_t q = 0; q < shard_hits.size(); ++q) hits[q].insert(hits[q].end(), shard_hits[q].begin(), shard_hits[q].end());
  for (auto& h : hits) {
    // Ties broken by row so results do not depend on shard order.
    std::sort(h.begin(), h.end(), [](const SearchHit& a, const SearchHit& b) {
      return a.score != b.score ? a.score > b.score : a.row < b.row;
    });
    if (h.size() > k) h.resize(k);
  }
  return hits;
}

}  // namespace sd::mining
