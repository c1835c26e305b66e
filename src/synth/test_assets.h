#pragma once
// The repo's three demo meshes as asset folders, for the synth tests (header-only; tests only, not part of the
// library). Axes and scales as the demo uses them (data/README.md): all y-up; the cone scaled to 0.7 m, the
// barrier and the car in metres, the barrier's front along the file's z.
#include <filesystem>
#include <string>
#include <vector>

#include "assetgen/asset.h"
#include "assetgen/canonical.h"
#include "io/mesh_io.h"
#include "testing/testing.h"

namespace sd::testing {

// Canonicalises data/<mesh> and saves it as <dir>/<id>; returns the asset as LoadAsset reads it back.
inline Asset ImportTestAsset(const std::filesystem::path& dir, const std::string& mesh, const std::string& id,
                             const std::string& category, const std::string& front, double scale, double height) {
  CanonicalizeOptions o;
  o.up = "+y";
  o.front = front;
  o.scale = scale;
  if (height > 0) o.target_height = height;
  const CanonicalizeResult c = Canonicalize(LoadMesh(RepoData(mesh)), o);
  Asset a;
  a.mesh = c.mesh;
  a.mesh.ComputeVertexNormals();
  a.info.id = id;
  a.info.category = category;
  a.info.extent = c.extent;
  SaveAsset(a, dir / id, false);
  return LoadAsset(dir / id);
}

// The cone, barrier and car of the demo, in that order.
inline std::vector<Asset> ImportDemoAssets(const std::filesystem::path& dir) {
  return {ImportTestAsset(dir, "assets/metadrive_traffic_cone/scene.gltf", "cone", "traffic_cone", "+x", 0, 0.7),
          ImportTestAsset(dir, "assets/metadrive_road_barrier/scene.gltf", "barrier", "barrier", "+z", 1.0, 0),
          ImportTestAsset(dir, "assets/torcs_p406/obj/torcs_p406.obj", "car", "car", "+x", 1.0, 0)};
}

}  // namespace sd::testing
