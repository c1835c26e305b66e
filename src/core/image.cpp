#include "core/image.h"

#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdlib>
#include <map>
#include <mutex>
#include <new>

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

constexpr size_t kLargePage = size_t{2} << 20;
// Blocks this large come from AllocateLarge and may go back to the cache; smaller ones are plain malloc.
bool IsLarge(size_t bytes) { return bytes >= 2 * kLargePage; }
size_t RoundedToLargePages(size_t bytes) { return (bytes + kLargePage - 1) / kLargePage * kLargePage; }

// Freed large blocks by their rounded size. Never destroyed: images may be freed during static destruction.
struct LargeBlockCache {
  std::mutex mutex;
  std::multimap<size_t, void*> blocks;
  size_t bytes = 0;
};
LargeBlockCache& Cache() {
  static LargeBlockCache* cache = new LargeBlockCache;
  return *cache;
}

}  // namespace

// A synthesised frame holds a few dozen camera-sized images per camera, and its cameras run at once: at 512 MB a
// five-object keyframe still faulted in some 6,000 fresh pages a frame, at 1.5 GB a fifth of that. A sixteenth
// of the machine's memory, within [512 MB, 2 GB], so that a worker per core on a large machine stays modest.
size_t ImageMemoryCacheLimit() {
  static const size_t limit = [] {
    const long pages = sysconf(_SC_PHYS_PAGES), page = sysconf(_SC_PAGESIZE);
    const size_t physical = pages > 0 && page > 0 ? static_cast<size_t>(pages) * static_cast<size_t>(page) : 0;
    return std::clamp(physical / 16, size_t{512} << 20, size_t{2048} << 20);
  }();
  return limit;
}

size_t ImageMemoryCached() {
  LargeBlockCache& c = Cache();
  std::lock_guard<std::mutex> lock(c.mutex);
  return c.bytes;
}

void* AllocateImageMemory(size_t bytes) {
  void* p = nullptr;
  if (IsLarge(bytes)) {
    const size_t rounded = RoundedToLargePages(bytes);
    {
      LargeBlockCache& c = Cache();
      std::lock_guard<std::mutex> lock(c.mutex);
      const auto it = c.blocks.find(rounded);
      if (it != c.blocks.end()) {
        p = it->second;
        c.blocks.erase(it);
        c.bytes -= rounded;
        return p;
      }
    }
    p = std::aligned_alloc(kLargePage, rounded);
#ifdef MADV_HUGEPAGE
    if (p) madvise(p, rounded, MADV_HUGEPAGE);  // advice only: without large pages the block works the same
#endif
  } else {
    p = std::malloc(bytes > 0 ? bytes : 1);
  }
  if (!p) throw std::bad_alloc();
  return p;
}

void FreeImageMemory(void* p, size_t bytes) {
  if (p == nullptr) return;
  if (IsLarge(bytes)) {
    const size_t rounded = RoundedToLargePages(bytes);
    LargeBlockCache& c = Cache();
    std::lock_guard<std::mutex> lock(c.mutex);
    if (c.bytes + rounded <= ImageMemoryCacheLimit()) {
      c.blocks.emplace(rounded, p);
      c.bytes += rounded;
      return;
    }
  }
  std::free(p);
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

// Bilinear filtering of `texel(x, y, c)` (a float) at (u, v) over a width x height grid: one arithmetic for every
// way a pixel's value is read.
template <typename T, typename Texel>
void SampleBilinearOf(const Image<T>& img, double u, double v, const Texel& texel, float* out) {
  const double x = std::clamp(u - 0.5, 0.0, img.width() - 1.0);
  const double y = std::clamp(v - 0.5, 0.0, img.height() - 1.0);
  const int x0 = static_cast<int>(x), y0 = static_cast<int>(y);
  const int x1 = std::min(x0 + 1, img.width() - 1), y1 = std::min(y0 + 1, img.height() - 1);
  const float fx = static_cast<float>(x - x0), fy = static_cast<float>(y - y0);
  for (int c = 0; c < img.channels(); ++c) {
    const float a = texel(x0, y0, c) * (1 - fx) + texel(x1, y0, c) * fx;
    const float b = texel(x0, y1, c) * (1 - fx) + texel(x1, y1, c) * fx;
    out[c] = a * (1 - fy) + b * fy;
  }
}

template <typename T>
void SampleBilinearImpl(const Image<T>& img, double u, double v, float* out) {
  SampleBilinearOf(img, u, v, [&](int x, int y, int c) { return static_cast<float>(img.at(x, y, c)); }, out);
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
  ToSrgb8Region(linear, 0, 0, linear.width(), linear.height(), &out);
  return out;
}

void ToSrgb8Region(const ImageF& linear, int x0, int y0, int x1, int y1, ImageU8* out) {
  SD_CHECK(out->width() == linear.width() && out->height() == linear.height() && out->channels() == linear.channels());
  x0 = std::max(0, x0), y0 = std::max(0, y0), x1 = std::min(linear.width(), x1), y1 = std::min(linear.height(), y1);
  if (x0 >= x1 || y0 >= y1) return;
  const int nc = linear.channels();
  // One pow per value: a whole camera image is ~4 M of them, so rows go in parallel (same result).
  ParallelFor(static_cast<size_t>(y0), static_cast<size_t>(y1), [&](size_t y) {
    const float* src = linear.pixel(x0, static_cast<int>(y));
    uint8_t* dst = out->pixel(x0, static_cast<int>(y));
    for (size_t i = 0; i < static_cast<size_t>(x1 - x0) * nc; ++i) {
      const bool alpha = nc == 4 && (i % 4) == 3;
      const float v = alpha ? std::clamp(src[i], 0.0f, 1.0f) : LinearToSrgb(src[i]);
      dst[i] = static_cast<uint8_t>(std::lround(v * 255.0f));
    }
  }, 16);
}

float SrgbByteToLinear(uint8_t v) { return SrgbTable()[v]; }

void SampleBilinear(const ImageF& img, double u, double v, float* out) { SampleBilinearImpl(img, u, v, out); }
void SampleBilinear(const ImageU8& img, double u, double v, float* out) { SampleBilinearImpl(img, u, v, out); }

void SampleBilinearLinear(const ImageU8& srgb, double u, double v, const float* gain, float* out) {
  // The texels ToLinear and a gain multiply would have stored.
  const auto& table = SrgbTable();
  const bool has_alpha = srgb.channels() == 4;
  SampleBilinearOf(srgb, u, v, [&](int x, int y, int c) {
    const uint8_t b = srgb.at(x, y, c);
    return has_alpha && c == 3 ? b / 255.0f : table[b] * gain[c];
  }, out);
}

}  // namespace sd
