#include "cli/hit_assets.h"

#include <chrono>
#include <cmath>

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
    PhotoObservation photo;
    photo.image = object.image;
    photo.mask = ImageF(object.image.width(), object.image.height(), 1, 0.0f);
    std::string method;
    if (object.prior && object.prior->source == "alpha") {
      for (size_t i = 0; i < photo.mask.vector().size(); ++i)
        photo.mask.vector()[i] = object.prior->mask.data()[i] > 127 ? 1.0f : 0.0f;
      method = "the image's alpha";
    } else {
      const models::Segmenter segmenter = models::Segmenter::Resolve(options_.segmenter);
      photo.mask = segmenter.Segment(object.image, object.box).mask;
      method = segmenter.Describe() + " in the hit's box";
    }
    ShapePriorOptions prior;
    prior.prior = options_.shape;
    prior.category = category.name;
    prior.size = object.size_lwh.value_or(size);
    prior.size_measured = object.size_lwh.has_value();
    return PhotoAsset(photo, prior, options_.generate, {"segment", method, Since(start)}, item.crop_file,
                      item.mask_file, object.source);
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

BuiltAsset PhotoAsset(const PhotoObservation& photo, ShapePriorOptions prior, const GenerateOptions& options,
                      StageReport segmentation, const fs::path& photo_file, const fs::path& mask_file,
                      const std::string& source) {
  BuiltAsset built;
  built.front.push_back(std::move(segmentation));
  const auto start = std::chrono::steady_clock::now();
  prior.hull_resolution = options.hull_resolution;
  PhotoShape shape;
  try {
    shape = ShapeFromPhoto(photo, prior);
  } catch (const InputError& e) {
    throw InputError(mask_file.empty() ? photo_file : mask_file, e.what());
  }
  built.front.push_back({"shape_prior",
                         Msg() << ToString(shape.prior) << " (" << shape.prior_reason << "), " << shape.views.size()
                               << " views, elevation " << shape.elevation_deg << " deg (" << shape.elevation_method << ")",
                         Since(start)});
  GenerateOptions o = options;
  o.canonical.target_size = prior.size;
  o.canonical.target_height.reset();
  try {
    built.mesh = GenerateFromPhotoShape(shape, o);
  } catch (const InputError& e) {
    throw InputError(photo_file, e.what());
  }
  built.views = shape.views;
  for (MultiView& v : built.views)
    if (!v.synthetic) v.source = source;
  // How well the asset reproduces the photo (a self-consistency figure: the photo supervised the shape;
  // held-out views are for benchmarks).
  const ViewAgreement agreement = AgreementAtView(built.mesh, shape.views.front(), shape.views.front().mask);
  built.quality = MeshQuality(built.mesh);
  built.quality[quality::kExtentToSize] = built.mesh.extent.cwiseQuotient(prior.size).maxCoeff();
  built.quality[quality::kShapePrior] = {
      {"prior", ToString(shape.prior)},
      {"reason", shape.prior_reason},
      {"silhouette_symmetry_iou", shape.symmetry_iou},
      {"axis_tilt_deg", shape.axis_tilt_deg},
      {"intrinsics_assumed", shape.intrinsics_assumed},
      {"vertical_fov_deg", 2 * std::atan(0.5 * shape.camera.height / shape.camera.fy) * 180 / 3.14159265358979323846},
      {"elevation_deg", shape.elevation_deg},
      {"elevation_method", shape.elevation_method},
      {"yaw_deg", shape.yaw_deg},
      {"yaw_method", shape.yaw_method},
      {"camera_distance_m", shape.distance_m},
      {"real_views", shape.real_views},
      {"virtual_views", int(shape.views.size()) - shape.real_views}};
  if (!shape.base_plate_note.empty()) {
    nlohmann::json plate = {{"found", shape.base_plate.has_value()}, {"how", shape.base_plate_note}};
    if (shape.base_plate)
      plate["size_m"] = {2 * shape.base_plate->half_x, 2 * shape.base_plate->half_y, shape.base_plate->thickness};
    built.quality[quality::kShapePrior]["base_plate"] = plate;
  }
  built.quality["photo_silhouette_iou"] = agreement.silhouette_iou;
  built.quality["photo_masked_psnr_db"] = agreement.masked_psnr_db;
  built.source = source;
  return built;
}

}  // namespace sd::cli
