#include "core/mesh.h"

#include <gtest/gtest.h>

#include <cmath>

namespace sd {
namespace {

constexpr double kPi = 3.14159265358979323846;

// Unit cube [0, 1]^3, 8 shared vertices, 12 outward-facing (counter-clockwise) triangles.
TriangleMesh UnitCube() {
  TriangleMesh m;
  for (int i = 0; i < 8; ++i) m.positions.emplace_back(i & 1, (i >> 1) & 1, (i >> 2) & 1);
  m.faces = {{0, 2, 1}, {1, 2, 3}, {4, 5, 6}, {5, 7, 6},   // z = 0 (down), z = 1 (up)
             {0, 1, 4}, {1, 5, 4}, {2, 6, 3}, {3, 6, 7},   // y = 0, y = 1
             {0, 4, 2}, {2, 4, 6}, {1, 3, 5}, {3, 7, 5}};  // x = 0, x = 1
  return m;
}

TriangleMesh RegularTetrahedron() {
  TriangleMesh m;
  m.positions = {{1, 1, 1}, {1, -1, -1}, {-1, 1, -1}, {-1, -1, 1}};
  m.faces = {{0, 1, 2}, {0, 3, 1}, {0, 2, 3}, {1, 3, 2}};
  return m;
}

TEST(Mesh, CubeAreaBoundsAndOutwardNormals) {
  TriangleMesh cube = UnitCube();
  EXPECT_EQ(cube.Validate(), "");
  EXPECT_DOUBLE_EQ(cube.SurfaceArea(), 6.0);
  const AlignedBox3f b = cube.Bounds();
  EXPECT_EQ(b.min, Eigen::Vector3f::Zero());
  EXPECT_EQ(b.max, Eigen::Vector3f::Ones());
  EXPECT_EQ(b.Center(), Eigen::Vector3f::Constant(0.5f));
  EXPECT_TRUE(TriangleMesh().Bounds().IsEmpty());
  const Eigen::Vector3f centre(0.5f, 0.5f, 0.5f);
  for (size_t f = 0; f < cube.NumFaces(); ++f) {
    const auto& face = cube.faces[f];
    const Eigen::Vector3f fc = (cube.positions[face[0]] + cube.positions[face[1]] + cube.positions[face[2]]) / 3;
    const Eigen::Vector3f n = cube.FaceNormal(f);
    EXPECT_NEAR(n.norm(), 1.0f, 1e-6f);
    EXPECT_NEAR(n.dot((fc - centre).normalized()), std::abs(n.dot(fc - centre)) / (fc - centre).norm(), 1e-6f);
    EXPECT_GT(n.dot(fc - centre), 0) << "face " << f << " points inwards";
  }
  cube.ComputeVertexNormals();
  for (size_t v = 0; v < 8; ++v) {
    const Eigen::Vector3f out = cube.positions[v] - centre;
    // Every vertex normal leans into the vertex's own octant.
    for (int k = 0; k < 3; ++k) EXPECT_GT(cube.normals[v][k] * out[k], 0) << v;
    EXPECT_NEAR(cube.normals[v].norm(), 1.0f, 1e-6f);
  }
}

TEST(Mesh, TetrahedronVertexNormalsPointAwayFromCentre) {
  TriangleMesh t = RegularTetrahedron();
  t.ComputeVertexNormals();
  for (size_t v = 0; v < 4; ++v) EXPECT_TRUE(t.normals[v].isApprox(t.positions[v].normalized(), 1e-6f)) << v;
  EXPECT_NEAR(t.SurfaceArea(), 4 * std::sqrt(3.0) / 4 * 8, 1e-5);  // 4 equilateral faces of side 2*sqrt(2)
}

TEST(Mesh, NormalsAreAreaWeighted) {
  // Vertex 0 shared by a triangle of area 2 in the xy plane (normal +z) and one of area 1 in the xz plane
  // (normal -y): the vertex normal is (0, -1, 2) normalised (an unweighted mean would give (0, -1, 1)).
  TriangleMesh m;
  m.positions = {{0, 0, 0}, {2, 0, 0}, {0, 2, 0}, {0, 0, 1}};
  m.faces = {{0, 1, 2}, {0, 1, 3}};
  EXPECT_NEAR(m.SurfaceArea(), 3.0, 1e-12);
  m.ComputeVertexNormals();
  EXPECT_TRUE(m.normals[0].isApprox(Eigen::Vector3f(0, -1, 2).normalized(), 1e-6f)) << m.normals[0].transpose();
  EXPECT_TRUE(m.normals[2].isApprox(Eigen::Vector3f::UnitZ()));
  EXPECT_TRUE(m.normals[3].isApprox(-Eigen::Vector3f::UnitY()));
  // A degenerate face has a zero normal.
  m.faces.push_back({0, 1, 1});
  EXPECT_EQ(m.FaceNormal(2), Eigen::Vector3f::Zero());
}

TEST(Mesh, TransformMovesPointsAndRotatesNormals) {
  TriangleMesh cube = UnitCube();
  cube.ComputeVertexNormals();
  const TriangleMesh before = cube;
  const Rigid3d T = Rigid3d::FromYaw(kPi / 2, {10, 0, -1});
  cube.Transform(T, 2.0);
  for (size_t v = 0; v < 8; ++v) {
    const Eigen::Vector3f p = before.positions[v];
    EXPECT_TRUE(cube.positions[v].isApprox(Eigen::Vector3f(10 - 2 * p.y(), 2 * p.x(), 2 * p.z() - 1), 1e-6f));
    EXPECT_TRUE(cube.normals[v].isApprox(Eigen::Vector3f(-before.normals[v].y(), before.normals[v].x(), before.normals[v].z()), 1e-6f));
  }
  EXPECT_NEAR(cube.SurfaceArea(), 24.0, 1e-5);
}

TEST(Mesh, AppendKeepsAttributesAligned) {
  TriangleMesh a = RegularTetrahedron();
  a.uvs.assign(4, Eigen::Vector2f(0.25f, 0.75f));
  Material m0, m1;
  m0.name = "m0";
  m1.name = "m1";
  a.materials = {m0, m1};
  a.face_material = {0, 1, 1, 0};
  TriangleMesh b = UnitCube();
  b.colors.assign(8, Eigen::Vector4f(1, 0, 0, 1));  // b has colours, a does not; a has uvs, b does not
  a.Append(b);
  EXPECT_EQ(a.Validate(), "");
  EXPECT_EQ(a.NumVertices(), 12u);
  EXPECT_EQ(a.NumFaces(), 16u);
  ASSERT_EQ(a.uvs.size(), 12u);
  ASSERT_EQ(a.colors.size(), 12u);
  EXPECT_EQ(a.uvs[3], Eigen::Vector2f(0.25f, 0.75f));
  EXPECT_EQ(a.colors[3], Eigen::Vector4f::Ones());          // neutral fill for a's vertices
  EXPECT_EQ(a.colors[4], Eigen::Vector4f(1, 0, 0, 1));      // b's own colours
  EXPECT_EQ(a.faces[4], Eigen::Vector3i(4, 6, 5));          // b's first face, shifted by 4
  EXPECT_EQ(a.MaterialOf(1), 1);
  EXPECT_EQ(a.MaterialOf(4), 2);                            // b's implied default material, after a's two
  ASSERT_EQ(a.materials.size(), 3u);
  EXPECT_EQ(a.materials[1].name, "m1");
  EXPECT_NEAR(a.SurfaceArea(), RegularTetrahedron().SurfaceArea() + 6.0, 1e-5);
}

TEST(Mesh, ValidateCatchesInconsistencies) {
  TriangleMesh m = UnitCube();
  m.faces.push_back({0, 1, 8});
  EXPECT_NE(m.Validate().find("face 12"), std::string::npos) << m.Validate();
  m = UnitCube();
  m.faces[3] = {0, -1, 2};
  EXPECT_NE(m.Validate(), "");
  m = UnitCube();
  m.uvs.resize(7);
  EXPECT_NE(m.Validate().find("uv count"), std::string::npos);
  m = UnitCube();
  m.positions[2].x() = std::nanf("");
  EXPECT_NE(m.Validate().find("vertex 2"), std::string::npos);
  m = UnitCube();
  m.face_material.assign(12, 0);
  m.face_material[5] = 1;  // only the implied default material exists
  EXPECT_NE(m.Validate().find("face 5"), std::string::npos);
  m.face_material.resize(11);
  EXPECT_NE(m.Validate(), "");
}

TEST(AlignedBox3f, ClipSegmentKeepsThePartInsideTheBox) {
  AlignedBox3f box;
  box.min = Eigen::Vector3f(0, 0, 0), box.max = Eigen::Vector3f(1, 1, 1);
  float t0 = -1, t1 = -1;
  ASSERT_TRUE(box.ClipSegment({-1, 0.5f, 0.5f}, {3, 0.5f, 0.5f}, &t0, &t1));
  EXPECT_FLOAT_EQ(t0, 0.25f);
  EXPECT_FLOAT_EQ(t1, 0.5f);
  ASSERT_TRUE(box.ClipSegment({0.5f, 0.5f, 0.5f}, {0.6f, 0.5f, 0.5f}, &t0, &t1));  // wholly inside
  EXPECT_FLOAT_EQ(t0, 0.0f);
  EXPECT_FLOAT_EQ(t1, 1.0f);
  EXPECT_FALSE(box.ClipSegment({-1, 2, 0.5f}, {3, 2, 0.5f}, &t0, &t1));   // parallel to x, above the box
  EXPECT_FALSE(box.ClipSegment({-2, 0.5f, 0.5f}, {-1, 0.5f, 0.5f}, &t0, &t1));  // stops short of it
}

}  // namespace
}  // namespace sd
