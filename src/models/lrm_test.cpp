#include "models/lrm.h"

#include <cmath>
#include <filesystem>
#include <map>

#include <gtest/gtest.h>

#include "core/device.h"
#include "core/error.h"
#include "testing/testing.h"

namespace sd::models {
namespace {

namespace fs = std::filesystem;

// The tiny LRM: the encoder stores the image's mean colour in the triplane, the decoder is the signed distance
// of a sphere at the origin of radius 0.15 + 0.2 * mean grey, coloured with the mean colour.
class LrmTest : public ::testing::Test {
 protected:
  void SetUp() override {
    const fs::path enc = testing::TestModel("lrm_tiny_encoder.pt");
    if (enc.empty()) GTEST_SKIP() << "tiny LRM test models not built (needs python3 with torch)";
    fs::copy_file(enc, dir_ / kLrmEncoderFile);
    fs::copy_file(testing::TestModel("lrm_tiny_decoder.pt"), dir_ / kLrmDecoderFile);
  }
  LrmReconstructor Load(int grid, int chunk) const {
    LrmOptions o;
    o.grid = grid;
    o.chunk = chunk;
    return LrmReconstructor::Load(dir_.path(), {}, o);
  }
  testing::TempDir dir_;
};

TEST_F(LrmTest, AnalyticSphereComesOutWithinOneGridCell) {
  const int grid = 41;
  const float cell = 1.0f / (grid - 1);
  const LrmReconstructor lrm = Load(grid, 5000);
  EXPECT_EQ(lrm.image_size(), 32);
  // A uniform (0.8, 0.4, 0.2) image: mean grey 0.4667 -> radius 0.15 + 0.2 * 0.4667.
  ImageF img(50, 50, 3);
  for (int y = 0; y < 50; ++y)
    for (int x = 0; x < 50; ++x) {
      img.at(x, y, 0) = 0.8f;
      img.at(x, y, 1) = 0.4f;
      img.at(x, y, 2) = 0.2f;
    }
  const float radius = 0.15f + 0.2f * (0.8f + 0.4f + 0.2f) / 3;
  const TriangleMesh mesh = lrm.Reconstruct(img);
  EXPECT_EQ(mesh.Validate(), "");
  ASSERT_GT(mesh.NumFaces(), 100u);
  ASSERT_EQ(mesh.colors.size(), mesh.NumVertices());
  ASSERT_EQ(mesh.normals.size(), mesh.NumVertices());
  float worst = 0;
  for (size_t v = 0; v < mesh.NumVertices(); ++v) {
    worst = std::max(worst, std::abs(mesh.positions[v].norm() - radius));
    EXPECT_NEAR(mesh.colors[v].x(), SrgbToLinear(0.8f), 1e-4f);
    EXPECT_NEAR(mesh.colors[v].y(), SrgbToLinear(0.4f), 1e-4f);
    EXPECT_NEAR(mesh.colors[v].z(), SrgbToLinear(0.2f), 1e-4f);
    EXPECT_GT(mesh.normals[v].dot(mesh.positions[v].normalized()), 0.9f);  // outward
  }
  EXPECT_LT(worst, cell);
  std::printf("sphere r=%.4f on a %d^3 grid: worst vertex radius error %.5f (cell %.4f), %zu faces\n", radius, grid,
              worst, cell, mesh.NumFaces());
  // Closed: every edge is shared by exactly two faces.
  std::map<std::pair<int, int>, int> edges;
  for (const Eigen::Vector3i& f : mesh.faces)
    for (int e = 0; e < 3; ++e) ++edges[{std::min(f[e], f[(e + 1) % 3]), std::max(f[e], f[(e + 1) % 3])}];
  for (const auto& [edge, count] : edges) ASSERT_EQ(count, 2);
}

TEST_F(LrmTest, ChunkSizeDoesNotChangeTheMesh) {
  ImageF img(20, 30, 3, 0.5f);
  const TriangleMesh a = Load(25, 97).Reconstruct(img);
  const TriangleMesh b = Load(25, 1 << 20).Reconstruct(img);
  ASSERT_EQ(a.NumVertices(), b.NumVertices());
  ASSERT_EQ(a.NumFaces(), b.NumFaces());
  // Equal on the CPU. On a GPU the decoder's matrix products pick kernels by batch size, which sum in another
  // order: last-bit differences (seen on an H100), never a different surface.
  const float tolerance = CurrentDevice() == Device::kCuda ? 1e-5f : 0.0f;
  for (size_t v = 0; v < a.NumVertices(); ++v) {
    EXPECT_LE((a.positions[v] - b.positions[v]).cwiseAbs().maxCoeff(), tolerance);
    EXPECT_LE((a.colors[v] - b.colors[v]).cwiseAbs().maxCoeff(), tolerance);
  }
  for (size_t f = 0; f < a.NumFaces(); ++f) EXPECT_EQ(a.faces[f], b.faces[f]);
}

TEST_F(LrmTest, DecoderWithAFixedPointCountGetsPaddedChunks) {
  // 17^3 = 4913 grid nodes: four full chunks of 1000 and one padded; the mesh must equal the free decoder's.
  testing::TempDir fixed;
  fs::copy_file(dir_ / kLrmEncoderFile, fixed / kLrmEncoderFile);
  fs::copy_file(testing::TestModel("lrm_tiny_decoder_p1000.pt"), fixed / kLrmDecoderFile);
  LrmOptions o;
  o.grid = 17;
  o.chunk = 333;  // ignored: the contract fixes P
  const ImageF img(32, 32, 3, 0.6f);
  const TriangleMesh a = LrmReconstructor::Load(fixed.path(), {}, o).Reconstruct(img);
  const TriangleMesh b = Load(17, 4096).Reconstruct(img);
  ASSERT_GT(a.NumFaces(), 0u);
  ASSERT_EQ(a.NumVertices(), b.NumVertices());
  for (size_t v = 0; v < a.NumVertices(); ++v) EXPECT_EQ(a.positions[v], b.positions[v]);
}

TEST_F(LrmTest, ImagesAreLetterboxedOnTheBackground) {
  const LrmReconstructor lrm = Load(9, 1000);
  // A black 40 x 20 image: centred in a white 40 x 40 square, resized to 32.
  const ImageF prepared = lrm.PrepareImage(ImageF(40, 20, 3, 0.0f));
  ASSERT_EQ(prepared.width(), 32);
  EXPECT_NEAR(prepared.at(16, 1, 0), 1.0f, 1e-5f);
  EXPECT_NEAR(prepared.at(16, 16, 0), 0.0f, 1e-5f);
  EXPECT_NEAR(prepared.at(16, 30, 2), 1.0f, 1e-5f);
  // Transparent pixels are background too.
  ImageF rgba(32, 32, 4, 0.0f);
  const ImageF clear = lrm.PrepareImage(rgba);
  for (float v : clear.vector()) EXPECT_NEAR(v, 1.0f, 1e-6f);
}

TEST_F(LrmTest, MissingFilesAndSwappedStagesAreNamed) {
  testing::TempDir half;
  fs::copy_file(dir_ / kLrmEncoderFile, half / kLrmEncoderFile);
  try {
    LrmReconstructor::Load(half.path());
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("lacks lrm_decoder.pt"), std::string::npos) << e.what();
  }
  fs::copy_file(dir_ / kLrmEncoderFile, half / kLrmDecoderFile);
  try {
    LrmReconstructor::Load(half.path());
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("lrm_decoder.pt: is a 'lrm_encoder' model"), std::string::npos) << e.what();
  }
  LrmOptions bad;
  bad.grid = 2;
  EXPECT_THROW(LrmReconstructor::Load(dir_.path(), {}, bad), InputError);
}

}  // namespace
}  // namespace sd::models
