#include "geometry/laplacian.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Geometry>

#include "core/error.h"
#include "geometry/edge_adjacency.h"

namespace sd::geometry {
namespace {

void CheckFaces(int num_vertices, const std::vector<Eigen::Vector3i>& faces, const char* what) {
  if (num_vertices < 0) throw InputError("", Msg() << what << ": negative vertex count " << num_vertices);
  for (size_t f = 0; f < faces.size(); ++f) {
    const Eigen::Vector3i& t = faces[f];
    if ((t.array() < 0).any() || (t.array() >= num_vertices).any()) {
      throw InputError("", Msg() << what << ": face " << f << " indexes a vertex outside [0, " << num_vertices
                                 << ")");
    }
  }
}

// Assembles L = D - W from symmetric off-diagonal weights (duplicates are summed by setFromTriplets).
Eigen::SparseMatrix<float> FromOffDiagonal(int n, std::vector<Eigen::Triplet<double>>& offdiag) {
  std::vector<double> diag(n, 0.0);
  for (const auto& t : offdiag) diag[t.row()] += t.value();
  std::vector<Eigen::Triplet<float>> triplets;
  triplets.reserve(offdiag.size() + n);
  for (const auto& t : offdiag) triplets.emplace_back(t.row(), t.col(), static_cast<float>(-t.value()));
  for (int i = 0; i < n; ++i) triplets.emplace_back(i, i, static_cast<float>(diag[i]));
  Eigen::SparseMatrix<float> L(n, n);
  L.setFromTriplets(triplets.begin(), triplets.end());
  L.makeCompressed();
  return L;
}

}  // namespace

Eigen::SparseMatrix<float> UniformLaplacian(int num_vertices, const std::vector<Eigen::Vector3i>& faces) {
  CheckFaces(num_vertices, faces, "UniformLaplacian");
  // One weight per undirected edge however many faces share it; self-edges of degenerate faces carry none.
  const EdgeAdjacency adjacency = BuildEdgeAdjacency(num_vertices, faces, DegenerateFaces::kKeepProperEdges);
  std::vector<Eigen::Triplet<double>> offdiag;
  offdiag.reserve(adjacency.edges.size() * 2);
  for (const Eigen::Vector2i& e : adjacency.edges) {
    offdiag.emplace_back(e[0], e[1], 1.0);
    offdiag.emplace_back(e[1], e[0], 1.0);
  }
  return FromOffDiagonal(num_vertices, offdiag);
}

Eigen::SparseMatrix<float> CotangentLaplacian(const std::vector<Eigen::Vector3f>& positions,
                                              const std::vector<Eigen::Vector3i>& faces) {
  const int n = static_cast<int>(positions.size());
  CheckFaces(n, faces, "CotangentLaplacian");
  // |cot| is capped at 1e4 (an angle of ~0.006 degrees): sliver triangles would otherwise give unbounded
  // weights that swamp the operator.
  constexpr double kMaxCot = 1e4;
  std::vector<Eigen::Triplet<double>> offdiag;
  offdiag.reserve(faces.size() * 6);
  for (const Eigen::Vector3i& t : faces) {
    for (int k = 0; k < 3; ++k) {
      // The angle at corner k is opposite the edge (k+1, k+2); each face adds half its cotangent.
      const int i = t[(k + 1) % 3], j = t[(k + 2) % 3];
      if (i == j || i == t[k] || j == t[k]) continue;
      const Eigen::Vector3d u = (positions[i] - positions[t[k]]).cast<double>();
      const Eigen::Vector3d v = (positions[j] - positions[t[k]]).cast<double>();
      const double sine = u.cross(v).norm(), cosine = u.dot(v);
      double cot = sine > 0 ? cosine / sine : (cosine >= 0 ? kMaxCot : -kMaxCot);
      cot = std::clamp(cot, -kMaxCot, kMaxCot);
      offdiag.emplace_back(i, j, 0.5 * cot);
      offdiag.emplace_back(j, i, 0.5 * cot);
    }
  }
  return FromOffDiagonal(n, offdiag);
}

double LaplacianLoss(const Eigen::SparseMatrix<float>& L, const std::vector<Eigen::Vector3f>& positions,
                     float weight, std::vector<Eigen::Vector3f>* grad_positions) {
  const Eigen::Index n = static_cast<Eigen::Index>(positions.size());
  SD_CHECK(L.rows() == n && L.cols() == n, << "Laplacian is " << L.rows() << "x" << L.cols() << " for " << n
                                           << " vertices");
  if (n == 0) return 0.0;
  using Matrix = Eigen::Matrix<float, Eigen::Dynamic, 3, Eigen::RowMajor>;
  const Eigen::Map<const Matrix> X(positions.data()->data(), n, 3);
  const Matrix LX = L * X;
  const double loss = weight * LX.cast<double>().squaredNorm() / static_cast<double>(n);
  if (grad_positions != nullptr) {
    if (grad_positions->empty()) grad_positions->assign(positions.size(), Eigen::Vector3f::Zero());
    SD_CHECK(grad_positions->size() == positions.size());
    Eigen::Map<Matrix> G(grad_positions->data()->data(), n, 3);
    const Matrix LtLX = L.transpose() * LX;
    G += (2.0f * weight / static_cast<float>(n)) * LtLX;
  }
  return loss;
}

}  // namespace sd::geometry
