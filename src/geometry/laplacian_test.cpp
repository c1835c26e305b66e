#include "geometry/laplacian.h"

#include <gtest/gtest.h>

#include <random>

#include <Eigen/Dense>

#include "geometry/test_meshes.h"

namespace sd::geometry {
namespace {

void ExpectSymmetricZeroRowSumPsd(const Eigen::SparseMatrix<float>& L, double tol) {
  const Eigen::MatrixXd D = Eigen::MatrixXd(L.cast<double>());
  EXPECT_LT((D - D.transpose()).cwiseAbs().maxCoeff(), tol);
  EXPECT_LT(D.rowwise().sum().cwiseAbs().maxCoeff(), tol);
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(D);
  // Smallest eigenvalue is 0 (constants) up to round-off.
  EXPECT_GT(eig.eigenvalues().minCoeff(), -tol * eig.eigenvalues().maxCoeff());
}

TEST(UniformLaplacian, GridAndIcosphereAreSymmetricZeroRowSumPsd) {
  const TriangleMesh grid = testing::Grid(6, 5);
  const auto Lg = UniformLaplacian(static_cast<int>(grid.positions.size()), grid.faces);
  ExpectSymmetricZeroRowSumPsd(Lg, 1e-9);
  // Interior vertex (3, 2) of the grid has 6 neighbours (diagonal split), a corner (0, 0) has 3 or 2.
  EXPECT_EQ(Lg.coeff(2 * 7 + 3, 2 * 7 + 3), 6.0f);
  EXPECT_EQ(Lg.coeff(2 * 7 + 3, 2 * 7 + 4), -1.0f);

  const TriangleMesh sphere = testing::Icosphere(2);
  const auto Ls = UniformLaplacian(static_cast<int>(sphere.positions.size()), sphere.faces);
  ExpectSymmetricZeroRowSumPsd(Ls, 1e-9);
  EXPECT_EQ(Ls.coeff(0, 0), 5.0f);  // an original icosahedron vertex keeps valence 5
}

TEST(CotangentLaplacian, SymmetricZeroRowSumPsdOnIcosphere) {
  const TriangleMesh sphere = testing::Icosphere(2);
  ExpectSymmetricZeroRowSumPsd(CotangentLaplacian(sphere.positions, sphere.faces), 1e-4);
}

TEST(CotangentLaplacian, LinearFunctionOnPlanarMeshIsHarmonic) {
  // An irregular planar mesh: a grid with jittered interior vertices (still a valid triangulation).
  TriangleMesh grid = testing::Grid(8, 7, 2.0f, 1.5f);
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> jitter(-0.06f, 0.06f);
  auto interior = [&](int v) {
    const int i = v % 9, j = v / 9;
    return i > 0 && i < 8 && j > 0 && j < 7;
  };
  for (size_t v = 0; v < grid.positions.size(); ++v) {
    if (interior(static_cast<int>(v))) grid.positions[v] += Eigen::Vector3f(jitter(rng), jitter(rng), 0.0f);
  }
  const auto L = CotangentLaplacian(grid.positions, grid.faces);
  Eigen::VectorXf f(grid.positions.size());
  for (size_t v = 0; v < grid.positions.size(); ++v) {
    f[v] = 0.7f * grid.positions[v].x() - 1.3f * grid.positions[v].y() + 2.0f;
  }
  const Eigen::VectorXf Lf = L * f;
  for (size_t v = 0; v < grid.positions.size(); ++v) {
    if (interior(static_cast<int>(v))) {
      EXPECT_NEAR(Lf[v], 0.0f, 1e-4f) << "vertex " << v;
    }
  }
}

TEST(LaplacianLoss, GradientMatchesCentralDifferences) {
  TriangleMesh m = testing::Icosphere(1);
  std::mt19937 rng(11);
  std::normal_distribution<float> noise(0.0f, 0.05f);
  for (auto& p : m.positions) p += Eigen::Vector3f(noise(rng), noise(rng), noise(rng));
  for (const bool cot : {false, true}) {
    const auto L = cot ? CotangentLaplacian(m.positions, m.faces)
                       : UniformLaplacian(static_cast<int>(m.positions.size()), m.faces);
    const float weight = 0.5f;
    std::vector<Eigen::Vector3f> grad;
    const double loss = LaplacianLoss(L, m.positions, weight, &grad);
    EXPECT_GT(loss, 0.0);
    ASSERT_EQ(grad.size(), m.positions.size());
    // The loss is quadratic: central differences are exact up to float round-off (h = 1e-2 keeps that small).
    const float h = 1e-2f;
    for (size_t v = 0; v < m.positions.size(); ++v) {
      for (int k = 0; k < 3; ++k) {
        std::vector<Eigen::Vector3f> plus = m.positions, minus = m.positions;
        plus[v][k] += h;
        minus[v][k] -= h;
        const double fd = (LaplacianLoss(L, plus, weight, nullptr) - LaplacianLoss(L, minus, weight, nullptr)) /
                          static_cast<double>(plus[v][k] - minus[v][k]);
        EXPECT_NEAR(grad[v][k], fd, 1e-4 + 1e-3 * std::abs(fd)) << (cot ? "cotangent" : "uniform") << " v " << v;
      }
    }
  }
}

}  // namespace
}  // namespace sd::geometry
