#include "geometry/marching_cubes.h"

#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <cstring>
#include <functional>
#include <limits>
#include <map>
#include <random>
#include <set>
#include <unordered_map>

#include "geometry/topology.h"

namespace sd::geometry {
namespace {

constexpr double kPi = 3.14159265358979323846;

ScalarGrid SampleField(int n, float half_extent, const std::function<float(const Eigen::Vector3f&)>& f) {
  ScalarGrid g;
  g.dims = Eigen::Vector3i::Constant(n);
  g.origin = Eigen::Vector3f::Constant(-half_extent);
  g.voxel_size = 2 * half_extent / (n - 1);
  g.values.resize(size_t(n) * n * n);
  for (int k = 0; k < n; ++k)
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) g.at(i, j, k) = f(g.NodePosition(i, j, k));
  return g;
}

struct Topology {
  bool closed_oriented_manifold = true;  // every directed edge once, with its reverse; every vertex one fan
  std::string problem;
  long euler = 0;
};

// Local check (independent of geometry/topology.h): a closed, consistently oriented 2-manifold has each
// directed edge exactly once and its reverse present (edge-manifold, oriented, no border), and around each
// vertex the "next" links of its faces form one cycle (no pinched vertices).
Topology CheckTopology(const TriangleMesh& m) {
  Topology t;
  auto fail = [&](const std::string& why) {
    if (t.closed_oriented_manifold) t.problem = why;
    t.closed_oriented_manifold = false;
  };
  std::map<std::pair<int, int>, int> directed;
  std::vector<std::unordered_map<int, int>> link(m.NumVertices());  // at v: x -> y for each face (v, x, y)
  std::vector<bool> used(m.NumVertices(), false);
  for (const auto& f : m.faces) {
    if (f[0] == f[1] || f[1] == f[2] || f[2] == f[0]) fail("face with a repeated vertex");
    for (int e = 0; e < 3; ++e) {
      const int a = f[e], b = f[(e + 1) % 3], c = f[(e + 2) % 3];
      if (++directed[{a, b}] > 1) fail("directed edge used twice (non-manifold or flipped face)");
      if (!link[a].emplace(b, c).second) fail("vertex link branches");
      used[a] = true;
    }
  }
  for (const auto& [edge, count] : directed)
    if (!directed.count({edge.second, edge.first})) fail("border edge (hole)");
  size_t vertices = 0;
  for (size_t v = 0; v < m.NumVertices(); ++v) {
    if (!used[v]) continue;
    ++vertices;
    const auto& l = link[v];
    // Walk the cycle from any start; it must visit every link entry.
    int x = l.begin()->first;
    size_t steps = 0;
    do {
      const auto it = l.find(x);
      if (it == l.end()) {
        fail("open vertex fan");
        break;
      }
      x = it->second;
      ++steps;
    } while (x != l.begin()->first && steps <= l.size());
    if (steps != l.size()) fail("pinched vertex (several fans)");
  }
  t.euler = long(vertices) - long(directed.size() / 2) + long(m.NumFaces());
  return t;
}

double SignedVolume(const TriangleMesh& m) {
  double v = 0;
  for (const auto& f : m.faces) {
    v += m.positions[f[0]].cast<double>().dot(m.positions[f[1]].cast<double>().cross(m.positions[f[2]].cast<double>())) / 6;
  }
  return v;
}

TEST(MarchingCubes, SphereIsClosedManifoldGenusZeroAndOutward) {
  const float r = 1.0f;
  const ScalarGrid g = SampleField(49, 1.25f, [&](const Eigen::Vector3f& p) { return r - p.norm(); });
  const TriangleMesh m = MarchingCubes(g, 0.0f);
  ASSERT_GT(m.NumFaces(), 1000u);
  EXPECT_EQ(m.Validate(), "");
  const Topology t = CheckTopology(m);
  EXPECT_TRUE(t.closed_oriented_manifold) << t.problem;
  EXPECT_EQ(t.euler, 2);
  double worst = 0;
  for (const auto& p : m.positions) worst = std::max(worst, std::abs(double(p.norm()) - r));
  EXPECT_LT(worst, 0.5 * g.voxel_size);
  const double exact = 4.0 / 3.0 * kPi * r * r * r;
  const double volume = SignedVolume(m);
  EXPECT_GT(volume, 0) << "faces point inwards";
  EXPECT_NEAR(volume / exact, 1.0, 0.02);
  // Every face normal points away from the centre.
  for (size_t f = 0; f < m.NumFaces(); ++f) EXPECT_GT(m.FaceNormal(f).dot(m.positions[m.faces[f][0]]), 0) << f;
  // Vertices are shared: a closed triangulation of the sphere has F = 2V - 4.
  EXPECT_EQ(m.NumFaces(), 2 * m.NumVertices() - 4);
}

TEST(MarchingCubes, TorusHasEulerCharacteristicZero) {
  const float R = 0.6f, a = 0.25f;
  const ScalarGrid g = SampleField(64, 1.0f, [&](const Eigen::Vector3f& p) {
    const float q = std::hypot(p.x(), p.y()) - R;
    return a - std::hypot(q, p.z());
  });
  const TriangleMesh m = MarchingCubes(g, 0.0f);
  const Topology t = CheckTopology(m);
  EXPECT_TRUE(t.closed_oriented_manifold) << t.problem;
  EXPECT_EQ(t.euler, 0);
  EXPECT_NEAR(SignedVolume(m) / (2 * kPi * kPi * R * a * a), 1.0, 0.02);
}

// Noise fields are full of ambiguous faces and cells: the consistency argument is what keeps them closed.
TEST(MarchingCubes, RandomFieldsGiveClosedOrientedManifolds) {
  for (int seed = 0; seed < 20; ++seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(-1, 1);
    ScalarGrid g;
    const int n = 4 + seed % 9;
    g.dims = Eigen::Vector3i(n, n + 1, n + 2);
    g.values.resize(size_t(n) * (n + 1) * (n + 2));
    for (int k = 0; k < g.dims.z(); ++k)
      for (int j = 0; j < g.dims.y(); ++j)
        for (int i = 0; i < g.dims.x(); ++i) {
          const bool border = i == 0 || j == 0 || k == 0 || i == g.dims.x() - 1 || j == g.dims.y() - 1 || k == g.dims.z() - 1;
          // Every third field is integer valued, putting samples exactly at the iso value.
          const float v = seed % 3 == 2 ? std::round(u(rng)) : u(rng);
          g.at(i, j, k) = border ? -1.0f : v;
        }
    const TriangleMesh m = MarchingCubes(g, 0.0f);
    EXPECT_EQ(m.Validate(), "") << seed;
    const Topology t = CheckTopology(m);
    EXPECT_TRUE(t.closed_oriented_manifold) << "seed " << seed << ": " << t.problem;
    // The module's own checker agrees.
    const TopologyReport report = AnalyzeTopology(int(m.NumVertices()), m.faces);
    EXPECT_TRUE(report.IsWatertight()) << "seed " << seed << ": " << report.Describe();
    EXPECT_EQ(report.euler_characteristic, t.euler) << seed;
    EXPECT_EQ(t.euler % 2, 0) << seed;  // closed orientable surfaces: chi = 2 (components - genus)
    EXPECT_GT(SignedVolume(m), 0) << seed;
    // Manifold by position too, not only by index: a sample exactly at the iso value must not put the vertices
    // of its several crossed edges at one point, which welding (as refinement does) would fuse into a
    // non-manifold edge.
    std::vector<Eigen::Vector3f> positions = m.positions;
    std::vector<Eigen::Vector3i> faces = m.faces;
    WeldVertices(&positions, &faces, 1e-6f * static_cast<float>(g.dims.cast<float>().norm()));
    const TopologyReport welded = AnalyzeTopology(int(positions.size()), faces);
    EXPECT_TRUE(welded.IsWatertight()) << "seed " << seed << ": " << welded.Describe();
  }
}

// FNV-1a over the vertex and face counts, the positions' bits and the face indices: equal hashes mean the same
// vertices in the same order and the same faces.
uint64_t MeshHash(const TriangleMesh& m) {
  uint64_t h = 14695981039346656037ull;
  auto mix = [&](const void* data, size_t bytes) {
    for (size_t b = 0; b < bytes; ++b) h = (h ^ static_cast<const unsigned char*>(data)[b]) * 1099511628211ull;
  };
  const uint64_t counts[2] = {m.NumVertices(), m.NumFaces()};
  mix(counts, sizeof(counts));
  for (const auto& p : m.positions) mix(p.data(), 3 * sizeof(float));
  for (const auto& f : m.faces) mix(f.data(), 3 * sizeof(int));
  return h;
}

// Pins the exact output (vertex order included) to what the implementation with full-grid edge-id arrays gave
// before it kept only two z-layers of them (hashes made then; g++ 12, x86-64, -O3 and -O0 alike: the build is ISO
// C++ without -march, so no FMA contraction changes a bit). Fields: closed (sphere, torus), open through the grid
// border on a non-cubic grid at a non-zero iso, and small noise with samples at the iso value and NaNs. A change
// that is meant to alter the output updates these hashes, and says so.
TEST(MarchingCubes, OutputIsPinned) {
  const ScalarGrid sphere = SampleField(40, 1.25f, [](const Eigen::Vector3f& p) { return 1.0f - p.norm(); });
  const ScalarGrid torus = SampleField(33, 1.0f, [](const Eigen::Vector3f& p) {
    return 0.25f - std::hypot(std::hypot(p.x(), p.y()) - 0.6f, p.z());
  });
  ScalarGrid blobs;
  blobs.dims = Eigen::Vector3i(37, 29, 23);
  blobs.origin = Eigen::Vector3f(-1.0f, -0.8f, -0.6f);
  blobs.voxel_size = 2.0f / 36;
  blobs.values.resize(size_t(37) * 29 * 23);
  for (int k = 0; k < 23; ++k)
    for (int j = 0; j < 29; ++j)
      for (int i = 0; i < 37; ++i) {
        const Eigen::Vector3f p = blobs.NodePosition(i, j, k);
        // Two blobs, one cut by the x = -1 and z = -0.6 faces of the grid, the other by y = 0.8.
        blobs.at(i, j, k) = std::exp(-(p - Eigen::Vector3f(-0.9f, 0.0f, -0.5f)).squaredNorm() / 0.2f) +
                            std::exp(-(p - Eigen::Vector3f(0.4f, 0.7f, 0.1f)).squaredNorm() / 0.15f);
      }
  std::vector<std::pair<const char*, ScalarGrid>> fields = {{"sphere", sphere}, {"torus", torus}, {"blobs", blobs}};
  for (int seed = 0; seed < 3; ++seed) {
    std::mt19937 rng(seed);
    std::uniform_real_distribution<float> u(-1, 1);
    ScalarGrid g;
    g.dims = Eigen::Vector3i(9 + seed, 11, 13 - seed);
    g.values.resize(size_t(g.dims.prod()));
    // Seed 1 is integer valued (samples exactly at the iso value); seed 2 has NaN samples.
    for (float& v : g.values) v = seed == 1 ? std::round(u(rng)) : u(rng);
    if (seed == 2)
      for (size_t n = 0; n < g.values.size(); n += 17) g.values[n] = std::numeric_limits<float>::quiet_NaN();
    fields.emplace_back(seed == 0 ? "noise0" : seed == 1 ? "noise1" : "noise2", g);
  }
  const std::map<std::string, uint64_t> pinned = {
      {"sphere", 0x2871af47b6d8adb7}, {"torus", 0xeae990355aa3302a},  {"blobs", 0xc233f46225e03b8f},
      {"noise0", 0xf171f451405b3f0d}, {"noise1", 0x1debcf53ef70710e}, {"noise2", 0x18cc992e30ed8449},
  };
  for (const auto& [name, grid] : fields) {
    const float iso = std::string(name) == "blobs" ? 0.3f : 0.0f;
    const TriangleMesh m = MarchingCubes(grid, iso);
    EXPECT_GT(m.NumFaces(), 0u) << name;
    EXPECT_EQ(MeshHash(m), pinned.at(name)) << name << ": 0x" << std::hex << MeshHash(m);
  }
}

TEST(MarchingCubes, SingleInsideNodeGivesAnOctahedron) {
  ScalarGrid g;
  g.dims = Eigen::Vector3i(3, 3, 3);
  g.values.assign(27, -1.0f);
  g.at(1, 1, 1) = 1.0f;
  const TriangleMesh m = MarchingCubes(g, 0.0f);
  EXPECT_EQ(m.NumVertices(), 6u);
  EXPECT_EQ(m.NumFaces(), 8u);
  for (const auto& p : m.positions) EXPECT_NEAR((p - Eigen::Vector3f(1, 1, 1)).norm(), 0.5f, 1e-6f);
  EXPECT_TRUE(CheckTopology(m).closed_oriented_manifold);
  EXPECT_GT(SignedVolume(m), 0);
}

TEST(MarchingCubes, EmptyAndDegenerateGrids) {
  EXPECT_EQ(MarchingCubes(ScalarGrid(), 0.0f).NumFaces(), 0u);
  ScalarGrid flat;
  flat.dims = Eigen::Vector3i(5, 5, 1);
  flat.values.assign(25, 1.0f);
  EXPECT_EQ(MarchingCubes(flat, 0.0f).NumFaces(), 0u);
  ScalarGrid all_inside;
  all_inside.dims = Eigen::Vector3i(4, 4, 4);
  all_inside.values.assign(64, 1.0f);
  EXPECT_EQ(MarchingCubes(all_inside, 0.0f).NumFaces(), 0u);  // nothing crosses (the border is not <= iso)
}

}  // namespace
}  // namespace sd::geometry
