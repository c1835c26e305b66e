#include "geometry/normals.h"

#include <cmath>
#include <string>

#include <Eigen/Geometry>

#include "core/error.h"

namespace sd::geometry {
namespace {

void CheckFaces(size_t num_vertices, const std::vector<Eigen::Vector3i>& faces) {
  const int n = static_cast<int>(num_vertices);
  for (size_t f = 0; f < faces.size(); ++f) {
    const Eigen::Vector3i& t = faces[f];
    if ((t.array() < 0).any() || (t.array() >= n).any()) {
      throw InputError("", Msg() << "VertexNormals: face " << f << " indexes a vertex outside [0, " << n << ")");
    }
  }
}

// Unnormalised sums s_v = sum_f (b - a) x (c - a) in double: the forward and backward passes must agree on
// the exact same s_v, and float round-off in a 30k-face sum is visible in finite-difference checks.
std::vector<Eigen::Vector3d> NormalSums(const std::vector<Eigen::Vector3f>& positions,
                                        const std::vector<Eigen::Vector3i>& faces) {
  std::vector<Eigen::Vector3d> sums(positions.size(), Eigen::Vector3d::Zero());
  for (const Eigen::Vector3i& t : faces) {
    const Eigen::Vector3d a = positions[t[0]].cast<double>();
    const Eigen::Vector3d n = (positions[t[1]].cast<double>() - a).cross(positions[t[2]].cast<double>() - a);
    for (int k = 0; k < 3; ++k) sums[t[k]] += n;
  }
  return sums;
}

}  // namespace

std::vector<Eigen::Vector3f> VertexNormals(const std::vector<Eigen::Vector3f>& positions,
                                           const std::vector<Eigen::Vector3i>& faces) {
  CheckFaces(positions.size(), faces);
  const std::vector<Eigen::Vector3d> sums = NormalSums(positions, faces);
  std::vector<Eigen::Vector3f> normals(positions.size(), Eigen::Vector3f::Zero());
  for (size_t v = 0; v < sums.size(); ++v) {
    const double len = sums[v].norm();
    if (len > 0) normals[v] = (sums[v] / len).cast<float>();
  }
  return normals;
}

void VertexNormalsBackward(const std::vector<Eigen::Vector3f>& positions, const std::vector<Eigen::Vector3i>& faces,
                           const std::vector<Eigen::Vector3f>& grad_normals,
                           std::vector<Eigen::Vector3f>* grad_positions) {
  SD_CHECK(grad_positions != nullptr);
  SD_CHECK(grad_normals.size() == positions.size(),
           << "grad_normals has " << grad_normals.size() << " entries for " << positions.size() << " vertices");
  if (grad_positions->empty()) grad_positions->assign(positions.size(), Eigen::Vector3f::Zero());
  SD_CHECK(grad_positions->size() == positions.size());
  CheckFaces(positions.size(), faces);

  // n = s / |s|  =>  dL/ds = (g - n (n . g)) / |s|: only the part of g orthogonal to n moves the normal.
  const std::vector<Eigen::Vector3d> sums = NormalSums(positions, faces);
  std::vector<Eigen::Vector3d> dL_ds(positions.size(), Eigen::Vector3d::Zero());
  for (size_t v = 0; v < sums.size(); ++v) {
    const double len = sums[v].norm();
    if (len <= 0) continue;  // the normal is the constant 0 there (header contract): no gradient
    const Eigen::Vector3d n = sums[v] / len;
    const Eigen::Vector3d g = grad_normals[v].cast<double>();
    dL_ds[v] = (g - n * n.dot(g)) / len;
  }
  // Each face adds n_f = (b - a) x (c - a) = a x b + b x c + c x a to its three vertices' sums, so with
  // G = sum of dL/ds over its vertices: dL/da = (b - c) x G, dL/db = (c - a) x G, dL/dc = (a - b) x G.
  std::vector<Eigen::Vector3d> dL_dpos(positions.size(), Eigen::Vector3d::Zero());
  for (const Eigen::Vector3i& t : faces) {
    const Eigen::Vector3d G = dL_ds[t[0]] + dL_ds[t[1]] + dL_ds[t[2]];
    const Eigen::Vector3d a = positions[t[0]].cast<double>();
    const Eigen::Vector3d b = positions[t[1]].cast<double>();
    const Eigen::Vector3d c = positions[t[2]].cast<double>();
    dL_dpos[t[0]] += (b - c).cross(G);
    dL_dpos[t[1]] += (c - a).cross(G);
    dL_dpos[t[2]] += (a - b).cross(G);
  }
  for (size_t v = 0; v < positions.size(); ++v) (*grad_positions)[v] += dL_dpos[v].cast<float>();
}

}  // namespace sd::geometry
