#include "assetgen/generate.h"

#include <gtest/gtest.h>

#include "assetgen/texture_eval.h"
#include "core/error.h"
#include "geometry/metrics.h"
#include "geometry/test_meshes.h"

namespace sd {
namespace {

// An ellipsoid (taller than wide, so the canonical scale is decided by its height) with a colour gradient from
// bottom to top, in the unit sphere as generated views have it.
TriangleMesh ColouredEllipsoid() {
  TriangleMesh mesh = geometry::testing::Icosphere(3, 1.0f);
  for (auto& p : mesh.positions) p = Eigen::Vector3f(0.6f * p.x(), 0.5f * p.y(), 0.9f * p.z());
  for (const auto& p : mesh.positions) {
    const float t = 0.5f * (p.z() / 0.9f + 1.0f);
    mesh.colors.emplace_back(0.1f + 0.8f * t, 0.3f, 0.9f - 0.8f * t, 1.0f);
  }
  return mesh;
}

TriangleMesh ToAssetFrame(TriangleMesh mesh, const GeneratedMesh& g) {
  for (auto& p : mesh.positions) p = (g.scale * (g.rotation * p.cast<double>()) + g.translation).cast<float>();
  return mesh;
}

GenerateOptions SmallOptions() {
  GenerateOptions o;
  o.hull_resolution = 48;
  o.refine.steps = 4;
  o.refine.show_progress = false;
  o.upscale = "bicubic";
  o.texture = "vertex";
  o.canonical.up = "+z";
  o.canonical.front = "+x";
  o.canonical.target_height = 0.7;  // metres, like a traffic cone's category prior
  return o;
}

TEST(GenerateFromViews, BuildsAMetricCanonicalTexturedMeshCloseToTheTruth) {
  const TriangleMesh truth = ColouredEllipsoid();
  const MultiViewSet views = RenderOracleViews(truth, Zero123PlusPlusRig(96), 2);
  const GeneratedMesh g = GenerateFromViews(views, SmallOptions());

  std::vector<std::string> stages;
  for (const StageReport& s : g.stages) stages.push_back(s.stage);
  EXPECT_EQ(stages, (std::vector<std::string>{"coarse_mesh", "refine", "super_resolution", "texture", "canonical"}));
  EXPECT_EQ(g.stages[2].method, "bicubic ×2 (classical)");

  // Metric and canonical: the height is the prior's, the object rests on z = 0, centred in x / y.
  const AlignedBox3f b = g.mesh.Bounds();
  EXPECT_NEAR(b.Size().z(), 0.7f, 1e-5f);
  EXPECT_NEAR(b.min.z(), 0.0f, 1e-6f);
  EXPECT_NEAR(b.Center().x(), 0.0f, 1e-5f);
  EXPECT_NEAR(g.extent.z(), 0.7, 1e-5);
  // The refined ellipsoid's height is within a few percent of the truth's 1.8, so the scale is ~0.7 / 1.8.
  EXPECT_NEAR(g.scale, 0.7 / 1.8, 0.03 * 0.7 / 1.8);

  // Close to the truth mapped with the asset's own transform (Chamfer in metres on a 0.7 m object).
  const TriangleMesh truth_asset = ToAssetFrame(truth, g);
  const geometry::GeometryMetrics m = geometry::CompareMeshes(g.mesh, truth_asset, {});
  std::printf("generated ellipsoid: CD %.5f m, F %.3f, IoU %.3f\n", m.chamfer, m.fscore, m.volume_iou);
  EXPECT_LT(m.chamfer, 0.01);
  EXPECT_GT(m.volume_iou, 0.9);
  // And its colours: every vertex coloured, the gradient reproduced at held-out views.
  ASSERT_EQ(g.mesh.colors.size(), g.mesh.NumVertices());
  const TextureMetrics t = CompareTextures(g.mesh, truth_asset, 96);
  std::printf("generated ellipsoid: PSNR %.2f dB, SSIM %.3f\n", t.psnr, t.ssim);
  EXPECT_GT(t.psnr, 25.0);
}

TEST(GenerateFromViews, RejectsViewsWithoutColourAndUnknownModes) {
  MultiViewSet views = RenderOracleViews(ColouredEllipsoid(), Zero123PlusPlusRig(48), 1);
  GenerateOptions bad_mode = SmallOptions();
  bad_mode.texture = "paint";
  EXPECT_THROW(GenerateFromViews(views, bad_mode), InputError);
  views[3].color = ImageF();
  try {
    GenerateFromViews(views, SmallOptions());
    FAIL() << "a view without colour was accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("has no colour image"), std::string::npos) << e.what();
  }
  EXPECT_THROW(GenerateFromViews({}, SmallOptions()), InputError);
}

}  // namespace
}  // namespace sd
