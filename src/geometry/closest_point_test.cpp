#include "geometry/closest_point.h"

#include <gtest/gtest.h>

#include <cmath>
#include <limits>
#include <random>

#include "geometry/test_meshes.h"

namespace sd::geometry {
namespace {

// The nearest of a dense barycentric sampling of the triangle: the reference the exact routine must match.
float BruteForceSquaredDistance(const Eigen::Vector3f& p, const Eigen::Vector3f& a, const Eigen::Vector3f& b,
                                const Eigen::Vector3f& c) {
  constexpr int n = 200;
  float best = std::numeric_limits<float>::infinity();
  for (int i = 0; i <= n; ++i)
    for (int j = 0; i + j <= n; ++j) {
      const float u = float(i) / n, v = float(j) / n;
      best = std::min(best, (p - ((1 - u - v) * a + u * b + v * c)).squaredNorm());
    }
  return best;
}

TEST(ClosestBarycentricOnTriangle, MatchesADenseSamplingInEveryRegion) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(-1, 1);
  for (int trial = 0; trial < 200; ++trial) {
    const Eigen::Vector3f a(u(rng), u(rng), u(rng)), b(u(rng), u(rng), u(rng)), c(u(rng), u(rng), u(rng));
    const Eigen::Vector3f p = 2 * Eigen::Vector3f(u(rng), u(rng), u(rng));
    const Eigen::Vector3f w = ClosestBarycentricOnTriangle(p, a, b, c);
    EXPECT_NEAR(w.sum(), 1.0f, 1e-5f);
    EXPECT_GE(w.minCoeff(), -1e-6f);
    const float exact = (p - (w[0] * a + w[1] * b + w[2] * c)).squaredNorm();
    const float sampled = BruteForceSquaredDistance(p, a, b, c);
    // Exact is never farther than a sample; the sampling is within its spacing of the exact answer.
    EXPECT_LE(exact, sampled + 1e-5f) << "trial " << trial;
    EXPECT_NEAR(std::sqrt(exact), std::sqrt(sampled), 0.02f) << "trial " << trial;
  }
}

TEST(TriangleBvh, FindsTheSameClosestPointAsAllTriangles) {
  const TriangleMesh mesh = testing::Icosphere(3, 0.8f, {0.1f, -0.2f, 0.3f});
  const TriangleBvh bvh(mesh.positions, mesh.faces);
  std::mt19937 rng(5);
  std::uniform_real_distribution<float> u(-1.5f, 1.5f);
  for (int trial = 0; trial < 300; ++trial) {
    const Eigen::Vector3f p(u(rng), u(rng), u(rng));
    float brute = std::numeric_limits<float>::infinity();
    for (const auto& f : mesh.faces) {
      const Eigen::Vector3f &a = mesh.positions[f[0]], &b = mesh.positions[f[1]], &c = mesh.positions[f[2]];
      const Eigen::Vector3f w = ClosestBarycentricOnTriangle(p, a, b, c);
      brute = std::min(brute, (p - (w[0] * a + w[1] * b + w[2] * c)).squaredNorm());
    }
    const SurfacePoint s = bvh.Closest(p);
    ASSERT_GE(s.face, 0);
    EXPECT_NEAR(s.squared_distance, brute, 1e-6f) << "trial " << trial;
    EXPECT_NEAR((s.point - p).squaredNorm(), s.squared_distance, 1e-6f);
  }
}

TEST(PointToSurfaceDistances, AreTheDistancesToASphere) {
  // A fine icosphere is within 0.5 % of its sphere: points at radius r lie |r - 1| from it.
  const TriangleMesh sphere = testing::Icosphere(4);
  const std::vector<Eigen::Vector3f> points = {{0, 0, 1.5f}, {0.3f, 0, 0}, {0, -2, 0}, {0.6f, 0.6f, 0.6f}};
  const std::vector<float> d = PointToSurfaceDistances(sphere.positions, sphere.faces, points);
  ASSERT_EQ(d.size(), points.size());
  for (size_t i = 0; i < points.size(); ++i) EXPECT_NEAR(d[i], std::abs(points[i].norm() - 1.0f), 0.006f) << i;
}

TEST(PointToSurfaceLoss, GradientMatchesFiniteDifferences) {
  TriangleMesh mesh = testing::Icosphere(1, 0.5f);
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> jitter(-0.05f, 0.05f);
  for (auto& p : mesh.positions) p += Eigen::Vector3f(jitter(rng), jitter(rng), jitter(rng));
  // Points near the surface, inside and out, so closest points fall on faces, edges and vertices.
  std::vector<Eigen::Vector3f> points;
  std::uniform_real_distribution<float> dir(-1, 1), radius(0.35f, 0.65f);
  for (int i = 0; i < 60; ++i) points.push_back(Eigen::Vector3f(dir(rng), dir(rng), dir(rng)).normalized() * radius(rng));
  const float weight = 3.0f, max_distance = 1.0f;
  std::vector<Eigen::Vector3f> grad(mesh.positions.size(), Eigen::Vector3f::Zero());
  const double loss = PointToSurfaceLoss(mesh.positions, mesh.faces, points, weight, max_distance, &grad);
  EXPECT_GT(loss, 0);
  // Central differences in double on the float loss: h large enough for float round-off, small enough that
  // no closest point jumps to another face for most coordinates (a jump shows as an outlier, so a few are
  // allowed).
  const double h = 2e-3;
  int checked = 0, agreeing = 0;
  for (size_t v = 0; v < mesh.positions.size(); ++v)
    for (int k = 0; k < 3; ++k) {
      std::vector<Eigen::Vector3f> plus = mesh.positions, minus = mesh.positions;
      plus[v][k] += float(h), minus[v][k] -= float(h);
      const double fd = (PointToSurfaceLoss(plus, mesh.faces, points, weight, max_distance, nullptr) -
                         PointToSurfaceLoss(minus, mesh.faces, points, weight, max_distance, nullptr)) / (2 * h);
      ++checked;
      agreeing += std::abs(grad[v][k] - fd) <= 2e-3 + 2e-2 * std::abs(fd);
    }
  EXPECT_GE(agreeing, checked * 97 / 100) << agreeing << " of " << checked << " coordinates agree";
}

TEST(PointToSurfaceLoss, IgnoresPointsBeyondTheMaximumDistance) {
  const TriangleMesh sphere = testing::Icosphere(3);
  const std::vector<Eigen::Vector3f> near = {{0, 0, 1.1f}, {1.1f, 0, 0}};
  std::vector<Eigen::Vector3f> with_outlier = near;
  with_outlier.push_back({0, 0, 5});
  size_t counted = 0;
  std::vector<Eigen::Vector3f> g1(sphere.positions.size(), Eigen::Vector3f::Zero()), g2 = g1;
  const double a = PointToSurfaceLoss(sphere.positions, sphere.faces, near, 1, 0.5f, &g1);
  const double b = PointToSurfaceLoss(sphere.positions, sphere.faces, with_outlier, 1, 0.5f, &g2, &counted);
  EXPECT_EQ(counted, 2u);
  EXPECT_NEAR(a, b, 1e-9);
  EXPECT_NEAR(a, 0.01, 0.001);  // both 0.1 from the sphere
  for (size_t i = 0; i < g1.size(); ++i) EXPECT_LT((g1[i] - g2[i]).norm(), 1e-7f);
}

}  // namespace
}  // namespace sd::geometry
