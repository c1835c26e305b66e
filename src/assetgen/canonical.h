#pragma once
// Making an arbitrary mesh a canonical, metric asset: axes (up -> +z, front -> +x), metric scale, and
// the origin at the centre of the ground contact.
#include <optional>
#include <string>

#include <Eigen/Core>

#include "core/mesh.h"

namespace sd {

struct CanonicalizeOptions {
  std::string up = "+z";      // the source's up axis: +x, -x, +y, -y, +z, -z (glTF files are +y)
  std::string front = "+x";   // the source's front axis (perpendicular to up)
  double scale = 0;           // source units -> metres; 0 = derive from the targets below
  std::optional<double> target_height;  // metres; used when scale == 0
  std::optional<Eigen::Vector3d> target_size;  // (length, width, height); best uniform fit when scale == 0
};

struct CanonicalizeResult {
  TriangleMesh mesh;
  double scale = 1;                 // applied uniform scale
  Eigen::Matrix3d rotation;         // applied rotation (source axes -> canonical)
  Eigen::Vector3d extent;           // length, width, height after canonicalisation, metres
};

// InputError for impossible options (unknown axis, up parallel to front, no scale source, empty mesh).
CanonicalizeResult Canonicalize(const TriangleMesh& mesh, const CanonicalizeOptions& options);
// The rotation taking `up` to +z and `front` to +x.
Eigen::Matrix3d AxesToCanonical(const std::string& up, const std::string& front);

}  // namespace sd
