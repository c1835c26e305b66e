#pragma once
// Assets from mining hits and photos with no learned model (docs/harvest.md, docs/shape_prior.md): what
// `generate --manifest` does on a machine without the single-image models, and what `demo` runs on the repo's
// data. A log hit is harvested from its log (every view of its track, its returns); an image hit, or a photo with
// its mask, gets its category's shape prior.
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include "assetgen/asset.h"
#include "assetgen/generate.h"
#include "assetgen/shape_prior.h"
#include "datasets/categories.h"
#include "datasets/log.h"
#include "mining/query.h"

namespace sd::cli {

// asset.json "stages": the front stages (harvest, segmentation, ...), the generated mesh's, and how its views'
// frame maps to the asset's.
nlohmann::json StagesJson(const std::vector<StageReport>& front, const GeneratedMesh& g, const std::string& source);

// A generated mesh -> the asset folder (atomic). `info` carries id, name, category and provenance; extent,
// stages and quality are filled here, `quality` adding to the refinement's figures; `views` go to views/.
void SaveGenerated(GeneratedMesh g, const MultiViewSet& views, const std::vector<StageReport>& front,
                   AssetInfo info, const std::string& source, const std::filesystem::path& out, bool overwrite,
                   const nlohmann::json& quality = nlohmann::json::object());

struct BuiltAsset {
  GeneratedMesh mesh;
  MultiViewSet views;             // the real views it came from (asset views/)
  std::vector<StageReport> front;
  nlohmann::json quality;
  std::string source;             // provenance line
};

struct HitAssetOptions {
  GenerateOptions generate;
  std::string segmenter = "classical";   // models::Segmenter::Resolve choice, for image hits without alpha
  std::optional<ShapePrior> shape;       // forced prior for image hits; else the category's
};

// Builds assets from hits, keeping each log it opens for the hits that follow.
class HitAssetBuilder {
 public:
  explicit HitAssetBuilder(HitAssetOptions options) : options_(std::move(options)) {}
  // `size` is the object's metric size for image hits (a log hit has its box). InputError naming `where` (the
  // manifest line) or the file for what cannot be built.
  BuiltAsset Build(const mining::ManifestEntry& entry, const std::string& where, const CategoryInfo& category,
                   const Eigen::Vector3d& size);

 private:
  HitAssetOptions options_;
  std::map<std::string, Log> logs_;
};

// One photo and its object's mask -> an asset by the shape prior (ShapeFromPhoto, GenerateFromPhotoShape);
// `prior` says the category, size and anything known of the camera. `segmentation` is the stage that made the
// mask. quality records the prior, what it assumed, the extent against the size and the photo's self-agreement
// (photo_silhouette_iou, photo_masked_psnr_db); views are the prior's (the photo, and its synthetic copies).
// InputError naming `mask_file` (or `photo_file` when empty) for a mask no prior fits, `photo_file` otherwise.
BuiltAsset PhotoAsset(const PhotoObservation& photo, ShapePriorOptions prior, const GenerateOptions& options,
                      StageReport segmentation, const std::filesystem::path& photo_file,
                      const std::filesystem::path& mask_file, const std::string& source);

}  // namespace sd::cli
