#pragma once
// The asset folder (DESIGN.md): <dir>/asset.json, <dir>/mesh.glb (textured, metric, canonical frame),
// <dir>/preview.png. Canonical frame: metres, z up, x forward (the object's front), origin at the centre
// of its ground contact (bounding-box centre in x/y, lowest point at z = 0).
#include <filesystem>
#include <string>

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include "assetgen/views.h"
#include "core/mesh.h"

namespace sd {

struct AssetInfo {
  std::string id;        // unique, file-name safe
  std::string name;      // human readable
  std::string category;  // canonical category (datasets/categories.h)
  Eigen::Vector3d extent = Eigen::Vector3d::Zero();  // length (x), width (y), height (z), metres
  std::string licence;
  std::string source;       // where the mesh came from
  std::string attribution;  // required credit, if any
  nlohmann::json stages = nlohmann::json::array();  // pipeline stages that built it, with versions
  nlohmann::json quality = nlohmann::json::object();  // quality figures, if measured
};

// The quality figures a generated asset carries in asset.json "quality" — the names the bank's gate and
// queries use. Each is absent where it cannot be measured (one view: nothing to hold out; no LiDAR returns).
namespace quality {
// Mean silhouette IoU of the asset redrawn at real views left out of its fit (leave one out), 0..1.
inline constexpr char kHeldOutSilhouetteIou[] = "heldout_silhouette_iou";
// Median distance of the object's LiDAR returns to the asset's surface, metres.
inline constexpr char kLidarPointToMeshMedianM[] = "lidar_p2m_median_m";
// Fraction of the surface (by area) textured from real camera pixels — not from symmetry, not propagated, 0..1.
inline constexpr char kRealTextureFraction[] = "real_texture_fraction";
// 1 when the mesh is a closed 2-manifold, else 0.
inline constexpr char kWatertight[] = "watertight";
// The largest ratio, over length, width and height, of the asset's extent to the size it was built for (the log's
// box, or the category's size for a photo): well above 1, the shape is not the object's.
inline constexpr char kExtentToSize[] = "extent_to_size_max";
// An object {"prior": "revolve" | "mirror" | "extrude" | "hull" | "views", "reason": ...}: what made the unseen sides.
inline constexpr char kShapePrior[] = "shape_prior";
}  // namespace quality

struct Asset {
  AssetInfo info;
  TriangleMesh mesh;  // canonical frame
  std::filesystem::path dir;
};

// Loads an asset folder (or its asset.json). InputError naming the file for a missing/corrupt asset.json,
// a missing or unloadable mesh, an extent that disagrees with the mesh by more than 5%, or a mesh that is
// not canonical (not resting on z = 0).
Asset LoadAsset(const std::filesystem::path& dir_or_json);
// Why `id` cannot be an asset id, or "" when it can. An id names the asset in labels, the bank and file names
// derived from it: 1-200 characters, none of them a path separator or a control character, and not "." or "..".
std::string AssetIdProblem(const std::string& id);
// Writes asset.json + mesh.glb + preview.png into `dir` atomically (staging directory). Refuses an
// existing `dir` unless `overwrite`. With `views`, also <dir>/views/ (the views folder format of views.h, in the
// views' own frame; the generate stage in asset.json records "views_to_asset", how it maps to the asset's).
void SaveAsset(const Asset& asset, const std::filesystem::path& dir, bool overwrite, const MultiViewSet* views = nullptr);

}  // namespace sd
