// `synthdrive generate`: object views (or, with the learned models, one object image) → a finished asset folder.
#include <filesystem>
#include <memory>
#include <vector>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "assetgen/asset.h"
#include "assetgen/generate.h"
#include "assetgen/views.h"
#include "cli/commands.h"
#include "cli/mesh_files.h"
#include "core/error.h"
#include "core/log.h"
#include "datasets/categories.h"
#include "io/image_io.h"
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

void RequireSingleImageModels(const fs::path& image, const fs::path& model_dir) {
  std::string missing;
  for (const std::string& f : kSingleImageModels)
    if (!fs::exists(model_dir / f)) missing += (missing.empty() ? "" : ", ") + f;
  if (missing.empty()) return;
  throw InputError(image, Msg() << "generating from a single image needs the multi-view diffusion and normal "
                                << "estimation models (missing in " << model_dir.string() << ": " << missing
                                << "; see docs/models.md), or pass --views with multi-view images and cameras");
}

// The learned front end: segmenter (classical unless --segmenter names a model), Zero123++ and the normal
// estimator, each loaded once.
MultiViewSet ViewsFromImageFile(const fs::path& file, const std::vector<double>& box_px, const fs::path& model_dir,
                                const std::string& segmenter_choice, int steps, float guidance, uint64_t seed,
                                std::vector<StageReport>* reports) {
  const ImageU8 image = ReadImage(file);
  RequireSingleImageModels(file, model_dir);
  const Box2 box = box_px.empty() ? Box2{0, 0, double(image.width()), double(image.height())}
                                  : Box2{box_px[0], box_px[1], box_px[2], box_px[3]};
  const models::Segmenter segmenter = models::Segmenter::Resolve(segmenter_choice);
  const models::MultiViewGenerator generator = models::MultiViewGenerator::Load(model_dir);
  const models::NormalEstimator normals = models::NormalEstimator::FromModel(model_dir / models::kNormalEstimatorFile);
  ImageToViewsStages stages;
  stages.segment = [&](const ImageU8& img, const Box2& b) { return segmenter.Segment(img, b).mask; };
  stages.generate_views = [&](const ImageU8& cutout) { return generator.Generate(cutout, steps, guidance, seed); };
  stages.estimate_normals = [&](const ImageF& view) { return normals.Estimate(view); };
  stages.methods = {segmenter.Describe(), generator.Describe(), normals.Describe()};
  try {
    return ViewsFromImage(image, box, stages, reports);
  } catch (const InputError& e) {
    throw InputError(file, e.what());
  }
}

nlohmann::json StagesJson(const std::vector<StageReport>& front, const GeneratedMesh& g, const std::string& source) {
  nlohmann::json stages = nlohmann::json::array();
  for (const StageReport& s : front)
    stages.push_back({{"stage", s.stage}, {"method", s.method}, {"seconds", s.seconds}});
  for (const StageReport& s : g.stages)
    stages.push_back({{"stage", s.stage}, {"method", s.method}, {"seconds", s.seconds}});
  nlohmann::json rotation = nlohmann::json::array();
  for (int r = 0; r < 3; ++r) rotation.push_back({g.rotation(r, 0), g.rotation(r, 1), g.rotation(r, 2)});
  stages.push_back({{"stage", "generate"},
                    {"version", "synthdrive 0.1.0"},
                    {"source", source},
                    {"views_to_asset",
                     {{"scale", g.scale},
                      {"rotation", rotation},
                      {"translation", {g.translation.x(), g.translation.y(), g.translation.z()}},
                      {"meaning", "p_asset = scale * rotation * p_views + translation"}}}});
  return stages;
}

}  // namespace

Runner AddGenerateCommand(CLI::App& app) {
  struct Args {
    std::string views, image, out, category, id, name, licence, source, attribution, model_dir;
    std::string segmenter = "classical";
    std::vector<double> size, box;
    int diffusion_steps = models::kZero123PlusDefaultSteps;
    float guidance = models::kZero123PlusDefaultGuidance;
    uint64_t seed = 0;
    double height = 0;
    bool overwrite = false;
    GenerateOptions options;
  };
  auto a = std::make_shared<Args>();
  auto* input = app.add_option_group("input", "what to build the asset from");
  input->add_option("--views", a->views,
                    "Views folder (cameras.json + colour images + normal maps + masks; docs/refine.md)");
  input->add_option("--image", a->image, "One object image (needs the multi-view and normal models installed)");
  input->require_option(1);
  app.add_option("--category", a->category, "Object category (see `synthdrive categories`); its size is the default scale")
      ->required();
  app.add_option("--out", a->out, "Asset folder to create")->required();
  app.add_option("--height", a->height, "Real height in metres (default: the category's)")->check(CLI::PositiveNumber);
  app.add_option("--size", a->size, "Real length width height in metres (best uniform fit)")->expected(3);
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
  app.add_option("--box", a->box, "The object's box in --image: x1 y1 x2 y2 pixels (default: the whole image)")
      ->expected(4);
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
    RefuseExisting(a->out, a->overwrite);
    const auto category = FindCategory(a->category);
    if (!category) throw InputError({}, "unknown category '" + a->category + "' (see `synthdrive categories`)");
    std::vector<StageReport> front;
    const fs::path model_dir = a->model_dir.empty() ? models::DefaultModelDir() : fs::path(a->model_dir);
    const MultiViewSet views = a->image.empty()
                                   ? LoadViews(a->views)
                                   : ViewsFromImageFile(a->image, a->box, model_dir, a->segmenter, a->diffusion_steps,
                                                        a->guidance, a->seed, &front);
    const std::string source = a->image.empty() ? a->views : a->image;
    GenerateOptions options = a->options;
    options.refine.show_progress = GetLogLevel() <= LogLevel::kInfo;
    options.canonical.up = "+z";
    if (!a->size.empty()) options.canonical.target_size = Eigen::Vector3d(a->size[0], a->size[1], a->size[2]);
    else options.canonical.target_height = a->height > 0 ? a->height : category->default_size.z();

    GeneratedMesh g;
    try {
      g = GenerateFromViews(views, options);
    } catch (const InputError& e) {
      throw InputError(a->image.empty() ? fs::path(a->views) / "cameras.json" : fs::path(a->image), e.what());
    }
    Asset asset;
    asset.mesh = std::move(g.mesh);
    if (asset.mesh.normals.empty()) asset.mesh.ComputeVertexNormals();
    asset.info.id = a->id.empty() ? fs::absolute(a->out).lexically_normal().filename().string() : a->id;
    asset.info.name = a->name.empty() ? asset.info.id : a->name;
    asset.info.category = category->name;
    asset.info.extent = g.extent;
    asset.info.licence = a->licence;
    asset.info.source = a->source.empty() ? source : a->source;
    asset.info.attribution = a->attribution;
    asset.info.stages = StagesJson(front, g, source);
    asset.info.quality = {{"refine_final_loss_normal", g.last_refine_step.loss_normal},
                          {"refine_final_loss_mask", g.last_refine_step.loss_mask},
                          {"views", views.size()}};
    SaveAsset(asset, a->out, a->overwrite, &views);
    double total = 0;
    for (const StageReport& s : front) total += s.seconds;
    for (const StageReport& s : g.stages) total += s.seconds;
    SD_LOG(Info, "asset " << asset.info.id << " (" << asset.info.category << "), " << g.extent.x() << " x "
                          << g.extent.y() << " x " << g.extent.z() << " m, " << asset.mesh.NumFaces()
                          << " triangles, " << total << " s -> " << a->out);
    return 0;
  };
}

}  // namespace sd::cli
