#include "cli/hit_assets.h"

#include <chrono>

#include "assetgen/harvest.h"
#include "assetgen/mined.h"
#include "assetgen/shape_prior.h"
#include "core/error.h"
#include "core/log.h"
#include "datasets/readers.h"
#include "models/segmentation.h"

namespace sd::cli {

namespace fs = std::filesystem;

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

void SaveGenerated(GeneratedMesh g, const MultiViewSet& views, const std::vector<StageReport>& front,
                   AssetInfo info, const std::string& source, const fs::path& out, bool overwrite,
                   const nlohmann::json& quality) {
  Asset asset;
  asset.mesh = std::move(g.mesh);
  if (asset.mesh.normals.empty()) asset.mesh.ComputeVertexNormals();
  asset.info = std::move(info);
  asset.info.extent = g.extent;
  asset.info.stages = StagesJson(front, g, source);
  asset.info.quality = {{"refine_final_loss_normal", g.last_refine_step.loss_normal},
                        {"refine_final_loss_mask", g.last_refine_step.loss_mask},
                        {"views", views.size()}};
  for (const auto& [key, value] : quality.items()) asset.info.quality[key] = value;
  SaveAsset(asset, out, overwrite, &views);
  double total = 0;
  for (const StageReport& s : front) total += s.seconds;
  for (const StageReport& s : g.stages) total += s.seconds;
  SD_LOG(Info, "asset " << asset.info.id << " (" << asset.info.category << "), " << g.extent.x() << " x "
                        << g.extent.y() << " x " << g.extent.z() << " m, " << asset.mesh.NumFaces() << " triangles, "
                        << total << " s -> " << out.string());
}


namespace {

double Since(std::chrono::steady_clock::time_point start) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
}

}  // namespace

BuiltAsset HitAssetBuilder::Build(const mining::ManifestEntry& entry, const std::string& where,
                                  const CategoryInfo& category, const Eigen::Vector3d& size) {
  const mining::MinedItem& item = entry.item;
  if (item.kind != mining::SourceKind::kLog) {
    // An image hit: its crop, masked by its alpha (exact) or by the segmenter inside its box.
    const MinedObject object = LoadMinedObject(entry);
    const auto start = std::chrono::steady_clock::now();
    ImageF mask(object.image.width(), object.image.height(), 1, 0.0f);
    std::string method;
    if (object.prior && object.prior->source == "alpha") {
      for (size_t i = 0; i < mask.vector().size(); ++i) mask.vector()[i] = object.prior->mask.data()[i] > 127 ? 1.0f : 0.0f;
      method = "the image's alpha";
    } else {
      const models::Segmenter segmenter = models::Segmenter::Resolve(options_.segmenter);
      mask = segmenter.Segment(object.image, object.box).mask;
      method = segmenter.Describe() + " in the hit's box";
    }
    BuiltAsset built = PhotoAsset(object.image, mask, method, category, object.size_lwh.value_or(size), options_,
                                  object.source);
    built.front.front().seconds += Since(start);
    return built;
  }
  // A log hit: every view of its track, its returns and box.
  if (!item.box_ego) throw InputError(where, "the log hit has no 3D box to find its object by");
  const auto start = std::chrono::steady_clock::now();
  auto it = logs_.find(item.source);
  if (it == logs_.end()) {
    if (!fs::exists(item.source))
      throw InputError(where, Msg() << "the hit's log " << item.source
                                    << " is not found (a relative path is taken from the working directory)");
    it = logs_.emplace(item.source, OpenLog(item.source)).first;
  }
  HarvestOptions harvest;
  harvest.progress = false;
  const HarvestedObject object = HarvestObject(it->second, {item.frame_token, *item.box_ego}, harvest);
  BuiltAsset built;
  built.front.push_back({"harvest", Msg() << object.source << "; " << object.points.size() << " LiDAR returns, "
                                          << object.free_segments.size() << " beams", Since(start)});
  HarvestFit fit;
  built.mesh = GenerateFromHarvest(object, options_.generate, &fit);
  built.views = object.views;
  built.quality = fit.quality;
  built.source = object.source;
  return built;
}

BuiltAsset PhotoAsset(const ImageU8& photo_image, const ImageF& mask, const std::string& mask_method,
                      const CategoryInfo& category, const Eigen::Vector3d& size, const HitAssetOptions& options,
                      const std::string& source) {
  BuiltAsset built;
  built.front.push_back({"segment", mask_method, 0.0});
  const auto start = std::chrono::steady_clock::now();
  PhotoObservation photo;
  photo.image = photo_image;
  photo.mask = mask;
  ShapePriorOptions prior;
  prior.prior = options.shape;
  prior.category = category.name;
  prior.size = size;
  prior.hull_resolution = options.generate.hull_resolution;
  const PhotoShape shape = ShapeFromPhoto(photo, prior);
  built.front.push_back({"shape_prior",
                         Msg() << ToString(shape.prior) << " (" << shape.prior_reason << "), " << shape.views.size()
                               << " views, elevation " << shape.elevation_deg << " deg (" << shape.elevation_method << ")",
                         Since(start)});
  GenerateOptions o = options.generate;
  o.canonical.target_size = size;
  o.canonical.target_height.reset();
  built.mesh = GenerateFromPhotoShape(shape, o);
  built.views = MultiViewSet(shape.views.begin(), shape.views.begin() + shape.real_views);
  for (MultiView& v : built.views) v.source = source;
  const ViewAgreement agreement = AgreementAtView(built.mesh, shape.views.front(), shape.views.front().mask);
  built.quality = MeshQuality(built.mesh);
  built.quality[quality::kExtentToSize] = built.mesh.extent.cwiseQuotient(size).maxCoeff();
  built.quality[quality::kShapePrior] = {{"prior", ToString(shape.prior)}, {"reason", shape.prior_reason},
                                         {"elevation_deg", shape.elevation_deg},
                                         {"elevation_method", shape.elevation_method},
                                         {"intrinsics_assumed", shape.intrinsics_assumed}};
  built.quality["photo_silhouette_iou"] = agreement.silhouette_iou;
  built.quality["photo_masked_psnr_db"] = agreement.masked_psnr_db;
  built.source = source;
  return built;
}

}  // namespace sd::cli
