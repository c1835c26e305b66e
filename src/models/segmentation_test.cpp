#include "models/segmentation.h"

#include <array>
#include <chrono>
#include <cmath>
#include <ctime>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <iostream>
#include <optional>
#include <random>
#include <tuple>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "core/error.h"
#include "io/image_io.h"
#include "models/grabcut.h"
#include "testing/testing.h"

namespace sd::models {
namespace {

namespace fs = std::filesystem;

std::string ErrorOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}


// IoU of (a ≥ 0.5) and (b ≥ 0.5).
double MaskIoU(const ImageF& a, const ImageF& b) {
  EXPECT_EQ(a.size(), b.size());
  double inter = 0, uni = 0;
  for (size_t i = 0; i < std::min(a.size(), b.size()); ++i) {
    const bool x = a.vector()[i] >= 0.5f, y = b.vector()[i] >= 0.5f;
    inter += x && y;
    uni += x || y;
  }
  return uni > 0 ? inter / uni : 1.0;
}

Box2 BoundsOf(const ImageF& mask, double margin) {
  int x0 = mask.width(), y0 = mask.height(), x1 = -1, y1 = -1;
  for (int y = 0; y < mask.height(); ++y)
    for (int x = 0; x < mask.width(); ++x)
      if (mask.at(x, y) >= 0.5f) x0 = std::min(x0, x), y0 = std::min(y0, y), x1 = std::max(x1, x), y1 = std::max(y1, y);
  return Box2{x0 - margin, y0 - margin, x1 + 1 + margin, y1 + 1 + margin};
}

// ---------------------------------------------------------------------------------------------------------------
// Max-flow.

// The minimum s-t cut by enumerating every labelling (source side = bit set).
struct TinyGraph {
  int n = 0;
  std::vector<double> source, sink;
  struct Edge {
    int a, b;
    double ab, ba;
  };
  std::vector<Edge> edges;

  double CutCost(uint32_t s_side) const {
    double cost = 0;
    for (int i = 0; i < n; ++i) cost += (s_side >> i & 1) ? sink[static_cast<size_t>(i)] : source[static_cast<size_t>(i)];
    for (const Edge& e : edges) {
      const bool sa = s_side >> e.a & 1, sb = s_side >> e.b & 1;
      if (sa && !sb) cost += e.ab;
      if (sb && !sa) cost += e.ba;
    }
    return cost;
  }
  double BruteForceMinCut() const {
    double best = 1e300;
    for (uint32_t m = 0; m < (1u << n); ++m) best = std::min(best, CutCost(m));
    return best;
  }
};

TEST(MaxFlow, EqualsTheBruteForceMinimumCutOnRandomTinyGraphs) {
  std::mt19937 rng(2024);
  for (int trial = 0; trial < 400; ++trial) {
    TinyGraph g;
    g.n = 1 + static_cast<int>(rng() % 11);
    std::uniform_int_distribution<int> cap(0, 9);
    for (int i = 0; i < g.n; ++i) {
      // Many nodes without terminal edges, some with both: the interesting cases for the trees.
      g.source.push_back(rng() % 3 == 0 ? cap(rng) : 0);
      g.sink.push_back(rng() % 3 == 0 ? cap(rng) : 0);
    }
    const int m = static_cast<int>(rng() % static_cast<unsigned>(3 * g.n + 1));
    for (int k = 0; k < m && g.n > 1; ++k) {
      const int a = static_cast<int>(rng() % static_cast<unsigned>(g.n));
      int b = static_cast<int>(rng() % static_cast<unsigned>(g.n - 1));
      if (b >= a) ++b;
      g.edges.push_back({a, b, static_cast<double>(cap(rng)), rng() % 2 ? static_cast<double>(cap(rng)) : 0.0});
    }
    MaxFlow flow(g.n);
    for (int i = 0; i < g.n; ++i) flow.AddTerminal(i, g.source[static_cast<size_t>(i)], g.sink[static_cast<size_t>(i)]);
    for (const auto& e : g.edges) flow.AddEdge(e.a, e.b, e.ab, e.ba);
    const double value = flow.Solve();
    const double expected = g.BruteForceMinCut();
    ASSERT_EQ(value, expected) << "trial " << trial << ", " << g.n << " nodes";
    uint32_t side = 0;
    for (int i = 0; i < g.n; ++i) side |= flow.SourceSide(i) ? 1u << i : 0u;
    EXPECT_EQ(g.CutCost(side), expected) << "trial " << trial;  // the reported labelling is a minimum cut
  }
}

TEST(MaxFlow, GridWithAKnownCut) {
  // A 30 x 20 grid, 4-connected with capacity 1; the left column tied to the source, the right to the sink:
  // the max flow is one unit per row (20), and the cut may fall anywhere along the rows.
  const int w = 30, h = 20;
  MaxFlow flow(w * h);
  for (int y = 0; y < h; ++y) {
    flow.AddTerminal(y * w, 100, 0);
    flow.AddTerminal(y * w + w - 1, 0, 100);
    for (int x = 0; x < w; ++x) {
      if (x + 1 < w) flow.AddEdge(y * w + x, y * w + x + 1, 1, 1);
      if (y + 1 < h) flow.AddEdge(y * w + x, (y + 1) * w + x, 1, 1);
    }
  }
  EXPECT_EQ(flow.Solve(), 20.0);
  for (int y = 0; y < h; ++y) {
    EXPECT_TRUE(flow.SourceSide(y * w));
    EXPECT_FALSE(flow.SourceSide(y * w + w - 1));
  }
}

// ---------------------------------------------------------------------------------------------------------------
// Helpers.

TEST(PixelsOf, TakesPixelsWhoseCentresLieInTheBoxClippedToTheImage) {
  PixelRect r = PixelsOf(Box2{10, 5, 20, 8}, 100, 50);
  EXPECT_EQ(r.x0, 10);
  EXPECT_EQ(r.x1, 20);
  EXPECT_EQ(r.y0, 5);
  EXPECT_EQ(r.y1, 8);
  r = PixelsOf(Box2{10.6, 4.4, 19.4, 8.6}, 100, 50);  // centres 11.5 .. 18.5 and 4.5 .. 8.5
  EXPECT_EQ(r.x0, 11);
  EXPECT_EQ(r.x1, 19);
  EXPECT_EQ(r.y0, 4);
  EXPECT_EQ(r.y1, 9);
  r = PixelsOf(Box2{-30, -2, 130, 60}, 100, 50);
  EXPECT_EQ(r.Area(), 5000);
  EXPECT_TRUE(PixelsOf(Box2{120, 0, 140, 10}, 100, 50).Empty());
  EXPECT_TRUE(PixelsOf(Box2{10, 10, 10, 20}, 100, 50).Empty());
  EXPECT_TRUE(PixelsOf(Box2{NAN, 10, 10, 20}, 100, 50).Empty());
}

TEST(LargestComponentFilled, KeepsTheBiggestBlobAndFillsItsHoles) {
  ImageF m(40, 30, 1, 0.0f);
  for (int y = 5; y < 25; ++y)
    for (int x = 5; x < 25; ++x) m.at(x, y) = 1;
  for (int y = 10; y < 15; ++y)
    for (int x = 10; x < 15; ++x) m.at(x, y) = 0;  // a hole
  for (int y = 0; y < 30; ++y) m.at(24, y) = 0;  // a notch open to the border is no hole
  for (int y = 2; y < 6; ++y)
    for (int x = 30; x < 36; ++x) m.at(x, y) = 1;  // a smaller blob
  const ImageF out = LargestComponentFilled(m);
  for (int y = 0; y < 30; ++y)
    for (int x = 0; x < 40; ++x) {
      const bool expected = x >= 5 && x < 24 && y >= 5 && y < 25;
      EXPECT_EQ(out.at(x, y), expected ? 1.0f : 0.0f) << x << "," << y;
    }
}

TEST(ResizeLinear, KeepsConstantsAndLinearRampsAndIsTheIdentityAtTheSameSize) {
  ImageF img(90, 60, 2);
  for (int y = 0; y < 60; ++y)
    for (int x = 0; x < 90; ++x) {
      img.at(x, y, 0) = 0.4f;
      img.at(x, y, 1) = 0.01f * static_cast<float>(x) + 0.005f * static_cast<float>(y);
    }
  EXPECT_EQ(ResizeLinear(img, 90, 60).vector(), img.vector());
  // Integer reductions (the tent's taps fall symmetrically) and enlargements (plain bilinear) reproduce ramps
  // exactly; other reductions shift the normalised sampled tent's centroid by up to ~0.05 pixel.
  for (const auto& [w, h, tolerance] : {std::tuple{45, 30, 1e-5}, std::tuple{30, 20, 1e-5}, std::tuple{200, 111, 1e-5},
                                        std::tuple{64, 64, 1e-3}}) {
    const ImageF out = ResizeLinear(img, w, h);
    const double sx = 90.0 / w, sy = 60.0 / h;
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x) {
        EXPECT_NEAR(out.at(x, y, 0), 0.4f, 1e-6f);
        const double u = (x + 0.5) * sx - 0.5, v = (y + 0.5) * sy - 0.5;
        // Where no tap is clamped at the border.
        if (u >= 2 * sx + 1 && u <= 89 - 2 * sx - 1 && v >= 2 * sy + 1 && v <= 59 - 2 * sy - 1) {
          EXPECT_NEAR(out.at(x, y, 1), 0.01 * u + 0.005 * v, tolerance) << w << "x" << h << " at " << x << "," << y;
        }
      }
  }
}

// ---------------------------------------------------------------------------------------------------------------
// Classical path on synthetic images.

// A textured warm object (an irregular blob with a bite out of its side) on a textured cool background, both
// with strong per-pixel noise and stripes, so neither colour nor texture alone is flat.
struct Synthetic {
  ImageU8 image;
  ImageF truth;
};

Synthetic MakeSynthetic(int w, int h, unsigned seed) {
  Synthetic s{ImageU8(w, h, 3), ImageF(w, h, 1, 0.0f)};
  std::mt19937 rng(seed);
  std::normal_distribution<double> noise(0, 12);
  const double cx = w * 0.5, cy = h * 0.55, rx = w * 0.28, ry = h * 0.3;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const double dx = (x + 0.5 - cx) / rx, dy = (y + 0.5 - cy) / ry;
      const double angle = std::atan2(dy, dx);
      const double radius = 1.0 + 0.15 * std::sin(5 * angle);
      const bool bite = std::hypot(x + 0.5 - (cx + 0.9 * rx), y + 0.5 - cy) < 0.35 * rx;
      const bool object = std::hypot(dx, dy) < radius && !bite;
      s.truth.at(x, y) = object ? 1.0f : 0.0f;
      std::array<double, 3> c{};
      if (object) {
        const double stripe = ((x + y) / 6) % 2 ? 30 : -30;  // diagonal stripes: orange / dark red
        c = {200 + stripe, 100 + stripe, 40};
      } else {
        const double stripe = (x / 9) % 2 ? 25 : -25;  // vertical stripes: grey-blue / green-grey
        c = {90, 120 + stripe, 150 - stripe};
      }
      for (int k = 0; k < 3; ++k)
        s.image.at(x, y, k) = static_cast<uint8_t>(std::clamp(std::lround(c[static_cast<size_t>(k)] + noise(rng)), 0L, 255L));
    }
  return s;
}

TEST(Segmenter, ClassicalSegmentsATexturedObjectOnATexturedBackground) {
  for (const auto& [w, h] : {std::pair{200, 160}, std::pair{512, 512}}) {
    const Synthetic s = MakeSynthetic(w, h, 5);
    const Box2 box = BoundsOf(s.truth, 0.04 * w);
    const Segmenter seg = Segmenter::Classical();
    EXPECT_FALSE(seg.learned());
    EXPECT_NE(seg.Describe().find("GrabCut"), std::string::npos);
    const auto t0 = std::chrono::steady_clock::now();
    const std::clock_t c0 = std::clock();
    const SegmentationResult r = seg.Segment(s.image, box);
    const double cpu = static_cast<double>(std::clock() - c0) / CLOCKS_PER_SEC;
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    EXPECT_EQ(r.method, "grabcut");
    ASSERT_EQ(r.mask.width(), w);
    ASSERT_EQ(r.mask.height(), h);
    ASSERT_EQ(r.mask.channels(), 1);
    const double iou = MaskIoU(r.mask, s.truth);
    std::cout << "synthetic " << w << "x" << h << ": IoU " << iou << ", " << seconds << " s wall, " << cpu << " s CPU\n";
    EXPECT_GE(iou, 0.95) << w << "x" << h;
  }
}

TEST(Segmenter, PriorPinsPartsTheColourModelsWouldGiveAway) {
  // The object's lower third is painted in the background's colours: from the box alone GrabCut drops it; a
  // prior covering a few pixels in it (as projected LiDAR points would) brings it back through the cut.
  Synthetic s = MakeSynthetic(200, 160, 9);
  const Box2 box = BoundsOf(s.truth, 8);
  const ImageU8 background = MakeSynthetic(200, 160, 10).image;
  int y_cut = static_cast<int>(box.y1 + 2 * (box.y2 - box.y1) / 3);
  ImageF prior(200, 160, 1, 0.0f);
  for (int y = y_cut; y < 160; ++y)
    for (int x = 0; x < 200; ++x)
      if (s.truth.at(x, y) >= 0.5f) {
        for (int k = 0; k < 3; ++k) s.image.at(x, y, k) = background.at(std::min(199, x / 2), 0, k);
        if ((x + y) % 3 == 0) prior.at(x, y) = 1.0f;  // a dense scatter of points
      }
  const Segmenter seg = Segmenter::Classical();
  const double without = MaskIoU(seg.Segment(s.image, box).mask, s.truth);
  const double with = MaskIoU(seg.Segment(s.image, box, &prior).mask, s.truth);
  std::cout << "prior: IoU " << without << " without, " << with << " with\n";
  EXPECT_LT(without, 0.9);
  EXPECT_GE(with, 0.9);
}

TEST(GrabCut, SureBackgroundInsideTheBoxStaysBackground) {
  // A wide box, as a projected 3D box is around a thin object: its corners marked sure background stay so, and
  // the object is still found; without the mark a background-coloured corner blob would be free to join.
  const Synthetic s = MakeSynthetic(200, 160, 11);
  const Box2 box{4, 4, 196, 156};
  ImageF background(200, 160, 1, 0.0f);
  for (int y = 0; y < 160; ++y)
    for (int x = 0; x < 200; ++x)
      if (s.truth.at(x, y) < 0.5f && (x < 30 || x >= 170)) background.at(x, y) = 1.0f;
  const ImageF mask = GrabCut(s.image, box, nullptr, {}, &background);
  for (int y = 0; y < 160; ++y) {
    for (int x = 0; x < 200; ++x) {
      if (background.at(x, y) >= 0.5f) {
        ASSERT_LT(mask.at(x, y), 0.5f) << x << "," << y;
      }
    }
  }
  EXPECT_GE(MaskIoU(mask, s.truth), 0.9);
}

TEST(GrabCut, ForegroundFromPriorLearnsTheObjectFromTheSeedsInAMostlyBackgroundBox) {
  // A thin, low-contrast object (a fifth of the box's width) in a box that is mostly background, its first colour
  // model learnt from seeds along its axis (as a cone's LiDAR returns give them): the cut still finds its outline.
  ImageU8 image(160, 160, 3);
  ImageF truth(160, 160, 1, 0.0f), seeds(160, 160, 1, 0.0f);
  std::mt19937 rng(3);
  std::normal_distribution<double> noise(0, 10);
  for (int y = 0; y < 160; ++y)
    for (int x = 0; x < 160; ++x) {
      const double half = 4 + 12.0 * y / 160;  // a cone: narrow at the top
      const bool object = y > 10 && y < 150 && std::abs(x + 0.5 - 80) < half;
      truth.at(x, y) = object ? 1.0f : 0.0f;
      if (object && std::abs(x + 0.5 - 80) < 0.4 * half && y % 2 == 0) seeds.at(x, y) = 1.0f;
      const std::array<double, 3> c = object ? std::array<double, 3>{84, 58, 54} : std::array<double, 3>{68, 70, 68};
      for (int k = 0; k < 3; ++k)
        image.at(x, y, k) = static_cast<uint8_t>(std::clamp(std::lround(c[static_cast<size_t>(k)] + noise(rng)), 0L, 255L));
    }
  const Box2 box{40, 4, 120, 156};
  GrabCutOptions seeded;
  seeded.foreground_from_prior = true;
  const double with = MaskIoU(GrabCut(image, box, &seeds, seeded), truth);
  std::cout << "thin object: IoU " << with << " from the seeds\n";
  EXPECT_GE(with, 0.85);
}

TEST(Segmenter, RejectsBadBoxesPriorsAndImagesWithoutAnObject) {
  const Synthetic s = MakeSynthetic(80, 60, 1);
  const Segmenter seg = Segmenter::Classical();
  EXPECT_NE(ErrorOf([&] { seg.Segment(s.image, Box2{100, 10, 120, 30}); }).find("holds no pixel"), std::string::npos);
  EXPECT_NE(ErrorOf([&] { seg.Segment(s.image, Box2{10, 10, 10, 30}); }).find("holds no pixel"), std::string::npos);
  EXPECT_NE(ErrorOf([&] { seg.Segment(ImageU8(), Box2{0, 0, 1, 1}); }).find("empty image"), std::string::npos);
  const ImageF small(10, 10, 1);
  EXPECT_NE(ErrorOf([&] { seg.Segment(s.image, Box2{10, 10, 50, 50}, &small); }).find("prior"), std::string::npos);
  // A flat image: nothing in the box differs from around it.
  const ImageU8 flat(80, 60, 3, 128);
  EXPECT_NE(ErrorOf([&] { seg.Segment(flat, Box2{20, 15, 60, 45}); }).find("no object found in the box"),
            std::string::npos);
  EXPECT_THROW(Segmenter::Classical({.components = 0}), InputError);
  EXPECT_THROW(Segmenter::Resolve("mask-rcnn"), InputError);
}

// ---------------------------------------------------------------------------------------------------------------
// Classical path on real images: GSO object renders (RGBA, exact alpha) composited onto driving camera images.

struct Composite {
  std::string name;
  ImageU8 image;
  ImageF truth;
  Box2 box;
};

// A 384² crop of a driving camera image (KITTI's 375 rows repeat the edge rows) with a 256² RGBA GSO render alpha-blended (in sRGB) at (64, 96); the
// truth is the render's alpha ≥ 0.5 and the box its bounds grown by 6 pixels.
Composite MakeComposite(const fs::path& render, const fs::path& scene_file, std::array<int, 2> crop_at) {
  const ImageU8 object = ReadImage(render, 4);
  const ImageU8 scene = ReadImage(scene_file, 3);
  const int size = 384;
  const int ox = std::min(crop_at[0], scene.width() - size), oy = std::min(crop_at[1], scene.height() - size);
  Composite c{render.stem().string() + " on " + scene_file.filename().string(), ImageU8(size, size, 3),
              ImageF(size, size, 1, 0.0f), {}};
  for (int y = 0; y < size; ++y)
    for (int x = 0; x < size; ++x) {
      const int u = x - 64, v = y - 96;
      const bool on = u >= 0 && v >= 0 && u < object.width() && v < object.height();
      const float a = on ? object.at(u, v, 3) / 255.0f : 0.0f;
      c.truth.at(x, y) = a >= 0.5f ? 1.0f : 0.0f;
      for (int k = 0; k < 3; ++k)
        c.image.at(x, y, k) = static_cast<uint8_t>(std::lround((1 - a) * scene.at(ox + x, std::clamp(oy + y, 0, scene.height() - 1), k) +
                                                               a * (on ? object.at(u, v, k) : 0)));
    }
  c.box = BoundsOf(c.truth, 6);
  return c;
}

std::vector<fs::path> Scenes() {
  std::vector<fs::path> scenes{testing::RepoData("driving/kitti-object/training/image_2/000001.png")};
  for (const auto& e : fs::directory_iterator(testing::RepoData("driving/nuscenes-scene0061-kf0/samples/CAM_FRONT")))
    scenes.push_back(e.path());
  return scenes;
}
// Placement in each scene: crops that show road, cars and buildings behind the object.
const std::vector<std::array<int, 2>> kCropAt{{400, 60}, {600, 380}};

void MaybeWriteFigure(const Composite& c, const ImageF& mask, const std::string& method) {
  const char* dir = std::getenv("SYNTHDRIVE_SEGMENTATION_FIGURES");
  if (dir == nullptr) return;
  ImageU8 vis = c.image;
  for (int y = 0; y < vis.height(); ++y)
    for (int x = 0; x < vis.width(); ++x)
      for (int k = 0; k < 3; ++k)
        vis.at(x, y, k) = static_cast<uint8_t>(std::lround(vis.at(x, y, k) * (0.25f + 0.75f * mask.at(x, y))));
  std::string stem = c.name.substr(0, c.name.find(' ')) + "_" + c.name.substr(c.name.rfind(' ') + 1, 6);
  WriteImage(fs::path(dir) / (stem + "_input.jpg"), c.image);
  WriteImage(fs::path(dir) / (stem + "_" + method + ".jpg"), vis);
}

TEST(Segmenter, ClassicalOnRealObjectsCompositedOntoDrivingImages) {
  SD_REQUIRE_SHARED(renders, "assets/gso_renders/syncdreamer_gso_input_views");
  const std::vector<fs::path> scenes = Scenes();
  const Segmenter seg = Segmenter::Classical();
  double sum = 0, worst = 1;
  int count = 0;
  for (const char* name : {"school_bus1", "shoe", "teapot", "toaster", "backpack", "alarm"}) {
    for (size_t k = 0; k < scenes.size(); ++k) {
      const Composite c = MakeComposite(renders / (std::string(name) + ".png"), scenes[k], kCropAt[k]);
      const SegmentationResult r = seg.Segment(c.image, c.box);
      const double iou = MaskIoU(r.mask, c.truth);
      std::cout << c.name << ": IoU " << iou << "\n";
      sum += iou;
      worst = std::min(worst, iou);
      ++count;
      MaybeWriteFigure(c, r.mask, "grabcut");
    }
  }
  std::cout << "real composites: mean IoU " << sum / count << ", worst " << worst << " over " << count << "\n";
  EXPECT_GE(sum / count, 0.9);
  EXPECT_GE(worst, 0.8);
}

// The installed ISNet (scripts/fetch_isnet.sh, opt-in) on the same composites, when present.
TEST(Segmenter, InstalledIsnetOnRealComposites) {
  SD_REQUIRE_SHARED(renders, "assets/gso_renders/syncdreamer_gso_input_views");
  const fs::path file = DefaultModelDir() / "isnet.pt";
  if (!RuntimeAvailable() || !fs::is_regular_file(file)) GTEST_SKIP() << file << " not installed (opt-in, AGPL-3.0)";
  const Segmenter seg = Segmenter::FromModel(file);
  const std::vector<fs::path> scenes = Scenes();
  double sum = 0;
  int count = 0;
  for (const char* name : {"school_bus1", "shoe", "teapot", "toaster", "backpack", "alarm"}) {
    const size_t k = static_cast<size_t>(count % 2);
    const Composite c = MakeComposite(renders / (std::string(name) + ".png"), scenes[k], kCropAt[k]);
    const SegmentationResult r = seg.Segment(c.image, c.box);
    const double iou = MaskIoU(r.mask, c.truth);
    std::cout << c.name << ": ISNet IoU " << iou << "\n";
    sum += iou;
    ++count;
    MaybeWriteFigure(c, r.mask, "isnet");
  }
  std::cout << "ISNet on real composites: mean IoU " << sum / count << " over " << count << "\n";
  EXPECT_GE(sum / count, 0.85);
}

// ---------------------------------------------------------------------------------------------------------------
// Learned path with the tiny models of tools/testing/make_segmentation_test_models.py.


TEST(Segmenter, LearnedPathReproducesTheModuleOnAnInputSizeImage) {
  SD_REQUIRE_TEST_MODEL(file, "seg_tiny.pt");
  const Segmenter seg = Segmenter::FromModel(file);
  EXPECT_TRUE(seg.learned());
  EXPECT_EQ(seg.input_size(), 64);
  EXPECT_NE(seg.Describe().find("seg-tiny"), std::string::npos);
  std::vector<int64_t> in_shape, out_shape;
  const auto pixels = testing::ReadRawBytes(testing::TestModel("seg_ref_input.u8"), &in_shape);
  const auto expected = testing::ReadRawFloats(testing::TestModel("seg_ref_mask.f32"), &out_shape);
  ASSERT_EQ(in_shape, (std::vector<int64_t>{64, 64, 3}));
  ImageU8 image(64, 64, 3);
  image.vector().assign(pixels.begin(), pixels.end());
  const SegmentationResult r = seg.Segment(image, Box2{0, 0, 64, 64});
  EXPECT_EQ(r.method, "seg-tiny");
  ASSERT_EQ(r.mask.size(), expected.size());
  for (size_t i = 0; i < expected.size(); ++i) ASSERT_NEAR(r.mask.vector()[i], expected[i], 1e-5f) << i;
  // The same module scaled to a 0..255 output range, declared in its contract, gives the same mask.
  SD_REQUIRE_TEST_MODEL(file255, "seg_tiny_255.pt");
  const SegmentationResult r255 = Segmenter::FromModel(file255).Segment(image, Box2{0, 0, 64, 64});
  for (size_t i = 0; i < expected.size(); ++i) ASSERT_NEAR(r255.mask.vector()[i], expected[i], 1e-5f) << i;
}

TEST(Segmenter, LearnedPathResizesBothWaysAndKeepsToTheBox) {
  SD_REQUIRE_TEST_MODEL(file, "seg_tiny.pt");
  // The tiny model's rule: red above blue (with green near 0.3) is object. An L-shaped object in a 230 x 150
  // image (not square, not 64: resized down and back up), and a second red blob far outside the box.
  const int w = 230, h = 150;
  ImageU8 image(w, h, 3);
  ImageF truth(w, h, 1, 0.0f);
  auto paint = [&](int x0, int y0, int x1, int y1, bool in_truth) {
    for (int y = y0; y < y1; ++y)
      for (int x = x0; x < x1; ++x) {
        image.at(x, y, 0) = 230, image.at(x, y, 1) = 77, image.at(x, y, 2) = 25;
        if (in_truth) truth.at(x, y) = 1;
      }
  };
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) image.at(x, y, 0) = 77, image.at(x, y, 1) = 77, image.at(x, y, 2) = 204;
  paint(30, 20, 60, 120, true);   // the L's upright
  paint(60, 90, 140, 120, true);  // its foot, to the right
  paint(190, 10, 220, 40, false);  // another object, outside the box
  const Box2 box{25, 15, 150, 125};
  const SegmentationResult r = Segmenter::FromModel(file).Segment(image, box);
  ASSERT_EQ(r.mask.width(), w);
  ASSERT_EQ(r.mask.height(), h);
  // Away from the edges (a model pixel is 3.6 x 2.3 image pixels; the up and down resampling blur by about two
  // model pixels) the mask matches the shape; outside the grown box it is zero.
  int checked = 0;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      bool near_edge = false;
      for (int dy = -6; dy <= 6 && !near_edge; ++dy)
        for (int dx = -9; dx <= 9 && !near_edge; ++dx) {
          const int qx = std::clamp(x + dx, 0, w - 1), qy = std::clamp(y + dy, 0, h - 1);
          near_edge = truth.at(qx, qy) != truth.at(x, y);
        }
      const bool in_grown = x >= 25 - 6.25 && x < 150 + 6.25 && y >= 15 - 6.25 && y < 125 + 6.25;
      if (!in_grown) {
        EXPECT_EQ(r.mask.at(x, y), 0.0f) << x << "," << y;
      } else if (!near_edge) {
        EXPECT_NEAR(r.mask.at(x, y), truth.at(x, y), 0.05f) << x << "," << y;
        ++checked;
      }
      EXPECT_GE(r.mask.at(x, y), 0.0f);
      EXPECT_LE(r.mask.at(x, y), 1.0f);
    }
  EXPECT_GT(checked, 8000);
}

TEST(Segmenter, LearnedPathErrors) {
  SD_REQUIRE_TEST_MODEL(empty, "seg_empty.pt");
  const ImageU8 image(100, 80, 3, 90);
  EXPECT_NE(ErrorOf([&] { Segmenter::FromModel(empty).Segment(image, Box2{10, 10, 50, 50}); })
                .find("no object found in the box"),
            std::string::npos);
  SD_REQUIRE_TEST_MODEL(wrong, "seg_wrong_stage.pt");
  const std::string stage_error = ErrorOf([&] { Segmenter::FromModel(wrong); });
  EXPECT_NE(stage_error.find(wrong.filename().string()), std::string::npos) << stage_error;
  EXPECT_NE(stage_error.find("super_resolution"), std::string::npos) << stage_error;
  SD_REQUIRE_TEST_MODEL(any, "seg_any_size.pt");
  const std::string shape_error = ErrorOf([&] { Segmenter::FromModel(any); });
  EXPECT_NE(shape_error.find("maps one image [1, 3, 64, 64]"), std::string::npos) << shape_error;
  EXPECT_NE(ErrorOf([&] { Segmenter::FromModel("/nonexistent/isnet.pt"); }).find("isnet.pt"), std::string::npos);
  SD_REQUIRE_TEST_MODEL(tiny, "seg_tiny.pt");
  EXPECT_NE(ErrorOf([&] { Segmenter::FromModel(tiny).Segment(image, Box2{-40, -40, -1, -1}); }).find("holds no pixel"),
            std::string::npos);
}

TEST(Segmenter, ResolveTakesClassicalAutoOrAModelPath) {
  testing::TempDir dir;
  const testing::ScopedEnv models("SYNTHDRIVE_MODELS", dir.path().string());
  EXPECT_FALSE(Segmenter::Resolve("classical").learned());
  EXPECT_FALSE(Segmenter::Resolve("auto").learned());  // nothing installed: GrabCut, with a warning
  SD_REQUIRE_TEST_MODEL(tiny, "seg_tiny.pt");
  EXPECT_TRUE(Segmenter::Resolve(tiny.string()).learned());
  fs::copy_file(tiny, dir / "isnet.pt");
  EXPECT_TRUE(Segmenter::Resolve("auto").learned());
}

}  // namespace
}  // namespace sd::models
