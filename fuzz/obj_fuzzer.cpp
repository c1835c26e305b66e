// Wavefront OBJ + MTL (io/mesh_io.h LoadObj): the input is an archive (fuzz_support.h) of the .obj, its .mtl and
// the textures the MTL names; the first .obj is loaded. Seeds: the repo's jersey barrier whole, and the first
// vertices and faces of the traffic cone and road barrier with their materials, textures shrunk.
#include <cstdlib>
#include <sstream>

#include "fuzz/fuzz_support.h"
#include "io/mesh_io.h"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  return sd::fuzz::ExpectOnlyInputErrors([&] {
    const std::filesystem::path dir = sd::fuzz::FreshCaseDir();
    for (const auto& path : sd::fuzz::WriteArchive(sd::fuzz::UnpackArchive(sd::fuzz::AsText(data, size)), dir))
      if (path.extension() == ".obj") {
        sd::LoadObj(path);
        break;
      }
  });
}

namespace {

// The OBJ's statements with at most `keep` of each vertex kind, and the faces that use only those: a small mesh
// written exactly as the real file writes it.
std::string ObjPrefix(const std::string& text, int keep) {
  std::istringstream in(text);
  std::ostringstream out;
  std::string line;
  int v = 0, vt = 0, vn = 0;
  while (std::getline(in, line)) {
    std::istringstream ls(line);
    std::string op;
    ls >> op;
    int* count = op == "v" ? &v : op == "vt" ? &vt : op == "vn" ? &vn : nullptr;
    if (count) {
      if (++*count <= keep) out << line << '\n';
      continue;
    }
    if (op == "f") {
      bool within = true;
      for (std::string corner; ls >> corner;) {
        std::istringstream parts(corner);
        for (std::string index; std::getline(parts, index, '/');)
          if (!index.empty() && std::abs(std::stoi(index)) > keep) within = false;
      }
      if (!within) continue;
    }
    out << line << '\n';
  }
  return out.str();
}

sd::fuzz::Seed ObjSeed(const std::string& folder, const std::string& stem, const std::string& texture, int keep) {
  const auto dir = sd::fuzz::RepoPath("data/assets/" + folder);
  const std::string obj = sd::fuzz::ReadBytes(dir / (stem + ".obj"));
  sd::fuzz::Archive files = {{stem + ".obj", keep > 0 ? ObjPrefix(obj, keep) : obj},
                             {stem + ".mtl", sd::fuzz::ReadBytes(dir / (stem + ".mtl"))}};
  if (!texture.empty()) {
    const std::string format = std::filesystem::path(texture).extension() == ".png" ? "png" : "jpg";
    files.emplace_back(texture, sd::fuzz::SmallImageFrom(dir / texture, 16, format));
  }
  return {stem, sd::fuzz::PackArchive(files)};
}

}  // namespace

std::vector<sd::fuzz::Seed> sd::fuzz::FuzzSeeds() {
  return {ObjSeed("procedural_jersey_barrier", "jersey_barrier", "", 0),
          ObjSeed("metadrive_traffic_cone/obj", "metadrive_traffic_cone", "cone_baseColor.jpeg", 60),
          ObjSeed("metadrive_road_barrier/obj", "metadrive_road_barrier", "lambert1_baseColor.png", 60)};
}
