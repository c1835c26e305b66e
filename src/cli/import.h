#pragma once
// Mesh file -> canonical asset folder, shared by `asset import` and `demo`.
#include <filesystem>
#include <optional>
#include <string>

#include "assetgen/asset.h"
#include "assetgen/canonical.h"

namespace sd::cli {

struct ImportRequest {
  std::filesystem::path mesh, out;
  std::string category, id, name, licence, source, attribution;
  CanonicalizeOptions canonical;
  std::optional<double> height;
  bool overwrite = false;
};

// Loads, canonicalises (scale: explicit, else --height/--size, else the category's default height) and
// saves the asset folder atomically. Returns the saved asset.
Asset ImportAsset(const ImportRequest& request);

}  // namespace sd::cli
