#pragma once
// Per-pixel loss terms as ops, so that a loss composes with the raster ops on either side of the bus
// (raster.h: an op runs where its buffers live). Each writes the gradient of its term with respect to its
// prediction (overwritten, times grad_scale) and ACCUMULATES the unscaled sum of its term into a one-element
// double Span, which on the device stays there until the caller downloads it, once, with the gradients.
// On the host the sums run in pixel order; on the device per warp, then atomically (the last bits may differ).
#include <cstdint>

#include "raster/raster.h"

namespace sd::raster {

// out[p] = 1 where the raster covers pixel p, else 0 (no gradient: coverage moves only through Antialias).
void Coverage(const RasterBuffer& rast, Span<float> out);

// |n/|n| - t|^2 for each pixel that the raster covers, whose mask is above 0.5 and whose target t has
// |t|^2 >= 0.5 (a pixel without a target normal holds zeros), n the predicted vector (3 per pixel, not
// normalised, e.g. interpolated vertex normals); elsewhere no term and a zero gradient.
struct UnitVectorLossInputs {
  Span<const float> prediction;  // 3 per pixel
  const RasterBuffer& rast;      // gives the resolution and the coverage
  Span<const float> target;      // 3 per pixel
  Span<const float> mask;        // 1 per pixel
};
void UnitVectorLoss(const UnitVectorLossInputs& in, float grad_scale, Span<float> grad_prediction,
                    Span<double> loss_sum);

// (p - t)^2 per element; an element whose target is negative (unknown) has no term and a zero gradient.
void SquaredErrorLoss(Span<const float> prediction, Span<const float> target, float grad_scale,
                      Span<float> grad_prediction, Span<double> loss_sum);

}  // namespace sd::raster
