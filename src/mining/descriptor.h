#pragma once
// Classical image measures for mining without learned weights: a global descriptor for search by example
// image, a perceptual hash for near-duplicate removal, and a sharpness figure for the blur filter.
// Images are 1 (grey), 3 (RGB) or 4 (RGBA) channels; for RGBA without a mask, alpha > 127 is the mask (the
// hash ignores alpha). An empty image, another channel count, a mask of another size or (descriptor) a mask
// with no object pixels is an InputError.
#include <cstdint>
#include <vector>

#include "core/image.h"

namespace sd::mining {

// The descriptor's length (floats). Stored in the index beside any CLIP vectors; changing the descriptor
// changes kDescriptorVersion, and an index built with another version is refused rather than silently mixed.
int DescriptorDim();
constexpr int kDescriptorVersion = 1;

// A unit-L2 descriptor of what the object looks like: colour (a masked joint hue-saturation histogram plus a
// grey-level histogram) and shape (histograms of gradient orientation on a coarse grid of the object's
// mask bounding box), each block normalised and weighted so neither dominates. `mask` (1 channel, >127 =
// object) restricts it to the object; null or empty = the whole image. Invariant to image size, robust to
// small shifts and brightness changes; the cosine of two descriptors (their dot product) ranks similarity.
std::vector<float> ImageDescriptor(const ImageU8& image, const ImageU8* mask = nullptr);

// 64-bit DCT perceptual hash: grey, resized (area filter) to 32 × 32, 2-D DCT-II, the 8 × 8 lowest
// frequencies without DC compared to their median. Re-encoding, rescaling and mild colour changes move it by a
// few bits; different images differ in ~32.
uint64_t PerceptualHash(const ImageU8& image);
int HammingDistance(uint64_t a, uint64_t b);

// Variance of the 4-neighbour Laplacian of the grey image (0..255 scale), after shrinking images whose shorter
// side is over 128 pixels to 128 (so the figure does not grow with resolution; smaller crops are measured as
// they are, never upsampled); over the mask's pixels when a mask is given (an
// RGBA image's alpha acts as the mask). Measured on real camera crops: nuScenes 80-100, KITTI about 1000; a
// Gaussian blur of sigma 2 at that scale brings them to 4-9 (descriptor_test.cpp), so ~10 separates blurred.
double Sharpness(const ImageU8& image, const ImageU8* mask = nullptr);

}  // namespace sd::mining
