// Asset folders (assetgen/asset.h LoadAsset): asset.json's fields, its checks against the mesh, and the GLB
// behind it. The input is an archive (fuzz_support.h) of the folder. Seeds: the repo's jersey barrier made into
// an asset folder as `asset import` makes one (canonical: z up, standing on z = 0, extent = the mesh's size).
#include "assetgen/asset.h"
#include "fuzz/fuzz_support.h"
#include "io/mesh_io.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  return sd::fuzz::ExpectOnlyInputErrors([&] {
    const std::filesystem::path dir = sd::fuzz::FreshCaseDir();
    sd::fuzz::WriteArchive(sd::fuzz::UnpackArchive(sd::fuzz::AsText(data, size)), dir);
    sd::LoadAsset(dir);
  });
}

std::vector<sd::fuzz::Seed> sd::fuzz::FuzzSeeds() {
  TriangleMesh mesh = LoadObj(RepoPath("data/assets/procedural_jersey_barrier/jersey_barrier.obj"));
  const float lowest = mesh.Bounds().min.z();
  for (Eigen::Vector3f& p : mesh.positions) p.z() -= lowest;
  const Eigen::Vector3f extent = mesh.Bounds().Size();
  const std::filesystem::path glb = FreshCaseDir() / "mesh.glb";
  SaveGlb(glb, mesh, /*convert_z_up_to_gltf=*/true);
  const nlohmann::json asset = {
      {"id", "jersey_barrier"}, {"name", "New Jersey barrier"}, {"category", "barrier"},
      {"extent_m", {extent.x(), extent.y(), extent.z()}}, {"mesh", "mesh.glb"}, {"licence", "CC0-1.0"},
      {"source", "tools/assets/make_jersey_barrier.py"}, {"stages", {{"import", 0.1}}}, {"quality", {{"watertight", true}}}};
  return {{"jersey-barrier", PackArchive({{"asset.json", asset.dump(2)}, {"mesh.glb", ReadBytes(glb)}})}};
}
