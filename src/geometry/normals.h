#pragma once
// Area-weighted vertex normals and their gradient.
//
// n_v = normalize(sum over faces f around v of (e1 x e2)_f), where (e1 x e2)_f is twice the face's area
// times its unit normal, so larger faces weigh more. Vertices whose sum vanishes get (0, 0, 0).
#include <vector>

#include <Eigen/Core>

namespace sd::geometry {

std::vector<Eigen::Vector3f> VertexNormals(const std::vector<Eigen::Vector3f>& positions,
                                           const std::vector<Eigen::Vector3i>& faces);
// Accumulates dL/dpositions into *grad_positions (resized to positions.size() if empty) from dL/dnormals.
void VertexNormalsBackward(const std::vector<Eigen::Vector3f>& positions, const std::vector<Eigen::Vector3i>& faces,
                           const std::vector<Eigen::Vector3f>& grad_normals,
                           std::vector<Eigen::Vector3f>* grad_positions);

}  // namespace sd::geometry
