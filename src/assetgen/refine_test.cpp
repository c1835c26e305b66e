#include "assetgen/refine.h"

#include <gtest/gtest.h>

#include "core/error.h"
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
