#include "raster/normal_mask_loss.h"

#include "core/error.h"
#include "raster/internal.h"

namespace sd::raster {

#if SYNTHDRIVE_WITH_CUDA
struct NormalMaskLoss::Targets {
  cuda::LossTargets* device = nullptr;
  ~Targets() { cuda::FreeLossTargets(device); }
};
#else
struct NormalMaskLoss::Targets {};
#endif

NormalMaskLoss::NormalMaskLoss(const std::vector<NormalMaskView>& views) : num_views_(views.size()) {
  if (!UseCuda()) throw InputError({}, "the device-resident refinement loss needs the CUDA device (--device cuda)");
#if SYNTHDRIVE_WITH_CUDA
  std::vector<cuda::LossViewHost> host(views.size());
  for (size_t i = 0; i < views.size(); ++i) {
    const NormalMaskView& v = views[i];
    const size_t np = static_cast<size_t>(v.width) * v.height;
    SD_CHECK(v.normals.size() == 3 * np && v.mask.size() == np, << "view " << i << ": targets do not match its size");
    for (int r = 0; r < 4; ++r)
      for (int c = 0; c < 4; ++c) host[i].clip_from_world[4 * r + c] = v.clip_from_world(r, c);
    host[i].width = v.width, host[i].height = v.height;
    host[i].normals = v.normals.data(), host[i].mask = v.mask.data();
    host[i].normal_grad_scale = v.normal_grad_scale, host[i].normal_loss_scale = v.normal_loss_scale;
    host[i].mask_grad_scale = v.mask_grad_scale, host[i].mask_loss_scale = v.mask_loss_scale;
  }
  targets_ = std::make_unique<Targets>();
  targets_->device = cuda::UploadLossTargets(host.data(), host.size());
#endif
}

NormalMaskLoss::~NormalMaskLoss() = default;

std::vector<NormalMaskLoss::Terms> NormalMaskLoss::Evaluate(const NormalMaskInputs& in,
                                                            std::span<float> grad_positions,
                                                            std::span<float> grad_normals) {
  const size_t nv = in.positions.size() / 3;
  SD_CHECK(in.positions.size() == 3 * nv && in.vertex_normals.size() == 3 * nv, << "positions / normals sizes");
  SD_CHECK(in.tris.size() % 3 == 0 && in.topology.neighbour.size() == in.tris.size(),
           << "topology built for another mesh");
  // The kernels index positions and normals by these without checks.
  internal::CheckVertexIndices(in.tris, nv);
  SD_CHECK(grad_positions.size() == 3 * nv && grad_normals.size() == 3 * nv, << "gradient buffers hold 3 floats per vertex");
  std::vector<Terms> terms(num_views_);
#if SYNTHDRIVE_WITH_CUDA
  std::vector<double> losses(2 * num_views_);
  const cuda::NormalMaskInputs device_in{in.positions.data(), in.vertex_normals.data(), nv, in.tris.data(),
                                         in.tris.size() / 3, in.topology.neighbour.data()};
  cuda::EvaluateLoss(*targets_->device, device_in, losses.data(), grad_positions.data(), grad_normals.data());
  for (size_t v = 0; v < num_views_; ++v) terms[v] = {losses[2 * v], losses[2 * v + 1]};
#endif
  return terms;
}

}  // namespace sd::raster
