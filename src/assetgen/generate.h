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
#include <functional>
#include <string>
#include <vector>

#include <Eigen/Core>
#include <nlohmann/json.hpp>

#include "assetgen/canonical.h"
#include "assetgen/harvest.h"
#include "assetgen/refine.h"
#include "assetgen/shape_prior.h"
#include "assetgen/texture.h"
#include "assetgen/views.h"
#include "core/box3.h"
#include "core/image.h"
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
  TextureProvenance texture_provenance;  // where the texture's colour came from (texture.h)

  // Anything given in the views' world frame (a ground-truth mesh, say) moved into the asset's frame, as the
  // asset was: positions by scale · rotation + translation, normals by the rotation.
  TriangleMesh ToAssetFrame(TriangleMesh mesh) const;
};

// InputError when a view has no colour image, or from any stage (refine.h, texture.h, canonical.h list them).
// options.refine.steps == 0 skips refinement (the coarse mesh is textured as it is).
GeneratedMesh GenerateFromViews(const MultiViewSet& views, const GenerateOptions& options);
// The no-model path from one photo (shape_prior.h): the prior's coarse mesh instead of the visual hull, not
// refined (options.refine is ignored: its views carry masks only, which the coarse mesh already fits), then the
// same back end; the prior's frame is already canonical and metric (+z up, +x front, metres): the canonical
// stage only re-grounds and centres it.
GeneratedMesh GenerateFromPhotoShape(const PhotoShape& shape, GenerateOptions options);

// The no-model path from an object harvested from a driving log (harvest.h): the shape prior's symmetry views
// (SymmetryViews) beside the real ones; the coarse mesh is the visual hull of all of them inside the metric box,
// carved by the LiDAR beams that passed the object (a view may be outvoted once there are six real ones:
// segmented masks err); refinement on the masks and the object's returns (the point term); then the same back
// end. With three or more real views, the one nearest the middle of the directions seen is held out of
// geometry and texture, and the asset redrawn there is the held-out silhouette figure; with 25 or more returns,
// every fifth is held out of the fit and the point-to-mesh figure measured on those. The harvest's frame is
// canonical and metric already.
struct HarvestFit {
  ShapePrior prior = ShapePrior::kHull;
  std::string prior_reason;
  int real_views = 0, synthetic_views = 0;
  std::vector<size_t> held_out;  // indices into the harvest's views
  nlohmann::json quality = nlohmann::json::object();  // asset.json figures (asset.h namespace quality)
};
GeneratedMesh GenerateFromHarvest(const HarvestedObject& object, GenerateOptions options, HarvestFit* fit);

// The figures every generated asset carries whatever made it (asset.h namespace quality): watertight (after
// welding the UV seams) and the real-texture fraction.
nlohmann::json MeshQuality(const GeneratedMesh& generated);

// The finished asset moved back into its views' frame and drawn (unlit base colour) at `view`: its silhouette
// IoU with `truth` (a mask of the view's size) and the PSNR of its colour against the view's, in sRGB, inside
// `truth`; pixels the view marks unknown (past its source image's border) are not judged. At a view the asset was
// made from this is a self-consistency figure, at a held-out one a test.
struct ViewAgreement {
  double silhouette_iou = 0;
  double masked_psnr_db = 0;
};
ViewAgreement AgreementAtView(const GeneratedMesh& generated, const MultiView& view, const ImageF& truth);

// The learned front of the pipeline, one object image → the views GenerateFromViews takes:
//   segment the object in its box (skipped when the image has an alpha channel: it is the mask) → RGBA cut-out
//   → multi-view generation at the Zero123++ rig → per view: the object mask (the generator paints a flat grey
//   background, kViewBackground) and camera-frame normals from the estimator, rotated into the rig's world frame.
// The stages are functions so any model set (models/multiview_diffusion.h, models/normal_estimation.h,
// models/segmentation.h) — or, in tests, oracle renders — can fill them.
struct ImageToViewsStages {
  // image + object box → object probability 0..1, image size, 1 channel
  std::function<ImageF(const ImageU8& image, const Box2& box)> segment;
  std::function<std::vector<ImageU8>(const ImageU8& object_rgba)> generate_views;  // 6 views, rig order
  std::function<ImageF(const ImageF& view_srgb)> estimate_normals;                 // OpenCV camera-frame normals
  std::vector<std::string> methods;  // one line per stage, for asset.json and logs
};
constexpr uint8_t kViewBackground = 127;  // Zero123++'s grey

// A mask the image's source already knows, for the segmentation stage. "alpha" masks are exact and used as
// they are. "lidar" (projected LiDAR returns) and "box" (a projected 3D box) masks are right about where the
// object is but coarse at its outline: the segmenter runs on the prior's bounding box, and its mask is kept
// only inside the prior grown by `grow_px`, which removes the background a box-seeded segmenter picks up. When
// the segmenter keeps less than `min_agreement` of the prior's area, the two disagree and the prior itself is
// the mask (the method in the stage report says which happened).
struct SegmentationPrior {
  ImageU8 mask;         // 1 channel, the image's size, > 127 = object
  std::string source;   // "alpha", "lidar" or "box"
  int grow_px = 6;
  double min_agreement = 0.25;
};

// InputError for an empty image, a box outside it, no object found, a prior of another size, or a generator
// that does not return 6 square views of one size. `reports` receives one StageReport per stage.
MultiViewSet ViewsFromImage(const ImageU8& image, const Box2& box, const ImageToViewsStages& stages,
                            std::vector<StageReport>* reports, const SegmentationPrior* prior = nullptr);
// The object mask of a generated view: pixels that differ from the flat background, cleaned to the largest
// connected component with its holes filled (hard 0 / 1 edges).
ImageF MaskFromFlatBackground(const ImageU8& view, uint8_t background = kViewBackground);

}  // namespace sd
