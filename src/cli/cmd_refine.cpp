// `synthdrive refine` (coarse mesh + views -> refined mesh) and `synthdrive views` (oracle views of a mesh).
#include <cstdio>
#include <filesystem>

#include <CLI/CLI.hpp>
#include <nlohmann/json.hpp>

#include "assetgen/refine.h"
#include "assetgen/views.h"
#include "cli/commands.h"
#include "cli/mesh_files.h"
#include "core/log.h"
#include "io/files.h"
#include "io/json.h"

namespace sd::cli {

Runner AddRefineCommand(CLI::App& app) {
  struct Args {
    std::string mesh, views, out, log;
    bool overwrite = false;
    int hull_resolution = 96;
    RefineOptions options;
  };
  auto a = std::make_shared<Args>();
  app.add_option("--views", a->views, "Views folder: cameras.json + normal maps + masks (see docs/refine.md)")->required();
  app.add_option("--out", a->out, "Refined mesh to write (.glb, .ply or .obj)")->required();
  app.add_option("--mesh", a->mesh, "Coarse mesh (.glb/.gltf read as z-up assets, .obj as-is); default: the visual hull of the masks");
  app.add_option("--hull-resolution", a->hull_resolution, "Voxels along the side of the visual hull's cube (without --mesh)")
      ->default_val(96)->check(CLI::Range(16, 512));
  app.add_option("--steps", a->options.steps, "Refinement steps (remesh + optimise)")->default_val(a->options.steps);
  app.add_option("--iterations", a->options.iterations_per_step, "Optimiser iterations per step")
      ->default_val(a->options.iterations_per_step);
  app.add_option("--lambda-normal", a->options.lambda_normal, "Weight of the normal-map loss")->default_val(a->options.lambda_normal);
  app.add_option("--lambda-mask", a->options.lambda_mask, "Weight of the silhouette loss")->default_val(a->options.lambda_mask);
  app.add_option("--lambda-lap", a->options.lambda_lap, "Weight of the Laplacian smoothness loss")->default_val(a->options.lambda_lap);
  app.add_option("--edge-min", a->options.remesh.edge_length_min, "Shortest target edge, in bounding-sphere radii")
      ->default_val(a->options.remesh.edge_length_min);
  app.add_option("--edge-max", a->options.remesh.edge_length_max, "Longest target edge, in bounding-sphere radii")
      ->default_val(a->options.remesh.edge_length_max);
  app.add_option("--lr", a->options.remesh.learning_rate, "Step size relative to the target edge length")
      ->default_val(a->options.remesh.learning_rate);
  app.add_option("--log", a->log, "Also write the per-step losses and mesh sizes as JSON");
  app.add_flag("--overwrite", a->overwrite, "Replace an existing output file");

  return [a]() {
    RefuseOutputOverInputs(a->out, {a->views, a->mesh});
    if (!a->log.empty()) RefuseOutputOverInputs(a->log, {a->views, a->mesh});
    RefuseExisting(a->out, a->overwrite);
    if (!a->log.empty()) RefuseExisting(a->log, a->overwrite);
    CheckMeshExtension(a->out);
    const MultiViewSet views = LoadViews(a->views);
    TriangleMesh coarse;
    if (!a->mesh.empty()) {
      coarse = PrepareForRefinement(ReadMeshFile(a->mesh), a->mesh);
    } else {
      coarse = CoarseMeshFromViews(views, a->hull_resolution);
      SD_LOG(Info, "coarse mesh: visual hull of " << views.size() << " masks, " << coarse.NumFaces() << " triangles");
    }
    const RefineResult r = RefineMesh(coarse, views, a->options);
    const RefineStepLog& last = r.log.back();
    SD_LOG(Info, "refined in " << r.seconds << " s: " << coarse.NumFaces() << " -> " << r.mesh.NumFaces()
                               << " triangles; last losses normal " << last.loss_normal << ", mask " << last.loss_mask);
    WriteMeshFile(a->out, r.mesh);
    if (!a->log.empty()) {
      nlohmann::json steps = nlohmann::json::array();
      for (const auto& s : r.log)
        steps.push_back({{"step", s.step}, {"loss_normal", s.loss_normal}, {"loss_mask", s.loss_mask}, {"loss_lap", s.loss_lap},
                         {"vertices", s.vertices}, {"faces", s.faces}, {"mean_target_edge", s.mean_target_edge},
                         {"seconds", s.seconds}});
      WriteJsonFile(a->log, {{"mesh", a->mesh}, {"views", a->views}, {"out", a->out}, {"seconds", r.seconds}, {"steps", steps}});
    }
    return 0;
  };
}

Runner AddViewsCommand(CLI::App& app) {
  struct Args {
    std::string mesh, out, frame = "camera";
    int size = 320, supersample = 2;
    OracleDegradation degradation;
    bool overwrite = false;
  };
  auto a = std::make_shared<Args>();
  app.add_option("--mesh", a->mesh, "Mesh to render (.glb/.gltf read as z-up assets, .obj as-is)")->required();
  app.add_option("--out", a->out, "Views folder to create")->required();
  app.add_option("--size", a->size, "Image size in pixels (square)")->default_val(320)->check(CLI::Range(16, 4096));
  app.add_option("--supersample", a->supersample, "Samples per pixel along each axis")->default_val(2)->check(CLI::Range(1, 8));
  app.add_option("--normal-frame", a->frame, "Frame of the normal maps on disk")->default_val("camera")
      ->check(CLI::IsMember({"camera", "world"}));
  app.add_option("--blur", a->degradation.blur_sigma_px, "Gaussian blur sigma in pixels")->default_val(0)->check(CLI::NonNegativeNumber);
  app.add_option("--noise", a->degradation.normal_noise, "Normal noise sigma per component")->default_val(0)->check(CLI::NonNegativeNumber);
  app.add_option("--pose-error", a->degradation.pose_error_deg, "Rendering-camera rotation error in degrees")
      ->default_val(0)->check(CLI::NonNegativeNumber);
  app.add_option("--seed", a->degradation.seed, "Seed of the degradations")->default_val(1);
  app.add_flag("--overwrite", a->overwrite, "Replace an existing views folder");
  app.footer("Renders the Zero123++ v1.2 rig (6 views) around the mesh's bounding sphere: oracle normal maps and masks,\n"
             "optionally degraded, in the folder format `synthdrive refine --views` reads.");

  return [a]() {
    RefuseOutputOverInputs(a->out, {a->mesh});
    const TriangleMesh mesh = ReadMeshFile(a->mesh);
    // The rig is defined for the unit sphere; place it around this mesh's bounding sphere instead of moving the
    // mesh, so views, refined meshes and the ground truth share the mesh's own frame.
    const SphereNormalization n = NormalizeIntoSphere(mesh);
    std::vector<ViewCamera> rig = Zero123PlusPlusRig(a->size);
    for (ViewCamera& v : rig) v.T_world_cam.translation = v.T_world_cam.translation / n.scale + n.centre.cast<double>();
    OracleDegradation d = a->degradation;
    d.pose_error_translation = 0;
    const MultiViewSet views = RenderOracleViews(mesh, rig, a->supersample, d);
    SaveViews(views, a->out, a->frame, a->overwrite);
    SD_LOG(Info, "wrote " << views.size() << " views of " << a->mesh << " to " << a->out);
    return 0;
  };
}

}  // namespace sd::cli
