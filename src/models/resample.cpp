// Separable image resampling shared by the stages: every model takes its input at its own size.
#include "models/resample.h"

#include <algorithm>
#include <cmath>
#include <vector>

#include "core/error.h"
#include "core/parallel.h"

namespace sd::models {

namespace {

float KeysCubic(float x) {
  constexpr float a = -0.5f;
  x = std::fabs(x);
  if (x <= 1) return ((a + 2) * x - (a + 3)) * x * x + 1;
  if (x < 2) return ((a * x - 5 * a) * x + 8 * a) * x - 4 * a;
  return 0;
}

struct Taps {
  int first = 0;
  std::vector<float> weight;
};

std::vector<Taps> ResampleTaps(int in_size, int out_size) {
  const double scale = static_cast<double>(in_size) / out_size;
  const double stretch = std::max(1.0, scale);  // widen the kernel when shrinking: it becomes the low-pass
  const double support = 2.0 * stretch;
  std::vector<Taps> taps(static_cast<size_t>(out_size));
  for (int o = 0; o < out_size; ++o) {
    const double centre = (o + 0.5) * scale;
    const int lo = std::max(0, static_cast<int>(std::floor(centre - support)));
    const int hi = std::min(in_size - 1, static_cast<int>(std::ceil(centre + support)));
    Taps& t = taps[static_cast<size_t>(o)];
    t.first = lo;
    double sum = 0;
    for (int i = lo; i <= hi; ++i) {
      const float w = KeysCubic(static_cast<float>((i + 0.5 - centre) / stretch));
      t.weight.push_back(w);
      sum += w;
    }
    for (float& w : t.weight) w = static_cast<float>(w / sum);
  }
  return taps;
}

// Taps of an antialiased tent filter for one axis: output o samples input around (o + 0.5) · in/out − 0.5.
struct AxisTaps {
  std::vector<int> first;      // per output: first tap's offset into index/weight
  std::vector<int> index;      // input coordinates (clamped)
  std::vector<float> weight;   // normalised weights
};

AxisTaps TentTaps(int in_size, int out_size) {
  AxisTaps t;
  const double scale = static_cast<double>(in_size) / out_size;
  const double support = std::max(1.0, scale);  // tent half-width in input pixels
  for (int o = 0; o < out_size; ++o) {
    t.first.push_back(static_cast<int>(t.index.size()));
    const double centre = (o + 0.5) * scale - 0.5;
    const int lo = static_cast<int>(std::floor(centre - support)), hi = static_cast<int>(std::ceil(centre + support));
    double total = 0;
    const size_t start = t.weight.size();
    for (int i = lo; i <= hi; ++i) {
      const double wgt = std::max(0.0, 1.0 - std::fabs(i - centre) / support);
      if (wgt <= 0) continue;
      t.index.push_back(std::clamp(i, 0, in_size - 1));
      t.weight.push_back(static_cast<float>(wgt));
      total += wgt;
    }
    for (size_t k = start; k < t.weight.size(); ++k) t.weight[k] = static_cast<float>(t.weight[k] / total);
  }
  t.first.push_back(static_cast<int>(t.index.size()));
  return t;
}

}  // namespace

ImageF ResizeBicubic(const ImageF& image, int width, int height) {
  SD_CHECK(width > 0 && height > 0 && !image.empty(), << width << "x" << height);
  const int w = image.width(), h = image.height(), ch = image.channels();
  const std::vector<Taps> tx = ResampleTaps(w, width), ty = ResampleTaps(h, height);
  ImageF wide(width, h, ch);
  ParallelRows(0, h, [&](int y) {
    for (int xo = 0; xo < width; ++xo) {
      const Taps& t = tx[static_cast<size_t>(xo)];
      for (int c = 0; c < ch; ++c) {
        float v = 0;
        for (size_t k = 0; k < t.weight.size(); ++k) v += t.weight[k] * image.at(t.first + static_cast<int>(k), y, c);
        wide.at(xo, y, c) = v;
      }
    }
  });
  ImageF out(width, height, ch);
  ParallelFor(0, static_cast<size_t>(height), [&](size_t yo) {
    const Taps& t = ty[yo];
    for (int x = 0; x < width; ++x)
      for (int c = 0; c < ch; ++c) {
        float v = 0;
        for (size_t k = 0; k < t.weight.size(); ++k) v += t.weight[k] * wide.at(x, t.first + static_cast<int>(k), c);
        out.at(x, static_cast<int>(yo), c) = v;
      }
  });
  return out;
}

ImageF ResizeLinear(const ImageF& image, int width, int height) {
  SD_CHECK(width > 0 && height > 0 && !image.empty(), << width << "x" << height);
  if (width == image.width() && height == image.height()) return image;
  const int ch = image.channels();
  const AxisTaps tx = TentTaps(image.width(), width), ty = TentTaps(image.height(), height);
  ImageF wide(width, image.height(), ch);
  ParallelFor(0, static_cast<size_t>(image.height()), [&](size_t y) {
    for (int x = 0; x < width; ++x)
      for (int c = 0; c < ch; ++c) {
        float v = 0;
        for (int k = tx.first[static_cast<size_t>(x)]; k < tx.first[static_cast<size_t>(x) + 1]; ++k)
          v += tx.weight[static_cast<size_t>(k)] * image.at(tx.index[static_cast<size_t>(k)], static_cast<int>(y), c);
        wide.at(x, static_cast<int>(y), c) = v;
      }
  });
  ImageF out(width, height, ch);
  ParallelFor(0, static_cast<size_t>(height), [&](size_t y) {
    for (int x = 0; x < width; ++x)
      for (int c = 0; c < ch; ++c) {
        float v = 0;
        for (int k = ty.first[y]; k < ty.first[y + 1]; ++k)
          v += ty.weight[static_cast<size_t>(k)] * wide.at(x, ty.index[static_cast<size_t>(k)], c);
        out.at(x, static_cast<int>(y), c) = v;
      }
  });
  return out;
}

ImageF UpscaleBicubic(const ImageF& image, int scale) {
  SD_CHECK(scale >= 1, << scale);
  if (image.empty()) return ImageF(image.width() * scale, image.height() * scale, image.channels());
  return ResizeBicubic(image, image.width() * scale, image.height() * scale);
}

}  // namespace sd::models
