#include "models/harmonization.h"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <numbers>
#include <random>

#include <gtest/gtest.h>

#include "core/error.h"
#include "testing/testing.h"

namespace sd::models {
namespace {

// A 60 x 50 scene: background colour `bg`, a 20 x 16 object of colour `fg` at (20, 17), each with Gaussian
// noise of the given std (sRGB units), kept inside 0..1 so no clamping hides a statistic.
struct Scene {
  ImageF composite{60, 50, 3};
  ImageF mask{60, 50, 1, 0.0f};
};

Scene MakeScene(std::array<float, 3> bg, float bg_noise, std::array<float, 3> fg, float fg_noise, unsigned seed) {
  Scene s;
  std::mt19937 rng(seed);
  std::normal_distribution<float> n(0, 1);
  for (int y = 0; y < 50; ++y)
    for (int x = 0; x < 60; ++x) {
      const bool in = x >= 20 && x < 40 && y >= 17 && y < 33;
      s.mask.at(x, y) = in ? 1.0f : 0.0f;
      for (int c = 0; c < 3; ++c)
        s.composite.at(x, y, c) =
            std::clamp(in ? fg[c] + fg_noise * n(rng) : bg[c] + bg_noise * n(rng), 0.02f, 0.98f);
    }
  return s;
}

std::array<double, 6> LabMeanStd(const ImageF& img, const ImageF& mask, bool inside, int ring) {
  std::array<double, 3> sum{}, sum2{};
  size_t count = 0;
  for (int y = 0; y < img.height(); ++y)
    for (int x = 0; x < img.width(); ++x) {
      const bool in = mask.at(x, y) >= 0.5f;
      const bool near = x >= 20 - ring && x < 40 + ring && y >= 17 - ring && y < 33 + ring;
      if (inside ? !in : (in || !near)) continue;
      const auto lab = SrgbToLab({img.at(x, y, 0), img.at(x, y, 1), img.at(x, y, 2)});
      for (int c = 0; c < 3; ++c) sum[c] += lab[c], sum2[c] += double(lab[c]) * lab[c];
      ++count;
    }
  std::array<double, 6> out{};
  for (int c = 0; c < 3; ++c) {
    out[c] = sum[c] / count;
    out[3 + c] = std::sqrt(std::max(0.0, sum2[c] / count - out[c] * out[c]));
  }
  return out;
}

TEST(Lab, RoundTripsAndKnownValues) {
  const auto white = SrgbToLab({1, 1, 1});
  EXPECT_NEAR(white[0], 100.0f, 1e-3f);
  EXPECT_NEAR(white[1], 0.0f, 1e-3f);
  EXPECT_NEAR(white[2], 0.0f, 1e-3f);
  const auto red = SrgbToLab({1, 0, 0});  // the textbook sRGB red: L 53.24, a 80.09, b 67.20
  EXPECT_NEAR(red[0], 53.24f, 0.02f);
  EXPECT_NEAR(red[1], 80.09f, 0.05f);
  EXPECT_NEAR(red[2], 67.20f, 0.05f);
  for (float r : {0.0f, 0.1f, 0.5f, 0.93f})
    for (float g : {0.02f, 0.6f})
      for (float b : {0.3f, 1.0f}) {
        const auto back = LabToSrgb(SrgbToLab({r, g, b}));
        EXPECT_NEAR(back[0], r, 1e-4f);
        EXPECT_NEAR(back[1], g, 1e-4f);
        EXPECT_NEAR(back[2], b, 1e-4f);
      }
}

TEST(Harmonizer, FullTransferMatchesTheRingStatisticsAndKeepsTheBackground) {
  const Scene s = MakeScene({0.35f, 0.4f, 0.45f}, 0.05f, {0.7f, 0.55f, 0.3f}, 0.04f, 5);
  HarmonizeOptions full;
  full.lightness_strength = full.chroma_strength = full.cast_strength = 1.0f;
  full.max_cast = 1e9f;  // plain Reinhard
  full.ring_px = 6;
  const Harmonizer h = Harmonizer::Classical(full);
  EXPECT_FALSE(h.learned());
  const ImageF out = h.Harmonize(s.composite, s.mask);
  for (int y = 0; y < 50; ++y)
    for (int x = 0; x < 60; ++x)
      if (s.mask.at(x, y) == 0) {
        for (int c = 0; c < 3; ++c) ASSERT_EQ(out.at(x, y, c), s.composite.at(x, y, c));
      }
  const auto ring = LabMeanStd(s.composite, s.mask, false, 6);
  const auto before = LabMeanStd(s.composite, s.mask, true, 0);
  const auto after = LabMeanStd(out, s.mask, true, 0);
  for (int c = 0; c < 3; ++c) {
    EXPECT_GT(std::abs(before[c] - ring[c]), 2.0) << c;  // the test means something
    EXPECT_NEAR(after[c], ring[c], 0.05) << c;
    EXPECT_NEAR(after[3 + c], ring[3 + c], 0.05 * ring[3 + c] + 0.05) << c;
  }
}

TEST(Harmonizer, UniformObjectTakesTheRingColourAndPartialStrengthsInterpolate) {
  const Scene s = MakeScene({0.3f, 0.5f, 0.6f}, 0.0f, {0.8f, 0.2f, 0.1f}, 0.0f, 1);
  HarmonizeOptions full;
  full.lightness_strength = full.chroma_strength = full.cast_strength = 1.0f;
  full.max_cast = 1e9f;
  const ImageF out = Harmonizer::Classical(full).Harmonize(s.composite, s.mask);
  for (int c = 0; c < 3; ++c) EXPECT_NEAR(out.at(30, 25, c), s.composite.at(0, 0, c), 1e-3f);
  HarmonizeOptions half;
  half.lightness_strength = 0.5f;
  half.chroma_strength = half.cast_strength = 0.25f;  // equal: the cast split cancels, plain Reinhard
  half.max_cast = 1e9f;
  const ImageF part = Harmonizer::Classical(half).Harmonize(s.composite, s.mask);
  const auto fg = SrgbToLab({0.8f, 0.2f, 0.1f}), bg = SrgbToLab({0.3f, 0.5f, 0.6f});
  const auto got = SrgbToLab({part.at(30, 25, 0), part.at(30, 25, 1), part.at(30, 25, 2)});
  EXPECT_NEAR(got[0], fg[0] + 0.5f * (bg[0] - fg[0]), 0.01f);
  EXPECT_NEAR(got[1], fg[1] + 0.25f * (bg[1] - fg[1]), 0.02f);
  EXPECT_NEAR(got[2], fg[2] + 0.25f * (bg[2] - fg[2]), 0.02f);
  // No object, nothing to do; a mask of the wrong size is an input error.
  const ImageF none(60, 50, 1, 0.0f);
  EXPECT_EQ(Harmonizer::Classical().Harmonize(s.composite, none).vector(), s.composite.vector());
  EXPECT_THROW(Harmonizer::Classical().Harmonize(s.composite, ImageF(10, 10, 1)), InputError);
}

// A warm light (linear per-channel gains, von Kries) on the background only: the object must take the cast the
// ring shows and keep its own hue.
ImageF ApplyGain(const ImageF& srgb, const ImageF& mask, bool inside, std::array<float, 3> gain) {
  ImageF out = srgb;
  for (int y = 0; y < srgb.height(); ++y)
    for (int x = 0; x < srgb.width(); ++x)
      if ((mask.at(x, y) >= 0.5f) == inside)
        for (int c = 0; c < 3; ++c) out.at(x, y, c) = LinearToSrgb(std::min(1.0f, SrgbToLinear(srgb.at(x, y, c)) * gain[c]));
  return out;
}

double HueDeg(double a, double b) { return std::atan2(b, a) * 180.0 / std::numbers::pi; }

constexpr std::array<float, 3> kWarm = {1.2f, 1.0f, 0.75f};

TEST(Harmonizer, BackgroundCastReachesTheObjectAndARedConeStaysRed) {
  const Scene s = MakeScene({0.45f, 0.45f, 0.45f}, 0.03f, {0.85f, 0.2f, 0.1f}, 0.03f, 7);  // road grey, red cone
  const ImageF cast = ApplyGain(s.composite, s.mask, false, kWarm);
  const Harmonizer h = Harmonizer::Classical();
  const ImageF out_plain = h.Harmonize(s.composite, s.mask), out_cast = h.Harmonize(cast, s.mask);
  const auto ring_plain = LabMeanStd(s.composite, s.mask, false, 6), ring_cast = LabMeanStd(cast, s.mask, false, 6);
  const auto obj_in = LabMeanStd(s.composite, s.mask, true, 0);
  const auto obj_plain = LabMeanStd(out_plain, s.mask, true, 0), obj_cast = LabMeanStd(out_cast, s.mask, true, 0);
  // The cast as the ring shows it (a*, b*), and the change it makes to the harmonised object.
  const double da = ring_cast[1] - ring_plain[1], db = ring_cast[2] - ring_plain[2];
  std::printf("cast on the ring (a*, b*) %.2f %.2f; the object received %.2f %.2f; hue in %.1f, out %.1f (plain), "
              "%.1f (cast); chroma in %.1f, out %.1f, %.1f\n",
              da, db, obj_cast[1] - obj_plain[1], obj_cast[2] - obj_plain[2], HueDeg(obj_in[1], obj_in[2]),
              HueDeg(obj_plain[1], obj_plain[2]), HueDeg(obj_cast[1], obj_cast[2]), std::hypot(obj_in[1], obj_in[2]),
              std::hypot(obj_plain[1], obj_plain[2]), std::hypot(obj_cast[1], obj_cast[2]));
  EXPECT_GT(std::hypot(da, db), 8.0);  // the test means something
  EXPECT_NEAR(obj_cast[1] - obj_plain[1], da, 1.0);
  EXPECT_NEAR(obj_cast[2] - obj_plain[2], db, 1.0);
  // Own colour: on a neutral road the cone's hue does not move and its chroma drops by at most chroma_strength.
  const double chroma_in = std::hypot(obj_in[1], obj_in[2]);
  EXPECT_NEAR(HueDeg(obj_plain[1], obj_plain[2]), HueDeg(obj_in[1], obj_in[2]), 1.0);
  EXPECT_GT(std::hypot(obj_plain[1], obj_plain[2]), 0.88 * chroma_in);
  // Under the cast it stays red: within 8 degrees of its own hue, and nowhere near the road's grey.
  EXPECT_NEAR(HueDeg(obj_cast[1], obj_cast[2]), HueDeg(obj_in[1], obj_in[2]), 8.0);
  EXPECT_GT(std::hypot(obj_cast[1], obj_cast[2]), 0.85 * chroma_in);
}

TEST(Harmonizer, AnObjectAlreadyUnderTheCastIsNotCastTwiceAndColouredRingsAreBounded) {
  // A grey car rendered under the same warm light as the scene: the casts agree, nothing to move in a*b*.
  Scene s = MakeScene({0.45f, 0.45f, 0.45f}, 0.03f, {0.55f, 0.55f, 0.55f}, 0.03f, 8);
  const ImageF lit = ApplyGain(ApplyGain(s.composite, s.mask, false, kWarm), s.mask, true, kWarm);
  const ImageF out = Harmonizer::Classical().Harmonize(lit, s.mask);
  const auto before = LabMeanStd(lit, s.mask, true, 0), after = LabMeanStd(out, s.mask, true, 0);
  EXPECT_GT(std::hypot(before[1], before[2]), 8.0);
  // Not exactly: a light's a*b* shift grows with L*, and the car is lighter than the road (adding the
  // ring's cast again would move b* by ~10).
  EXPECT_NEAR(after[1], before[1], 2.0);
  EXPECT_NEAR(after[2], before[2], 2.0);
  // A lawn all round (no grey pixels): no cast is inferred, only chroma_strength of the colour difference moves.
  const Scene g = MakeScene({0.2f, 0.55f, 0.15f}, 0.02f, {0.85f, 0.2f, 0.1f}, 0.02f, 9);
  const ImageF gout = Harmonizer::Classical().Harmonize(g.composite, g.mask);
  const auto gin = LabMeanStd(g.composite, g.mask, true, 0), gobj = LabMeanStd(gout, g.mask, true, 0);
  const auto lawn = LabMeanStd(g.composite, g.mask, false, 6);
  for (int c = 1; c < 3; ++c) EXPECT_NEAR(gobj[c] - gin[c], 0.1 * (lawn[c] - gin[c]), 0.3) << c;
  // A near-grey ring with a strong tint: the cast applied is bounded by max_cast.
  const Scene t = MakeScene({0.45f, 0.45f, 0.45f}, 0.02f, {0.85f, 0.2f, 0.1f}, 0.02f, 10);
  const ImageF tinted = ApplyGain(t.composite, t.mask, false, {1.0f, 1.0f, 1.6f});
  HarmonizeOptions bounded;
  bounded.chroma_strength = 0;
  bounded.max_cast = 5;
  const auto tin = LabMeanStd(tinted, t.mask, true, 0);
  const auto tout = LabMeanStd(Harmonizer::Classical(bounded).Harmonize(tinted, t.mask), t.mask, true, 0);
  EXPECT_NEAR(std::hypot(tout[1] - tin[1], tout[2] - tin[2]), 5.0, 0.3);
}

TEST(HarmonizeInsert, CompositesThenHarmonisesAndKeepsTheBackground) {
  const Scene s = MakeScene({0.45f, 0.45f, 0.45f}, 0.03f, {0.85f, 0.2f, 0.1f}, 0.03f, 11);
  const ImageF image = ApplyGain(s.composite, s.mask, false, kWarm);
  // The object layer: its colour everywhere (straight alpha), a soft edge column at x = 19.
  ImageF object(60, 50, 3), alpha = s.mask;
  for (int y = 0; y < 50; ++y)
    for (int x = 0; x < 60; ++x)
      for (int c = 0; c < 3; ++c) object.at(x, y, c) = s.composite.at(std::clamp(x, 20, 39), std::clamp(y, 17, 32), c);
  for (int y = 17; y < 33; ++y) alpha.at(19, y) = 0.5f;
  const ImageF out = HarmonizeInsert(image, object, alpha);
  ImageF composite = image;
  for (int y = 0; y < 50; ++y)
    for (int x = 0; x < 60; ++x)
      for (int c = 0; c < 3; ++c)
        composite.at(x, y, c) = image.at(x, y, c) * (1 - alpha.at(x, y)) + object.at(x, y, c) * alpha.at(x, y);
  EXPECT_EQ(out.vector(), Harmonizer::Classical().Harmonize(composite, alpha).vector());
  for (int y = 0; y < 50; ++y)
    for (int x = 0; x < 60; ++x)
      if (alpha.at(x, y) == 0) {
        for (int c = 0; c < 3; ++c) ASSERT_EQ(out.at(x, y, c), image.at(x, y, c));
      }
  EXPECT_THROW(HarmonizeInsert(image, ImageF(10, 10, 3), alpha), InputError);
  EXPECT_THROW(HarmonizeInsert(image, object, ImageF(60, 50, 3)), InputError);
}

TEST(HarmonizeInsert, UsesTheLearnedModelWhenGiven) {
  SD_REQUIRE_TEST_MODEL(file, "harmonizer_tiny.pt");
  const Harmonizer h = Harmonizer::FromModel(file);
  const Scene s = MakeScene({0.3f, 0.5f, 0.6f}, 0.1f, {0.8f, 0.2f, 0.1f}, 0.1f, 12);
  ImageF object(60, 50, 3, 0.7f), alpha = s.mask;
  alpha.at(19, 20) = 0.25f;
  InsertOptions opt;
  opt.harmonizer = &h;
  const ImageF out = HarmonizeInsert(s.composite, object, alpha, opt);
  for (int y = 0; y < 50; ++y)
    for (int x = 0; x < 60; ++x) {
      const float m = alpha.at(x, y);
      for (int c = 0; c < 3; ++c) {
        const float v = s.composite.at(x, y, c) * (1 - m) + 0.7f * m;  // the composite
        const float model = m * (0.5f * v + 0.25f) + (1 - m) * (v + 0.1f);
        const float expected = m == 0 ? v : std::clamp(v + m * (model - v), 0.0f, 1.0f);
        ASSERT_NEAR(out.at(x, y, c), expected, 1e-6f) << x << "," << y;
      }
    }
}

TEST(Harmonizer, AutoWithoutAModelIsClassical) {
  testing::TempDir empty;
  const char* old = std::getenv("SYNTHDRIVE_MODELS");
  const std::string saved = old ? old : "";
  setenv("SYNTHDRIVE_MODELS", empty.path().c_str(), 1);
  const Harmonizer h = Harmonizer::Resolve("auto");
  EXPECT_FALSE(h.learned());
  EXPECT_NE(h.Describe().find("classical"), std::string::npos) << h.Describe();
  if (old) setenv("SYNTHDRIVE_MODELS", saved.c_str(), 1);
  else unsetenv("SYNTHDRIVE_MODELS");
  EXPECT_THROW(Harmonizer::Resolve((empty / "missing.pt").string()), InputError);
}

// The tiny model: 0.5 · composite + 0.25 inside the mask, composite + 0.1 outside (which must not survive).
TEST(Harmonizer, LearnedPathBlendsByTheMask) {
  SD_REQUIRE_TEST_MODEL(file, "harmonizer_tiny.pt");
  const Harmonizer h = Harmonizer::FromModel(file);
  EXPECT_TRUE(h.learned());
  Scene s = MakeScene({0.3f, 0.5f, 0.6f}, 0.1f, {0.8f, 0.2f, 0.1f}, 0.1f, 2);
  s.mask.at(19, 20) = 0.25f;  // a soft edge pixel
  const ImageF out = h.Harmonize(s.composite, s.mask);
  for (int y = 0; y < 50; ++y)
    for (int x = 0; x < 60; ++x) {
      const float m = s.mask.at(x, y);
      for (int c = 0; c < 3; ++c) {
        const float v = s.composite.at(x, y, c);
        const float model = m * (0.5f * v + 0.25f) + (1 - m) * (v + 0.1f);
        const float expected = m == 0 ? v : std::clamp(v + m * (model - v), 0.0f, 1.0f);
        ASSERT_NEAR(out.at(x, y, c), expected, 1e-6f) << x << "," << y;
      }
    }
}

TEST(Harmonizer, FixedResolutionModelAddsItsChangeAtFullResolution) {
  SD_REQUIRE_TEST_MODEL(file, "harmonizer_tiny_64.pt");
  const Harmonizer h = Harmonizer::FromModel(file);
  EXPECT_NE(h.Describe().find("runs at 64x64"), std::string::npos) << h.Describe();
  // A uniform object on a uniform background: the low-resolution change is uniform inside and resizes back
  // exactly away from the object's edge; the photograph's noise-free background stays exact.
  const Scene s = MakeScene({0.3f, 0.5f, 0.6f}, 0.0f, {0.8f, 0.2f, 0.1f}, 0.0f, 3);
  const ImageF out = h.Harmonize(s.composite, s.mask);
  for (int c = 0; c < 3; ++c) {
    EXPECT_NEAR(out.at(30, 25, c), 0.5f * s.composite.at(30, 25, c) + 0.25f, 1e-4f);
    EXPECT_EQ(out.at(2, 2, c), s.composite.at(2, 2, c));
  }
  SD_REQUIRE_TEST_MODEL(other, "normals_tiny.pt");
  EXPECT_THROW(Harmonizer::FromModel(other), InputError);
}

}  // namespace
}  // namespace sd::models
