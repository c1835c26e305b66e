#include <cstdio>

#include <CLI/CLI.hpp>

#include "assetgen/asset.h"
#include "assetgen/canonical.h"
#include "cli/commands.h"
#include "cli/import.h"
#include "core/log.h"
#include "datasets/categories.h"

namespace sd::cli {

Runner AddAssetCommand(CLI::App& app) {
  app.require_subcommand(1);
  auto opt = std::make_shared<ImportRequest>();
  auto size = std::make_shared<std::vector<double>>();
  CLI::App* imp = app.add_subcommand("import", "Turn a mesh file (OBJ, glTF, GLB) into a canonical, metric asset folder");
  imp->add_option("--mesh", opt->mesh, "Source mesh (.obj with .mtl, .gltf, .glb)")->required();
  imp->add_option("--category", opt->category, "Object category (see `synthdrive categories`)")->required();
  imp->add_option("--out", opt->out, "Asset folder to create")->required();
  imp->add_option("--id", opt->id, "Asset id (default: the output folder's name)");
  imp->add_option("--name", opt->name, "Human-readable name");
  imp->add_option("--up", opt->canonical.up,
                  "The source's up axis (+x -x +y -y +z -z; glTF files are +y), or auto: estimated from the convex-hull "
                  "face the object rests on stably (docs/canonical.md)")
      ->default_val("+z");
  imp->add_option("--front", opt->canonical.front,
                  "The source's front axis, or auto: from the vertical mirror plane, taller end at the back "
                  "(docs/canonical.md)")
      ->default_val("+x");
  imp->add_option("--scale", opt->canonical.scale, "Source units -> metres (default: from --height/--size or the category)");
  imp->add_option("--height", opt->height, "Target height in metres");
  imp->add_option("--size", *size, "Target length width height in metres (best uniform fit)")->expected(3);
  imp->add_option("--licence", opt->licence, "Licence of the source mesh");
  imp->add_option("--source", opt->source, "Where the mesh came from");
  imp->add_option("--attribution", opt->attribution, "Required credit");
  imp->add_flag("--overwrite", opt->overwrite, "Replace an existing asset folder");

  auto show_path = std::make_shared<std::string>();
  CLI::App* show = app.add_subcommand("show", "Print an asset's metadata after checking that it loads");
  show->add_option("dir", *show_path, "Asset folder")->required();

  return [=]() {
    if (imp->parsed()) {
      ImportRequest r = *opt;
      if (!size->empty()) r.canonical.target_size = Eigen::Vector3d((*size)[0], (*size)[1], (*size)[2]);
      const Asset a = ImportAsset(r);
      SD_LOG(Info, "asset " << a.info.id << " (" << a.info.category << "), " << a.info.extent.x() << " x " << a.info.extent.y()
                            << " x " << a.info.extent.z() << " m, " << a.mesh.NumFaces() << " triangles -> " << r.out.string());
      return 0;
    }
    const Asset a = LoadAsset(*show_path);
    std::printf("id:        %s\nname:      %s\ncategory:  %s\nextent:    %.3f x %.3f x %.3f m (length, width, height)\n"
                "triangles: %zu\ntextured:  %s\nlicence:   %s\nsource:    %s\n",
                a.info.id.c_str(), a.info.name.c_str(), a.info.category.c_str(), a.info.extent.x(), a.info.extent.y(),
                a.info.extent.z(), a.mesh.NumFaces(), a.mesh.uvs.empty() ? "no" : "yes", a.info.licence.c_str(),
                a.info.source.c_str());
    return 0;
  };
}

Runner AddCategoriesCommand(CLI::App& app) {
  return []() {
    std::printf("%-24s %-38s %-22s %-38s %s\n", "category", "nuScenes", "KITTI", "PandaSet", "default size l x w x h (m)");
    for (const auto& c : Categories())
      std::printf("%-24s %-38s %-22s %-38s %.2f x %.2f x %.2f\n", c.name.c_str(), c.nuscenes_name.c_str(), c.kitti_name.c_str(),
                  c.pandaset_name.c_str(), c.default_size.x(), c.default_size.y(), c.default_size.z());
    return 0;
  };
}

}  // namespace sd::cli
