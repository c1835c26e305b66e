#include "assetgen/canonical.h"

#include <cmath>

#include "core/error.h"

namespace sd {
namespace {

Eigen::Vector3d ParseAxis(const std::string& s) {
  if (s.size() == 2 && (s[0] == '+' || s[0] == '-')) {
    const double sign = s[0] == '+' ? 1 : -1;
    if (s[1] == 'x') return sign * Eigen::Vector3d::UnitX();
    if (s[1] == 'y') return sign * Eigen::Vector3d::UnitY();
    if (s[1] == 'z') return sign * Eigen::Vector3d::UnitZ();
  }
  throw InputError("", "unknown axis '" + s + "' (use +x, -x, +y, -y, +z or -z)");
}

}  // namespace

Eigen::Matrix3d AxesToCanonical(const std::string& up, const std::string& front) {
  const Eigen::Vector3d u = ParseAxis(up), f = ParseAxis(front);
  if (std::abs(u.dot(f)) > 0.5) throw InputError("", "up axis " + up + " and front axis " + front + " must differ");
  // Rows are the source directions that become canonical x (front), y (left = up x front), z (up).
  Eigen::Matrix3d R;
  R.row(0) = f.transpose();
  R.row(1) = u.cross(f).transpose();
  R.row(2) = u.transpose();
  return R;
}

CanonicalizeResult Canonicalize(const TriangleMesh& mesh, const CanonicalizeOptions& options) {
  if (mesh.positions.empty() || mesh.faces.empty()) throw InputError("", "mesh has no triangles");
  CanonicalizeResult r;
  r.rotation = AxesToCanonical(options.up, options.front);
  r.mesh = mesh;
  const Eigen::Matrix3f R = r.rotation.cast<float>();
  for (auto& p : r.mesh.positions) p = R * p;
  for (auto& n : r.mesh.normals) n = R * n;
  const AlignedBox3f b = r.mesh.Bounds();
  const Eigen::Vector3d size = b.Size().cast<double>();

  if (options.scale < 0 || !std::isfinite(options.scale))
    throw InputError("", Msg() << "impossible scale " << options.scale << " (must be positive)");
  if (options.target_height && !(*options.target_height > 0))
    throw InputError("", Msg() << "impossible target height " << *options.target_height << " m");
  if (options.scale > 0) {
    r.scale = options.scale;
  } else if (options.target_size) {
    // Uniform scale minimising the squared relative error over the three dimensions.
    const Eigen::Vector3d& t = *options.target_size;
    double num = 0, den = 0;
    for (int k = 0; k < 3; ++k) {
      if (size[k] <= 0 || t[k] <= 0) continue;
      num += size[k] / t[k];
      den += (size[k] / t[k]) * (size[k] / t[k]);
    }
    if (den <= 0) throw InputError("", "target size and mesh size give no scale");
    r.scale = num / den;
  } else if (options.target_height) {
    if (size.z() <= 0) throw InputError("", "mesh is flat along its up axis; cannot scale to a height");
    r.scale = *options.target_height / size.z();
  } else {
    throw InputError("", "no metric scale: give a scale, a target height or a target size");
  }
  if (!(r.scale > 0) || !std::isfinite(r.scale)) throw InputError("", Msg() << "impossible scale " << r.scale);

  // Origin at the centre of the ground contact: bbox centre in x/y, lowest point at z = 0.
  const Eigen::Vector3f offset(-b.Center().x(), -b.Center().y(), -b.min.z());
  const float s = static_cast<float>(r.scale);
  for (auto& p : r.mesh.positions) p = s * (p + offset);
  r.extent = r.scale * size;
  return r;
}

}  // namespace sd
