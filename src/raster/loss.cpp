// Coverage, UnitVectorLoss and SquaredErrorLoss on the host (below) and the device (cuda/raster_cuda.cu's
// kernels of the same names, the same expressions).
#include "raster/loss.h"

#include <Eigen/Core>

#include "raster/internal.h"

namespace sd::raster {

void Coverage(const RasterBuffer& rast, Span<float> out) {
  internal::CheckRaster(rast);
  const size_t np = rast.NumPixels();
  SD_CHECK(out.size() == np, << "coverage: " << out.size() << " floats for " << np << " pixels");
  if (internal::CommonMemory("Coverage", rast, out) == Memory::kDevice) {
    internal::CheckDeviceBuild("Coverage");
#if SYNTHDRIVE_WITH_CUDA
    cuda::Coverage(rast.triangle.data(), np, out.data());
#endif
    return;
  }
  const std::span<float> o = out.host();
  for (size_t p = 0; p < np; ++p) o[p] = rast.triangle[p] >= 0 ? 1.0f : 0.0f;
}

void UnitVectorLoss(const UnitVectorLossInputs& in, float grad_scale, Span<float> grad_prediction,
                    Span<double> loss_sum) {
  internal::CheckRaster(in.rast);
  const size_t np = in.rast.NumPixels();
  SD_CHECK(in.prediction.size() == 3 * np && in.target.size() == 3 * np && in.mask.size() == np &&
               grad_prediction.size() == 3 * np,
           << "UnitVectorLoss: buffers do not match " << in.rast.width << "x" << in.rast.height);
  SD_CHECK(loss_sum.size() == 1, << "UnitVectorLoss: loss_sum holds one value");
  if (internal::CommonMemory("UnitVectorLoss", in.prediction, in.rast, in.target, in.mask, grad_prediction,
                             loss_sum) == Memory::kDevice) {
    internal::CheckDeviceBuild("UnitVectorLoss");
#if SYNTHDRIVE_WITH_CUDA
    cuda::UnitVectorLoss(in.prediction.data(), in.rast.triangle.data(), in.target.data(), in.mask.data(), np,
                         grad_scale, grad_prediction.data(), loss_sum.data());
#endif
    return;
  }
  const std::span<const float> prediction = in.prediction.host(), target_normals = in.target.host(),
                               mask = in.mask.host();
  const std::span<float> grad = grad_prediction.host();
  std::fill(grad.begin(), grad.end(), 0.0f);
  double sum = 0;
  for (size_t p = 0; p < np; ++p) {
    if (in.rast.triangle[p] < 0 || mask[p] <= 0.5f) continue;
    const Eigen::Vector3f target(&target_normals[3 * p]);
    if (target.squaredNorm() < 0.5f) continue;
    const Eigen::Vector3f n(&prediction[3 * p]);
    const float len = n.norm();
    if (len < 1e-8f) continue;
    const Eigen::Vector3f nh = n / len;
    const Eigen::Vector3f d = nh - target;
    sum += d.squaredNorm();
    // d/dn of |n/|n| - t|^2 = (I - nh nh^T) * 2 d / |n|.
    const Eigen::Vector3f g = grad_scale * 2.0f * (d - nh * nh.dot(d)) / len;
    for (int c = 0; c < 3; ++c) grad[3 * p + c] = g[c];
  }
  loss_sum.host()[0] += sum;
}

void SquaredErrorLoss(Span<const float> prediction_in, Span<const float> target_in, float grad_scale,
                      Span<float> grad_prediction, Span<double> loss_sum) {
  const size_t n = prediction_in.size();
  SD_CHECK(target_in.size() == n && grad_prediction.size() == n,
           << "SquaredErrorLoss: " << n << " predictions, " << target_in.size() << " targets, "
           << grad_prediction.size() << " gradients");
  SD_CHECK(loss_sum.size() == 1, << "SquaredErrorLoss: loss_sum holds one value");
  if (internal::CommonMemory("SquaredErrorLoss", prediction_in, target_in, grad_prediction, loss_sum) ==
      Memory::kDevice) {
    internal::CheckDeviceBuild("SquaredErrorLoss");
#if SYNTHDRIVE_WITH_CUDA
    cuda::SquaredErrorLoss(prediction_in.data(), target_in.data(), n, grad_scale, grad_prediction.data(),
                           loss_sum.data());
#endif
    return;
  }
  const std::span<const float> prediction = prediction_in.host(), target = target_in.host();
  const std::span<float> grad = grad_prediction.host();
  double sum = 0;
  for (size_t p = 0; p < n; ++p) {
    if (target[p] < 0) {
      grad[p] = 0;
      continue;
    }
    const float d = prediction[p] - target[p];
    sum += d * d;
    grad[p] = grad_scale * 2.0f * d;
  }
  loss_sum.host()[0] += sum;
}

}  // namespace sd::raster
