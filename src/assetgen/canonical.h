#pragma once
// Making an arbitrary mesh a canonical, metric asset: axes (up -> +z, front -> +x), metric scale, and
// the origin at the centre of the ground contact.
//
// The source axes are either named ("+y", "-z", ...) or estimated from the geometry ("auto"):
//  - up: the object is put to rest on the face of its convex hull it stands on stably (the projection of its
//    centre of mass falls inside the face) with the largest support area; near-ties go to the lower centre of
//    mass. Up = minus that face's outward normal.
//  - front: the vertical mirror plane with the smallest symmetry residual gives the front line; the sign puts
//    the taller end at the back (cabins, cargo boxes). Without a convincing mirror plane the longest
//    horizontal principal axis is used. docs/canonical.md has the rules, the ambiguities and measured figures.
#include <optional>
#include <string>

#include <Eigen/Core>

#include "core/mesh.h"

namespace sd {

struct CanonicalizeOptions {
  std::string up = "+z";      // the source's up axis: +x, -x, +y, -y, +z, -z (glTF files are +y), or "auto"
  std::string front = "+x";   // the source's front axis (perpendicular to up), or "auto"
  // Overrides `front`: any source-frame direction (made horizontal), e.g. where a log's 3D box says the object
  // in a mined crop faces (assetgen/mined.h).
  std::optional<Eigen::Vector3d> front_direction;
  double scale = 0;           // source units -> metres; 0 = derive from the targets below
  std::optional<double> target_height;  // metres; used when scale == 0
  std::optional<Eigen::Vector3d> target_size;  // (length, width, height); best uniform fit when scale == 0
};

// The canonical frame estimated from geometry alone. Directions are in the source frame.
struct FrameEstimate {
  Eigen::Matrix3d rotation;   // source -> canonical; rows = source directions of canonical x (front), y (left), z (up)
  Eigen::Vector3d up;         // unit, source frame
  Eigen::Vector3d front;      // unit, source frame, perpendicular to up
  double support_area = 0;    // area of the support polygon the object rests on (source units^2)
  double symmetry_error = 0;  // mirror-symmetry residual of the chosen front (fraction of the bounding radius)
  std::string up_method, front_method;  // which rule decided, for asset.json provenance and logs
};

struct CanonicalizeResult {
  TriangleMesh mesh;
  double scale = 1;                 // applied uniform scale
  Eigen::Matrix3d rotation;         // applied rotation (source axes -> canonical)
  Eigen::Vector3d extent;           // length, width, height after canonicalisation, metres
  std::optional<FrameEstimate> frame;  // set when up or front was "auto": the estimate that was used
};

// InputError for impossible options (unknown axis, up parallel to front, no scale source, empty mesh, "auto"
// on a mesh with no volume to rest on).
CanonicalizeResult Canonicalize(const TriangleMesh& mesh, const CanonicalizeOptions& options);
// The rotation taking `up` to +z and `front` to +x.
Eigen::Matrix3d AxesToCanonical(const std::string& up, const std::string& front);

// Estimates up and front from the geometry (see the top comment). Deterministic. InputError when the mesh
// has no triangles or is flat (its convex hull has no volume: there is no face to rest on).
// Cost: about 0.3 s for the 1k-20k-vertex meshes of the tests (2 cores).
FrameEstimate EstimateCanonicalFrame(const TriangleMesh& mesh);

}  // namespace sd
