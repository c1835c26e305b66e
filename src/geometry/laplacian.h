#pragma once
// Mesh Laplacians as sparse matrices, L = D - W (symmetric positive semi-definite, rows sum to zero):
//  - uniform: W_ij = 1 for each edge ij;
//  - cotangent: W_ij = (cot a_ij + cot b_ij) / 2 over the two angles opposite edge ij (one on boundaries);
//    negative weights from obtuse angles are kept (the textbook operator); degenerate angles are clamped.
// (L x)_i is then deg_i * x_i - sum_j x_j for the uniform one: the "umbrella" vector pointing from the
// neighbours' centroid (scaled) to the vertex.
#include <vector>

#include <Eigen/Core>
#include <Eigen/SparseCore>

namespace sd::geometry {

Eigen::SparseMatrix<float> UniformLaplacian(int num_vertices, const std::vector<Eigen::Vector3i>& faces);
Eigen::SparseMatrix<float> CotangentLaplacian(const std::vector<Eigen::Vector3f>& positions,
                                              const std::vector<Eigen::Vector3i>& faces);

// Smoothness loss sum_i |(L x)_i|^2 / num_vertices for a fixed L, with its gradient
// (2 / n) L^T L x accumulated into *grad_positions (times `weight`; resized to positions.size() if empty,
// skipped if null). Returns the loss (times `weight`).
double LaplacianLoss(const Eigen::SparseMatrix<float>& L, const std::vector<Eigen::Vector3f>& positions,
                     float weight, std::vector<Eigen::Vector3f>* grad_positions);

}  // namespace sd::geometry
