// `synthdrive generate`: object views, or one object photo (learned models, else a shape prior) → a finished
// asset folder.
#include <chrono>
#include <filesystem>
#include <fstream>
#include <map>
#include <optional>
#include <memory>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "assetgen/asset.h"
#include "assetgen/generate.h"
#include "assetgen/harvest.h"
#include "assetgen/mined.h"
#include "assetgen/shape_prior.h"
#include "assetgen/views.h"
#include "cli/commands.h"
#include "cli/hit_assets.h"
#include "cli/mesh_files.h"
#include "core/error.h"
#include "core/log.h"
#include "core/shard.h"
#include "io/batch.h"
#include "datasets/categories.h"
#include "datasets/readers.h"
#include "io/files.h"
#include "io/image_io.h"
#include "mining/query.h"
#include "models/multiview_diffusion.h"
#include "models/normal_estimation.h"
#include "models/runtime.h"
#include "models/segmentation.h"

namespace sd::cli {

namespace {

namespace fs = std::filesystem;

// The model files single-image generation needs (docs/models.md): checked up front, so a user learns every
// missing file in one line instead of one per run.
const std::vector<std::string> kSingleImageModels = {models::kMvImageEncoderFile, models::kMvUnetFile,
                                                     models::kMvVaeDecoderFile, models::kNormalEstimatorFile};

bool SingleImageModelsInstalled(const fs::path& model_dir) {
  for (const std::string& f : kSingleImageModels)
    if (!fs::exists(model_dir / f)) return false;
  return true;
}

// The learned front end — segmenter (classical unless --segmenter names a model), Zero123++ and the normal
// estimator — loaded once and reused for every image of a batch.
class ImageFrontEnd {
 public:
  ImageFrontEnd(const fs::path& model_dir, const std::string& segmenter_choice, int steps, float guidance,
                uint64_t seed)
      : segmenter_(models::Segmenter::Resolve(segmenter_choice)),
        generator_(models::MultiViewGenerator::Load(model_dir)),
        normals_(models::NormalEstimator::FromModel(model_dir / models::kNormalEstimatorFile)),
        steps_(steps),
        guidance_(guidance),
        seed_(seed) {}

  MultiViewSet Views(const ImageU8& image, const Box2& box, const SegmentationPrior* prior,
                     std::vector<StageReport>* reports) const {
    ImageToViewsStages stages;
    stages.segment = [&](const ImageU8& img, const Box2& b) { return segmenter_.Segment(img, b).mask; };
    stages.generate_views = [&](const ImageU8& cutout) { return generator_.Generate(cutout, steps_, guidance_, seed_); };
    stages.estimate_normals = [&](const ImageF& view) { return normals_.Estimate(view); };
    stages.methods = {segmenter_.Describe(), generator_.Describe(), normals_.Describe()};
    return ViewsFromImage(image, box, stages, reports, prior);
  }

 private:
  models::Segmenter segmenter_;
  models::MultiViewGenerator generator_;
  models::NormalEstimator normals_;
  int steps_;
  float guidance_;
  uint64_t seed_;
};


struct Args {
  std::string views, image, manifest, out, category, id, name, licence, source, attribution, model_dir, shard = "0/1";
  int limit = 0;
  std::string segmenter = "classical";
  std::vector<double> size, box;
  std::string mask, shape = "auto";
  std::optional<double> elevation, yaw;
  double fov = 50;
  int diffusion_steps = models::kZero123PlusDefaultSteps;
  float guidance = models::kZero123PlusDefaultGuidance;
  uint64_t seed = 0;
  double height = 0;
  bool overwrite = false;
  GenerateOptions options;
};

// Views -> refined, textured, canonical mesh -> the asset folder.
void BuildAndSave(const MultiViewSet& views, const std::vector<StageReport>& front, const GenerateOptions& options,
                  AssetInfo info, const std::string& source, const fs::path& out, bool overwrite) {
  SaveGenerated(GenerateFromViews(views, options), views, front, std::move(info), source, out, overwrite);
}

// The object's metric size: --size, else the category's proportions at --height, else the category's size.
Eigen::Vector3d ObjectSize(const Args& a, const CategoryInfo& category) {
  if (!a.size.empty()) {
    const Eigen::Vector3d s(a.size[0], a.size[1], a.size[2]);
    if (!(s.minCoeff() > 0)) throw InputError({}, "--size: length, width and height must all be > 0 metres");
    return s;
  }
  if (a.height > 0) return category.default_size * (a.height / category.default_size.z());
  return category.default_size;
}

// The object's mask in the photo: --mask, else the photo's alpha channel, else GrabCut (or --segmenter's
// model) inside --box (or the whole photo less a 2% border: a photo of the object alone).
ImageF PhotoMask(const Args& a, const ImageU8& raw, const ImageU8& image, StageReport* stage) {
  const auto start = std::chrono::steady_clock::now();
  ImageF mask(image.width(), image.height(), 1, 0.0f);
  std::string method;
  if (!a.mask.empty()) {
    const ImageU8 m = ReadImage(a.mask, 1);
    if (m.width() != image.width() || m.height() != image.height())
      throw InputError(a.mask, Msg() << "the mask is " << m.width() << "x" << m.height() << ", the photo "
                                     << image.width() << "x" << image.height());
    for (int y = 0; y < m.height(); ++y)
      for (int x = 0; x < m.width(); ++x) mask.at(x, y) = m.at(x, y) > 127 ? 1.0f : 0.0f;
    method = "given mask " + a.mask;
  } else if (raw.channels() == 4 && a.box.empty()) {
    for (int y = 0; y < raw.height(); ++y)
      for (int x = 0; x < raw.width(); ++x) mask.at(x, y) = raw.at(x, y, 3) > 127 ? 1.0f : 0.0f;
    method = "the photo's alpha channel";
  } else {
    Box2 box{0.02 * image.width(), 0.02 * image.height(), 0.98 * image.width(), 0.98 * image.height()};
    if (!a.box.empty()) {
      box = Box2{a.box[0], a.box[1], a.box[2], a.box[3]};
      if (!(box.x2 > box.x1 && box.y2 > box.y1))
        throw InputError(a.image, Msg() << "--box " << box.x1 << "," << box.y1 << "," << box.x2 << "," << box.y2
                                        << " is empty (x2 must exceed x1, y2 y1)");
      if (box.x2 <= 0 || box.y2 <= 0 || box.x1 >= image.width() || box.y1 >= image.height())
        throw InputError(a.image, Msg() << "--box " << box.x1 << "," << box.y1 << "," << box.x2 << "," << box.y2
                                        << " lies outside the " << image.width() << "x" << image.height() << " photo");
    }
    const models::Segmenter segmenter = models::Segmenter::Resolve(a.segmenter);
    mask = segmenter.Segment(image, box).mask;
    method = segmenter.Describe() + (a.box.empty() ? " in the whole photo" : " in --box");
  }
  *stage = {"segment", method, std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count()};
  return mask;
}

// `generate --image` with no learned model (or --shape naming a prior): shape_prior.h makes the views and the
// coarse mesh from the photo, then the common back end. The asset records the prior, what was assumed, and how
// well the asset reproduces the photo it came from.
void RunPhotoShape(const Args& a, const CategoryInfo& category, GenerateOptions options, const AssetInfo& info) {
  const ImageU8 raw = ReadImage(a.image);
  const ImageU8 image = raw.channels() == 3 ? raw : ReadImage(a.image, 3);
  StageReport segmentation;
  PhotoObservation photo;
  photo.mask = PhotoMask(a, raw, image, &segmentation);
  photo.image = image;
  photo.elevation_deg = a.elevation;
  ShapePriorOptions prior;
  if (a.shape != "auto") prior.prior = ParseShapePrior(a.shape);
  prior.category = category.name;
  prior.size = ObjectSize(a, category);
  prior.size_measured = !a.size.empty();
  prior.yaw_deg = a.yaw;
  prior.assumed_vertical_fov_deg = a.fov;
  BuiltAsset built = PhotoAsset(photo, prior, options, segmentation, a.image, a.mask, a.image);
  SD_LOG(Info, a.image << ": " << built.quality[quality::kShapePrior]["prior"].get<std::string>()
                       << " prior, photo silhouette IoU " << built.quality["photo_silhouette_iou"].get<double>());
  SaveGenerated(std::move(built.mesh), built.views, built.front, info, a.image, a.out, a.overwrite, built.quality);
}

// `generate --manifest`: one asset per mining hit, as a batch (DESIGN.md): the shard's share of the hits, each
// written atomically to <out>/<hit id>/, hits whose folder exists skipped, progress, and a failed hit reported
// without losing the others (exit 1 when any failed). With the learned single-image models installed (and
// --shape auto) every hit goes through them; without, a log hit is harvested from its log (every view of its
// track, its returns: docs/harvest.md) and a folder or URL hit gets its category's shape prior. Hits of one
// track make one asset, under the first hit's id.
int RunManifest(const Args& a, const fs::path& model_dir) {
  const fs::path manifest(a.manifest);
  std::vector<mining::ManifestEntry> entries = mining::ReadManifest(manifest);
  if (a.limit > 0 && entries.size() > static_cast<size_t>(a.limit)) entries.resize(a.limit);
  const ShardSpec shard = ParseShard(a.shard);
  std::optional<CategoryInfo> fallback;
  if (!a.category.empty()) {
    fallback = FindCategory(a.category);
    if (!fallback) throw InputError({}, "unknown category '" + a.category + "' (see `synthdrive categories`)");
  }
  if (fs::exists(a.out) && !fs::is_directory(a.out)) throw InputError(a.out, "exists and is not a folder");
  const bool learned = a.shape == "auto" && SingleImageModelsInstalled(model_dir);
  // One asset per track: later hits of a track already taken are left out of the work list before it is
  // sharded, so that two shards never build the same track.
  std::map<std::string, std::string> track_owner;  // "<log>|<instance>" -> the first hit's id
  std::vector<size_t> work;                         // indices into entries
  size_t same_track = 0;
  for (size_t i = 0; i < entries.size(); ++i) {
    const mining::MinedItem& item = entries[i].item;
    if (!learned && item.kind == mining::SourceKind::kLog && !item.instance_token.empty()) {
      const auto [it, first] = track_owner.emplace(item.source + "|" + item.instance_token, item.id);
      if (!first) {
        ++same_track;
        continue;
      }
    }
    work.push_back(i);
  }
  auto asset_dir = [&](size_t w) { return fs::path(a.out) / entries[work[w]].item.id; };
  size_t owned = 0, complete = 0;
  for (size_t w = 0; w < work.size(); ++w)
    if (shard.Owns(w)) ++owned, complete += fs::exists(asset_dir(w) / "asset.json") ? 1 : 0;
  SD_LOG(Info, manifest.string() << ": " << entries.size() << " hits (" << same_track << " more views of a track already"
                                 << " taken); shard " << shard.ToString() << ": " << owned - complete << " to build, " << complete
                                 << " already built; " << (learned ? "learned multi-view models" : "no learned models: "
                                 "log hits harvested from their logs, image hits by shape priors"));
  if (owned == complete) return 0;
  std::optional<ImageFrontEnd> front_end;
  if (learned) front_end.emplace(model_dir, a.segmenter, a.diffusion_steps, a.guidance, a.seed);
  HitAssetOptions hit_options;
  hit_options.generate = a.options;
  hit_options.generate.refine.show_progress = false;
  hit_options.segmenter = a.segmenter;
  if (a.shape != "auto") hit_options.shape = ParseShapePrior(a.shape);
  HitAssetBuilder builder(hit_options);
  fs::create_directories(a.out);

  // The batch runner (io/batch.h) keeps the run log <out>/generate-log-K-of-N.jsonl, one line per hit.
  BatchJob job;
  job.size = work.size();
  job.describe = [&](size_t w) { return nlohmann::json{{"hit", work[w] + 1}, {"id", entries[work[w]].item.id}}; };
  job.name = [&](size_t w) { return manifest.string() + ":" + std::to_string(work[w] + 1); };
  job.output = asset_dir;
  job.complete = [&](size_t w) { return fs::exists(asset_dir(w) / "asset.json"); };
  job.run = [&](size_t w, nlohmann::json*) {
    const size_t i = work[w];
    const mining::ManifestEntry& e = entries[i];
    const std::string where = job.name(w);
    const MinedObject object = LoadMinedObject(e);
    const std::optional<CategoryInfo> category = object.category.empty() ? fallback : FindCategory(object.category);
    if (!category)
      throw InputError(where, object.category.empty() ? "hit has no category: pass --category"
                                                      : "unknown category '" + object.category + "'");
    std::vector<StageReport> front;
    GenerateOptions options = a.options;
    options.refine.show_progress = false;
    options.canonical.up = "+z";
    AssetInfo info;
    info.id = e.item.id;
    info.name = e.prompt.empty() ? e.item.id : e.prompt + " #" + std::to_string(e.rank);
    info.category = category->name;
    info.licence = a.licence;
    info.source = object.source;
    info.attribution = a.attribution;
    const fs::path out = asset_dir(w);
    if (learned) {
      const MultiViewSet views = front_end->Views(object.image, object.box, object.prior ? &*object.prior : nullptr, &front);
      if (object.front_in_rig) options.canonical.front_direction = *object.front_in_rig;
      // Metric scale: the log's 3D box, else --size / --height, else the category's size prior.
      if (object.size_lwh) options.canonical.target_size = *object.size_lwh;
      else if (!a.size.empty()) options.canonical.target_size = Eigen::Vector3d(a.size[0], a.size[1], a.size[2]);
      else options.canonical.target_height = a.height > 0 ? a.height : category->default_size.z();
      BuildAndSave(views, front, options, info, object.source, out, false);
    } else {
      const Eigen::Vector3d size = ObjectSize(a, *category);
      BuiltAsset built = builder.Build(e, where, *category, size);
      front.insert(front.end(), built.front.begin(), built.front.end());
      info.source = built.source;
      SaveGenerated(std::move(built.mesh), built.views, front, info, built.source, out, false, built.quality);
    }
  };
  BatchOptions batch;
  batch.label = "generate";
  batch.shard = shard;
  batch.run_log = fs::path(a.out) / ("generate-log-" + std::to_string(shard.index) + "-of-" + std::to_string(shard.count) + ".jsonl");
  const BatchSummary run = RunBatch(job, batch);
  const size_t failed = run.failures.size();
  SD_LOG(Info, "generate: " << run.done << " assets built, " << failed << " failed, " << run.skipped
                            << " already there -> " << a.out << " (run log " << batch.run_log.string() << ")");
  return failed == 0 ? 0 : 1;
}

}  // namespace

Runner AddGenerateCommand(CLI::App& app) {
  auto a = std::make_shared<Args>();
  auto* input = app.add_option_group("input", "what to build the asset from");
  input->add_option("--views", a->views,
                    "Views folder (cameras.json + colour images + normal maps + masks; docs/refine.md)");
  input->add_option("--image", a->image,
                    "One object photo: the learned multi-view path when its models are installed, else (or with "
                    "--shape) a shape prior");
  input->add_option("--manifest", a->manifest,
                    "A mining run's manifest.jsonl (mine query): one asset per hit (per track for log hits), into "
                    "<out>/<hit id>/; learned models when installed, else log hits are harvested from their logs and "
                    "image hits get a shape prior (docs/harvest.md)");
  input->require_option(1);
  app.add_option("--category", a->category,
                 "Object category (see `synthdrive categories`); its size is the default scale. With --manifest, "
                 "only for hits that carry no category");
  app.add_option("--out", a->out, "Asset folder to create (with --manifest: the folder of asset folders)")->required();
  app.add_option("--limit", a->limit, "--manifest: at most this many hits (in manifest order; 0 = all)")
      ->default_val(0)->check(CLI::NonNegativeNumber);
  app.add_option("--shard", a->shard, "--manifest: build only items K, K+N, ... of the work list (one hit per track; K/N, 0-based)")->default_val("0/1");
  app.add_option("--height", a->height, "Real height in metres (default: the category's)")->check(CLI::PositiveNumber);
  app.add_option("--size", a->size, "Real length width height in metres (l w h or l,w,h)")->expected(3)->delimiter(',');
  app.add_option("--front", a->options.canonical.front,
                 "The views' axis that is the object's front (+x, -y, ...), or auto (from mirror symmetry)")
      ->default_val("+x");
  app.add_option("--id", a->id, "Asset id (default: the output folder's name)");
  app.add_option("--name", a->name, "Human-readable name");
  app.add_option("--licence", a->licence, "Licence of the source images");
  app.add_option("--source", a->source, "Where the images came from");
  app.add_option("--attribution", a->attribution, "Required credit");
  app.add_option("--upscale", a->options.upscale, "x2 super-resolution of the views: auto, none, bicubic, a model name or .pt")
      ->default_val("auto");
  app.add_option("--texture", a->options.texture, "bake (UV atlas) or vertex")->default_val("bake")
      ->check(CLI::IsMember({"bake", "vertex"}));
  app.add_option("--texture-size", a->options.texture_size, "Atlas side in texels")->default_val(1024)
      ->check(CLI::Range(64, 16384));
  app.add_option("--steps", a->options.refine.steps, "Refinement steps")->default_val(a->options.refine.steps)
      ->check(CLI::Range(1, 1000));
  app.add_option("--hull-resolution", a->options.hull_resolution, "Voxels along the visual hull's cube")
      ->default_val(96)->check(CLI::Range(16, 512));
  app.add_option("--box", a->box, "The object's box in --image: x1 y1 x2 y2 (or x1,y1,x2,y2) pixels (default: the whole image)")
      ->expected(4)->delimiter(',');
  app.add_option("--mask", a->mask, "--image: the object's mask (white = object), the photo's size");
  app.add_option("--shape", a->shape,
                 "--image: auto (learned models if installed, else the category's prior), revolve, mirror, extrude "
                 "or hull (docs/shape_prior.md)")
      ->default_val("auto")->check(CLI::IsMember({"auto", "revolve", "mirror", "extrude", "hull"}));
  app.add_option("--elevation", a->elevation, "--image: the camera's elevation above the object, degrees "
                                              "(default: from a revolve's base ellipse, else 8)")
      ->check(CLI::Range(-30.0, 89.0));
  app.add_option("--yaw", a->yaw, "--image: the camera's azimuth about the object, degrees, 0 = in front of it "
                                  "(default: from the silhouette's aspect)")
      ->check(CLI::Range(-360.0, 360.0));
  app.add_option("--fov", a->fov, "--image: the photo's vertical field of view when unknown, degrees")
      ->default_val(50)->check(CLI::Range(5.0, 150.0));
  app.add_option("--segmenter", a->segmenter, "classical (GrabCut from the box), auto (installed ISNet if any) or a .pt")
      ->default_val("classical");
  app.add_option("--diffusion-steps", a->diffusion_steps, "Denoising steps of the multi-view generator")
      ->default_val(a->diffusion_steps)->check(CLI::Range(1, 1000));
  app.add_option("--guidance", a->guidance, "Classifier-free guidance scale of the multi-view generator")
      ->default_val(a->guidance)->check(CLI::NonNegativeNumber);
  app.add_option("--seed", a->seed, "Seed of the multi-view generator's noise")->default_val(0);
  app.add_option("--models", a->model_dir, "Folder of installed models (default: $SYNTHDRIVE_MODELS or ~/.cache/synthdrive/models)");
  app.add_flag("--overwrite", a->overwrite, "Replace an existing asset folder");

  return [a]() {
    const fs::path model_dir = a->model_dir.empty() ? models::DefaultModelDir() : fs::path(a->model_dir);
    RefuseOutputOverInputs(a->out, {a->views, a->image, a->manifest});
    if (!a->manifest.empty()) return RunManifest(*a, model_dir);
    if (a->category.empty()) throw InputError({}, "--category is required with --views and --image");
    RefuseExisting(a->out, a->overwrite);
    const auto category = FindCategory(a->category);
    if (!category) throw InputError({}, "unknown category '" + a->category + "' (see `synthdrive categories`)");
    std::vector<StageReport> front;
    MultiViewSet views;
    const bool photo_prior = !a->image.empty() && (a->shape != "auto" || !SingleImageModelsInstalled(model_dir));
    if (a->image.empty()) {
      views = LoadViews(a->views);
    } else if (!photo_prior) {
      const ImageU8 image = ReadImage(a->image);
      const Box2 box = a->box.empty() ? Box2{0, 0, double(image.width()), double(image.height())}
                                      : Box2{a->box[0], a->box[1], a->box[2], a->box[3]};
      const ImageFrontEnd front_end(model_dir, a->segmenter, a->diffusion_steps, a->guidance, a->seed);
      try {
        views = front_end.Views(image, box, nullptr, &front);
      } catch (const InputError& e) {
        throw InputError(a->image, e.what());
      }
    }
    const std::string source = a->image.empty() ? a->views : a->image;
    GenerateOptions options = a->options;
    options.refine.show_progress = GetLogLevel() <= LogLevel::kInfo;
    options.canonical.up = "+z";
    if (!a->size.empty()) options.canonical.target_size = Eigen::Vector3d(a->size[0], a->size[1], a->size[2]);
    else options.canonical.target_height = a->height > 0 ? a->height : category->default_size.z();
    if (!a->size.empty()) ObjectSize(*a, *category);  // refuses sizes that are not positive
    AssetInfo info;
    info.id = a->id.empty() ? fs::absolute(a->out).lexically_normal().filename().string() : a->id;
    info.name = a->name.empty() ? info.id : a->name;
    info.category = category->name;
    info.licence = a->licence;
    info.source = a->source.empty() ? source : a->source;
    info.attribution = a->attribution;
    if (photo_prior) {
      RunPhotoShape(*a, *category, options, info);
      return 0;
    }
    try {
      BuildAndSave(views, front, options, info, source, a->out, a->overwrite);
    } catch (const InputError& e) {
      throw InputError(a->image.empty() ? fs::path(a->views) / "cameras.json" : fs::path(a->image), e.what());
    }
    return 0;
  };
}

}  // namespace sd::cli
