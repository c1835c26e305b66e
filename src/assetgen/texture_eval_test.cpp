#include "assetgen/texture_eval.h"

#include <cmath>
#include <memory>
#include <random>

#include <gtest/gtest.h>

#include "core/error.h"
#include "geometry/test_meshes.h"

namespace sd {
namespace {

// A unit cube with its own vertices per face, each face one material of a known colour.
TriangleMesh ColouredCube(const std::vector<Eigen::Vector3f>& face_colours) {
  const TriangleMesh shared = geometry::testing::Cube(Eigen::Vector3f::Constant(-0.5f), Eigen::Vector3f::Constant(0.5f));
  TriangleMesh m;
  for (const Eigen::Vector3f& c : face_colours) {
    Material mat;
    mat.base_color_factor << c, 1.0f;
    m.materials.push_back(mat);
  }
  for (size_t f = 0; f < shared.faces.size(); ++f) {
    const int base = static_cast<int>(m.positions.size());
    for (int k = 0; k < 3; ++k) m.positions.push_back(shared.positions[shared.faces[f][k]]);
    m.faces.emplace_back(base, base + 1, base + 2);
    m.face_material.push_back(static_cast<int>(f / 2));  // the cube's two triangles per side are consecutive
  }
  return m;
}

std::vector<Eigen::Vector3f> SixColours() {
  return {{0.8f, 0.1f, 0.1f}, {0.1f, 0.8f, 0.1f}, {0.1f, 0.1f, 0.8f},
          {0.8f, 0.8f, 0.1f}, {0.1f, 0.8f, 0.8f}, {0.8f, 0.1f, 0.8f}};
}

TEST(MaskedPsnr, ConstantErrorGivesTheAnalyticValue) {
  ImageF a(16, 16, 3, 0.5f), b(16, 16, 3, 0.6f), w(16, 16, 1, 0.0f);
  for (int y = 4; y < 12; ++y)
    for (int x = 4; x < 12; ++x) w.at(x, y) = 1;
  b.at(0, 0, 0) = 0.0f;  // outside the mask: ignored
  EXPECT_NEAR(MaskedPsnr(a, b, w), 20.0, 1e-4);  // MSE 0.01
  EXPECT_NEAR(MaskedPsnr(a, a, w), 120.0, 1e-9);
}

TEST(MaskedSsim, OneForIdenticalLowerForNoise) {
  std::mt19937 rng(1);
  std::uniform_real_distribution<float> u(0, 1);
  ImageF a(48, 48, 3), w(48, 48, 1, 1.0f);
  for (size_t i = 0; i < a.size(); ++i) a.data()[i] = u(rng);
  EXPECT_NEAR(MaskedSsim(a, a, w), 1.0, 1e-6);
  ImageF noisy = a;
  std::normal_distribution<float> n(0, 0.2f);
  for (size_t i = 0; i < noisy.size(); ++i) noisy.data()[i] += n(rng);
  const double s = MaskedSsim(a, noisy, w);
  EXPECT_LT(s, 0.9);
  EXPECT_GT(s, 0.0);
}

TEST(RenderAlbedo, CubeFacesShowTheirColourAndTexturesAreSampled) {
  const TriangleMesh cube = ColouredCube(SixColours());
  const ViewCamera v = OrbitCamera("front", 0, 0, 4, 30, 64, 64);  // looks at the +x face head-on
  const AlbedoRender r = RenderAlbedo(cube, v);
  // The +x face: find its material by the face whose normal is +x.
  int material = -1;
  for (size_t f = 0; f < cube.NumFaces(); ++f)
    if (cube.FaceNormal(f).x() > 0.99f) material = cube.face_material[f];
  ASSERT_GE(material, 0);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(r.color.at(32, 32, c), SixColours()[material][c], 1e-5f);
  EXPECT_EQ(r.mask.at(32, 32), 1.0f);
  EXPECT_EQ(r.mask.at(0, 0), 0.0f);

  // The same cube with a 2x2 texture (sRGB 255 and 0 columns) on every face: the factor multiplies it.
  TriangleMesh textured = cube;
  auto tex = std::make_shared<ImageU8>(2, 1, 3);
  for (int c = 0; c < 3; ++c) tex->at(0, 0, c) = 255, tex->at(1, 0, c) = 0;
  for (auto& m : textured.materials) m.base_color_texture = tex;
  textured.uvs.assign(textured.NumVertices(), Eigen::Vector2f(0.25f, 0.5f));  // the white texel's centre
  const AlbedoRender rt = RenderAlbedo(textured, v);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(rt.color.at(32, 32, c), SixColours()[material][c], 1e-5f);
  textured.uvs.assign(textured.NumVertices(), Eigen::Vector2f(0.75f, 0.5f));  // the black texel
  EXPECT_NEAR(RenderAlbedo(textured, v).color.at(32, 32, 0), 0.0f, 1e-6f);
}

TEST(HeldOutViews, NoneIsARigView) {
  const std::vector<ViewCamera> held = HeldOutViews(Eigen::Vector3f::Zero(), 1.0f);
  ASSERT_EQ(held.size(), 8u);
  for (const ViewCamera& h : held)
    for (const ViewCamera& r : Zero123PlusPlusRig())
      EXPECT_GT((h.T_world_cam.translation - r.T_world_cam.translation).norm(), 0.5);
}

TEST(CompareTextures, IdenticalIsPerfectAndAChangedFaceShowsInTheViewsThatSeeIt) {
  const TriangleMesh cube = ColouredCube(SixColours());
  const TextureMetrics same = CompareTextures(cube, cube, 64);
  EXPECT_NEAR(same.psnr, 120.0, 1e-9);
  EXPECT_NEAR(same.ssim, 1.0, 1e-6);

  std::vector<Eigen::Vector3f> changed = SixColours();
  changed[5] = {0.2f, 0.2f, 0.2f};
  const TextureMetrics diff = CompareTextures(ColouredCube(changed), cube, 64);
  EXPECT_LT(diff.psnr, 40.0);
  EXPECT_GT(diff.psnr, 5.0);
  EXPECT_LT(diff.ssim, 1.0);
  // Some views do not see the changed face at all and stay perfect.
  int perfect = 0;
  for (double p : diff.psnr_per_view) perfect += p > 100;
  EXPECT_GT(perfect, 0);
  EXPECT_LT(perfect, 8);
  EXPECT_THROW(CompareTextures(TriangleMesh{}, cube), InputError);
}

}  // namespace
}  // namespace sd
