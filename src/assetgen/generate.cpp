#include "assetgen/generate.h"

#include <chrono>
#include <memory>

#include "assetgen/texture.h"
#include "assetgen/uv_atlas.h"
#include "core/error.h"
#include "core/log.h"
#include "models/super_resolution.h"

namespace sd {

namespace {

class StageTimer {
 public:
  explicit StageTimer(std::vector<StageReport>* reports) : reports_(reports) {}
  // Runs `body`, records its wall time under `stage` with the method it returns.
  template <typename F>
  void Run(const std::string& stage, F&& body) {
    const auto t0 = std::chrono::steady_clock::now();
    std::string method = body();
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    SD_LOG(Info, "generate: " << stage << " (" << method << ") " << s << " s");
    reports_->push_back({stage, std::move(method), s});
  }

 private:
  std::vector<StageReport>* reports_;
};

ColorViewSet ColorViewsOf(const MultiViewSet& views) {
  ColorViewSet out;
  for (size_t i = 0; i < views.size(); ++i) {
    if (views[i].color.empty())
      throw InputError({}, Msg() << "view '" << views[i].view.name << "' has no colour image (texturing needs one per view)");
    out.push_back({views[i].view, views[i].color, views[i].mask});
  }
  return out;
}

}  // namespace

GeneratedMesh GenerateFromViews(const MultiViewSet& views, const GenerateOptions& options) {
  if (views.empty()) throw InputError({}, "no views to generate from");
  if (options.texture != "bake" && options.texture != "vertex")
    throw InputError({}, Msg() << "unknown texture mode '" << options.texture << "' (bake or vertex)");
  ColorViewSet color_views = ColorViewsOf(views);
  GeneratedMesh out;
  StageTimer timer(&out.stages);

  TriangleMesh coarse;
  timer.Run("coarse_mesh", [&] {
    coarse = CoarseMeshFromViews(views, options.hull_resolution);
    return std::string(Msg() << "visual hull of " << views.size() << " masks, " << options.hull_resolution << "^3, "
                             << coarse.NumFaces() << " triangles");
  });

  TriangleMesh mesh;
  timer.Run("refine", [&] {
    RefineResult r = RefineMesh(coarse, views, options.refine);
    mesh = std::move(r.mesh);
    out.last_refine_step = r.log.back();
    return std::string(Msg() << "normal + silhouette, " << options.refine.steps << " steps x "
                             << options.refine.iterations_per_step << " iterations, " << mesh.NumFaces() << " triangles");
  });

  if (options.upscale != "none") {
    timer.Run("super_resolution", [&] {
      const models::Upscaler upscaler = models::Upscaler::Resolve(options.upscale, 2);
      color_views = SuperResolveViews(color_views, upscaler);
      return upscaler.Describe();
    });
  }

  timer.Run("texture", [&] {
    if (options.texture == "vertex") {
      const VertexFusionResult fused = FuseVertexColors(mesh, color_views);
      mesh.colors.resize(mesh.NumVertices());
      for (size_t v = 0; v < mesh.NumVertices(); ++v) mesh.colors[v] << fused.colors[v], 1.0f;
      return std::string(Msg() << "vertex colours, " << fused.propagated << " of " << mesh.NumVertices()
                               << " vertices propagated");
    }
    UvAtlasOptions atlas;
    atlas.texture_size = options.texture_size;
    UvAtlasStats stats;
    mesh = BuildUvAtlas(mesh, atlas, &stats);
    Material material;
    material.name = "baked";
    material.base_color_texture = std::make_shared<ImageU8>(BakeTexture(mesh, color_views, options.texture_size));
    material.base_color_texture_name = "baked.png";
    mesh.materials = {material};
    return std::string(Msg() << "UV atlas " << options.texture_size << "^2, " << stats.charts << " charts, "
                             << static_cast<int>(100 * stats.utilisation) << "% used");
  });

  timer.Run("canonical", [&] {
    const Eigen::Vector3f before = mesh.positions.front();
    CanonicalizeResult c = Canonicalize(mesh, options.canonical);
    out.rotation = c.rotation;
    out.scale = c.scale;
    out.translation = c.mesh.positions.front().cast<double>() - c.scale * (c.rotation * before.cast<double>());
    out.extent = c.extent;
    out.mesh = std::move(c.mesh);
    return std::string(Msg() << "up " << options.canonical.up << ", front " << options.canonical.front << ", scale "
                             << c.scale << " m per view unit");
  });
  return out;
}

}  // namespace sd
