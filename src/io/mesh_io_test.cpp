#include "io/mesh_io.h"

#include <gtest/gtest.h>
#include <sys/stat.h>

#include <algorithm>
#include <cstring>
#include <fstream>

#include "io/files.h"
#include "testing/testing.h"

namespace sd {
namespace {
namespace fs = std::filesystem;
using testing::RepoData;
using testing::TempDir;

Eigen::Vector3f SortedExtent(const TriangleMesh& m) {
  Eigen::Vector3f s = m.Bounds().Size();
  std::sort(s.data(), s.data() + 3);
  return s;
}

void ExpectTextured(const TriangleMesh& m) {
  EXPECT_EQ(m.Validate(), "");
  ASSERT_EQ(m.uvs.size(), m.NumVertices());
  ASSERT_FALSE(m.materials.empty());
  ASSERT_TRUE(m.materials[m.MaterialOf(0)].base_color_texture);
  EXPECT_GT(m.materials[m.MaterialOf(0)].base_color_texture->width(), 0);
}

TEST(MeshIo, TrafficConeObjAndGltfAgree) {
  const TriangleMesh gltf = LoadMesh(RepoData("assets/metadrive_traffic_cone/scene.gltf"));
  const TriangleMesh obj = LoadMesh(RepoData("assets/metadrive_traffic_cone/obj/metadrive_traffic_cone.obj"));
  ExpectTextured(gltf);
  ExpectTextured(obj);
  // The glTF stores the cone in metres (0.2 x 0.2 x 0.295, z up) under node transforms that scale by 100 and
  // turn it y-up; the OBJ (assimp conversion) has those transforms baked in. Both: 20 x 29.48 x 20 units.
  EXPECT_EQ(gltf.NumFaces(), 1664u);
  EXPECT_EQ(obj.NumFaces(), 1664u);
  EXPECT_EQ(gltf.NumVertices(), 1221u);
  const Eigen::Vector3f eg = SortedExtent(gltf), eo = SortedExtent(obj);
  EXPECT_TRUE(eg.isApprox(eo, 1e-4f)) << eg.transpose() << " vs " << eo.transpose();
  EXPECT_NEAR(gltf.Bounds().Size().y(), 29.4833f, 1e-3f);  // up axis is y in both files
  EXPECT_NEAR(obj.Bounds().Size().y(), 29.4833f, 1e-3f);
  EXPECT_NEAR(gltf.Bounds().min.y(), 0.0f, 1e-3f);  // origin at the ground contact
  EXPECT_NEAR(gltf.Bounds().Size().x(), 20.0f, 1e-3f);
  // Same texture file (2048 x 2048 RGB JPEG) on both paths.
  const auto& tg = *gltf.materials[0].base_color_texture;
  const auto& to = *obj.materials[obj.MaterialOf(0)].base_color_texture;
  EXPECT_EQ(tg.width(), 2048);
  EXPECT_EQ(tg.height(), 2048);
  EXPECT_EQ(tg.channels(), 3);
  EXPECT_EQ(tg.vector(), to.vector());
  EXPECT_EQ(gltf.materials[0].base_color_texture_name, "cone_baseColor.jpeg");
  EXPECT_EQ(gltf.materials[0].metallic, 1.0f);  // the file's factor (its metallicRoughness texture is not read)
  // The UVs agree too (OBJ v flipped to glTF's top-left origin): compare the sorted uv sets.
  auto sorted_uvs = [](const TriangleMesh& m) {
    std::vector<std::pair<float, float>> v;
    for (const auto& uv : m.uvs) v.emplace_back(uv.x(), uv.y());
    std::sort(v.begin(), v.end());
    return v;
  };
  const auto ug = sorted_uvs(gltf), uo = sorted_uvs(obj);
  ASSERT_FALSE(uo.empty());
  // OBJ vertices are deduplicated per (v, vt, vn) triple, so compare ranges rather than element by element.
  EXPECT_NEAR(ug.front().first, uo.front().first, 1e-5f);
  EXPECT_NEAR(ug.back().first, uo.back().first, 1e-5f);
  float gmin = 1, gmax = 0, omin = 1, omax = 0;
  for (auto [u, v] : ug) gmin = std::min(gmin, v), gmax = std::max(gmax, v);
  for (auto [u, v] : uo) omin = std::min(omin, v), omax = std::max(omax, v);
  EXPECT_NEAR(gmin, omin, 1e-5f);
  EXPECT_NEAR(gmax, omax, 1e-5f);
}

TEST(MeshIo, BarrierAndCarLoadWithTextures) {
  const TriangleMesh barrier = LoadGltf(RepoData("assets/metadrive_road_barrier/scene.gltf"));
  ExpectTextured(barrier);
  EXPECT_EQ(barrier.NumFaces(), 724u);
  EXPECT_EQ(barrier.materials[0].base_color_texture_name, "lambert1_baseColor.png");
  EXPECT_EQ(barrier.materials[0].base_color_texture->channels(), 4);
  // Node scale 1.09905 applied: the raw accessor spans y in [-1, 1].
  EXPECT_NEAR(barrier.Bounds().Size().y(), 2 * 1.099050760269165f, 1e-4f);
  const TriangleMesh barrier_obj = LoadObj(RepoData("assets/metadrive_road_barrier/obj/metadrive_road_barrier.obj"));
  EXPECT_TRUE(barrier.Bounds().Size().isApprox(barrier_obj.Bounds().Size(), 1e-4f));

  const TriangleMesh car = LoadObj(RepoData("assets/torcs_p406/obj/torcs_p406.obj"));
  ExpectTextured(car);
  // TORCS's body (8557 faces) and the four wheels scripts/car_wheels.py added (320 faces each, tyre and rim).
  EXPECT_EQ(car.NumFaces(), 8557u + 4 * 320u);
  ASSERT_EQ(car.materials.size(), 3u);
  EXPECT_EQ(car.materials[0].base_color_texture_name, "p406.png");
  EXPECT_EQ(car.materials[0].base_color_texture->width(), 512);
  EXPECT_EQ(car.materials[car.MaterialOf(car.NumFaces() - 1)].name, "rim");
  // Metres, x forward, y up: 4.64 long, 1.42 tall (the tyres reach 0.147 below the body's sill), 2.0 wide.
  EXPECT_TRUE(car.Bounds().Size().isApprox(Eigen::Vector3f(4.64f, 1.422f, 2.0f), 1e-4f));
  for (const auto& uv : car.uvs) ASSERT_TRUE(uv.allFinite());
}

// The shipped car stands on four wheels, not on its sill: its lowest points (within 2 cm of the ground) lie in
// four patches at the corners of a wheelbase and track, and nothing else reaches down there.
TEST(MeshIo, TheShippedCarStandsOnFourWheels) {
  const TriangleMesh car = LoadObj(RepoData("assets/torcs_p406/obj/torcs_p406.obj"));  // x forward, y up, z side
  const float ground = car.Bounds().min.y();
  int quadrant[2][2] = {{0, 0}, {0, 0}};
  for (const auto& p : car.positions) {
    if (p.y() > ground + 0.02f) continue;
    ASSERT_GT(std::abs(p.x()), 1.1f) << "a low point between the axles: " << p.transpose();
    ASSERT_GT(std::abs(p.z()), 0.6f) << "a low point between the wheels: " << p.transpose();
    ++quadrant[p.x() > 0][p.z() > 0];
  }
  for (const auto& row : quadrant)
    for (int n : row) EXPECT_GT(n, 0);
}

TEST(MeshIo, ObjSplitsVerticesAndFlipsV) {
  TempDir tmp;
  // A quad whose corner 1 is used with two different uvs: 4 positions, 5 distinct (v, vt) pairs.
  const std::string obj =
      "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
      "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvt 0.5 0.25\n"
      "f 1/1 2/2 3/3\nf 1/5 3/3 4/4\n";
  WriteFileAtomic(tmp / "quad.obj", obj);
  const TriangleMesh m = LoadObj(tmp / "quad.obj");
  EXPECT_EQ(m.NumFaces(), 2u);
  EXPECT_EQ(m.NumVertices(), 5u);
  EXPECT_TRUE(m.normals.empty());
  EXPECT_TRUE(m.materials[0].base_color_texture == nullptr);
  // vt (0.5, 0.25) becomes glTF (0.5, 0.75).
  bool found = false;
  for (const auto& uv : m.uvs) found |= uv.isApprox(Eigen::Vector2f(0.5f, 0.75f));
  EXPECT_TRUE(found);
  EXPECT_NEAR(m.SurfaceArea(), 1.0, 1e-6);
  // A polygon is triangulated.
  WriteFileAtomic(tmp / "pent.obj", "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0.5 1.5 0\nv 0 1 0\nf 1 2 3 4 5\n");
  EXPECT_EQ(LoadObj(tmp / "pent.obj").NumFaces(), 3u);
}

TEST(MeshIo, GlbRoundTripInZUp) {
  // The car's body alone (one material, so the GLB keeps the vertex order): the OBJ cut at the wheels' block.
  TempDir tmp;
  const std::filesystem::path obj = RepoData("assets/torcs_p406/obj/torcs_p406.obj");
  const std::string text = ReadFileToString(obj);
  const size_t wheels = text.find("\n# --- wheels added by scripts/car_wheels.py");
  ASSERT_NE(wheels, std::string::npos);
  WriteFileAtomic(tmp / "body.obj", text.substr(0, wheels + 1));
  for (const char* f : {"torcs_p406.mtl", "p406.png"}) std::filesystem::copy_file(obj.parent_path() / f, tmp / f);
  TriangleMesh m = LoadObj(tmp / "body.obj");
  ASSERT_EQ(m.NumFaces(), 8557u);
  SaveGlb(tmp / "car.glb", m);
  // The raw file is y-up: the car's y-up OBJ is treated as z-up, so its y extent (1.27) lands on -z.
  const TriangleMesh raw = LoadGltf(tmp / "car.glb");
  EXPECT_NEAR(raw.Bounds().Size().z(), m.Bounds().Size().y(), 1e-5f);
  EXPECT_NEAR(raw.Bounds().max.z(), -m.Bounds().min.y(), 1e-5f);
  EXPECT_NEAR(raw.Bounds().max.y(), m.Bounds().max.z(), 1e-5f);

  const TriangleMesh back = LoadGlbZUp(tmp / "car.glb");
  ASSERT_EQ(back.NumVertices(), m.NumVertices());  // one material: vertex order kept
  ASSERT_EQ(back.NumFaces(), m.NumFaces());
  for (size_t i = 0; i < m.NumVertices(); ++i) {
    ASSERT_EQ(back.positions[i], m.positions[i]) << i;  // the axis swap is exact in float
    ASSERT_EQ(back.uvs[i], m.uvs[i]) << i;
    ASSERT_NEAR((back.normals[i] - m.normals[i]).norm(), 0.0f, 1e-6f) << i;
  }
  for (size_t f = 0; f < m.NumFaces(); ++f) ASSERT_EQ(back.faces[f], m.faces[f]) << f;
  ASSERT_TRUE(back.materials[0].base_color_texture);
  EXPECT_EQ(back.materials[0].base_color_texture->vector(), m.materials[0].base_color_texture->vector());  // PNG: lossless
  EXPECT_EQ(back.materials[0].base_color_texture_name, "p406.png");
}

TEST(MeshIo, GlbRoundTripMaterialsAndColours) {
  // Two triangles with different materials sharing an edge, vertex colours, one texture.
  TriangleMesh m;
  m.positions = {{0, 0, 0}, {1, 0, 0}, {1, 1, 0.5f}, {0, 1, 0}};
  m.faces = {{0, 1, 2}, {0, 2, 3}};
  m.colors = {{1, 0, 0, 1}, {0, 1, 0, 1}, {0, 0, 1, 0.5f}, {0.25f, 0.5f, 0.75f, 1}};
  m.uvs = {{0, 0}, {1, 0}, {1, 1}, {0, 1}};
  m.ComputeVertexNormals();
  ImageU8 tex(3, 2, 3);
  for (size_t i = 0; i < tex.size(); ++i) tex.data()[i] = static_cast<uint8_t>(i * 13);
  Material a, b;
  a.name = "red";
  a.base_color_factor = {0.5f, 0.25f, 0.125f, 1.0f};
  a.metallic = 0.3f;
  a.roughness = 0.7f;
  b.name = "textured";
  b.base_color_texture = std::make_shared<const ImageU8>(tex);
  b.base_color_texture_name = "tex.png";
  m.materials = {a, b};
  m.face_material = {1, 0};
  TempDir tmp;
  SaveGlb(tmp / "m.glb", m);
  const TriangleMesh back = LoadGlbZUp(tmp / "m.glb");
  ASSERT_EQ(back.NumFaces(), 2u);
  ASSERT_EQ(back.materials.size(), 2u);
  EXPECT_EQ(back.materials[0].name, "red");
  EXPECT_TRUE(back.materials[0].base_color_factor.isApprox(a.base_color_factor));
  EXPECT_FLOAT_EQ(back.materials[0].metallic, 0.3f);
  EXPECT_FLOAT_EQ(back.materials[0].roughness, 0.7f);
  ASSERT_TRUE(back.materials[1].base_color_texture);
  EXPECT_EQ(back.materials[1].base_color_texture->vector(), tex.vector());
  EXPECT_EQ(back.SurfaceArea(), m.SurfaceArea());
  // Each face keeps its material and its corner attributes (vertices are duplicated per primitive).
  for (size_t f = 0; f < 2; ++f) {
    const size_t orig = back.MaterialOf(f) == 1 ? 0 : 1;
    EXPECT_EQ(m.MaterialOf(orig), back.MaterialOf(f));
    for (int k = 0; k < 3; ++k) {
      EXPECT_EQ(back.positions[back.faces[f][k]], m.positions[m.faces[orig][k]]);
      EXPECT_EQ(back.colors[back.faces[f][k]], m.colors[m.faces[orig][k]]);
      EXPECT_EQ(back.uvs[back.faces[f][k]], m.uvs[m.faces[orig][k]]);
    }
  }
}

TEST(MeshIo, PlyHeaderAnnouncesCounts) {
  const TriangleMesh m = LoadGltf(RepoData("assets/metadrive_traffic_cone/scene.gltf"));
  TempDir tmp;
  SavePly(tmp / "cone.ply", m);
  const std::string bytes = ReadFileToString(tmp / "cone.ply");
  const size_t end = bytes.find("end_header\n");
  ASSERT_NE(end, std::string::npos);
  const std::string header = bytes.substr(0, end);
  EXPECT_NE(header.find("format binary_little_endian 1.0"), std::string::npos);
  EXPECT_NE(header.find("element vertex 1221\n"), std::string::npos);
  EXPECT_NE(header.find("element face 1664\n"), std::string::npos);
  EXPECT_NE(header.find("property float nx"), std::string::npos);
  EXPECT_EQ(header.find("property uchar red"), std::string::npos);  // no vertex colours
  // Body: 1221 vertices x 24 B (xyz + normal) + 1664 faces x 13 B.
  EXPECT_EQ(bytes.size() - (end + 11), 1221u * 24 + 1664u * 13);
  float x0;
  std::memcpy(&x0, bytes.data() + end + 11, 4);
  EXPECT_EQ(x0, m.positions[0].x());
}

TEST(MeshIo, ErrorsNameTheFile) {
  TempDir tmp;
  const fs::path missing = tmp / "nope.obj";
  try {
    LoadMesh(missing);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("nope.obj"), std::string::npos) << e.what();
  }
  EXPECT_THROW(LoadGltf(tmp / "nope.gltf"), InputError);
  EXPECT_THROW(LoadMesh(tmp / "x.stl"), InputError);

  // Missing OBJ texture: the error names the texture file.
  WriteFileAtomic(tmp / "t.mtl", "newmtl m\nKd 1 1 1\nmap_Kd gone.png\n");
  WriteFileAtomic(tmp / "t.obj", "mtllib t.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl m\nf 1 2 3\n");
  try {
    LoadObj(tmp / "t.obj");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("gone.png"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("t.obj"), std::string::npos) << e.what();
  }
  // Missing glTF texture: copy the cone glTF without its textures folder.
  fs::copy_file(RepoData("assets/metadrive_traffic_cone/scene.gltf"), tmp / "cone.gltf");
  fs::copy_file(RepoData("assets/metadrive_traffic_cone/scene.bin"), tmp / "scene.bin");
  try {
    LoadGltf(tmp / "cone.gltf");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("textures/cone_baseColor.jpeg"), std::string::npos) << e.what();
  }
  // No triangles, and a parse failure.
  WriteFileAtomic(tmp / "points.obj", "v 0 0 0\nv 1 0 0\n");
  EXPECT_THROW(LoadObj(tmp / "points.obj"), InputError);
  WriteFileAtomic(tmp / "bad.gltf", "{ this is not json");
  try {
    LoadGltf(tmp / "bad.gltf");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("bad.gltf"), std::string::npos) << e.what();
  }
}

// A glTF's textures are decoded by DecodeImage, which refuses what Debian's stb_image 2.27 would overflow on: the
// cone's JPEG with its first Huffman table declaring 4080 codes (a fuzzed glTF reached stb's overrun when the
// reader called stb itself). The error names the glTF and the image.
TEST(MeshIo, AGltfTextureStbWouldOverflowOnIsRefused) {
  TempDir tmp;
  const fs::path cone = RepoData("assets/metadrive_traffic_cone");
  fs::copy_file(cone / "scene.gltf", tmp / "cone.gltf");
  fs::copy_file(cone / "scene.bin", tmp / "scene.bin");
  fs::create_directories(tmp / "textures");
  for (const auto& entry : fs::directory_iterator(cone / "textures")) fs::copy_file(entry.path(), tmp / "textures" / entry.path().filename());
  ASSERT_NO_THROW(LoadGltf(tmp / "cone.gltf"));
  std::string jpeg = ReadFileToString(tmp / "textures/cone_baseColor.jpeg");
  const size_t dht = jpeg.find("\xFF\xC4");
  ASSERT_NE(dht, std::string::npos);
  for (size_t i = 1; i <= 16; ++i) jpeg[dht + 4 + i] = static_cast<char>(0xFF);
  WriteFileAtomic(tmp / "textures/cone_baseColor.jpeg", jpeg);
  try {
    LoadGltf(tmp / "cone.gltf");
    FAIL() << "loaded";
  } catch (const InputError& e) {
    const std::string what = e.what();
    EXPECT_NE(what.find("cone_baseColor.jpeg"), std::string::npos) << what;
    EXPECT_NE(what.find("a Huffman table declares 4080 codes"), std::string::npos) << what;
  }
}

// The mesh readers open files themselves: a FIFO (or device) would block them, deep JSON would overflow
// tinygltf's recursive parser. Both refused with the file named.
TEST(MeshIo, OnlyRegularFilesAndBoundedGltfJsonAreRead) {
  TempDir tmp;
  const fs::path fifo = tmp / "pipe.obj";
  ASSERT_EQ(mkfifo(fifo.c_str(), 0600), 0);
  try {
    LoadMesh(fifo);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("pipe.obj: is not a regular file"), std::string::npos) << e.what();
  }
  std::string deep = R"({"asset": {"version": "2.0"}, "extras": )";
  deep += std::string(100000, '[') + std::string(100000, ']') + "}";
  WriteFileAtomic(tmp / "deep.gltf", deep);
  try {
    LoadGltf(tmp / "deep.gltf");
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("deep.gltf"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("nest"), std::string::npos) << e.what();
  }
}

// tinyobjloader reads a number it cannot parse as 0: "v nan 0 0" used to put a vertex at the origin unseen.
TEST(MeshIo, ObjNumbersThatAreNotFiniteAreRefusedWithTheirLine) {
  TempDir tmp;
  const std::string faces = "f 1 2 3\n";
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"v 0 0 0\nv nan 0 0\nv 0 1 0\n", "line 2: 'nan'"},
      {"v 0 0 0\nv 1 0 0\nv 0 1e999 0\n", "line 3: '1e999'"},
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nvn 0 0 x\n", "line 4: 'x' is not a finite number (vn line)"},
      {"v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0.5 inf\n", "line 4: 'inf'"},
      {"v 0 0 0\nv 1,5 0 0\nv 0 1 0\n", "line 2: '1,5'"},
  };
  for (const auto& [text, expected] : cases) {
    WriteFileAtomic(tmp / "bad.obj", text + faces);
    try {
      LoadObj(tmp / "bad.obj");
      ADD_FAILURE() << "accepted: " << text;
    } catch (const InputError& e) {
      EXPECT_NE(std::string(e.what()).find("bad.obj"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find(expected), std::string::npos) << e.what();
    }
  }
  // Comments, tabs, CRLF line ends, vertex colours and a w coordinate are all numbers as OBJ has them.
  WriteFileAtomic(tmp / "ok.obj", "# a triangle\r\nv 0 0 0 1 0 0\r\nv\t1 0 0 0 1 0\r\nv 0 1 0 0 0 1 # top\r\nvt 0 0 0\r\nf 1 2 3\r\n");
  EXPECT_EQ(LoadObj(tmp / "ok.obj").NumFaces(), 1u);
}

}  // namespace
}  // namespace sd
