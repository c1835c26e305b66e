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
  const TriangleMesh truth_asset = g.ToAssetFrame(truth);
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

// Oracle stages: the generator "returns" renders of the true object on the grey background, the estimator its
// exact camera-frame normals, the segmenter the true mask of the photo. What ViewsFromImage adds — masks from the
// flat background, normals rotated into the rig frame, the cut-out, the checks — is then measurable exactly.
struct OracleStages {
  MultiViewSet truth_views;
  ImageF photo_mask;
  int segment_calls = 0, normal_calls = 0;
  Box2 seen_box;

  ImageToViewsStages Stages() {
    ImageToViewsStages s;
    s.segment = [this](const ImageU8&, const Box2& box) {
      ++segment_calls;
      seen_box = box;
      return photo_mask;
    };
    s.generate_views = [this](const ImageU8& cutout) {
      EXPECT_EQ(cutout.channels(), 4);
      std::vector<ImageU8> out;
      for (const MultiView& v : truth_views) {
        const ImageU8 srgb = ToSrgb8(v.color);
        ImageU8 view(srgb.width(), srgb.height(), 3);
        for (int y = 0; y < view.height(); ++y)
          for (int x = 0; x < view.width(); ++x)
            for (int c = 0; c < 3; ++c) {
              const float a = v.mask.at(x, y);
              view.at(x, y, c) = static_cast<uint8_t>(std::lround(a * srgb.at(x, y, c) + (1 - a) * kViewBackground));
            }
        out.push_back(view);
      }
      return out;
    };
    s.estimate_normals = [this](const ImageF&) {
      const MultiView& v = truth_views[static_cast<size_t>(normal_calls++)];
      const Eigen::Matrix3f R_cam_world = v.view.T_world_cam.Rotation().transpose().cast<float>();
      ImageF n(v.normals.width(), v.normals.height(), 3);
      for (int y = 0; y < n.height(); ++y)
        for (int x = 0; x < n.width(); ++x) {
          const Eigen::Vector3f c = R_cam_world * Eigen::Vector3f(v.normals.at(x, y, 0), v.normals.at(x, y, 1), v.normals.at(x, y, 2));
          for (int k = 0; k < 3; ++k) n.at(x, y, k) = c[k];
        }
      return n;
    };
    s.methods = {"oracle mask", "oracle renders", "oracle normals"};
    return s;
  }
};

TEST(ViewsFromImage, TurnsOneImageIntoRegisteredViewsThatGenerateAnAsset) {
  const TriangleMesh truth = ColouredEllipsoid();
  OracleStages oracle;
  oracle.truth_views = RenderOracleViews(truth, Zero123PlusPlusRig(96), 2);
  // The "photo": the object at another camera, on a mid-grey-free background.
  const MultiView photo = RenderOracleViews(truth, {OrbitCamera("photo", 10, 5, kRigDistance, 30, 160, 120)}, 2)[0];
  ImageU8 image = ToSrgb8(photo.color);
  oracle.photo_mask = photo.mask;
  const Box2 box{40, 10, 120, 110};

  std::vector<StageReport> reports;
  const MultiViewSet views = ViewsFromImage(image, box, oracle.Stages(), &reports);
  EXPECT_EQ(oracle.segment_calls, 1);
  EXPECT_EQ(oracle.normal_calls, 6);
  EXPECT_DOUBLE_EQ(oracle.seen_box.x2, 120);
  ASSERT_EQ(reports.size(), 3u);
  EXPECT_EQ(reports[0].method, "oracle mask");
  ASSERT_EQ(views.size(), 6u);

  double inter = 0, uni = 0, worst_normal = 0;
  for (size_t i = 0; i < 6; ++i) {
    EXPECT_EQ(views[i].view.name, oracle.truth_views[i].view.name);
    for (int y = 0; y < 96; ++y)
      for (int x = 0; x < 96; ++x) {
        const bool a = views[i].mask.at(x, y) > 0.5f, b = oracle.truth_views[i].mask.at(x, y) > 0.5f;
        inter += a && b;
        uni += a || b;
        if (a && oracle.truth_views[i].mask.at(x, y) == 1.0f) {
          for (int c = 0; c < 3; ++c)
            worst_normal = std::max(worst_normal, double(std::abs(views[i].normals.at(x, y, c) - oracle.truth_views[i].normals.at(x, y, c))));
        }
      }
  }
  std::printf("masks from the grey background: IoU %.4f; normals back in the rig frame: worst %.2g\n", inter / uni, worst_normal);
  EXPECT_GT(inter / uni, 0.97);
  EXPECT_LT(worst_normal, 1e-5);

  const GeneratedMesh g = GenerateFromViews(views, SmallOptions());
  const geometry::GeometryMetrics m = geometry::CompareMeshes(g.mesh, g.ToAssetFrame(truth), {});
  EXPECT_LT(m.chamfer, 0.01);

  // An RGBA image is its own mask: no segmentation call; an empty mask is "no object".
  ImageU8 rgba(image.width(), image.height(), 4);
  for (int y = 0; y < image.height(); ++y)
    for (int x = 0; x < image.width(); ++x) {
      for (int c = 0; c < 3; ++c) rgba.at(x, y, c) = image.at(x, y, c);
      rgba.at(x, y, 3) = static_cast<uint8_t>(std::lround(255 * photo.mask.at(x, y)));
    }
  OracleStages second;
  second.truth_views = oracle.truth_views;
  ViewsFromImage(rgba, box, second.Stages(), nullptr);
  EXPECT_EQ(second.segment_calls, 0);
  OracleStages empty;
  empty.truth_views = oracle.truth_views;
  empty.photo_mask = ImageF(image.width(), image.height(), 1, 0.0f);
  try {
    ViewsFromImage(image, box, empty.Stages(), nullptr);
    FAIL() << "an empty mask passed";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("no object found"), std::string::npos);
  }
  EXPECT_THROW(ViewsFromImage(image, Box2{500, 500, 600, 600}, oracle.Stages(), nullptr), InputError);
}

// A coarse mask from the source (a projected LiDAR mask or 3D box) keeps the segmenter off the background, and
// replaces a segmenter that finds little inside it.
TEST(ViewsFromImage, CoarsePriorMasksTheSegmenterOrReplacesIt) {
  const TriangleMesh truth = ColouredEllipsoid();
  OracleStages oracle;
  oracle.truth_views = RenderOracleViews(truth, Zero123PlusPlusRig(64), 2);
  const MultiView photo = RenderOracleViews(truth, {OrbitCamera("photo", 10, 5, kRigDistance, 30, 160, 120)}, 2)[0];
  const ImageU8 image = ToSrgb8(photo.color);
  // The segmenter's answer: the object plus a background blob a box-seeded segmenter might add.
  oracle.photo_mask = photo.mask;
  for (int y = 5; y < 25; ++y)
    for (int x = 130; x < 155; ++x) oracle.photo_mask.at(x, y) = 1.0f;
  // The prior: the object's mask grown by 3 px (coarse, but nowhere near the blob).
  SegmentationPrior prior;
  prior.source = "lidar";
  prior.grow_px = 4;
  prior.mask = ImageU8(160, 120, 1, 0);
  double object_area = 0;
  for (int y = 0; y < 120; ++y)
    for (int x = 0; x < 160; ++x) {
      object_area += photo.mask.at(x, y) > 0.5f;
      for (int dy = -3; dy <= 3; ++dy)
        for (int dx = -3; dx <= 3; ++dx) {
          const int xx = std::clamp(x + dx, 0, 159), yy = std::clamp(y + dy, 0, 119);
          if (photo.mask.at(xx, yy) > 0.5f) prior.mask.at(x, y) = 255;
        }
    }
  std::vector<StageReport> reports;
  ViewsFromImage(image, Box2{0, 0, 160, 120}, oracle.Stages(), &reports, &prior);
  EXPECT_EQ(reports[0].method, "oracle mask within the lidar mask (grown 4 px)");
  // The segmenter saw the prior's bounding box, not the whole image, so its blob was outside from the start.
  EXPECT_GT(oracle.seen_box.x1, 0);
  EXPECT_LT(oracle.seen_box.x2, 130);

  // A segmenter that finds nothing inside the prior: the prior is the mask.
  OracleStages blind;
  blind.truth_views = oracle.truth_views;
  blind.photo_mask = ImageF(160, 120, 1, 0.0f);
  reports.clear();
  ViewsFromImage(image, Box2{0, 0, 160, 120}, blind.Stages(), &reports, &prior);
  EXPECT_EQ(reports[0].method.rfind("the lidar mask (oracle mask kept only 0% of it)", 0), 0u) << reports[0].method;

  // An exact (alpha) prior is used as it is; a prior of the wrong size is refused.
  SegmentationPrior alpha = prior;
  alpha.source = "alpha";
  OracleStages exact;
  exact.truth_views = oracle.truth_views;
  ViewsFromImage(image, Box2{0, 0, 160, 120}, exact.Stages(), nullptr, &alpha);
  EXPECT_EQ(exact.segment_calls, 0);
  alpha.mask = ImageU8(80, 60, 1, 255);
  EXPECT_THROW(ViewsFromImage(image, Box2{0, 0, 160, 120}, exact.Stages(), nullptr, &alpha), InputError);
  EXPECT_GT(object_area, 500);
}

TEST(MaskFromFlatBackground, KeepsTheLargestComponentAndFillsItsHoles) {
  ImageU8 view(20, 20, 3, kViewBackground);
  for (int y = 4; y < 16; ++y)
    for (int x = 4; x < 16; ++x)
      for (int c = 0; c < 3; ++c) view.at(x, y, c) = 200;
  for (int c = 0; c < 3; ++c) {
    view.at(9, 9, c) = kViewBackground;  // a hole inside the object (e.g. a grey patch on it)
    view.at(1, 1, c) = 10;               // a speck of noise away from it
    view.at(7, 8, c) = kViewBackground + 5;  // decoder noise on the object is not background
  }
  const ImageF mask = MaskFromFlatBackground(view);
  EXPECT_EQ(mask.at(9, 9), 1.0f);
  EXPECT_EQ(mask.at(1, 1), 0.0f);
  EXPECT_EQ(mask.at(4, 4), 1.0f);
  EXPECT_EQ(mask.at(3, 4), 0.0f);
  double area = 0;
  for (float m : mask.vector()) area += m;
  EXPECT_EQ(area, 144.0);
}

}  // namespace
}  // namespace sd
