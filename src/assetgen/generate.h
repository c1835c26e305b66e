#pragma once
// The image → asset pipeline (DESIGN.md "generate"), from the multi-view stage on:
//
//   views (colour + normals + masks, Zero123++ rig or any cameras)
//     → coarse mesh: visual hull of the masks
//     → refinement: normal + silhouette supervision with continuous remeshing (refine.h)
//     → ×2 super-resolution of the colour views (models/super_resolution.h; learned when installed, else bicubic)
//     → texture: fusion onto the refined mesh, baked into a UV atlas or kept as vertex colours (texture.h, uv_atlas.h)
//     → canonical, metric frame: z up, x forward, resting on z = 0, in metres (canonical.h)
//
// The views' world frame must have +z up (true of the rig and of `synthdrive views`); the front is the views'
// +x unless CanonicalizeOptions say otherwise. The scale comes from the caller: a log's 3D box, a category's size
// prior, or an explicit height. Every stage's method and wall time are reported, so an asset records how it was
// made (asset.json "stages") and benchmarks can report seconds per stage.
#include <string>
#include <vector>

#include <Eigen/Core>

#include "assetgen/canonical.h"
#include "assetgen/refine.h"
#include "assetgen/views.h"
#include "core/mesh.h"

namespace sd {

struct GenerateOptions {
  int hull_resolution = 96;
  RefineOptions refine;
  std::string upscale = "auto";  // models::Upscaler::Resolve choice, or "none"
  std::string texture = "bake";  // "bake" (UV atlas) or "vertex"
  int texture_size = 1024;
  CanonicalizeOptions canonical;  // up "+z" (the rig's up); the scale or target size must be set
};

struct StageReport {
  std::string stage;   // "coarse_mesh", "refine", "super_resolution", "texture", "canonical"
  std::string method;  // what ran, e.g. "visual hull 96^3", "esrgan-slim-x2 ×2 (...)"
  double seconds = 0;
};

struct GeneratedMesh {
  TriangleMesh mesh;            // canonical frame, metres, textured
  Eigen::Vector3d extent;       // length, width, height, metres
  double scale = 1;             // views' world units → metres
  Eigen::Matrix3d rotation;     // views' world frame → canonical
  Eigen::Vector3d translation;  // canonical = scale · (rotation · world) + translation
  std::vector<StageReport> stages;
  RefineStepLog last_refine_step;
};

// InputError when a view has no colour image, or from any stage (refine.h, texture.h, canonical.h list them).
GeneratedMesh GenerateFromViews(const MultiViewSet& views, const GenerateOptions& options);

}  // namespace sd
