#pragma once
// Images: interleaved channels, row-major, (0, 0) is the top-left pixel.
//  - ImageU8: 8-bit, sRGB-encoded colour as stored on disk (1, 3 or 4 channels).
//  - ImageF: 32-bit float, linear light where lighting is computed (values usually 0..1, HDR allowed).
// Alpha, when present, is linear and not premultiplied.
#include <cstddef>
#include <cstdint>
#include <vector>

#include "core/error.h"

namespace sd {

// Large blocks (a camera image as floats is 6-17 MB) asked of the kernel in 2 MB pages where it allows (madvise):
// a frame allocates dozens of camera-sized images, and with 4 KB pages every first touch of each was a page
// fault, a quarter of a one-frame synth process on a virtual machine (2.5 s -> 1.9 s with large pages).
// Freed large blocks are kept for reuse (up to ImageMemoryCacheLimit() bytes in all), because the kernel
// zeroes every page it hands out again: each frame's camera-sized images otherwise fault in and clear their
// pages anew, frame after frame.
void* AllocateImageMemory(size_t bytes);
void FreeImageMemory(void* p, size_t bytes);
size_t ImageMemoryCacheLimit();
// Bytes held for reuse now (for tests and diagnostics).
size_t ImageMemoryCached();

template <typename T>
struct ImageAllocator {
  using value_type = T;
  ImageAllocator() = default;
  template <typename U>
  ImageAllocator(const ImageAllocator<U>&) {}  // NOLINT: allocators convert implicitly
  T* allocate(size_t n) { return static_cast<T*>(AllocateImageMemory(n * sizeof(T))); }
  void deallocate(T* p, size_t n) { FreeImageMemory(p, n * sizeof(T)); }
  template <typename U>
  bool operator==(const ImageAllocator<U>&) const { return true; }
};

// An image's pixels: a std::vector with the allocator above.
template <typename T>
using ImageBuffer = std::vector<T, ImageAllocator<T>>;

template <typename T>
class Image {
 public:
  Image() = default;
  Image(int width, int height, int channels, T fill = T{})
      : width_(width), height_(height), channels_(channels),
        data_(static_cast<size_t>(width) * height * channels, fill) {
    SD_CHECK(width >= 0 && height >= 0 && channels > 0, << width << "x" << height << "x" << channels);
  }

  int width() const { return width_; }
  int height() const { return height_; }
  int channels() const { return channels_; }
  bool empty() const { return data_.empty(); }
  size_t size() const { return data_.size(); }

  T& at(int x, int y, int c = 0) { return data_[Index(x, y, c)]; }
  const T& at(int x, int y, int c = 0) const { return data_[Index(x, y, c)]; }
  T* pixel(int x, int y) { return &data_[Index(x, y, 0)]; }
  const T* pixel(int x, int y) const { return &data_[Index(x, y, 0)]; }
  T* data() { return data_.data(); }
  const T* data() const { return data_.data(); }
  ImageBuffer<T>& vector() { return data_; }
  const ImageBuffer<T>& vector() const { return data_; }

 private:
  size_t Index(int x, int y, int c) const {
    return (static_cast<size_t>(y) * width_ + x) * channels_ + c;
  }
  int width_ = 0, height_ = 0, channels_ = 0;
  ImageBuffer<T> data_;
};

using ImageU8 = Image<uint8_t>;
using ImageF = Image<float>;

// sRGB transfer function (IEC 61966-2-1), per channel value in [0, 1].
float SrgbToLinear(float v);
float LinearToSrgb(float v);
// Luminance Y of a linear Rec. 709 / sRGB colour (3 values).
inline float LinearLuminance(const float* rgb) { return 0.2126f * rgb[0] + 0.7152f * rgb[1] + 0.0722f * rgb[2]; }
// Colour channels go through the transfer function; a 4th (alpha) channel is only rescaled.
ImageF ToLinear(const ImageU8& srgb);
ImageU8 ToSrgb8(const ImageF& linear);
// ToSrgb8 of the pixels [x0, x1) x [y0, y1) only (clamped to the image), written into `out` (the same size and
// channels): a stage that changed a region of a photograph converts that region and keeps the rest byte for byte.
void ToSrgb8Region(const ImageF& linear, int x0, int y0, int x1, int y1, ImageU8* out);
// SrgbToLinear(v / 255) from a table: for loops over whole 8-bit images.
float SrgbByteToLinear(uint8_t v);

// Bilinear sample at continuous coordinates (pixel centres at +0.5), clamped at the border.
// `out` receives channels() values.
void SampleBilinear(const ImageF& img, double u, double v, float* out);
void SampleBilinear(const ImageU8& img, double u, double v, float* out);  // out in 0..255
// SampleBilinear(ToLinear(srgb)) with colour channel c scaled by gain[c] before filtering, bit for bit, without the
// float copy of the image (a camera image's is 17 MB): for the few thousand samples a check reads of a whole rig.
void SampleBilinearLinear(const ImageU8& srgb, double u, double v, const float* gain, float* out);

}  // namespace sd
