#pragma once
// The objects of ../shared/data/assets the asset-generation benchmarks run on, and how they are loaded.
// Header-only, benchmarks only.
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "core/error.h"
#include "core/mesh.h"
#include "io/mesh_io.h"

namespace sd::bench {

namespace fs = std::filesystem;

struct BenchObject {
  std::string name, category, file, up;  // up: the file's up axis (the rig orbits about +z)
};

// Scanned ground truth (category B) and road objects (category A) in ../shared/data/assets.
inline std::vector<BenchObject> Objects() {
  return {
      {"gso_chefmate_8_frypan", "scanned", "scanned_gso/gso_chefmate_8_frypan/chefmate_8_frypan.obj", "+z"},
      {"gso_chicken_nesting", "scanned", "scanned_gso/gso_chicken_nesting/meshes/model.obj", "+z"},
      {"hope_alphabet_soup", "scanned", "scanned_hope/hope_alphabet_soup/textured.obj", "+z"},
      {"hope_bbq_sauce", "scanned", "scanned_hope/hope_bbq_sauce/bbq_sauce.obj", "+z"},
      {"hope_butter", "scanned", "scanned_hope/hope_butter/butter.obj", "+z"},
      {"hope_chocolate_pudding", "scanned", "scanned_hope/hope_chocolate_pudding/textured.obj", "+z"},
      {"hope_cream_cheese", "scanned", "scanned_hope/hope_cream_cheese/cream_cheese.obj", "+z"},
      {"hope_macaroni_and_cheese", "scanned", "scanned_hope/hope_macaroni_and_cheese/textured.obj", "+z"},
      {"hope_new_salad_dressing", "scanned", "scanned_hope/hope_new_salad_dressing/textured.obj", "+z"},
      {"hope_orange_juice", "scanned", "scanned_hope/hope_orange_juice/textured.obj", "+z"},
      {"stanford_bunny_lowres", "scanned", "scanned_stanford/stanford_bunny_lowres/bunny.obj", "+y"},
      {"ycb_banana", "scanned", "scanned_ycb/ycb_banana/textured_simple_reoriented.obj", "+z"},
      {"metadrive_traffic_cone", "road", "traffic_cone/metadrive_traffic_cone/obj/metadrive_traffic_cone.obj", "+y"},
      {"quaternius_traffic_cone", "road", "traffic_cone/quaternius_traffic_cone/obj/quaternius_traffic_cone.obj", "+y"},
      {"metadrive_road_barrier", "road", "barricade/metadrive_road_barrier/obj/metadrive_road_barrier.obj", "+y"},
      {"torcs_p406", "road", "car/torcs_p406/obj/torcs_p406.obj", "+y"},
  };
}

// Geometry only: some scans ship their OBJ without the texture the MTL names (the GSO chicken), which the
// asset loader rightly refuses; the benchmark needs the surface alone, so material lines are dropped.
inline TriangleMesh LoadGeometry(const fs::path& obj, const fs::path& scratch) {
  std::ifstream in(obj);
  if (!in) throw InputError(obj, "cannot open");
  const fs::path copy = scratch / (obj.stem().string() + "_geometry.obj");
  std::ofstream out(copy);
  for (std::string line; std::getline(in, line);)
    if (line.rfind("mtllib", 0) != 0 && line.rfind("usemtl", 0) != 0) out << line << '\n';
  out.close();
  TriangleMesh mesh = LoadMesh(copy);
  fs::remove(copy);
  return mesh;
}


}  // namespace sd::bench
