#pragma once
// Indexed triangle mesh with optional per-vertex UVs, normals and colours, and per-face materials.
//
// Layout: attribute arrays are either empty or have one entry per vertex (loaders split vertices where a
// format indexes attributes separately, e.g. OBJ). Faces are counter-clockwise seen from outside.
// UV convention: glTF's — (0, 0) is the top-left of the texture image, v grows downwards. OBJ's
// bottom-left origin is converted by the loader (v_gltf = 1 - v_obj).
// Colours (vertex colours, material factors) are linear RGBA; textures are kept as sRGB 8-bit images.
// Units are whatever the source file used until an asset is made canonical (metres, z up, x forward).
#include <memory>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/image.h"
#include "core/rigid3.h"

namespace sd {

struct Material {
  std::string name;
  Eigen::Vector4f base_color_factor = Eigen::Vector4f::Ones();  // linear RGBA, multiplies the texture
  std::shared_ptr<const ImageU8> base_color_texture;             // sRGB, may be null
  std::string base_color_texture_name;                           // file name it came from, for export
  float metallic = 0.0f, roughness = 1.0f;
};

struct AlignedBox3f {
  Eigen::Vector3f min = Eigen::Vector3f::Constant(std::numeric_limits<float>::max());
  Eigen::Vector3f max = Eigen::Vector3f::Constant(-std::numeric_limits<float>::max());
  void Extend(const Eigen::Vector3f& p) { min = min.cwiseMin(p); max = max.cwiseMax(p); }
  Eigen::Vector3f Size() const { return max - min; }
  Eigen::Vector3f Center() const { return 0.5f * (min + max); }
  bool IsEmpty() const { return (max.array() < min.array()).any(); }
  // The part of the segment a + t (b - a), t in [0, 1], inside the box (slabs): true and *t0 <= *t1 when it meets it.
  bool ClipSegment(const Eigen::Vector3f& a, const Eigen::Vector3f& b, float* t0, float* t1) const;
};

struct TriangleMesh {
  std::vector<Eigen::Vector3f> positions;
  std::vector<Eigen::Vector3i> faces;
  std::vector<Eigen::Vector2f> uvs;      // empty or per vertex
  std::vector<Eigen::Vector3f> normals;  // empty or per vertex, unit length
  std::vector<Eigen::Vector4f> colors;   // empty or per vertex, linear RGBA
  std::vector<int> face_material;        // empty (all faces use material 0) or per face
  std::vector<Material> materials;       // may be empty: a default white material is implied

  size_t NumVertices() const { return positions.size(); }
  size_t NumFaces() const { return faces.size(); }
  int MaterialOf(size_t face) const { return face_material.empty() ? 0 : face_material[face]; }

  AlignedBox3f Bounds() const;
  double SurfaceArea() const;
  // Area-weighted vertex normals (overwrites `normals`).
  void ComputeVertexNormals();
  Eigen::Vector3f FaceNormal(size_t face) const;  // unit, zero for degenerate faces
  // Applies p' = T * (scale * p); normals are rotated.
  void Transform(const Rigid3d& T, double scale = 1.0);
  // Appends another mesh, remapping its materials after this mesh's.
  void Append(const TriangleMesh& other);
  // Empty string when consistent; otherwise what is wrong (attribute sizes, out-of-range indices, NaN).
  std::string Validate() const;
};

}  // namespace sd
