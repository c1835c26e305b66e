// The vertex normals op (normals.h) on host buffers: the same bits as geometry's face-loop normals and their
// backward, on a bumpy sphere with a degenerate face and a vertex no face uses; the incidence it gathers
// over; and its refusal of an incidence of another mesh. raster_cuda_test.cpp holds the device to the host.
#include "raster/normals.h"

#include <gtest/gtest.h>

#include <random>
#include <vector>

#include <Eigen/Core>

#include "geometry/normals.h"
#include "raster/test_util.h"

namespace sd::raster {
namespace {

// A bumpy closed sphere, plus a degenerate face (a, a, b) and a last vertex that no face uses.
testing::Mesh AwkwardMesh() {
  testing::Mesh m = testing::Sphere(14, 28, 1.0f, 0.15f, 5);
  m.tris.insert(m.tris.end(), {3, 3, 9});
  m.positions.insert(m.positions.end(), {2.0f, 0.5f, -0.25f});
  return m;
}

std::vector<Eigen::Vector3f> AsVectors(const std::vector<float>& flat) {
  std::vector<Eigen::Vector3f> out(flat.size() / 3);
  for (size_t v = 0; v < out.size(); ++v) out[v] = Eigen::Vector3f(&flat[3 * v]);
  return out;
}
std::vector<Eigen::Vector3i> AsFaces(const std::vector<int32_t>& flat) {
  std::vector<Eigen::Vector3i> out(flat.size() / 3);
  for (size_t f = 0; f < out.size(); ++f) out[f] = Eigen::Vector3i(flat[3 * f], flat[3 * f + 1], flat[3 * f + 2]);
  return out;
}

TEST(BuildVertexFaces, ListsEachVertexsCornersInAscendingOrder) {
  const std::vector<int32_t> tris{0, 1, 2, 2, 1, 3, 3, 3, 0};
  const VertexFaces incidence = BuildVertexFaces(tris, 5);
  EXPECT_EQ(incidence.offset.host(), (std::vector<int32_t>{0, 2, 4, 6, 9, 9}));
  // Vertex 0: corners 0 and 8; 1: 1, 4; 2: 2, 3; 3: 5, 6, 7 (twice in the degenerate face); 4: none.
  EXPECT_EQ(incidence.corner.host(), (std::vector<int32_t>{0, 8, 1, 4, 2, 3, 5, 6, 7}));
}

TEST(VertexNormals, AreGeometrysNormalsBitForBit) {
  const testing::Mesh m = AwkwardMesh();
  const size_t nv = m.positions.size() / 3;
  const VertexFaces incidence = BuildVertexFaces(m.tris, m.NumVertices());
  std::vector<float> normals(3 * nv, 7.0f);
  std::vector<double> sums(3 * nv, 7.0);
  VertexNormals(m.positions, m.tris, incidence, normals, sums);
  const std::vector<Eigen::Vector3f> expected = geometry::VertexNormals(AsVectors(m.positions), AsFaces(m.tris));
  for (size_t v = 0; v < nv; ++v)
    for (int c = 0; c < 3; ++c) ASSERT_EQ(normals[3 * v + c], expected[v][c]) << "vertex " << v;
  EXPECT_EQ(Eigen::Vector3f(&normals[3 * (nv - 1)]), Eigen::Vector3f::Zero()) << "a vertex without faces";
  EXPECT_NEAR(Eigen::Vector3f(&normals[9]).norm(), 1.0f, 1e-6f) << "the degenerate face adds nothing";
}

TEST(VertexNormalsBackward, IsGeometrysBackwardBitForBitAndAccumulates) {
  const testing::Mesh m = AwkwardMesh();
  const size_t nv = m.positions.size() / 3;
  const VertexFaces incidence = BuildVertexFaces(m.tris, m.NumVertices());
  std::vector<float> normals(3 * nv);
  std::vector<double> sums(3 * nv);
  VertexNormals(m.positions, m.tris, incidence, normals, sums);
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> unit(-1, 1);
  std::vector<float> grad_normals(3 * nv), start(3 * nv);
  for (float& g : grad_normals) g = unit(rng);
  for (float& g : start) g = unit(rng);
  std::vector<float> grad = start;  // accumulated into
  VertexNormalsBackward(m.positions, m.tris, incidence, sums, grad_normals, grad);
  std::vector<Eigen::Vector3f> expected = AsVectors(start);
  geometry::VertexNormalsBackward(AsVectors(m.positions), AsFaces(m.tris), AsVectors(grad_normals), &expected);
  for (size_t v = 0; v < nv; ++v)
    for (int c = 0; c < 3; ++c) ASSERT_EQ(grad[3 * v + c], expected[v][c]) << "vertex " << v;
  EXPECT_EQ(Eigen::Vector3f(&grad[3 * (nv - 1)]), Eigen::Vector3f(&start[3 * (nv - 1)])) << "no faces, no gradient";
}

TEST(VertexNormalsDeathTest, RefusesAnIncidenceOfAnotherMesh) {
  GTEST_FLAG_SET(death_test_style, "threadsafe");
  const testing::Mesh m = testing::Sphere(6, 12, 1.0f);
  const size_t nv = m.positions.size() / 3;
  std::vector<float> normals(3 * nv);
  std::vector<double> sums(3 * nv);
  // Same counts, other triangles: the sizes fit but a corner lies past this mesh's.
  VertexFaces other = BuildVertexFaces(m.tris, m.NumVertices());
  other.corner.host().back() = static_cast<int32_t>(m.tris.size());
  EXPECT_DEATH(VertexNormals(m.positions, m.tris, other, normals, sums), "corner lies past");
  const VertexFaces smaller = BuildVertexFaces(testing::Sphere(5, 10, 1.0f).tris, m.NumVertices());
  EXPECT_DEATH(VertexNormals(m.positions, m.tris, smaller, normals, sums), "incidence is of another mesh");
}

}  // namespace
}  // namespace sd::raster
