#pragma once
// Separable resampling of images (interleaved channels, pixel centres at +0.5), shared by the stages that feed
// models at their own input size and by the classical upscaler.
#include "core/image.h"

namespace sd::models {

// Keys' cubic convolution (a = −0.5) to any size; when shrinking, the kernel is stretched by the factor (as
// PIL does), so it also low-passes. Taps outside the image are dropped and the weights renormalised, so
// constants stay exact up to the border.
ImageF ResizeBicubic(const ImageF& image, int width, int height);
// Antialiased linear resampling (a tent widened by the reduction factor when shrinking, so every input pixel
// contributes), edges clamped. Same size returns the image unchanged.
ImageF ResizeLinear(const ImageF& image, int width, int height);
// ResizeBicubic by an integer factor: the classical super-resolution path.
ImageF UpscaleBicubic(const ImageF& image, int scale);

}  // namespace sd::models
