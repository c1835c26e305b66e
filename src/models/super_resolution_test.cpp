#include "models/super_resolution.h"

#include <cmath>
#include <cstdlib>
#include <fstream>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "io/image_io.h"
#include "testing/testing.h"

namespace sd::models {
namespace {

namespace fs = std::filesystem;

// NCHW 0..255 (batch 1) -> interleaved 0..1.
ImageF ToImage(const std::vector<float>& nchw, const std::vector<int64_t>& shape) {
  const int c = static_cast<int>(shape[1]), h = static_cast<int>(shape[2]), w = static_cast<int>(shape[3]);
  ImageF img(w, h, c);
  for (int k = 0; k < c; ++k)
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) img.at(x, y, k) = nchw[(static_cast<size_t>(k) * h + y) * w + x] / 255.0f;
  return img;
}

TEST(UpscaleBicubic, KeepsConstantsAndReproducesLinearRamps) {
  ImageF img(12, 9, 2);
  for (int y = 0; y < 9; ++y)
    for (int x = 0; x < 12; ++x) {
      img.at(x, y, 0) = 0.25f;
      img.at(x, y, 1) = 0.03f * static_cast<float>(x) + 0.02f * static_cast<float>(y);
    }
  const ImageF up = UpscaleBicubic(img, 3);
  ASSERT_EQ(up.width(), 36);
  ASSERT_EQ(up.height(), 27);
  ASSERT_EQ(up.channels(), 2);
  for (int y = 0; y < 27; ++y)
    for (int x = 0; x < 36; ++x) {
      EXPECT_NEAR(up.at(x, y, 0), 0.25f, 1e-6f);
      // Keys' kernel reproduces linear functions exactly where no tap is clamped: 2 input pixels from the edge.
      const float u = (static_cast<float>(x) + 0.5f) / 3 - 0.5f, v = (static_cast<float>(y) + 0.5f) / 3 - 0.5f;
      if (u >= 1 && u <= 10 && v >= 1 && v <= 7) {
        EXPECT_NEAR(up.at(x, y, 1), 0.03f * u + 0.02f * v, 1e-5f) << x << "," << y;
      }
    }
}

TEST(Upscaler, ClassicalPathSaysSoAndKeepsChannels) {
  const Upscaler up = Upscaler::Classical(2);
  EXPECT_FALSE(up.learned());
  EXPECT_EQ(up.Describe(), "bicubic ×2 (classical)");
  ImageU8 rgba(5, 4, 4, 200);
  const ImageU8 out = up.Upscale(rgba);
  EXPECT_EQ(out.width(), 10);
  EXPECT_EQ(out.height(), 8);
  EXPECT_EQ(out.channels(), 4);
  for (uint8_t v : out.vector()) EXPECT_EQ(v, 200);
  EXPECT_THROW(Upscaler::Classical(1), InputError);
  EXPECT_THROW(up.Upscale(ImageF()), InputError);
}

TEST(Upscaler, TiledLearnedPassEqualsTheWholeImageReference) {
  SD_REQUIRE_TEST_MODEL(file, "sr_tiny_x2.pt");
  std::vector<int64_t> in_shape, out_shape;
  const ImageF input = ToImage(testing::ReadRawFloats(testing::TestModel("sr_tiny_x2_input.f32"), &in_shape), in_shape);
  const ImageF expected = ToImage(testing::ReadRawFloats(testing::TestModel("sr_tiny_x2_output.f32"), &out_shape), out_shape);
  // 16-pixel tiles cut the 70x45 image into 5x3 tiles with interior seams; a tile margin smaller than the
  // model's receptive radius would show there.
  UpscaleOptions options;
  options.tile = 16;
  const Upscaler up = Upscaler::FromModel(file, {}, options);
  EXPECT_TRUE(up.learned());
  EXPECT_EQ(up.scale(), 2);
  EXPECT_NE(up.Describe().find("sr-tiny-x2 ×2"), std::string::npos) << up.Describe();
  const ImageF out = up.Upscale(input);
  ASSERT_EQ(out.width(), expected.width());
  ASSERT_EQ(out.height(), expected.height());
  float worst = 0;
  for (size_t i = 0; i < out.size(); ++i)
    worst = std::max(worst, std::abs(out.vector()[i] - std::clamp(expected.vector()[i], 0.0f, 1.0f)));
  EXPECT_LT(worst, 1e-5f);
}

TEST(Upscaler, AlphaGoesThroughTheClassicalPath) {
  SD_REQUIRE_TEST_MODEL(file, "sr_tiny_x2.pt");
  ImageF rgba(20, 10, 4, 0.5f);
  for (int y = 0; y < 10; ++y)
    for (int x = 0; x < 20; ++x) rgba.at(x, y, 3) = x < 10 ? 0.0f : 1.0f;
  const ImageF out = Upscaler::FromModel(file).Upscale(rgba);
  const ImageF alpha = UpscaleBicubic(
      [&] {
        ImageF a(20, 10, 1);
        for (int y = 0; y < 10; ++y)
          for (int x = 0; x < 20; ++x) a.at(x, y) = rgba.at(x, y, 3);
        return a;
      }(),
      2);
  ASSERT_EQ(out.channels(), 4);
  for (int y = 0; y < 20; ++y)
    for (int x = 0; x < 40; ++x) EXPECT_NEAR(out.at(x, y, 3), std::clamp(alpha.at(x, y), 0.0f, 1.0f), 1e-6f);
}

TEST(Upscaler, ModelThatDoesNotUpscaleIsReported) {
  SD_REQUIRE_TEST_MODEL(file, "not_upscaling.pt");
  const Upscaler up = Upscaler::FromModel(file);
  try {
    up.Upscale(ImageF(8, 8, 3, 0.5f));
    FAIL() << "an identity model passed as a x2 upscaler";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("turned a 8x8 tile into 8x8, not ×2"), std::string::npos) << e.what();
  }
}

TEST(Upscaler, AutoFallsBackToBicubicWithoutWeightsAndNamedModelsMustExist) {
  testing::TempDir empty;
  const testing::ScopedEnv env("SYNTHDRIVE_MODELS", empty.path().string());
  const Upscaler up = Upscaler::Resolve("auto", 2);
  EXPECT_FALSE(up.learned());
  try {
    Upscaler::Resolve("esrgan-medium", 4);
    FAIL() << "a missing named model resolved";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("esrgan-medium-x4.pt: no such model file"), std::string::npos) << e.what();
  }
}

TEST(Upscaler, ScaleOfAModelFileMustMatchTheRequest) {
  SD_REQUIRE_TEST_MODEL(file, "sr_tiny_x2.pt");
  EXPECT_TRUE(Upscaler::Resolve(file.string(), 2).learned());
  EXPECT_THROW(Upscaler::Resolve(file.string(), 4), InputError);
}

double Psnr(const ImageU8& a, const ImageU8& b) {
  double se = 0;
  size_t n = 0;
  for (int y = 0; y < a.height(); ++y)
    for (int x = 0; x < a.width(); ++x)
      for (int c = 0; c < 3; ++c, ++n) {
        const double d = double(a.at(x, y, c)) - double(b.at(x, y, c));
        se += d * d;
      }
  return se == 0 ? 99.0 : 10 * std::log10(255.0 * 255.0 * static_cast<double>(n) / se);
}

// The real UpscalerJS weights as scripts/fetch_models.sh installs them: our import, run by our tiled C++ stage,
// must reproduce the packages' own sample outputs of their fixture image.
TEST(Upscaler, ReproducesTheEsrganPackageSamples) {
  int checked = 0;
  for (const std::string size : {"slim", "medium"})
    for (int scale : {2, 4}) {
      const fs::path model = DefaultModelDir() / ("esrgan-" + size + "-x" + std::to_string(scale) + ".pt");
      const fs::path package = DefaultModelDir() / "npm" / ("upscalerjs-esrgan-" + size + "-1.0.0") / "package";
      if (!fs::exists(model) || !fs::exists(package / "assets" / "fixture.png")) continue;
      const ImageU8 fixture = ReadImage(package / "assets" / "fixture.png", 3);
      const ImageU8 expected = ReadImage(package / "assets" / "samples" / (std::to_string(scale) + "x") / "result.png", 3);
      UpscaleOptions tiled;
      tiled.tile = 48;  // seams inside the 128-pixel fixture, so tiling is part of what is checked
      const ImageU8 ours = Upscaler::FromModel(model, {}, tiled).Upscale(fixture);
      ASSERT_EQ(ours.width(), expected.width());
      ASSERT_EQ(ours.height(), expected.height());
      const double learned = Psnr(ours, expected);
      const double bicubic = Psnr(Upscaler::Classical(scale).Upscale(fixture), expected);
      // The import reproduces the samples to > 90 dB (rounding only); bicubic is ~30 dB from them.
      EXPECT_GT(learned, 60.0) << model;
      EXPECT_LT(bicubic, 45.0) << model;
      std::printf("%s: PSNR %.1f dB against the package sample (bicubic %.1f dB)\n", model.filename().c_str(), learned,
                  bicubic);
      ++checked;
    }
  if (checked == 0)
    GTEST_SKIP() << "no UpscalerJS weights in " << DefaultModelDir() << " (scripts/fetch_models.sh installs them)";
}

}  // namespace
}  // namespace sd::models
