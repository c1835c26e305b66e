#include "mining/descriptor.h"

#include <algorithm>
#include <cmath>
#include <iostream>
#include <numeric>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "core/error.h"
#include "io/image_io.h"
#include "testing/testing.h"

namespace sd::mining {
namespace {

namespace fs = std::filesystem;

// ---- image helpers (written here, independent of the implementation's resampler) ----

ImageU8 Crop(const ImageU8& img, int x0, int y0, int w, int h) {
  SD_CHECK(x0 >= 0 && y0 >= 0 && x0 + w <= img.width() && y0 + h <= img.height(), << x0 << "," << y0);
  ImageU8 out(w, h, img.channels());
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < img.channels(); ++c) out.at(x, y, c) = img.at(x0 + x, y0 + y, c);
  return out;
}

// Box downscale: every source pixel is averaged into the output pixel its centre falls in.
ImageU8 Shrink(const ImageU8& img, int ow, int oh) {
  const int c = img.channels();
  std::vector<double> sum(static_cast<size_t>(ow) * oh * c, 0.0);
  std::vector<int> n(static_cast<size_t>(ow) * oh, 0);
  for (int y = 0; y < img.height(); ++y)
    for (int x = 0; x < img.width(); ++x) {
      const int ox = (2 * x + 1) * ow / (2 * img.width()), oy = (2 * y + 1) * oh / (2 * img.height());
      const size_t o = static_cast<size_t>(oy) * ow + ox;
      ++n[o];
      for (int k = 0; k < c; ++k) sum[o * c + k] += img.at(x, y, k);
    }
  ImageU8 out(ow, oh, c);
  for (size_t o = 0; o < n.size(); ++o)
    for (int k = 0; k < c; ++k) out.data()[o * c + k] = static_cast<uint8_t>(std::lround(sum[o * c + k] / n[o]));
  return out;
}

ImageU8 Scale(const ImageU8& img, double s) {
  return Shrink(img, static_cast<int>(std::lround(img.width() * s)), static_cast<int>(std::lround(img.height() * s)));
}

ImageU8 Upscale2(const ImageU8& img) {
  ImageU8 out(img.width() * 2, img.height() * 2, img.channels());
  std::vector<float> px(img.channels());
  for (int y = 0; y < out.height(); ++y)
    for (int x = 0; x < out.width(); ++x) {
      SampleBilinear(img, (x + 0.5) / 2, (y + 0.5) / 2, px.data());
      for (int c = 0; c < img.channels(); ++c) out.at(x, y, c) = static_cast<uint8_t>(std::lround(px[c]));
    }
  return out;
}

ImageU8 Brightness(const ImageU8& img, double f) {
  ImageU8 out = img;
  for (uint8_t& v : out.vector()) v = static_cast<uint8_t>(std::lround(std::min(255.0, v * f)));
  return out;
}

ImageU8 Jpeg(const ImageU8& img, int quality) {
  testing::TempDir dir;
  WriteImage(dir / "x.jpg", img, quality);
  return ReadImage(dir / "x.jpg", img.channels());
}

// Separable Gaussian blur, kernel radius ceil(3 sigma), clamped borders.
ImageU8 Blur(const ImageU8& img, double sigma) {
  const int r = static_cast<int>(std::ceil(3 * sigma));
  std::vector<double> k(2 * r + 1);
  for (int i = -r; i <= r; ++i) k[i + r] = std::exp(-0.5 * i * i / (sigma * sigma));
  const double ks = std::accumulate(k.begin(), k.end(), 0.0);
  for (double& v : k) v /= ks;
  const int w = img.width(), h = img.height(), c = img.channels();
  std::vector<double> tmp(img.size());
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int ch = 0; ch < c; ++ch) {
        double s = 0;
        for (int i = -r; i <= r; ++i) s += k[i + r] * img.at(std::clamp(x + i, 0, w - 1), y, ch);
        tmp[(static_cast<size_t>(y) * w + x) * c + ch] = s;
      }
  ImageU8 out(w, h, c);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int ch = 0; ch < c; ++ch) {
        double s = 0;
        for (int i = -r; i <= r; ++i)
          s += k[i + r] * tmp[(static_cast<size_t>(std::clamp(y + i, 0, h - 1)) * w + x) * c + ch];
        out.at(x, y, ch) = static_cast<uint8_t>(std::lround(std::clamp(s, 0.0, 255.0)));
      }
  return out;
}

double Cosine(const std::vector<float>& a, const std::vector<float>& b) {
  EXPECT_EQ(a.size(), b.size());
  double s = 0;
  for (size_t i = 0; i < a.size(); ++i) s += static_cast<double>(a[i]) * b[i];
  return s;
}

double Norm(const std::vector<float>& a) { return std::sqrt(Cosine(a, a)); }

// ---- repo images: 6 nuScenes cameras (1600 × 900) and 3 KITTI images (1242 × 375) ----

std::vector<ImageU8> RepoImages() {
  std::vector<ImageU8> images;
  const fs::path nus = testing::RepoData("driving/nuscenes-scene0061-kf0/samples");
  for (const char* cam : {"CAM_FRONT", "CAM_FRONT_LEFT", "CAM_FRONT_RIGHT", "CAM_BACK", "CAM_BACK_LEFT",
                          "CAM_BACK_RIGHT"}) {
    std::vector<fs::path> files;
    for (const auto& e : fs::directory_iterator(nus / cam)) files.push_back(e.path());
    std::sort(files.begin(), files.end());
    images.push_back(ReadImage(files.at(0), 3));
  }
  for (const char* f : {"000000.png", "000001.png", "000002.png"})
    images.push_back(ReadImage(testing::RepoData(std::string("driving/kitti-object/training/image_2/") + f), 3));
  return images;
}

struct CropSpec {
  int image, x, y, size;
};

// 45 distinct crops: 2 rows of three across each nuScenes camera (320 px), three across each KITTI image (300 px),
// each leaving room for a 10 × 7 pixel shift.
std::vector<CropSpec> CropSpecs() {
  std::vector<CropSpec> specs;
  for (int i = 0; i < 6; ++i)
    for (int y : {300, 560})
      for (int x : {80, 640, 1200}) specs.push_back({i, x, y, 320});
  for (int i = 6; i < 9; ++i)
    for (int x : {60, 470, 880}) specs.push_back({i, x, 40, 300});
  return specs;
}

std::vector<ImageU8> RepoCrops(const std::vector<ImageU8>& images, int dx = 0, int dy = 0) {
  std::vector<ImageU8> crops;
  for (const CropSpec& s : CropSpecs()) crops.push_back(Crop(images[s.image], s.x + dx, s.y + dy, s.size, s.size));
  return crops;
}

ImageU8 Composite(const ImageU8& fg, const ImageU8& mask, const ImageU8& bg) {
  ImageU8 out = bg;
  for (int y = 0; y < bg.height(); ++y)
    for (int x = 0; x < bg.width(); ++x)
      if (mask.at(x, y) > 127)
        for (int c = 0; c < 3; ++c) out.at(x, y, c) = fg.at(x, y, c);
  return out;
}

ImageU8 Ellipse(int w, int h, double rx, double ry) {
  ImageU8 m(w, h, 1);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const double u = (x + 0.5 - w / 2.0) / rx, v = (y + 0.5 - h / 2.0) / ry;
      m.at(x, y) = u * u + v * v <= 1 ? 255 : 0;
    }
  return m;
}

// Rank-1 rate of `queries[i]` against `gallery` (the right answer is gallery[i]).
double RankOneRate(const std::vector<std::vector<float>>& gallery, const std::vector<std::vector<float>>& queries,
                   std::vector<int>* misses) {
  int hits = 0;
  for (size_t q = 0; q < queries.size(); ++q) {
    size_t best = 0;
    double best_cos = -2;
    for (size_t g = 0; g < gallery.size(); ++g) {
      const double c = Cosine(queries[q], gallery[g]);
      if (c > best_cos) best_cos = c, best = g;
    }
    if (best == q) ++hits;
    else misses->push_back(static_cast<int>(q));
  }
  return static_cast<double>(hits) / queries.size();
}

// ---- ImageDescriptor ----

TEST(ImageDescriptor, UnitNormConstantDimensionDeterministic) {
  const std::vector<ImageU8> images = RepoImages();
  const ImageU8 crop = Crop(images[0], 640, 300, 320, 320);
  const int dim = DescriptorDim();
  EXPECT_EQ(dim, 12 * 4 + 8 + 3 * 3 * 4 * 9);  // hue × saturation + grey; 3 × 3 HOG blocks of 2 × 2 cells × 9
  for (const ImageU8& img : {crop, images[6], Crop(crop, 0, 0, 7, 300), Scale(crop, 0.1), Crop(crop, 5, 5, 1, 1)}) {
    const std::vector<float> d = ImageDescriptor(img);
    ASSERT_EQ(static_cast<int>(d.size()), dim);
    EXPECT_NEAR(Norm(d), 1.0, 1e-5);
    for (float v : d) EXPECT_TRUE(std::isfinite(v));
  }
  EXPECT_EQ(ImageDescriptor(crop), ImageDescriptor(crop));
  // A 512 × 256 checkerboard mask (x + y odd): 4 × 128² object pixels, so colour samples every 2nd pixel
  // from the bounding box's corner, where x + y is even: the lattice misses the object, all pixels are used.
  ImageU8 checker(512, 256, 1, 0);
  for (int y = 0; y < 256; ++y)
    for (int x = 0; x < 512; ++x) checker.at(x, y) = (x + y) % 2 ? 255 : 0;
  const std::vector<float> d = ImageDescriptor(Crop(images[0], 100, 100, 512, 256), &checker);
  for (float v : d) ASSERT_TRUE(std::isfinite(v));
  EXPECT_NEAR(Norm(d), 1.0, 1e-5);
  // A flat image has no gradients: only the colour block, still unit.
  const std::vector<float> flat = ImageDescriptor(ImageU8(50, 40, 3, 128));
  ASSERT_EQ(static_cast<int>(flat.size()), dim);
  EXPECT_NEAR(Norm(flat), 1.0, 1e-5);
}

TEST(ImageDescriptor, SurvivesRescaleJpegAndBrightness) {
  const std::vector<ImageU8> crops = RepoCrops(RepoImages());
  double min_scale = 1, min_jpeg = 1, min_bright = 1;
  for (const ImageU8& crop : crops) {
    const std::vector<float> d = ImageDescriptor(crop);
    min_scale = std::min(min_scale, Cosine(d, ImageDescriptor(Scale(crop, 0.5))));
    min_jpeg = std::min(min_jpeg, Cosine(d, ImageDescriptor(Jpeg(crop, 75))));
    min_bright = std::min(min_bright, Cosine(d, ImageDescriptor(Brightness(crop, 0.9))));
  }
  std::cout << "min cosine over " << crops.size() << " crops: rescale 0.5x " << min_scale << ", JPEG q75 "
            << min_jpeg << ", brightness x0.9 " << min_bright << "\n";
  EXPECT_GT(min_scale, 0.9);
  EXPECT_GT(min_jpeg, 0.9);
  EXPECT_GT(min_bright, 0.9);
}

TEST(ImageDescriptor, AugmentedCropsFindTheirOriginal) {
  const std::vector<ImageU8> images = RepoImages();
  const std::vector<ImageU8> originals = RepoCrops(images);
  const std::vector<ImageU8> shifted = RepoCrops(images, 10, 7);
  std::vector<std::vector<float>> gallery, queries;
  for (const ImageU8& c : originals) gallery.push_back(ImageDescriptor(c));
  for (const ImageU8& c : shifted) queries.push_back(ImageDescriptor(Jpeg(Scale(c, 0.6), 75)));
  std::vector<int> misses;
  const double rate = RankOneRate(gallery, queries, &misses);
  std::cout << "rank-1 " << rate << " over " << queries.size() << " crops (shift 10x7 px, 0.6x, JPEG q75); misses:";
  for (int m : misses) std::cout << " " << m;
  std::cout << "\n";
  EXPECT_GE(rate, 0.9);
}

TEST(ImageDescriptor, MaskIgnoresTheBackground) {
  const std::vector<ImageU8> images = RepoImages();
  const ImageU8 object = Crop(images[0], 700, 380, 240, 200);  // CAM_FRONT, the road ahead
  const ImageU8 mask = Ellipse(240, 200, 100, 80);
  const ImageU8 on_a = Jpeg(Composite(object, mask, Crop(images[6], 500, 100, 240, 200)), 90);  // KITTI
  const ImageU8 on_b = Jpeg(Composite(object, mask, Crop(images[4], 100, 200, 240, 200)), 90);  // BACK_LEFT
  const double masked = Cosine(ImageDescriptor(on_a, &mask), ImageDescriptor(on_b, &mask));
  const double unmasked = Cosine(ImageDescriptor(on_a), ImageDescriptor(on_b));
  std::cout << "same object, two backgrounds: cosine with mask " << masked << ", without " << unmasked << "\n";
  EXPECT_GT(masked, 0.95);
  EXPECT_LT(unmasked, masked - 0.05);
  // Pixels outside the mask are never read: the object alone gives the same vector.
  const std::vector<float> alone = ImageDescriptor(object, &mask);
  const ImageU8 pasted_image = Composite(object, mask, Crop(images[6], 500, 100, 240, 200));
  const std::vector<float> pasted = ImageDescriptor(pasted_image, &mask);
  EXPECT_EQ(alone, pasted);
}

TEST(ImageDescriptor, GreyAndRgbaInputs) {
  const ImageU8 crop = Crop(RepoImages()[0], 640, 300, 160, 120);
  ImageU8 grey(crop.width(), crop.height(), 1), grey3(crop.width(), crop.height(), 3);
  for (int y = 0; y < crop.height(); ++y)
    for (int x = 0; x < crop.width(); ++x) {
      const uint8_t g = crop.at(x, y, 1);
      grey.at(x, y) = g;
      for (int c = 0; c < 3; ++c) grey3.at(x, y, c) = g;
    }
  // R = G = B has no chroma: the grey image and its RGB copy describe alike.
  EXPECT_GT(Cosine(ImageDescriptor(grey), ImageDescriptor(grey3)), 0.99999);

  // RGBA: alpha > 127 is the mask when none is given; an explicit mask wins over alpha.
  const ImageU8 mask = Ellipse(160, 120, 60, 50);
  ImageU8 rgba(crop.width(), crop.height(), 4);
  for (int y = 0; y < crop.height(); ++y)
    for (int x = 0; x < crop.width(); ++x) {
      for (int c = 0; c < 3; ++c) rgba.at(x, y, c) = crop.at(x, y, c);
      rgba.at(x, y, 3) = mask.at(x, y) ? 200 : 100;
    }
  EXPECT_EQ(ImageDescriptor(rgba), ImageDescriptor(crop, &mask));
  const ImageU8 all(crop.width(), crop.height(), 1, 255);
  EXPECT_EQ(ImageDescriptor(rgba, &all), ImageDescriptor(crop));
}

TEST(ImageDescriptor, RejectsBadInput) {
  const ImageU8 img(20, 10, 3, 90);
  const ImageU8 wrong_size(10, 10, 1, 255), empty_mask(20, 10, 1, 0);
  EXPECT_THROW(ImageDescriptor(img, &wrong_size), InputError);
  EXPECT_THROW(ImageDescriptor(img, &empty_mask), InputError);
  EXPECT_THROW(ImageDescriptor(ImageU8()), InputError);
  EXPECT_THROW(ImageDescriptor(ImageU8(4, 4, 2)), InputError);
}

// Rendered objects (../shared/data): 14 GSO input views and 16 views of one GSO object, RGBA 256 × 256.
std::vector<ImageU8> GsoObjects(const fs::path& renders) {
  std::vector<fs::path> files;
  for (const auto& e : fs::directory_iterator(renders / "syncdreamer_gso_input_views"))
    if (e.path().extension() == ".png") files.push_back(e.path());
  for (const auto& e : fs::directory_iterator(renders / "chicken_nesting_syncdreamer_gt/views"))
    if (e.path().extension() == ".png" && e.path().stem().string().find("depth") == std::string::npos)
      files.push_back(e.path());
  std::sort(files.begin(), files.end());
  std::vector<ImageU8> objects;
  for (const fs::path& f : files) objects.push_back(ReadImage(f, 4));
  return objects;
}

// The object's RGB and alpha mask moved by (dx, dy) onto `bg` (same size).
void Paste(const ImageU8& rgba, const ImageU8& bg, int dx, int dy, ImageU8* image, ImageU8* mask) {
  *image = bg;
  *mask = ImageU8(bg.width(), bg.height(), 1, 0);
  for (int y = 0; y < rgba.height(); ++y)
    for (int x = 0; x < rgba.width(); ++x) {
      const int u = x + dx, v = y + dy;
      if (u < 0 || v < 0 || u >= bg.width() || v >= bg.height() || rgba.at(x, y, 3) <= 127) continue;
      for (int c = 0; c < 3; ++c) image->at(u, v, c) = rgba.at(x, y, c);
      mask->at(u, v) = 255;
    }
}

ImageU8 Threshold(const ImageU8& m) {
  ImageU8 out = m;
  for (uint8_t& v : out.vector()) v = v > 127 ? 255 : 0;
  return out;
}

TEST(ImageDescriptor, RenderedObjectsOnDrivingBackgrounds) {
  SD_REQUIRE_SHARED(renders, "assets/gso_renders");
  const std::vector<ImageU8> objects = GsoObjects(renders);
  ASSERT_EQ(objects.size(), 30u);
  const std::vector<ImageU8> images = RepoImages();
  std::vector<std::vector<float>> gallery, queries;
  double min_masked = 1, mean_unmasked = 0;
  for (size_t i = 0; i < objects.size(); ++i) {
    const ImageU8& obj = objects[i];
    gallery.push_back(ImageDescriptor(obj));  // alpha is the mask
    const CropSpec a = CropSpecs()[i % 27], b = CropSpecs()[(i + 13) % 27];
    ImageU8 on_a, on_b, mask_a, mask_b;
    Paste(obj, Crop(images[a.image], a.x, a.y, 256, 256), 0, 0, &on_a, &mask_a);
    Paste(obj, Crop(images[b.image], b.x, b.y, 256, 256), 0, 0, &on_b, &mask_b);
    on_a = Jpeg(on_a, 90);
    on_b = Jpeg(on_b, 90);
    const double masked = Cosine(ImageDescriptor(on_a, &mask_a), ImageDescriptor(on_b, &mask_b));
    const double unmasked = Cosine(ImageDescriptor(on_a), ImageDescriptor(on_b));
    min_masked = std::min(min_masked, masked);
    mean_unmasked += unmasked / objects.size();
    EXPECT_LT(unmasked, masked) << i;
    // The query: on a background, shifted, rescaled 0.6x, JPEG q75, with its (rescaled) mask.
    ImageU8 query, qmask;
    Paste(obj, Crop(images[b.image], b.x, b.y, 256, 256), 9, -6, &query, &qmask);
    const ImageU8 small_mask = Threshold(Scale(qmask, 0.6));
    queries.push_back(ImageDescriptor(Jpeg(Scale(query, 0.6), 75), &small_mask));
  }
  std::vector<int> misses;
  const double rate = RankOneRate(gallery, queries, &misses);
  std::cout << objects.size() << " rendered objects on two backgrounds: min cosine with mask " << min_masked
            << ", mean without " << mean_unmasked << "; rank-1 of shifted 0.6x JPEG queries " << rate << ", misses:";
  for (int m : misses) std::cout << " " << m;
  std::cout << "\n";
  EXPECT_GT(min_masked, 0.95);
  EXPECT_GE(rate, 0.9);
}

// ---- PerceptualHash ----

TEST(PerceptualHash, StableUnderReencodeAndRescaleDistinctOtherwise) {
  const std::vector<ImageU8> crops = RepoCrops(RepoImages());
  std::vector<uint64_t> hashes;
  int max_jpeg = 0, max_scale = 0;
  for (const ImageU8& c : crops) {
    hashes.push_back(PerceptualHash(c));
    max_jpeg = std::max(max_jpeg, HammingDistance(hashes.back(), PerceptualHash(Jpeg(c, 70))));
    max_scale = std::max(max_scale, HammingDistance(hashes.back(), PerceptualHash(Scale(c, 0.5))));
  }
  double sum = 0;
  int n = 0, min_distinct = 64;
  for (size_t i = 0; i < hashes.size(); ++i)
    for (size_t j = i + 1; j < hashes.size(); ++j) {
      const int d = HammingDistance(hashes[i], hashes[j]);
      sum += d;
      ++n;
      min_distinct = std::min(min_distinct, d);
    }
  const double mean = sum / n;
  std::cout << "pHash over " << crops.size() << " crops: max Hamming JPEG q70 " << max_jpeg << ", 0.5x "
            << max_scale << "; distinct pairs mean " << mean << " min " << min_distinct << "\n";
  EXPECT_LE(max_jpeg, 6);
  EXPECT_LE(max_scale, 6);
  EXPECT_GE(mean, 20);
  EXPECT_LE(mean, 44);
  EXPECT_GT(min_distinct, 10);
}

TEST(PerceptualHash, FlatImageAndHamming) {
  EXPECT_EQ(PerceptualHash(ImageU8(64, 48, 3, 77)), 0u);
  EXPECT_EQ(PerceptualHash(ImageU8(1, 1, 1, 200)), 0u);
  EXPECT_EQ(HammingDistance(0, ~uint64_t{0}), 64);
  EXPECT_EQ(HammingDistance(0b1011, 0b0110), 3);
  // A horizontal ramp: only the horizontal frequencies are non-zero, half of them above the median.
  ImageU8 ramp(64, 64, 1);
  for (int y = 0; y < 64; ++y)
    for (int x = 0; x < 64; ++x) ramp.at(x, y) = static_cast<uint8_t>(x * 4);
  const uint64_t h = PerceptualHash(ramp);
  EXPECT_EQ(h & 1u, 0u);  // the DC bit is never set
  EXPECT_EQ(HammingDistance(h, PerceptualHash(Scale(ramp, 0.5))), 0);
}

// ---- Sharpness ----

TEST(Sharpness, FallsWithBlur) {
  const std::vector<ImageU8> images = RepoImages();
  // 128-pixel crops are measured at their own scale, so sigma is in Sharpness's pixels.
  for (const CropSpec& s : {CropSpec{0, 700, 380, 128}, CropSpec{6, 900, 150, 128}, CropSpec{2, 300, 400, 128}}) {
    const ImageU8 crop = Crop(images[s.image], s.x, s.y, 192, s.size);
    const double sharp = Sharpness(crop);
    const double b1 = Sharpness(Blur(crop, 1)), b2 = Sharpness(Blur(crop, 2)), b4 = Sharpness(Blur(crop, 4));
    std::cout << "sharpness image " << s.image << ": " << sharp << " blur1 " << b1 << " blur2 " << b2 << " blur4 "
              << b4 << " (sharp / blur2 = " << sharp / b2 << ")\n";
    EXPECT_GT(sharp, b1);
    EXPECT_GT(b1, b2);
    EXPECT_GT(b2, b4);
    EXPECT_GT(sharp / b2, 3);
  }
}

TEST(Sharpness, IndependentOfSize) {
  const std::vector<ImageU8> images = RepoImages();
  for (const CropSpec& s : {CropSpec{0, 600, 300, 320}, CropSpec{6, 500, 40, 300}, CropSpec{3, 200, 350, 400}}) {
    const ImageU8 crop = Crop(images[s.image], s.x, s.y, s.size, s.size);
    const double a = Sharpness(crop), b = Sharpness(Upscale2(crop));
    std::cout << "sharpness " << s.size << " px: " << a << ", upscaled 2x: " << b << " (ratio " << b / a << ")\n";
    EXPECT_NEAR(b / a, 1.0, 0.25);
  }
}

// A distant object's crop (shorter side under 128 px) is measured at its own resolution, never upsampled: the
// figure is then the plain variance of its Laplacian, computed here independently.
TEST(Sharpness, SmallCropsAreMeasuredAsTheyAre) {
  const std::vector<ImageU8> images = RepoImages();
  const ImageU8 rgb = Crop(images[0], 700, 420, 40, 40);
  ImageU8 grey(40, 52, 1);
  for (int y = 0; y < 52; ++y)
    for (int x = 0; x < 40; ++x) grey.at(x, y) = images[0].at(700 + x, 420 + y, 1);
  double sum = 0, sum2 = 0, n = 0;
  for (int y = 1; y + 1 < 52; ++y)
    for (int x = 1; x + 1 < 40; ++x) {
      const double lap = grey.at(x - 1, y) + grey.at(x + 1, y) + grey.at(x, y - 1) + grey.at(x, y + 1) - 4.0 * grey.at(x, y);
      sum += lap;
      sum2 += lap * lap;
      ++n;
    }
  const double expected = sum2 / n - (sum / n) * (sum / n);
  EXPECT_NEAR(Sharpness(grey), expected, 1e-3 * expected);
  // The same region upsampled 4x (what measuring small crops at a fixed 128 px would do) reads far blurrier.
  EXPECT_GT(Sharpness(rgb), 4 * Sharpness(Upscale2(Upscale2(rgb))));
}

TEST(Sharpness, MaskedLooksOnlyAtMaskPixels) {
  const std::vector<ImageU8> images = RepoImages();
  const ImageU8 sharp = Crop(images[0], 600, 300, 256, 256);
  const ImageU8 blurred = Blur(sharp, 3);
  ImageU8 mask(256, 256, 1, 0);
  for (int y = 0; y < 256; ++y)
    for (int x = 128; x < 256; ++x) mask.at(x, y) = 255;
  // Left half sharp, right half blurred; then the left half replaced by something else entirely.
  ImageU8 half = blurred, other = blurred;
  const ImageU8 elsewhere = Crop(images[6], 100, 40, 256, 256);
  for (int y = 0; y < 256; ++y)
    for (int x = 0; x < 128; ++x)
      for (int c = 0; c < 3; ++c) {
        half.at(x, y, c) = sharp.at(x, y, c);
        other.at(x, y, c) = elsewhere.at(x, y, c);
      }
  const double masked = Sharpness(half, &mask);
  const double whole = Sharpness(half);
  std::cout << "masked (blurred half) " << masked << ", whole " << whole << ", blurred image "
            << Sharpness(blurred) << "\n";
  EXPECT_DOUBLE_EQ(masked, Sharpness(other, &mask));
  EXPECT_DOUBLE_EQ(masked, Sharpness(blurred, &mask));
  EXPECT_LT(masked, 0.3 * whole);
  // Alpha acts as the mask of an RGBA image.
  ImageU8 rgba(256, 256, 4);
  for (int y = 0; y < 256; ++y)
    for (int x = 0; x < 256; ++x) {
      for (int c = 0; c < 3; ++c) rgba.at(x, y, c) = half.at(x, y, c);
      rgba.at(x, y, 3) = mask.at(x, y);
    }
  EXPECT_DOUBLE_EQ(Sharpness(rgba), masked);
  EXPECT_EQ(Sharpness(ImageU8(300, 200, 3, 50)), 0.0);
  EXPECT_EQ(Sharpness(ImageU8(1, 1, 3, 50)), 0.0);
  const ImageU8 no_object(256, 256, 1, 0);
  EXPECT_EQ(Sharpness(half, &no_object), 0.0);
}

}  // namespace
}  // namespace sd::mining
