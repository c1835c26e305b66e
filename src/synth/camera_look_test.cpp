#include "synth/camera_look.h"

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <map>
#include <numbers>
#include <random>

#include "io/files.h"
#include "datasets/categories.h"
#include "datasets/readers.h"
#include "geometry/polygon.h"
#include "io/image_io.h"
#include "synth/real_shadows.h"
#include "synth/realism.h"
#include "synth/test_cameras.h"
#include "testing/testing.h"

namespace sd {
namespace {
namespace fs = std::filesystem;

uint8_t Clamp8(double v) { return static_cast<uint8_t>(std::clamp(std::lround(v), 0L, 255L)); }

// A smooth horizontal ramp 30..220 with Gaussian noise of variance a + b v per pixel: what a camera's flat
// regions look like before compression.
ImageU8 NoisyRamp(int w, int h, double a, double b, uint64_t seed) {
  ImageU8 im(w, h, 3);
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> unit(0.0, 1.0);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const double v = 30 + 190.0 * x / (w - 1);
      for (int c = 0; c < 3; ++c) im.at(x, y, c) = Clamp8(v + unit(rng) * std::sqrt(a + b * v));
    }
  return im;
}

// Vertical step edges 60 -> 200 every 40 px, blurred by a Gaussian of `sigma`, on an otherwise flat image.
ImageU8 BlurredSteps(int w, int h, double sigma) {
  ImageU8 im(w, h, 3);
  for (int x = 0; x < w; ++x) {
    const double phase = std::fmod(x + 0.5, 40.0);
    // Distance to the step at phase 20, as a signed coordinate; the erf profile is the blurred step.
    const double d = phase - 20;
    const double v = 60 + 140 * 0.5 * (1 + std::erf(d / (std::sqrt(2.0) * sigma)));
    for (int y = 0; y < h; ++y)
      for (int c = 0; c < 3; ++c) im.at(x, y, c) = Clamp8(v);
  }
  return im;
}

TEST(CameraLook, RecoversSignalDependentNoiseFromFlatRegions) {
  const double a = 1.0, b = 0.02;  // sigma 1.0 at black, 1.9 at 128, 2.4 at 220
  const CameraLook look = EstimateCameraLook(NoisyRamp(640, 480, a, b, 7), std::nullopt);
  ASSERT_GT(look.noise.blocks, 1000);
  for (int c = 0; c < 3; ++c) {
    // The 20th percentile of the blocks' sigma sits a little below the true one; the fit follows the slope.
    EXPECT_NEAR(look.noise.Sigma(c, 128), std::sqrt(a + b * 128), 0.25) << c;
    EXPECT_GT(look.noise.Sigma(c, 220), look.noise.Sigma(c, 50)) << c;
  }
  EXPECT_EQ(look.jpeg_quality, 0);
}

TEST(CameraLook, MeasuresTheEdgeRiseOfBlurredSteps) {
  for (double sigma : {0.8, 1.5, 2.5}) {
    const std::vector<double> widths = EdgeRiseWidths(BlurredSteps(400, 120, sigma));
    ASSERT_GT(widths.size(), 50u) << sigma;
    const double median = widths[widths.size() / 2];
    EXPECT_NEAR(median, 2.563 * sigma, 0.2 + 0.08 * 2.563 * sigma) << sigma;
  }
}

// Motion blur softens one direction: a checkerboard blurred by sigma 2.0 along x and 0.8 along y measures its
// objects' edges across x and across y apart (the vertical edges' rise is the x blur's).
TEST(CameraLook, SplitsTheObjectsEdgeRiseByDirection) {
  const double sigma_x = 2.0, sigma_y = 0.8;
  const auto square_wave = [](double t, double sigma) {  // +-1 every 40 px, blurred
    const double d = std::fmod(t + 0.5, 40.0) - 20;
    return std::erf(d / (std::sqrt(2.0) * sigma)) * (std::fmod(std::floor((t + 0.5) / 40.0), 2.0) == 0 ? 1 : -1);
  };
  ImageU8 board(400, 320, 3);
  for (int y = 0; y < 320; ++y)
    for (int x = 0; x < 400; ++x)
      for (int c = 0; c < 3; ++c) board.at(x, y, c) = Clamp8(130 + 70 * square_wave(x, sigma_x) * square_wave(y, sigma_y));
  const ImageF everywhere(400, 320, 1, 1.0f);
  const CameraLook look = EstimateCameraLook(board, std::nullopt, &everywhere);
  std::printf("rise across x %.2f px (%d edges), across y %.2f px (%d)\n", look.object_edge_rise_across_x_px,
              look.object_edges_across_x, look.object_edge_rise_across_y_px, look.object_edges_across_y);
  EXPECT_NEAR(look.object_edge_rise_across_x_px, 2.563 * sigma_x, 0.15 * 2.563 * sigma_x);
  EXPECT_NEAR(look.object_edge_rise_across_y_px, 2.563 * sigma_y, 0.3 + 0.15 * 2.563 * sigma_y);
  EXPECT_GT(look.object_edges_across_x, 100);
  EXPECT_GT(look.object_edges_across_y, 100);
}

TEST(CameraLook, ExtraBlurAddsInQuadratureAndABlurredStepRisesAsAsked) {
  EXPECT_DOUBLE_EQ(ExtraBlurSigma(3.0, 2.0), 0.0);  // already softer
  EXPECT_NEAR(ExtraBlurSigma(0.0, 2.563), 1.0, 1e-3);
  const double s = ExtraBlurSigma(1.0, 3.0);
  EXPECT_NEAR(std::hypot(1.0 / 2.5631, s), 3.0 / 2.5631, 1e-9);
  // A sharp step blurred to a rise of 3 px measures 3 px.
  ImageF step(200, 60, 1, 0.0f);
  for (int y = 0; y < 60; ++y)
    for (int x = 0; x < 200; ++x) step.at(x, y) = std::fmod(x, 40.0) < 20 ? 60.0f : 200.0f;
  GaussianBlurRegion(&step, ExtraBlurSigma(0.0, 3.0), 0, 0, 200, 60);
  ImageU8 u8(200, 60, 3);
  for (int y = 0; y < 60; ++y)
    for (int x = 0; x < 200; ++x)
      for (int c = 0; c < 3; ++c) u8.at(x, y, c) = Clamp8(step.at(x, y));
  const std::vector<double> widths = EdgeRiseWidths(u8);
  ASSERT_FALSE(widths.empty());
  EXPECT_NEAR(widths[widths.size() / 2], 3.0, 0.35);
}

// A camera image (noisy, then JPEG at 85) and a noiseless flat patch pasted into it: after the sensor's steps
// the patch's noise measures like the image's own flat regions, pixels outside the patch are untouched, and the
// patch's 8x8 blocks carry the image's compression.
TEST(CameraLook, InsertedPixelsGetTheImagesNoiseThroughItsCompression) {
  const ImageU8 raw = NoisyRamp(320, 240, 2.0, 0.03, 11);
  const std::string jpeg = EncodeImage(raw, "jpg", 85);
  const ImageU8 photo = DecodeImage(jpeg, "photo", 3);
  const CameraLook look = EstimateCameraLook(photo, EstimateJpegQuality(jpeg));
  ASSERT_EQ(look.jpeg_quality, 85);
  ASSERT_GT(look.noise.blocks, 100);

  ImageU8 composite = photo;
  ImageF alpha(320, 240, 1, 0.0f);
  for (int y = 64; y < 160; ++y)
    for (int x = 96; x < 224; ++x) {
      const double v = 30 + 190.0 * x / 319;  // the ramp, without noise
      for (int c = 0; c < 3; ++c) composite.at(x, y, c) = Clamp8(v);
      alpha.at(x, y) = 1;
    }
  ImageU8 out = composite;
  ApplySensorToInserts(&out, alpha, nullptr, 96, 64, 224, 160, {}, look, CameraLookOptions{}, 3);
  for (int y = 0; y < 240; ++y)
    for (int x = 0; x < 320; ++x)
      if (alpha.at(x, y) == 0) {
        for (int c = 0; c < 3; ++c) ASSERT_EQ(out.at(x, y, c), composite.at(x, y, c)) << x << "," << y;
      }
  // Noise of the patch's blocks against the photo's blocks over the same columns (same levels).
  auto sigma_over = [](const ImageU8& im, int by0, int by1) {
    std::vector<double> s;
    for (int by = by0; by < by1; ++by)
      for (int bx = 96 / 8; bx < 224 / 8; ++bx) s.push_back(BlockNoiseSigma(im, bx, by, 1));
    std::sort(s.begin(), s.end());
    return s[s.size() / 2];
  };
  const double real = sigma_over(photo, 64 / 8, 160 / 8), inserted = sigma_over(out, 64 / 8, 160 / 8);
  const double bare = sigma_over(composite, 64 / 8, 160 / 8);
  EXPECT_LT(bare, 0.2 * real);  // the pasted patch had no noise
  EXPECT_GT(inserted / real, 0.7) << inserted << " vs " << real;
  EXPECT_LT(inserted / real, 1.4) << inserted << " vs " << real;
  // Off: nothing changes.
  ImageU8 untouched = composite;
  ApplySensorToInserts(&untouched, alpha, nullptr, 96, 64, 224, 160, {}, look, CameraLookOptions{false, false, false, false},
                       3);
  EXPECT_EQ(untouched.vector(), composite.vector());
}

TEST(CameraLook, SensorStepsOnPartsGiveTheWholeRectanglesBytes) {
  const ImageU8 raw = NoisyRamp(320, 240, 2.0, 0.03, 5);
  const std::string jpeg = EncodeImage(raw, "jpg", 80);  // chroma subsampled: blocks read their neighbours' chroma
  const ImageU8 photo = DecodeImage(jpeg, "photo", 3);
  const CameraLook look = EstimateCameraLook(photo, EstimateJpegQuality(jpeg));
  ASSERT_GT(look.jpeg_quality, 0);
  // Two coloured inserts with soft edges, far apart, and a shadow beside the second; the parts are their
  // rectangles, off the 16-pixel grid.
  ImageU8 composite = photo;
  ImageF alpha(320, 240, 1, 0.0f), shadow_noise(320, 240, 1, 0.0f);
  const std::vector<std::array<int, 4>> parts = {{37, 29, 93, 71}, {197, 147, 263, 229}};
  const auto paint = [&](const std::array<int, 4>& r, uint8_t red) {
    for (int y = r[1] + 2; y < r[3] - 2; ++y)
      for (int x = r[0] + 2; x < r[2] - 2; ++x) {
        const bool edge = x == r[0] + 2 || y == r[1] + 2 || x == r[2] - 3 || y == r[3] - 3;
        // Colour changing along both axes, so that the chroma a block reads of its neighbours differs.
        composite.at(x, y, 0) = red;
        composite.at(x, y, 1) = static_cast<uint8_t>(x);
        composite.at(x, y, 2) = static_cast<uint8_t>(5 * y);
        alpha.at(x, y) = edge ? 0.5f : 1.0f;
      }
  };
  paint(parts[0], 230);
  paint(parts[1], 20);
  for (int y = 210; y < 226; ++y)
    for (int x = 200; x < 260; ++x) shadow_noise.at(x, y) = 0.6f;
  ImageU8 whole = composite, on_parts = composite;
  ApplySensorToInserts(&whole, alpha, &shadow_noise, 37, 29, 263, 229, {}, look, CameraLookOptions{}, 9);
  ApplySensorToInserts(&on_parts, alpha, &shadow_noise, 37, 29, 263, 229, parts, look, CameraLookOptions{}, 9);
  EXPECT_EQ(on_parts.vector(), whole.vector());
  EXPECT_FALSE(whole.vector() == composite.vector());
  // The compression alone against its definition: one round trip of the rectangle's 16-pixel grid (x 32..272,
  // y 16..240), blended by alpha.
  const CameraLookOptions jpeg_only{false, false, true, false};
  ImageU8 expected = composite;
  ImageU8 crop(272 - 32, 240 - 16, 3);
  for (int y = 16; y < 240; ++y)
    for (int x = 32; x < 272; ++x)
      for (int c = 0; c < 3; ++c) crop.at(x - 32, y - 16, c) = composite.at(x, y, c);
  const ImageU8 round_trip = DecodeImage(EncodeImage(crop, "jpg", look.jpeg_quality), "crop", 3);
  for (int y = 0; y < 240; ++y)
    for (int x = 0; x < 320; ++x)
      if (const float a = alpha.at(x, y); a > 0)
        for (int c = 0; c < 3; ++c)
          expected.at(x, y, c) = Clamp8(a * round_trip.at(x - 32, y - 16, c) + (1 - a) * composite.at(x, y, c));
  on_parts = composite;
  ApplySensorToInserts(&on_parts, alpha, nullptr, 37, 29, 263, 229, parts, look, jpeg_only, 9);
  EXPECT_EQ(on_parts.vector(), expected.vector());
}

TEST(CameraLook, TheRepoKeyframeIsAQuality80JpegWithSoftEdges) {
  const fs::path file = testing::RepoData(
      "driving/nuscenes-scene0061-kf0/samples/CAM_FRONT/n015-2018-07-24-11-22-45+0800__CAM_FRONT__1532402927612460.jpg");
  const CameraLook look = EstimateCameraLook(ReadImage(file, 3), EstimateJpegQuality(ReadFileToString(file)));
  EXPECT_EQ(look.jpeg_quality, 80);
  // Its sharpest edges rise over 2-4 px (a 1600 px wide automotive camera behind a windscreen, JPEG 80); a render's
  // anti-aliased edge rises over about 1 px.
  EXPECT_GT(look.edge_width_px, 2.0);
  EXPECT_LT(look.edge_width_px, 4.0);
  EXPECT_GT(look.edges, 500);
  const nlohmann::json j = look.ToJson();
  EXPECT_EQ(j["jpeg_quality"], 80);
  EXPECT_TRUE(j.contains("noise_variance_a"));
}

// synth/realism.h measures an object over its projected box: on a noisy photograph its noise is the image's own
// (ratio about 1); a noiseless orange patch pasted over the same box measures no noise and a high saturation.
TEST(Realism, AnObjectsNoiseAndSaturationOverItsProjectedBox) {
  CameraSensor cam;
  cam.channel = "CAM";
  cam.intrinsics.width = 640, cam.intrinsics.height = 480;
  cam.intrinsics.fx = cam.intrinsics.fy = 500, cam.intrinsics.cx = 320, cam.intrinsics.cy = 240;
  // Camera looking along ego +x: camera z = ego x, camera x = -ego y, camera y = -ego z.
  Eigen::Matrix3d R;
  R << 0, 0, 1, -1, 0, 0, 0, -1, 0;
  cam.T_ego_cam = Rigid3d(R, Eigen::Vector3d::Zero());
  Box3 box;
  box.T_frame_box.translation = Eigen::Vector3d(10, 0, 0);
  box.size = Eigen::Vector3d(1, 2, 2);  // about 100 x 100 px
  const ImageU8 photo = NoisyRamp(640, 480, 2.0, 0.02, 5);
  const CameraLook look = EstimateCameraLook(photo, std::nullopt);
  const ObjectLook real = MeasureObjectLook(photo, cam, box, look);
  EXPECT_GT(real.pixels, 80 * 80);
  EXPECT_GT(real.noise_blocks, 50);
  EXPECT_NEAR(real.noise_ratio, 1.0, 0.25);
  EXPECT_LT(real.saturation, 0.1);
  ImageU8 pasted = photo;
  for (int y = 140; y < 340; ++y)
    for (int x = 220; x < 420; ++x) pasted.at(x, y, 0) = 230, pasted.at(x, y, 1) = 90, pasted.at(x, y, 2) = 20;
  const ObjectLook fake = MeasureObjectLook(pasted, cam, box, look);
  EXPECT_LT(fake.noise_ratio, 0.2);
  EXPECT_GT(fake.saturation, 0.8);
  // Behind the camera: nothing to measure.
  box.T_frame_box.translation = Eigen::Vector3d(-10, 0, 0);
  EXPECT_EQ(MeasureObjectLook(photo, cam, box, look).pixels, 0);
}

// The colour cap on orange, white and grey inserts over a grey road: the orange one is moved towards its luminance
// until its outline measures the ceiling; white and grey ones, already below it, are untouched; so is every pixel
// the insert does not cover.
TEST(CameraLook, SaturationCapMovesOnlyTooColourfulInsertsToTheCeiling) {
  const int w = 64, h = 48;
  struct Case { std::array<float, 3> colour; bool capped; };
  for (const Case c : {Case{{0.80f, 0.12f, 0.01f}, true}, Case{{0.85f, 0.85f, 0.85f}, false}, Case{{0.2f, 0.2f, 0.21f}, false}}) {
    ImageF linear(w, h, 3, 0.1f);  // grey road
    ImageF outline(w, h, 1, 0.0f), weight(w, h, 1, 0.0f);
    for (int y = 8; y < 40; ++y)
      for (int x = 16; x < 48; ++x) {
        outline.at(x, y) = 1;
        if (x >= 20 && x < 44) {  // the insert, with a soft left edge
          weight.at(x, y) = x == 20 ? 0.5f : 1.0f;
          for (int ch = 0; ch < 3; ++ch) linear.at(x, y, ch) = c.colour[ch] * weight.at(x, y) + 0.1f * (1 - weight.at(x, y));
        }
      }
    const ImageF before = linear;
    // The same cap from the outline's pixel list (what synth passes per object).
    ImageF by_list = linear;
    std::vector<OutlinePixel> pixels;
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        if (outline.at(x, y) > 0.5f) pixels.push_back({x, y, weight.at(x, y)});
    const SaturationCap listed = CapSaturation(&by_list, pixels, 0.3);
    const SaturationCap cap = CapSaturation(&linear, outline, weight, 0.3);
    EXPECT_EQ(listed.scale, cap.scale);
    EXPECT_EQ(listed.after, cap.after);
    EXPECT_EQ(by_list.vector(), linear.vector());
    SCOPED_TRACE(c.colour[0]);
    if (c.capped) {
      EXPECT_GT(cap.before, 0.6);
      EXPECT_NEAR(cap.after, 0.3, 0.01);
      EXPECT_LT(cap.scale, 1.0);
      // Moved towards luminance: the luminance of a fully covered pixel is kept.
      const auto lum = [](const ImageF& im, int x, int y) { return 0.2126f * im.at(x, y, 0) + 0.7152f * im.at(x, y, 1) + 0.0722f * im.at(x, y, 2); };
      EXPECT_NEAR(lum(linear, 30, 20), lum(before, 30, 20), 1e-5);
    } else {
      EXPECT_LT(cap.before, 0.3);
      EXPECT_EQ(cap.scale, 1.0);
    }
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        if (weight.at(x, y) > 0) continue;
        for (int ch = 0; ch < 3; ++ch) ASSERT_EQ(linear.at(x, y, ch), before.at(x, y, ch));
      }
  }
}

// The two-sample classifier: at chance on objects drawn from one distribution, near 1 when inserts carry three
// times the real objects' grain, and silent with a single insert.
TEST(Realism, TheRealVsInsertedClassifierIsAtChanceOnlyWhenTheyMeasureAlike) {
  std::mt19937 rng(11);
  std::lognormal_distribution<double> noise(0.0, 0.3), rise(1.0, 0.3);
  std::uniform_real_distribution<double> saturation(0.1, 0.4);
  const auto draw = [&](bool inserted, double grain) {
    ObjectLook o;
    o.inserted = inserted;
    o.pixels = 1000;
    o.noise_blocks = 10;
    o.noise_ratio = grain * noise(rng);
    o.edges = 5;
    o.edge_rise_px = rise(rng);
    o.saturation = saturation(rng);
    return o;
  };
  std::vector<ObjectLook> alike, pasted;
  for (int i = 0; i < 60; ++i) alike.push_back(draw(false, 1.0)), pasted.push_back(draw(false, 1.0));
  for (int i = 0; i < 30; ++i) alike.push_back(draw(true, 1.0)), pasted.push_back(draw(true, 3.0));
  const TwoSampleTest same = ClassifyRealVsInserted(alike);
  EXPECT_EQ(same.folds, 5);
  EXPECT_EQ(same.real, 60);
  EXPECT_EQ(same.inserted, 30);
  EXPECT_GT(same.balanced_accuracy, 0.3);
  EXPECT_LT(same.balanced_accuracy, 0.65);
  const TwoSampleTest told = ClassifyRealVsInserted(pasted);
  EXPECT_GT(told.balanced_accuracy, 0.9);
  EXPECT_GT(told.weights[0], 0);  // more grain: inserted
  std::vector<ObjectLook> one(alike.begin(), alike.begin() + 61);
  EXPECT_EQ(ClassifyRealVsInserted(one).folds, 0);
}

// A box standing on the ground (z = 0) of the synthetic road frames below.
Box3 GroundBox(double x, double y, double yaw, const Eigen::Vector3d& size) {
  Box3 b;
  b.T_frame_box = Rigid3d::FromYaw(yaw, Eigen::Vector3d(x, y, size.z() / 2));
  b.size = size;
  return b;
}

// A frame seen by a camera 12 m above flat ground looking straight down, with two real cars of `car_size`.
Frame TopDownRoadWithTwoCars(const Eigen::Vector3d& car_size) {
  Frame f;
  f.token = "synthetic";
  f.cameras.push_back(testing::TopDownCamera(12));
  for (const Box3& b : {GroundBox(4, 3, 0.3, car_size), GroundBox(-4, 3.5, -0.7, car_size)}) {
    Annotation a;
    a.category = "car";
    a.box = b;
    f.annotations.push_back(a);
  }
  return f;
}

// A camera 12 m above flat ground looking straight down at two real cars and two inserted cones, the ground
// drawn with each box's shadow (a box's shadow with its footprint is exactly real_shadows.h's ShadowHull): the
// real cars' shadows at a quarter of the lit road, the inserts' at half. The measure reads 4 and 2; the cone
// standing where a car's shadow covers the road it would be compared with is left out.
TEST(Realism, ShadowContrastOfRealAndInsertedObjectsOnASyntheticRoad) {
  const Frame f = TopDownRoadWithTwoCars({1.8, 1.2, 1.6});
  const CameraSensor& cam = f.cameras[0];
  const auto box = GroundBox;
  const Eigen::Vector3d cone(0.5, 0.5, 0.7);
  const std::vector<std::pair<std::string, Box3>> inserted = {{"traffic_cone", box(-3, -3, 0.2, cone)},
                                                              {"traffic_cone", box(3.3, 1.0, 0.0, cone)}};
  const double az = 65 * std::numbers::pi / 180, el = 50 * std::numbers::pi / 180;
  const Eigen::Vector3d sun(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el));
  ImageF img(cam.intrinsics.width, cam.intrinsics.height, 3, 0.3f);
  for (int y = 0; y < img.height(); ++y)
    for (int x = 0; x < img.width(); ++x) {
      const Eigen::Vector3d o = cam.T_ego_cam.translation, d = cam.T_ego_cam.rotation * cam.intrinsics.RayDirection({x + 0.5, y + 0.5});
      const Eigen::Vector2d p = (o + d * (-o.z() / d.z())).head<2>();
      float value = 0.3f;
      for (const Annotation& a : f.annotations)
        if (geometry::InsideConvexPolygon(ShadowHull(a.box, sun), p)) value = 0.075f;
      for (const auto& [category, b] : inserted)
        if (geometry::InsideConvexPolygon(ShadowHull(b, sun), p)) value = std::min(value, 0.15f);
      for (int c = 0; c < 3; ++c) img.at(x, y, c) = value;
    }
  const std::vector<ShadowContrast> shadows = MeasureShadowContrasts(f, inserted, std::vector<ImageF>{img}, sun);
  int real = 0, ins = 0;
  for (const ShadowContrast& s : shadows) {
    EXPECT_EQ(s.frame, "synthetic");
    EXPECT_EQ(s.channel, "CAM_FRONT");
    if (s.inserted) {
      ++ins;
      EXPECT_EQ(s.category, "traffic_cone");
      EXPECT_NEAR(s.contrast, 2.0, 0.1);
    } else {
      ++real;
      EXPECT_EQ(s.category, "car");
      EXPECT_NEAR(s.contrast, 4.0, 0.2);
    }
  }
  EXPECT_EQ(real, 2);
  EXPECT_EQ(ins, 1);  // the cone beside the car is left out
  const ShadowComparison c = CompareShadows(shadows);
  EXPECT_EQ(c.real, 2);
  EXPECT_EQ(c.inserted, 1);
  EXPECT_NEAR(c.inserted_contrast / c.real_contrast, 0.5, 0.05);
  // Without a sun-lit shadow drawn, the contrast is 1.
  const ImageF flat(cam.intrinsics.width, cam.intrinsics.height, 3, 0.3f);
  for (const ShadowContrast& s : MeasureShadowContrasts(f, inserted, std::vector<ImageF>{flat}, sun)) EXPECT_NEAR(s.contrast, 1.0, 1e-6);
}

// Contact darkening on the same kind of synthetic road: the ground within 25 cm of each real car's footprint at
// half the open road's luminance, of each inserted cone's at two thirds. The measure reads 2 and 1.5; the cars'
// cast shadows, drawn darker still, are left out of both bands when the sun is known; a plain road reads 1.
TEST(Realism, ContactDarkeningOfRealAndInsertedObjectsOnASyntheticRoad) {
  const Frame f = TopDownRoadWithTwoCars({4.2, 1.8, 1.5});
  const CameraSensor& cam = f.cameras[0];
  const auto box = GroundBox;
  const Eigen::Vector3d cone(0.4, 0.4, 0.7);
  const std::vector<std::pair<std::string, Box3>> inserted = {{"traffic_cone", box(-2, -3, 0.2, cone)},
                                                              {"traffic_cone", box(3, -2.5, 0.0, cone)}};
  // The sun behind the cars: their shadows fall towards the camera, onto road it sees.
  const double az = 100 * std::numbers::pi / 180, el = 40 * std::numbers::pi / 180;
  const Eigen::Vector3d sun(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el));
  // Distance from a ground point to a box's footprint.
  auto footprint_distance = [](const Box3& b, const Eigen::Vector2d& p) {
    const Eigen::Vector3d q = b.T_frame_box.Inverse() * Eigen::Vector3d(p.x(), p.y(), 0);
    return std::hypot(std::max(std::abs(q.x()) - b.size.x() / 2, 0.0), std::max(std::abs(q.y()) - b.size.y() / 2, 0.0));
  };
  auto draw = [&](bool with_shadows) {
    ImageF img(cam.intrinsics.width, cam.intrinsics.height, 3, 0.3f);
    for (int y = 0; y < img.height(); ++y)
      for (int x = 0; x < img.width(); ++x) {
        const Eigen::Vector3d o = cam.T_ego_cam.translation, d = cam.T_ego_cam.rotation * cam.intrinsics.RayDirection({x + 0.5, y + 0.5});
        const Eigen::Vector2d p = (o + d * (-o.z() / d.z())).head<2>();
        float value = 0.3f;
        for (const Annotation& a : f.annotations) {
          if (footprint_distance(a.box, p) < 0.25) value = 0.15f;
          if (with_shadows && geometry::InsideConvexPolygon(ShadowHull(a.box, sun), p)) value = 0.03f;
        }
        for (const auto& [category, b] : inserted)
          if (footprint_distance(b, p) < 0.25) value = 0.2f;
        for (int c = 0; c < 3; ++c) img.at(x, y, c) = value;
      }
    return img;
  };
  const std::vector<ContactDarkening> contacts = MeasureContactDarkening(f, inserted, std::vector<ImageF>{draw(true)}, sun);
  int real = 0, ins = 0;
  for (const ContactDarkening& c : contacts) {
    EXPECT_EQ(c.frame, "synthetic");
    EXPECT_EQ(c.channel, "CAM_FRONT");
    if (c.inserted) {
      ++ins;
      EXPECT_EQ(c.category, "traffic_cone");
      EXPECT_NEAR(c.darkening, 1.5, 0.05);
    } else {
      ++real;
      EXPECT_EQ(c.category, "car");
      EXPECT_NEAR(c.darkening, 2.0, 0.05);
    }
  }
  EXPECT_EQ(real, 2);
  EXPECT_EQ(ins, 2);
  const std::vector<ContactComparison> by = CompareContacts(contacts);
  ASSERT_EQ(by.size(), 2u);  // all objects, then the inserted category
  EXPECT_EQ(by[1].category, "traffic_cone");
  EXPECT_EQ(by[1].real, 0);
  EXPECT_EQ(by[1].inserted, 2);
  EXPECT_NEAR(by[1].inserted_darkening, 1.5, 0.05);
  // The sun unknown, the cars' shadows fall into their bands and the measure no longer reads their rim.
  for (const ContactDarkening& c : MeasureContactDarkening(f, inserted, std::vector<ImageF>{draw(true)}, std::nullopt)) {
    if (c.category == "car") {
      EXPECT_GT(std::abs(c.darkening - 2.0), 0.3);
    }
  }
  const ImageF flat(cam.intrinsics.width, cam.intrinsics.height, 3, 0.3f);
  const auto plain = MeasureContactDarkening(f, inserted, std::vector<ImageF>{flat}, sun);
  EXPECT_EQ(plain.size(), 4u);
  for (const ContactDarkening& c : plain) EXPECT_NEAR(c.darkening, 1.0, 1e-6);
}

// The colour cap's reference over the repo keyframe's real objects: barriers (a standard livery, 25 views) take
// their median, so one vivid barrier does not lift the ceiling for all; cars (every paint) their most saturated;
// the one real cone its own (fewer than three views).
TEST(Realism, TheColourReferenceIsTheMedianOfAStandardLiveryAndTheMostColourfulCar) {
  const Log log = OpenLog(testing::RepoData("driving/nuscenes-scene0061-kf0/mmdet3d_info/n015-2018-07-24-11-22-45+0800.json"));
  const auto ref = RealSaturation(log, {0}, {"barrier", "car", "traffic_cone"});
  std::map<std::string, std::vector<double>> by_hand;
  const Frame& frame = log.frames[0];
  for (const CameraSensor& cam : frame.cameras) {
    const ImageU8 image = ReadImage(cam.image_path, 3);
    for (const Annotation& a : frame.annotations) {
      int pixels = 0;
      const double sat = MeasureSaturation(image, cam, a.box, &pixels);
      if (pixels >= 24 * 12) by_hand[CanonicalCategory(a.category)].push_back(sat);
    }
  }
  auto median = [](std::vector<double> v) {  // the middle view (the upper one of an even count)
    std::sort(v.begin(), v.end());
    return v[v.size() / 2];
  };
  const std::vector<double>& barriers = by_hand["barrier"];
  ASSERT_GE(barriers.size(), 3u);
  EXPECT_EQ(ref.at("barrier").statistic, "median");
  EXPECT_EQ(ref.at("barrier").views, static_cast<int>(barriers.size()));
  EXPECT_NEAR(ref.at("barrier").ceiling, median(barriers), 1e-12);
  EXPECT_LT(ref.at("barrier").ceiling, *std::max_element(barriers.begin(), barriers.end()));
  const std::vector<double>& cars = by_hand["car"];
  ASSERT_FALSE(cars.empty());
  EXPECT_EQ(ref.at("car").statistic, "max");
  EXPECT_NEAR(ref.at("car").ceiling, *std::max_element(cars.begin(), cars.end()), 1e-12);
  EXPECT_EQ(ref.at("traffic_cone").views, static_cast<int>(by_hand["traffic_cone"].size()));
  if (by_hand["traffic_cone"].size() < 3) {
    EXPECT_EQ(ref.at("traffic_cone").statistic, "max");
  }
}

}  // namespace
}  // namespace sd
