#include "core/image.h"

#include <algorithm>
#include <array>
#include <cmath>

#include "core/parallel.h"

namespace sd {

float SrgbToLinear(float v) {
  return v <= 0.04045f ? v / 12.92f : std::pow((v + 0.055f) / 1.055f, 2.4f);
}

float LinearToSrgb(float v) {
  v = std::clamp(v, 0.0f, 1.0f);
  return v <= 0.0031308f ? v * 12.92f : 1.055f * std::pow(v, 1.0f / 2.4f) - 0.055f;
}

namespace {
const std::array<float, 256>& SrgbTable() {
  static const std::array<float, 256> table = [] {
    std::array<float, 256> t{};
    for (int i = 0; i < 256; ++i) t[i] = SrgbToLinear(i / 255.0f);
    return t;
  }();
  return table;
}

template <typename T>
void SampleBilinearImpl(const Image<T>& img, double u, double v, float* out) {
  const double x = std::clamp(u - 0.5, 0.0, img.width() - 1.0);
  const double y = std::clamp(v - 0.5, 0.0, img.height() - 1.0);
  const int x0 = static_cast<int>(x), y0 = static_cast<int>(y);
  const int x1 = std::min(x0 + 1, img.width() - 1), y1 = std::min(y0 + 1, img.height() - 1);
  const float fx = static_cast<float>(x - x0), fy = static_cast<float>(y - y0);
  for (int c = 0; c < img.channels(); ++c) {
    const float a = static_cast<float>(img.at(x0, y0, c)) * (1 - fx) + static_cast<float>(img.at(x1, y0, c)) * fx;
    const float b = static_cast<float>(img.at(x0, y1, c)) * (1 - fx) + static_cast<float>(img.at(x1, y1, c)) * fx;
    out[c] = a * (1 - fy) + b * fy;
  }
}
}  // namespace

ImageF ToLinear(const ImageU8& srgb) {
  ImageF out(srgb.width(), srgb.height(), srgb.channels());
  const auto& table = SrgbTable();
  const int nc = srgb.channels();
  const size_t n = srgb.size();
  for (size_t i = 0; i < n; ++i) {
    const bool alpha = nc == 4 && (i % 4) == 3;
    out.data()[i] = alpha ? srgb.data()[i] / 255.0f : table[srgb.data()[i]];
  }
  return out;
}

ImageU8 ToSrgb8(const ImageF& linear) {
  ImageU8 out(linear.width(), linear.height(), linear.channels());
  const int nc = linear.channels();
  const size_t row = static_cast<size_t>(linear.width()) * nc;
  // One pow per value: a whole camera image is ~4 M of them, so rows go in parallel (same result).
  ParallelFor(0, static_cast<size_t>(linear.height()), [&](size_t y) {
    for (size_t i = y * row; i < (y + 1) * row; ++i) {
      const bool alpha = nc == 4 && (i % 4) == 3;
      const float v = alpha ? std::clamp(linear.data()[i], 0.0f, 1.0f) : LinearToSrgb(linear.data()[i]);
      out.data()[i] = static_cast<uint8_t>(std::lround(v * 255.0f));
    }
  }, 16);
  return out;
}

void SampleBilinear(const ImageF& img, double u, double v, float* out) { SampleBilinearImpl(img, u, v, out); }
void SampleBilinear(const ImageU8& img, double u, double v, float* out) { SampleBilinearImpl(img, u, v, out); }

}  // namespace sd
