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

// Sampling the 8-bit image as linear light with a gain gives, bit for bit, what sampling its float copy does.
TEST(Image, BilinearLinearEqualsBilinearOfTheLinearCopy) {
  for (int channels : {3, 4}) {
    ImageU8 srgb(7, 5, channels);
    for (size_t i = 0; i < srgb.size(); ++i) srgb.data()[i] = static_cast<uint8_t>((i * 37 + 11) % 256);
    const float gain[3] = {1.0f, 0.83f, 1.27f};
    ImageF linear = ToLinear(srgb);
    for (int y = 0; y < srgb.height(); ++y)
      for (int x = 0; x < srgb.width(); ++x)
        for (int c = 0; c < 3; ++c) linear.at(x, y, c) *= gain[c];
    for (double v = -1.0; v < 6.5; v += 0.37)
      for (double u = -1.0; u < 8.5; u += 0.29) {
        float want[4], got[4];
        SampleBilinear(linear, u, v, want);
        SampleBilinearLinear(srgb, u, v, gain, got);
        for (int c = 0; c < channels; ++c) ASSERT_EQ(got[c], want[c]) << u << ", " << v << " channel " << c;
      }
  }
}

// A region converted back leaves every other byte as it was, and inside equals the whole image's conversion;
// and an 8-bit value survives the round trip through linear exactly.
TEST(ImageConversion, Srgb8RegionKeepsTheRestAndRoundTrips) {
  ImageU8 photo(40, 30, 3);
  for (size_t i = 0; i < photo.size(); ++i) photo.vector()[i] = static_cast<uint8_t>((i * 37) % 256);
  ImageF linear = ToLinear(photo);
  EXPECT_EQ(ToSrgb8(linear).vector(), photo.vector()) << "every 8-bit value round-trips";
  for (int v = 0; v < 256; ++v) EXPECT_EQ(SrgbByteToLinear(static_cast<uint8_t>(v)), SrgbToLinear(v / 255.0f));
  for (int y = 5; y < 20; ++y)
    for (int x = 10; x < 25; ++x)
      for (int c = 0; c < 3; ++c) linear.at(x, y, c) = 0.5f * linear.at(x, y, c) + 0.1f;
  ImageU8 out = photo;
  ToSrgb8Region(linear, 10, 5, 25, 20, &out);
  const ImageU8 whole = ToSrgb8(linear);
  for (int y = 0; y < 30; ++y)
    for (int x = 0; x < 40; ++x)
      for (int c = 0; c < 3; ++c) {
        const bool inside = x >= 10 && x < 25 && y >= 5 && y < 20;
        ASSERT_EQ(out.at(x, y, c), inside ? whole.at(x, y, c) : photo.at(x, y, c)) << x << "," << y;
      }
  ToSrgb8Region(linear, -5, -5, 0, 100, &out);  // empty after clamping: nothing changes
  ToSrgb8Region(linear, 35, 25, 100, 100, &out);  // clamped to the image
  EXPECT_EQ(out.at(39, 29, 0), whole.at(39, 29, 0));
}

// A camera-sized image freed is kept and handed to the next image of its size, which still gets its fill
// value everywhere; what the cache holds stays within its limit.
TEST(ImageMemory, LargeBlocksAreReusedWithinTheLimit) {
  const size_t before = ImageMemoryCached();
  const float* first = nullptr;
  {
    ImageF a(1600, 900, 1, 7.0f);
    first = a.data();
    a.at(5, 5) = 3.0f;
  }
  const size_t block = size_t{6} << 20;  // 5.76 MB rounded up to 2 MB pages
  const size_t held = ImageMemoryCached();
  EXPECT_EQ(held, before + block) << "the freed block is kept";
  {
    ImageF b(1600, 900, 1, 0.5f);  // the same rounded size: a kept block, filled anew
    EXPECT_EQ(ImageMemoryCached(), before);
    if (before == 0) {
      EXPECT_EQ(b.data(), first);
    }
    for (float v : b.vector()) ASSERT_EQ(v, 0.5f);
  }
  // Small images never enter the cache.
  { ImageF small(64, 64, 3, 1.0f); }
  EXPECT_EQ(ImageMemoryCached(), held);
  // More freed at once than the limit: the cache stops at it and frees the rest.
  {
    std::vector<ImageF> many;
    const size_t block = size_t{64} << 20;
    for (size_t total = 0; total <= ImageMemoryCacheLimit() + block; total += block)
      many.emplace_back(4096, 4096, 1, 0.0f);  // 64 MB each
  }
  EXPECT_LE(ImageMemoryCached(), ImageMemoryCacheLimit());
}

}  // namespace
}  // namespace sd
