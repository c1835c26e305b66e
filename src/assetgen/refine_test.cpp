#include "assetgen/refine.h"

#include <gtest/gtest.h>

#include <cmath>

#include "core/error.h"
#include "geometry/closest_point.h"
#include "geometry/metrics.h"
#include "geometry/test_meshes.h"
#include "geometry/topology.h"

namespace sd {
namespace {

TriangleMesh Ellipsoid(int subdivisions, const Eigen::Vector3f& radii) {
  TriangleMesh m = geometry::testing::Icosphere(subdivisions, 1.0f);
  for (auto& p : m.positions) p = p.cwiseProduct(radii);
  return m;
}

// A shape with a concavity the visual hull cannot see from the rig, so that only the normal maps can
// recover it: an ellipsoid with a dent in its top.
TriangleMesh DentedEllipsoid() {
  TriangleMesh m = Ellipsoid(5, Eigen::Vector3f(0.9f, 0.7f, 0.55f));
  for (auto& p : m.positions) {
    const float r2 = (p.x() * p.x() + p.y() * p.y()) / 0.16f;
    if (p.z() > 0) p.z() -= 0.25f * std::exp(-r2);
  }
  return m;
}

TEST(RefineMesh, ImprovesOnTheVisualHullOfAnEllipsoidWithADent) {
  const TriangleMesh gt = DentedEllipsoid();
  const MultiViewSet views = RenderOracleViews(gt, Zero123PlusPlusRig(128), 2);
  const TriangleMesh coarse = CoarseMeshFromViews(views, 48);
  RefineOptions options;
  options.steps = 20;
  options.show_progress = false;
  const RefineResult r = RefineMesh(coarse, views, options);
  ASSERT_EQ(r.log.size(), 20u);

  geometry::GeometryMetricsOptions mo;
  mo.num_samples = 20000;
  mo.iou_resolution = 64;
  const geometry::GeometryMetrics before = geometry::CompareMeshes(coarse, gt, mo);
  const geometry::GeometryMetrics after = geometry::CompareMeshes(r.mesh, gt, mo);
  EXPECT_LT(after.chamfer, 0.7 * before.chamfer) << "coarse " << before.chamfer << " refined " << after.chamfer;
  EXPECT_GT(after.normal_consistency, before.normal_consistency);
  EXPECT_GT(after.volume_iou, 0.9);
  // The loss went down and the mesh stayed a closed manifold.
  EXPECT_LT(r.log.back().loss_normal, r.log.front().loss_normal);
  const geometry::TopologyReport topo = geometry::AnalyzeTopology(static_cast<int>(r.mesh.NumVertices()), r.mesh.faces);
  EXPECT_TRUE(topo.IsWatertight()) << topo.Describe();
}

// Silhouettes alone cannot see the dent; points on the true surface (what LiDAR returns give) pull the mesh
// into it. Masks only (no normal maps, as for a real photo or a log's camera) with and without the points.
TEST(RefineMesh, PointsRecoverTheConcavityTheSilhouettesCannotSee) {
  const TriangleMesh gt = DentedEllipsoid();
  MultiViewSet views = RenderOracleViews(gt, Zero123PlusPlusRig(128), 2);
  for (MultiView& v : views) v.normals = ImageF(v.normals.width(), v.normals.height(), 3, 0.0f);
  const TriangleMesh coarse = CoarseMeshFromViews(views, 48);
  // Points in the dent and around it, as a sensor above the object would see them.
  std::vector<Eigen::Vector3f> points;
  for (const auto& p : gt.positions)
    if (p.z() > 0.1f && p.head<2>().norm() < 0.5f) points.push_back(p);
  ASSERT_GT(points.size(), 200u);
  RefineOptions options;
  options.steps = 15;
  options.lambda_normal = 0;
  options.show_progress = false;
  const RefineResult masks_only = RefineMesh(coarse, views, options);
  options.lambda_points = 10;
  const RefineResult with_points = RefineMesh(coarse, views, options, points);
  auto dent_error = [&](const TriangleMesh& m) {
    std::vector<Eigen::Vector3f> centre = {Eigen::Vector3f(0, 0, 0.55f - 0.25f)};  // the dent's floor
    return geometry::PointToSurfaceDistances(m.positions, m.faces, centre)[0];
  };
  const float before = dent_error(masks_only.mesh), after = dent_error(with_points.mesh);
  std::printf("distance of the dent's floor to the mesh: masks only %.4f, with points %.4f\n", before, after);
  EXPECT_GT(before, 0.12f);  // the hull bridges the dent, 0.25 deep
  EXPECT_LT(after, 0.04f);
  EXPECT_GT(with_points.log.back().loss_points, 0);
  EXPECT_LT(with_points.log.back().loss_points, with_points.log.front().loss_points);
  std::vector<Eigen::Vector3f> bad = {Eigen::Vector3f(0, 0, std::nanf(""))};
  EXPECT_THROW(RefineMesh(coarse, views, options, bad), InputError);
}

// Views cut by the image border: the pixels past it are unknown (MultiView::known) and must not pull the surface.
// Every view's right third is cut (its mask there empty, as a camera that did not see it would give): marked
// unknown, the sphere keeps its shape; taken as background, refinement shaves the sphere's sides away.
TEST(RefineMesh, PixelsPastTheImageBorderSuperviseNothing) {
  const TriangleMesh sphere = geometry::testing::Icosphere(3, 0.8f);
  MultiViewSet views = RenderOracleViews(sphere, Zero123PlusPlusRig(96), 2);
  for (MultiView& v : views) v.normals = ImageF(v.normals.width(), v.normals.height(), 3, 0.0f);
  RefineOptions options;
  options.steps = 10;
  options.lambda_normal = 0;
  options.show_progress = false;
  const RefineResult whole = RefineMesh(sphere, views, options);
  for (MultiView& v : views) {
    v.known = ImageF(v.mask.width(), v.mask.height(), 1, 1.0f);
    for (int y = 0; y < v.mask.height(); ++y)
      for (int x = 2 * v.mask.width() / 3; x < v.mask.width(); ++x) v.mask.at(x, y) = 0, v.known.at(x, y) = 0;
    EXPECT_FALSE(IsWhole(v));
  }
  const RefineResult known = RefineMesh(sphere, views, options);
  for (MultiView& v : views) v.known = ImageF();
  const RefineResult cut = RefineMesh(sphere, views, options);
  geometry::GeometryMetricsOptions mo;
  mo.num_samples = 20000;
  mo.iou_resolution = 64;
  const double cd_whole = geometry::CompareMeshes(whole.mesh, sphere, mo).chamfer;
  const double cd_known = geometry::CompareMeshes(known.mesh, sphere, mo).chamfer;
  const double cd_cut = geometry::CompareMeshes(cut.mesh, sphere, mo).chamfer;
  std::printf("Chamfer to the sphere: whole views %.5f, unknown pixels skipped %.5f, taken as background %.5f\n",
              cd_whole, cd_known, cd_cut);
  EXPECT_LT(cd_known, 1.4 * cd_whole);
  EXPECT_GT(cd_cut, 1.5 * cd_known);
}

TEST(RefineMesh, RejectsBadInput) {
  const TriangleMesh sphere = geometry::testing::Icosphere(2, 0.8f);
  const MultiViewSet views = RenderOracleViews(sphere, Zero123PlusPlusRig(32), 1);
  RefineOptions o;
  o.show_progress = false;
  EXPECT_THROW(RefineMesh(TriangleMesh{}, views, o), InputError);
  EXPECT_THROW(RefineMesh(sphere, MultiViewSet{}, o), InputError);

  // Two cubes sharing one edge: that edge has four faces.
  TriangleMesh nonmanifold = geometry::testing::Cube(Eigen::Vector3f(0, 0, 0), Eigen::Vector3f(1, 1, 1));
  TriangleMesh other = geometry::testing::Cube(Eigen::Vector3f(1, 1, 0), Eigen::Vector3f(2, 2, 1));
  nonmanifold.Append(other);
  try {
    RefineMesh(nonmanifold, views, o);
    FAIL() << "non-manifold mesh accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("not manifold"), std::string::npos) << e.what();
  }

  MultiViewSet mixed = views;
  mixed[2].mask = ImageF(16, 16, 1);
  EXPECT_THROW(RefineMesh(sphere, mixed, o), InputError);
  MultiViewSet bad_known = views;
  bad_known[0].known = ImageF(8, 8, 1, 1.0f);
  EXPECT_THROW(RefineMesh(sphere, bad_known, o), InputError);
  MultiViewSet resized = views;
  resized[1].view.camera.width = 64;
  EXPECT_THROW(RefineMesh(sphere, resized, o), InputError);

  RefineOptions bad = o;
  bad.steps = 0;
  EXPECT_THROW(RefineMesh(sphere, views, bad), InputError);
  bad = o;
  bad.lambda_normal = bad.lambda_mask = 0;
  EXPECT_THROW(RefineMesh(sphere, views, bad), InputError);
}

TEST(PrepareForRefinement, WeldsSeamSplitVertices) {
  // A cube whose faces each have their own vertices, as loaders produce at UV seams.
  const TriangleMesh shared = geometry::testing::Cube();
  TriangleMesh split;
  for (const auto& f : shared.faces) {
    const int base = static_cast<int>(split.positions.size());
    for (int k = 0; k < 3; ++k) split.positions.push_back(shared.positions[f[k]]);
    split.faces.emplace_back(base, base + 1, base + 2);
  }
  const TriangleMesh welded = PrepareForRefinement(split, "split cube");
  EXPECT_EQ(welded.NumVertices(), 8u);
  EXPECT_TRUE(geometry::AnalyzeTopology(8, welded.faces).IsWatertight());
}

}  // namespace
}  // namespace sd
