#include "core/mesh.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"

namespace sd {

bool AlignedBox3f::ClipSegment(const Eigen::Vector3f& a, const Eigen::Vector3f& b, float* t0, float* t1) const {
  *t0 = 0, *t1 = 1;
  const Eigen::Vector3f d = b - a;
  for (int k = 0; k < 3; ++k) {
    if (std::abs(d[k]) < 1e-12f) {
      if (a[k] < min[k] || a[k] > max[k]) return false;
      continue;
    }
    float ta = (min[k] - a[k]) / d[k], tb = (max[k] - a[k]) / d[k];
    if (ta > tb) std::swap(ta, tb);
    *t0 = std::max(*t0, ta), *t1 = std::min(*t1, tb);
    if (*t0 > *t1) return false;
  }
  return true;
}

AlignedBox3f TriangleMesh::Bounds() const {
  AlignedBox3f b;
  for (const auto& p : positions) b.Extend(p);
  return b;
}

double TriangleMesh::SurfaceArea() const {
  double area = 0;
  for (const auto& f : faces) {
    const Eigen::Vector3d a = positions[f[0]].cast<double>(), b = positions[f[1]].cast<double>(),
                          c = positions[f[2]].cast<double>();
    area += 0.5 * (b - a).cross(c - a).norm();
  }
  return area;
}

Eigen::Vector3f TriangleMesh::FaceNormal(size_t face) const {
  const auto& f = faces[face];
  const Eigen::Vector3f n = (positions[f[1]] - positions[f[0]]).cross(positions[f[2]] - positions[f[0]]);
  const float len = n.norm();
  return len > 0 ? Eigen::Vector3f(n / len) : Eigen::Vector3f::Zero();
}

void TriangleMesh::ComputeVertexNormals() {
  normals.assign(positions.size(), Eigen::Vector3f::Zero());
  for (const auto& f : faces) {
    // The unnormalised cross product is twice the face area: area weighting for free.
    const Eigen::Vector3f n = (positions[f[1]] - positions[f[0]]).cross(positions[f[2]] - positions[f[0]]);
    for (int k = 0; k < 3; ++k) normals[f[k]] += n;
  }
  for (auto& n : normals) {
    const float len = n.norm();
    n = len > 0 ? Eigen::Vector3f(n / len) : Eigen::Vector3f::UnitZ();
  }
}

void TriangleMesh::Transform(const Rigid3d& T, double scale) {
  const Eigen::Matrix3f R = T.Rotation().cast<float>();
  const Eigen::Vector3f t = T.translation.cast<float>();
  const float s = static_cast<float>(scale);
  for (auto& p : positions) p = R * (s * p) + t;
  for (auto& n : normals) n = R * n;
}

void TriangleMesh::Append(const TriangleMesh& other) {
  const int vbase = static_cast<int>(positions.size());
  const int mbase = static_cast<int>(std::max<size_t>(materials.size(), 1));
  const size_t fbase = faces.size();
  // Keep optional attributes aligned: if either side has one, both get it (filled with neutral values).
  const size_t nv = positions.size() + other.positions.size();
  const bool want_uv = !uvs.empty() || !other.uvs.empty();
  const bool want_n = !normals.empty() || !other.normals.empty();
  const bool want_c = !colors.empty() || !other.colors.empty();
  if (want_uv) uvs.resize(positions.size(), Eigen::Vector2f::Zero());
  if (want_n) normals.resize(positions.size(), Eigen::Vector3f::UnitZ());
  if (want_c) colors.resize(positions.size(), Eigen::Vector4f::Ones());
  positions.insert(positions.end(), other.positions.begin(), other.positions.end());
  if (want_uv) {
    if (other.uvs.empty()) uvs.resize(nv, Eigen::Vector2f::Zero()); else uvs.insert(uvs.end(), other.uvs.begin(), other.uvs.end());
  }
  if (want_n) {
    if (other.normals.empty()) normals.resize(nv, Eigen::Vector3f::UnitZ()); else normals.insert(normals.end(), other.normals.begin(), other.normals.end());
  }
  if (want_c) {
    if (other.colors.empty()) colors.resize(nv, Eigen::Vector4f::Ones()); else colors.insert(colors.end(), other.colors.begin(), other.colors.end());
  }
  for (const auto& f : other.faces) faces.push_back(f.array() + vbase);
  if (materials.empty()) materials.push_back(Material{});
  face_material.resize(fbase, 0);
  for (size_t i = 0; i < other.faces.size(); ++i) face_material.push_back(mbase + other.MaterialOf(i));
  if (other.materials.empty()) materials.push_back(Material{});
  materials.insert(materials.end(), other.materials.begin(), other.materials.end());
}

std::string TriangleMesh::Validate() const {
  const size_t nv = positions.size();
  if (!uvs.empty() && uvs.size() != nv) return Msg() << "uv count " << uvs.size() << " != vertex count " << nv;
  if (!normals.empty() && normals.size() != nv) return Msg() << "normal count " << normals.size() << " != vertex count " << nv;
  if (!colors.empty() && colors.size() != nv) return Msg() << "colour count " << colors.size() << " != vertex count " << nv;
  if (!face_material.empty() && face_material.size() != faces.size()) return Msg() << "face material count mismatch";
  for (size_t i = 0; i < nv; ++i)
    if (!positions[i].allFinite()) return Msg() << "vertex " << i << " is not finite";
  for (size_t i = 0; i < faces.size(); ++i)
    for (int k = 0; k < 3; ++k)
      if (faces[i][k] < 0 || static_cast<size_t>(faces[i][k]) >= nv)
        return Msg() << "face " << i << " indexes vertex " << faces[i][k] << " of " << nv;
  const size_t nm = std::max<size_t>(materials.size(), 1);
  for (size_t i = 0; i < face_material.size(); ++i)
    if (face_material[i] < 0 || static_cast<size_t>(face_material[i]) >= nm) return Msg() << "face " << i << " has bad material";
  return {};
}

}  // namespace sd
