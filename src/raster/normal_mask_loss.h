#pragma once
// Refinement's loss of a set of views, evaluated on the GPU in one device-resident pass per view.
//
// Per view: the vertex normals interpolated over the rasterised mesh against a target normal map
// (|n/|n| - t|^2 where the pixel is covered, inside the target mask and has a target), and the antialiased
// coverage against the target mask (L2). assetgen/refine.cpp evaluates the same two terms on the CPU with the
// ops of raster.h, one op at a time; on CUDA those ops each move their buffers across the bus, which made GPU
// refinement slower than 16 CPU cores (bench/RESULTS.md). Here the targets are uploaded once, an evaluation
// uploads positions and vertex normals and downloads the gradients, and the raster kernels between run on
// the same device buffers. The per-pixel and per-pair arithmetic is shared.h's, as in the ops; the loss
// terms follow refine.cpp's (raster_cuda_test checks both against a CPU evaluation with the ops).
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include <Eigen/Core>

#include "raster/raster.h"

namespace sd::raster {

struct NormalMaskView {
  Eigen::Matrix4f clip_from_world;
  int width = 0, height = 0;
  std::vector<float> normals;  // 3 per pixel, world frame; a pixel with |t|^2 < 0.5 has no target
  std::vector<float> mask;     // 1 per pixel, 0..1; negative: unknown (past the source image's border), no term
  // Per-term factors: the gradient of the loss is grad_scale * d(sum over pixels)/dx and the reported term
  // loss_scale * sum; 0 grad_scale switches a term off.
  float normal_grad_scale = 0, normal_loss_scale = 0, mask_grad_scale = 0, mask_loss_scale = 0;
};

// The mesh a NormalMaskLoss evaluates.
struct NormalMaskInputs {
  std::span<const float> positions;       // 3 per vertex, world frame
  std::span<const float> vertex_normals;  // 3 per vertex, world frame
  std::span<const int32_t> tris;          // 3 per triangle
  const EdgeTopology& topology;           // BuildEdgeTopology(tris, ...)
};

class NormalMaskLoss {
 public:
  // Uploads the targets. InputError when the ops cannot run on CUDA (UseCuda()).
  explicit NormalMaskLoss(const std::vector<NormalMaskView>& views);
  ~NormalMaskLoss();
  NormalMaskLoss(const NormalMaskLoss&) = delete;
  NormalMaskLoss& operator=(const NormalMaskLoss&) = delete;

  struct Terms {
    double normal = 0, mask = 0;
  };
  // Per view: the terms. The gradients with respect to the positions and the vertex normals (3 floats per
  // vertex each, overwritten) are the views' shares summed in view order, each rounded to float first, as
  // refine.cpp sums them on the CPU. The connectivity (tris, topology) is uploaded only when it differs from
  // the last evaluation's: refinement changes it once per remeshing pass.
  std::vector<Terms> Evaluate(const NormalMaskInputs& in, std::span<float> grad_positions,
                              std::span<float> grad_normals);
  size_t num_views() const { return num_views_; }

 private:
  struct Targets;
  std::unique_ptr<Targets> targets_;
  size_t num_views_ = 0;
};

}  // namespace sd::raster
