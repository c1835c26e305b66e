// `synthdrive texture`: colour views fused onto a mesh, as vertex colours or a baked UV texture atlas.
#include <filesystem>
#include <memory>

#include <CLI/CLI.hpp>

#include "assetgen/texture.h"
#include "assetgen/uv_atlas.h"
#include "assetgen/views.h"
#include "cli/commands.h"
#include "cli/mesh_files.h"
#include "core/error.h"
#include "core/log.h"
#include "io/files.h"
#include "models/super_resolution.h"

namespace sd::cli {

Runner AddTextureCommand(CLI::App& app) {
  struct Args {
    std::string mesh, views, out, mode = "bake", upscale = "auto";
    int texture_size = 1024;
    bool overwrite = false;
  };
  auto a = std::make_shared<Args>();
  app.add_option("--mesh", a->mesh, "Mesh to texture (.glb/.gltf read as z-up assets, .obj as-is)")->required();
  app.add_option("--views", a->views, "Views folder whose cameras.json names a colour \"image\" per view")->required();
  app.add_option("--out", a->out, "Textured mesh to write (.glb; .ply keeps vertex colours only)")->required();
  app.add_option("--mode", a->mode, "bake: UV atlas texture (sharp); vertex: per-vertex colours (the paper's fusion)")
      ->default_val("bake")->check(CLI::IsMember({"bake", "vertex"}));
  app.add_option("--texture-size", a->texture_size, "Atlas side in texels (bake)")->default_val(1024)->check(CLI::Range(64, 16384));
  app.add_option("--upscale", a->upscale,
                 "x2 super-resolution of the views before fusion: auto (installed ESRGAN-slim, else bicubic), "
                 "none, bicubic, an installed model name (esrgan-medium) or a .pt file")
      ->default_val("auto");
  app.add_flag("--overwrite", a->overwrite, "Replace an existing output file");

  return [a]() {
    RefuseOutputOverInputs(a->out, {a->mesh, a->views});
    RefuseExisting(a->out, a->overwrite);
    CheckMeshExtension(a->out);
    TriangleMesh mesh = ReadMeshFile(a->mesh);
    const MultiViewSet views = LoadViews(a->views);
    ColorViewSet color_views;
    for (size_t i = 0; i < views.size(); ++i) {
      if (views[i].color.empty())
        throw InputError(std::filesystem::path(a->views) / "cameras.json",
                         Msg() << "views[" << i << "] has no \"image\" (texturing needs a colour picture per view)");
      color_views.push_back({views[i].view, views[i].color, views[i].mask});
    }
    if (a->upscale != "none") {
      const models::Upscaler upscaler = models::Upscaler::Resolve(a->upscale, 2);
      SD_LOG(Info, "super-resolution of the views: " << upscaler.Describe());
      color_views = SuperResolveViews(color_views, upscaler);
    }
    mesh.uvs.clear();
    mesh.colors.clear();
    mesh.materials.clear();
    mesh.face_material.clear();
    if (a->mode == "vertex") {
      const VertexFusionResult fused = FuseVertexColors(mesh, color_views);
      mesh.colors.resize(mesh.NumVertices());
      for (size_t v = 0; v < mesh.NumVertices(); ++v) mesh.colors[v] << fused.colors[v], 1.0f;
      SD_LOG(Info, "vertex colours: " << mesh.NumVertices() << " vertices, " << fused.propagated << " propagated");
    } else {
      UvAtlasOptions atlas_options;
      atlas_options.texture_size = a->texture_size;
      UvAtlasStats stats;
      mesh = BuildUvAtlas(mesh, atlas_options, &stats);
      Material material;
      material.name = "baked";
      material.base_color_texture = std::make_shared<ImageU8>(BakeTexture(mesh, color_views, a->texture_size));
      material.base_color_texture_name = "baked.png";
      mesh.materials = {material};
      SD_LOG(Info, "baked " << a->texture_size << "x" << a->texture_size << " atlas: " << stats.charts << " charts, "
                            << static_cast<int>(100 * stats.utilisation) << "% used");
    }
    WriteMeshFile(a->out, mesh);
    return 0;
  };
}

}  // namespace sd::cli
