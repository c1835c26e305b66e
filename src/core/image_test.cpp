#include "core/image.h"

#include <gtest/gtest.h>

#include <cmath>

namespace sd {
namespace {

TEST(Image, SrgbLinearRoundTripAll256) {
  for (int i = 0; i < 256; ++i) {
    const float lin = SrgbToLinear(i / 255.0f);
    EXPECT_EQ(std::lround(LinearToSrgb(lin) * 255.0f), i) << i;
  }
  // Reference points of IEC 61966-2-1.
  EXPECT_EQ(SrgbToLinear(0.0f), 0.0f);
  EXPECT_NEAR(SrgbToLinear(1.0f), 1.0f, 1e-6f);
  EXPECT_NEAR(SrgbToLinear(0.5f), 0.214041f, 1e-5f);
  EXPECT_NEAR(SrgbToLinear(0.04045f), 0.04045f / 12.92f, 1e-7f);  // end of the linear segment
  EXPECT_NEAR(LinearToSrgb(0.0031308f), 0.04045f, 1e-5f);
  EXPECT_NEAR(LinearToSrgb(2.0f), 1.0f, 1e-6f);  // HDR values clamp
  EXPECT_EQ(LinearToSrgb(-1.0f), 0.0f);
}

TEST(Image, ImageConversionKeepsAlphaLinear) {
  ImageU8 img(256, 1, 4);
  for (int x = 0; x < 256; ++x)
    for (int c = 0; c < 4; ++c) img.at(x, 0, c) = static_cast<uint8_t>(x);
  const ImageF lin = ToLinear(img);
  EXPECT_NEAR(lin.at(128, 0, 0), SrgbToLinear(128 / 255.0f), 1e-7f);
  EXPECT_NEAR(lin.at(128, 0, 3), 128 / 255.0f, 1e-7f);  // alpha only rescaled
  EXPECT_EQ(ToSrgb8(lin).vector(), img.vector());
  // With 3 channels every channel is colour.
  ImageU8 rgb(1, 1, 3, 128);
  EXPECT_NEAR(ToLinear(rgb).at(0, 0, 2), SrgbToLinear(128 / 255.0f), 1e-7f);
}

TEST(Image, BilinearAtPixelCentres) {
  ImageF img(3, 2, 2);
  for (int y = 0; y < 2; ++y)
    for (int x = 0; x < 3; ++x) {
      img.at(x, y, 0) = static_cast<float>(10 * y + x);
      img.at(x, y, 1) = static_cast<float>(-x);
    }
  float out[2];
  for (int y = 0; y < 2; ++y)
    for (int x = 0; x < 3; ++x) {
      SampleBilinear(img, x + 0.5, y + 0.5, out);  // pixel centres give the pixel exactly
      EXPECT_EQ(out[0], img.at(x, y, 0));
      EXPECT_EQ(out[1], img.at(x, y, 1));
    }
  SampleBilinear(img, 1.0, 0.5, out);  // halfway between centres of (0,0) and (1,0)
  EXPECT_FLOAT_EQ(out[0], 0.5f);
  SampleBilinear(img, 2.0, 1.0, out);  // centre of the 2x2 block (1..2, 0..1)
  EXPECT_FLOAT_EQ(out[0], (1 + 2 + 11 + 12) / 4.0f);
  SampleBilinear(img, 1.25, 0.5, out);
  EXPECT_FLOAT_EQ(out[0], 0.75f);
  // Clamped at the border: anything left of / above the first centre reads the edge pixel.
  SampleBilinear(img, 0.0, 0.0, out);
  EXPECT_EQ(out[0], 0.0f);
  SampleBilinear(img, -5.0, 100.0, out);
  EXPECT_EQ(out[0], 10.0f);
  SampleBilinear(img, 3.0, 2.0, out);
  EXPECT_EQ(out[0], 12.0f);

  ImageU8 u8(2, 1, 1);
  u8.at(0, 0) = 0;
  u8.at(1, 0) = 255;
  float o;
  SampleBilinear(u8, 1.0, 0.5, &o);
  EXPECT_FLOAT_EQ(o, 127.5f);  // 0..255 scale, no sRGB decoding
}

}  // namespace
}  // namespace sd
