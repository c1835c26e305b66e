#pragma once
// What the synthesis benchmarks share: finding the repo's data/, and the demo's three meshes with the axes and
// scales the demo imports them with (src/cli/cmd_demo.cpp, data/README.md): y-up; the cone scaled to 0.7 m,
// the barrier and the car in metres, the barrier's front along the file's z.
#include <cstdlib>
#include <filesystem>
#include <optional>
#include <vector>

#include "assetgen/canonical.h"

namespace sd::bench {

// $SYNTHDRIVE_SOURCE_DIR, else the executable's build/bin/../../, whichever holds data/driving and data/assets.
inline std::optional<std::filesystem::path> FindRepoRoot() {
  namespace fs = std::filesystem;
  std::vector<fs::path> candidates;
  if (const char* env = std::getenv("SYNTHDRIVE_SOURCE_DIR"); env && *env) candidates.emplace_back(env);
  std::error_code ec;
  const fs::path exe = fs::read_symlink("/proc/self/exe", ec);
  if (!ec) candidates.push_back(exe.parent_path() / ".." / "..");
  for (const auto& c : candidates)
    if (fs::is_directory(c / "data" / "driving") && fs::is_directory(c / "data" / "assets")) return fs::canonical(c);
  return std::nullopt;
}

struct DemoMesh {
  const char* mesh;  // relative to data/
  const char* id;
  const char* category;
  const char* front;
  double scale, height;  // CanonicalizeOptions::scale (0 = from the height), target height (0 = none)

  CanonicalizeOptions Options() const {
    CanonicalizeOptions o;
    o.up = "+y";
    o.front = front;
    o.scale = scale;
    if (height > 0) o.target_height = height;
    return o;
  }
};

// The cone, barrier and car, in that order.
inline std::vector<DemoMesh> DemoMeshes() {
  return {{"assets/metadrive_traffic_cone/scene.gltf", "metadrive_traffic_cone", "traffic_cone", "+x", 0, 0.70},
          {"assets/metadrive_road_barrier/scene.gltf", "metadrive_road_barrier", "barrier", "+z", 1.0, 0},
          {"assets/torcs_p406/obj/torcs_p406.obj", "torcs_p406", "car", "+x", 1.0, 0}};
}

}  // namespace sd::bench
