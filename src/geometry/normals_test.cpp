#include "geometry/normals.h"

#include <gtest/gtest.h>

#include <cmath>
#include <random>

#include "core/error.h"
#include "geometry/test_meshes.h"

namespace sd::geometry {
namespace {

// L = sum_v w_v . n_v for fixed random w_v: dL/dn = w, so the backward pass must match d/dp of L.
double Objective(const std::vector<Eigen::Vector3f>& positions, const std::vector<Eigen::Vector3i>& faces,
                 const std::vector<Eigen::Vector3f>& w) {
  const std::vector<Eigen::Vector3f> n = VertexNormals(positions, faces);
  double sum = 0;
  for (size_t v = 0; v < n.size(); ++v) sum += static_cast<double>(w[v].dot(n[v]));
  return sum;
}

TEST(VertexNormals, IcospherePointsRadially) {
  const TriangleMesh sphere = testing::Icosphere(3, 2.0f, Eigen::Vector3f(0.5f, -1.0f, 3.0f));
  const std::vector<Eigen::Vector3f> n = VertexNormals(sphere.positions, sphere.faces);
  ASSERT_EQ(n.size(), sphere.positions.size());
  double worst_deg = 0;
  for (size_t v = 0; v < n.size(); ++v) {
    const Eigen::Vector3f radial = (sphere.positions[v] - Eigen::Vector3f(0.5f, -1.0f, 3.0f)).normalized();
    EXPECT_NEAR(n[v].norm(), 1.0f, 1e-5f);
    worst_deg = std::max(worst_deg, std::acos(std::min(1.0, static_cast<double>(n[v].dot(radial)))) * 180 / M_PI);
  }
  // The area-weighted normal of a subdivided icosahedron deviates from the radius only by the slight
  // irregularity of the triangles around each vertex: under a degree at 3 subdivisions.
  EXPECT_LT(worst_deg, 1.0);
}

TEST(VertexNormals, IsolatedVertexGetsZeroAndBadIndexThrows) {
  std::vector<Eigen::Vector3f> p = {{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {5, 5, 5}};
  std::vector<Eigen::Vector3i> f = {{0, 1, 2}};
  const auto n = VertexNormals(p, f);
  EXPECT_TRUE(n[0].isApprox(Eigen::Vector3f::UnitZ()));
  EXPECT_EQ(n[3], Eigen::Vector3f::Zero());
  f.emplace_back(0, 1, 4);
  EXPECT_THROW(VertexNormals(p, f), InputError);
}

TEST(VertexNormalsBackward, MatchesCentralDifferences) {
  std::mt19937 rng(7);
  std::normal_distribution<float> noise(0.0f, 1.0f);
  for (int trial = 0; trial < 4; ++trial) {
    TriangleMesh m = testing::Icosphere(trial % 2 == 0 ? 1 : 2);
    for (auto& p : m.positions) p += 0.08f * Eigen::Vector3f(noise(rng), noise(rng), noise(rng));
    std::vector<Eigen::Vector3f> w(m.positions.size());
    for (auto& x : w) x = Eigen::Vector3f(noise(rng), noise(rng), noise(rng));

    std::vector<Eigen::Vector3f> grad;
    VertexNormalsBackward(m.positions, m.faces, w, &grad);
    ASSERT_EQ(grad.size(), m.positions.size());

    // Central differences in float positions with h = 1e-3 (the function is smooth at this scale; float
    // position round-off contributes ~1e-4 relative error). Tolerance: 2e-3 absolute + 1e-2 relative per
    // component, on every coordinate of up to 60 vertices.
    const float h = 1e-3f;
    double max_err = 0;
    for (size_t v = 0; v < m.positions.size() && v < 60; ++v) {
      for (int k = 0; k < 3; ++k) {
        std::vector<Eigen::Vector3f> plus = m.positions, minus = m.positions;
        plus[v][k] += h;
        minus[v][k] -= h;
        const double fd = (Objective(plus, m.faces, w) - Objective(minus, m.faces, w)) /
                          static_cast<double>(plus[v][k] - minus[v][k]);
        const double err = std::abs(fd - grad[v][k]);
        EXPECT_LE(err, 2e-3 + 1e-2 * std::abs(fd)) << "trial " << trial << " vertex " << v << " axis " << k;
        max_err = std::max(max_err, err);
      }
    }
    RecordProperty("max_abs_error_trial_" + std::to_string(trial), std::to_string(max_err));
  }
}

TEST(VertexNormalsBackward, Accumulates) {
  const TriangleMesh m = testing::Icosphere(1);
  std::vector<Eigen::Vector3f> w(m.positions.size(), Eigen::Vector3f(0.3f, -0.2f, 0.7f));
  std::vector<Eigen::Vector3f> once, twice;
  VertexNormalsBackward(m.positions, m.faces, w, &once);
  VertexNormalsBackward(m.positions, m.faces, w, &twice);
  VertexNormalsBackward(m.positions, m.faces, w, &twice);
  for (size_t v = 0; v < once.size(); ++v) EXPECT_TRUE(twice[v].isApprox(2.0f * once[v], 1e-5f));
}

}  // namespace
}  // namespace sd::geometry
