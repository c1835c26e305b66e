#include "assetgen/asset.h"

#include <cmath>

#include "assetgen/preview.h"
#include "core/error.h"
#include "io/files.h"
#include "io/image_io.h"
#include "io/json.h"
#include "io/mesh_io.h"

namespace sd {
namespace fs = std::filesystem;

Asset LoadAsset(const fs::path& dir_or_json) {
  const fs::path json_path = fs::is_directory(dir_or_json) ? dir_or_json / "asset.json" : dir_or_json;
  if (!fs::exists(json_path)) {
    if (fs::is_directory(dir_or_json))
      throw InputError(dir_or_json, "not an asset folder (no asset.json); import a mesh with `synthdrive asset import`");
    throw InputError(json_path, "file not found");
  }
  const nlohmann::json j = ReadJsonFile(json_path);
  const JsonReader r(j, json_path);
  Asset a;
  a.dir = json_path.parent_path();
  a.info.id = r["id"].String();
  if (const std::string problem = AssetIdProblem(a.info.id); !problem.empty()) r["id"].Fail(problem);
  a.info.name = r.StringOr("name", a.info.id);
  a.info.category = r["category"].String();
  const JsonReader extent = r["extent_m"];
  if (extent.Size() != 3) extent.Fail("expected [length, width, height]");
  for (int k = 0; k < 3; ++k) {
    a.info.extent[k] = extent[k].Number();
    if (!(a.info.extent[k] > 0)) extent[k].Fail("extent must be positive");
  }
  a.info.licence = r.StringOr("licence", "");
  a.info.source = r.StringOr("source", "");
  a.info.attribution = r.StringOr("attribution", "");
  if (j.contains("stages")) a.info.stages = j["stages"];
  if (j.contains("quality")) a.info.quality = j["quality"];
  const fs::path mesh_path = a.dir / r.StringOr("mesh", "mesh.glb");
  a.mesh = LoadGlbZUp(mesh_path);
  if (const std::string err = a.mesh.Validate(); !err.empty()) throw InputError(mesh_path, err);
  const AlignedBox3f b = a.mesh.Bounds();
  if (std::abs(b.min.z()) > 0.02 * std::max(1.0f, b.Size().z()))
    throw InputError(mesh_path, Msg() << "mesh is not canonical: lowest point at z = " << b.min.z() << " m, expected 0");
  const Eigen::Vector3d size = b.Size().cast<double>();
  for (int k = 0; k < 3; ++k)
    if (std::abs(size[k] - a.info.extent[k]) > 0.05 * a.info.extent[k] + 1e-3)
      throw InputError(json_path, Msg() << "extent_m " << a.info.extent.transpose() << " disagrees with the mesh size "
                                        << size.transpose());
  if (a.mesh.normals.empty()) a.mesh.ComputeVertexNormals();
  return a;
}

std::string AssetIdProblem(const std::string& id) {
  if (id.empty()) return "an asset id cannot be empty";
  if (id.size() > 200) return Msg() << "an asset id of " << id.size() << " characters (at most 200)";
  if (id == "." || id == "..") return "'" + id + "' cannot be an asset id";
  for (const char c : id)
    if (c == '/' || c == '\\' || static_cast<unsigned char>(c) < 0x20 || c == 0x7f)
      return "an asset id cannot hold a path separator or a control character ('" + std::string(1, c == '/' || c == '\\' ? c : '?') + "' in it)";
  return "";
}

void SaveAsset(const Asset& asset, const fs::path& dir, bool overwrite, const MultiViewSet* views) {
  StagingDirectory out(dir, overwrite);
  nlohmann::json j;
  j["id"] = asset.info.id;
  j["name"] = asset.info.name;
  j["category"] = asset.info.category;
  j["extent_m"] = {asset.info.extent.x(), asset.info.extent.y(), asset.info.extent.z()};
  j["frame"] = "metres; z up, x forward, origin at the centre of the ground contact";
  j["mesh"] = "mesh.glb";
  j["preview"] = "preview.png";
  j["licence"] = asset.info.licence;
  j["source"] = asset.info.source;
  j["attribution"] = asset.info.attribution;
  j["stages"] = asset.info.stages;
  j["quality"] = asset.info.quality;
  SaveGlb(out.path() / "mesh.glb", asset.mesh, /*convert_z_up_to_gltf=*/true);
  WriteImage(out.path() / "preview.png", RenderPreview(asset.mesh, 320, 240));
  if (views) {
    SaveViews(*views, out.path() / "views", "camera", /*overwrite=*/false);
    j["views"] = "views/cameras.json";
  }
  WriteJsonFile(out.path() / "asset.json", j);
  out.Commit();
}

}  // namespace sd
