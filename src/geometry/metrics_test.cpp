#include "geometry/metrics.h"

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>

#include "core/error.h"
#include "geometry/test_meshes.h"

namespace sd::geometry {
namespace {

using testing::Cube;
using testing::Icosphere;

// Level 5: 20480 faces, edges ~0.035, faces within 2e-4 of the sphere — far below the effects measured here.
constexpr int kLevel = 5;

TEST(SampleSurface, UniformByAreaOnTheSurfaceAndDeterministic) {
  // Box 2 x 1 x 1: the two 2x1 faces of each orientation carry 2/10, the 1x1 faces 1/10 of the area each.
  const TriangleMesh box = Cube(Eigen::Vector3f(0, 0, 0), Eigen::Vector3f(2, 1, 1));
  const int n = 200000;
  const SurfaceSamples s = SampleSurface(box, n, 7);
  ASSERT_EQ(s.points.size(), size_t(n));
  ASSERT_EQ(s.normals.size(), size_t(n));
  int on_x_end = 0, on_z_low = 0;
  for (int i = 0; i < n; ++i) {
    const Eigen::Vector3f& p = s.points[i];
    const Eigen::Vector3f d = p.cwiseMin(Eigen::Vector3f(2, 1, 1) - p);  // distance to the nearest face per axis
    EXPECT_LT(d.minCoeff(), 1e-5f) << "sample off the surface";
    if (std::abs(p.x() - 2) < 1e-5f) {
      ++on_x_end;
      EXPECT_NEAR(s.normals[i].x(), 1.0f, 1e-6f);
    }
    if (std::abs(p.z()) < 1e-5f) ++on_z_low;
  }
  // Binomial standard deviation at p = 0.1 is ~0.0007, at 0.2 ~0.0009.
  EXPECT_NEAR(on_x_end / double(n), 0.1, 0.004);
  EXPECT_NEAR(on_z_low / double(n), 0.2, 0.004);

  const SurfaceSamples again = SampleSurface(box, n, 7);
  EXPECT_EQ(again.points, s.points);
  const SurfaceSamples other = SampleSurface(box, n, 8);
  EXPECT_NE(other.points, s.points);
  EXPECT_TRUE(SampleSurface(TriangleMesh(), 10, 1).points.empty());
}

TEST(CompareMeshes, IdenticalMeshesSitAtTheSamplingNoiseFloor) {
  const TriangleMesh sphere = Icosphere(kLevel);
  const GeometryMetrics m = CompareMeshes(sphere, sphere, {});
  // Independent sample streams: the mean NN distance between two 100k Poisson samplings of a sphere of
  // area pi (normalised units) is ~0.5 / sqrt(density) ~ 0.003.
  EXPECT_GT(m.chamfer, 0.0);
  EXPECT_LT(m.chamfer, 0.004);
  EXPECT_GT(m.fscore, 0.999);
  EXPECT_DOUBLE_EQ(m.volume_iou, 1.0);
  EXPECT_GT(m.normal_consistency, 0.995);
}

TEST(CompareMeshes, ConcentricSpheresMatchTheAnalyticValues) {
  const TriangleMesh gt = Icosphere(kLevel, 1.0f), pred = Icosphere(kLevel, 1.1f);
  const auto start = std::chrono::steady_clock::now();
  const GeometryMetrics m = CompareMeshes(pred, gt, {});
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf("CompareMeshes at defaults (100k samples, 128^3, %d + %d faces): %.3f s\n", int(pred.NumFaces()),
              int(gt.NumFaces()), seconds);
  // Radii differ by 0.1; normalised by the GT's longest side 2 that is 0.05 in both directions.
  EXPECT_NEAR(m.chamfer, 0.05, 0.05 * 0.02);
  EXPECT_NEAR(m.volume_iou, std::pow(1 / 1.1, 3), 0.01);
  EXPECT_GT(m.normal_consistency, 0.99);
  // Default tau 0.01 is well below 0.05.
  EXPECT_EQ(m.fscore, 0.0);

  GeometryMetricsOptions o;
  o.fscore_threshold = 0.045f;
  EXPECT_EQ(CompareMeshes(pred, gt, o).fscore, 0.0);
  o.fscore_threshold = 0.06f;
  const GeometryMetrics wide = CompareMeshes(pred, gt, o);
  EXPECT_EQ(wide.precision, 1.0);
  EXPECT_EQ(wide.recall, 1.0);
  EXPECT_EQ(wide.fscore, 1.0);
}

TEST(CompareMeshes, OffsetBoxesGiveTheAnalyticIou) {
  const TriangleMesh a = Cube(Eigen::Vector3f(0, 0, 0), Eigen::Vector3f(1, 1, 1));
  const TriangleMesh b = Cube(Eigen::Vector3f(0.25f, 0.25f, 0), Eigen::Vector3f(1.25f, 1.25f, 1));
  // Overlap 0.75 x 0.75 x 1 = 0.5625; union 2 - 0.5625.
  const double expected = 0.5625 / (2 - 0.5625);
  GeometryMetricsOptions o;
  o.num_samples = 1000;
  // At 128^3 over the joint bounds (1.25 wide) the faces fall inside voxels: voxel-centre counting gives
  // 76^2 / (2 * 102^2 - 76^2) = 0.384, the discretisation this resolution has.
  EXPECT_NEAR(CompareMeshes(a, b, o).volume_iou, expected, 0.01);
  // At 125^3 the voxels are 0.01 and every face lies on a voxel boundary: exact.
  o.iou_resolution = 125;
  EXPECT_NEAR(CompareMeshes(a, b, o).volume_iou, expected, 1e-9);
  EXPECT_NEAR(CompareMeshes(b, a, o).volume_iou, expected, 1e-9);
  // Disjoint boxes.
  const TriangleMesh far = Cube(Eigen::Vector3f(2, 0, 0), Eigen::Vector3f(3, 1, 1));
  EXPECT_EQ(CompareMeshes(far, a, o).volume_iou, 0.0);
}

// At an odd resolution the middle ray of every axis runs exactly along the faces' diagonals (through the
// shared edge of two triangles) on both cubes: each voxel must still count exactly one crossing per face.
TEST(CompareMeshes, RaysAlongSharedEdgesCountOnce) {
  const TriangleMesh outer = Cube(Eigen::Vector3f::Constant(-0.5f), Eigen::Vector3f::Constant(0.5f));
  const TriangleMesh inner = Cube(Eigen::Vector3f::Constant(-0.25f), Eigen::Vector3f::Constant(0.25f));
  GeometryMetricsOptions o;
  o.num_samples = 1000;
  o.iou_resolution = 127;
  // Centres -0.5 + (j + 0.5) / 127: 63 of them inside (-0.25, 0.25) per axis, all 127 inside the outer cube.
  EXPECT_NEAR(CompareMeshes(inner, outer, o).volume_iou, std::pow(63.0 / 127.0, 3), 1e-12);
}

TEST(CompareMeshes, MajorityParityToleratesASmallHole) {
  const TriangleMesh gt = Icosphere(4);
  TriangleMesh holed = gt;
  holed.faces.erase(holed.faces.begin() + 100);
  GeometryMetricsOptions o;
  o.num_samples = 1000;
  EXPECT_GT(CompareMeshes(holed, gt, o).volume_iou, 0.995);
}

TEST(CompareMeshes, IsInvariantToACommonTranslationAndScale) {
  GeometryMetricsOptions o;
  o.num_samples = 20000;
  const GeometryMetrics unit = CompareMeshes(Icosphere(4, 1.1f), Icosphere(4, 1.0f), o);
  const Eigen::Vector3f c(5, -3, 2);
  const GeometryMetrics moved = CompareMeshes(Icosphere(4, 11.0f, c), Icosphere(4, 10.0f, c), o);
  EXPECT_NEAR(moved.chamfer, unit.chamfer, 1e-4);
  EXPECT_NEAR(moved.volume_iou, unit.volume_iou, 2e-3);
}

TEST(CompareMeshes, RejectsMeshesWithoutFaces) {
  const TriangleMesh sphere = Icosphere(1);
  EXPECT_THROW(CompareMeshes(TriangleMesh(), sphere, {}), InputError);
  EXPECT_THROW(CompareMeshes(sphere, TriangleMesh(), {}), InputError);
  TriangleMesh bad = sphere;
  bad.faces[0] = Eigen::Vector3i(0, 1, 100000);
  EXPECT_THROW(CompareMeshes(bad, sphere, {}), InputError);
}

TEST(DescribeProtocol, FillsInTheOptions) {
  GeometryMetricsOptions o;
  o.num_samples = 12345;
  o.fscore_threshold = 0.02f;
  o.iou_resolution = 64;
  const std::string s = DescribeProtocol(o);
  EXPECT_NE(s.find("12345"), std::string::npos) << s;
  EXPECT_NE(s.find("0.02"), std::string::npos) << s;
  EXPECT_NE(s.find("64^3"), std::string::npos) << s;
}

}  // namespace
}  // namespace sd::geometry
