// glTF 2.0 and GLB (io/mesh_io.h LoadGltf, through tinygltf): the input is an archive (fuzz_support.h) of a .gltf
// with its buffers and images, or of one .glb; the first .gltf / .glb is loaded. Seeds: the repo's traffic cone
// and road barrier glTFs (textures shrunk), and a GLB that SaveGlb writes of the jersey barrier with a texture.
#include "fuzz/fuzz_support.h"
#include "io/image_io.h"
#include "io/mesh_io.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  return sd::fuzz::ExpectOnlyInputErrors([&] {
    const std::filesystem::path dir = sd::fuzz::FreshCaseDir();
    for (const auto& path : sd::fuzz::WriteArchive(sd::fuzz::UnpackArchive(sd::fuzz::AsText(data, size)), dir))
      if (path.extension() == ".gltf" || path.extension() == ".glb") {
        sd::LoadGltf(path);
        break;
      }
  });
}

namespace {

sd::fuzz::Seed GltfSeed(const std::string& asset, const std::vector<std::string>& textures) {
  const auto dir = sd::fuzz::RepoPath("data/assets/" + asset);
  sd::fuzz::Archive files = {{"scene.gltf", sd::fuzz::ReadBytes(dir / "scene.gltf")},
                             {"scene.bin", sd::fuzz::ReadBytes(dir / "scene.bin")}};
  for (const std::string& texture : textures) {
    const std::string format = std::filesystem::path(texture).extension() == ".png" ? "png" : "jpg";
    files.emplace_back(texture, sd::fuzz::SmallImageFrom(dir / texture, 16, format));
  }
  return {asset, sd::fuzz::PackArchive(files)};
}

}  // namespace

std::vector<sd::fuzz::Seed> sd::fuzz::FuzzSeeds() {
  TriangleMesh barrier = LoadObj(RepoPath("data/assets/procedural_jersey_barrier/jersey_barrier.obj"));
  auto texture = std::make_shared<ImageU8>(4, 4, 3, 200);
  for (Material& m : barrier.materials) m.base_color_texture = texture;
  if (barrier.uvs.empty()) barrier.uvs.assign(barrier.positions.size(), Eigen::Vector2f(0.5f, 0.5f));
  const std::filesystem::path glb = FreshCaseDir() / "barrier.glb";
  SaveGlb(glb, barrier);
  return {GltfSeed("metadrive_traffic_cone", {"textures/cone_baseColor.jpeg", "textures/cone_metallicRoughness.png",
                                              "textures/cone_normal.png"}),
          GltfSeed("metadrive_road_barrier", {"lambert1_baseColor.png", "lambert1_metallicRoughness.png",
                                              "lambert1_normal.png"}),
          {"jersey-barrier.glb", PackArchive({{"barrier.glb", ReadBytes(glb)}})}};
}
