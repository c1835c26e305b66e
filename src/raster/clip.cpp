// ClipFromWorld / TransformToClip / TransformToClipBackward.
//
// With camera coordinates (X, Y, Z) (OpenCV: Z forward) we take w = Z and require
//   u = (x/w + 1) W/2 = fx X/Z + cx   =>   x = (2 fx / W) X + (2 cx / W - 1) Z,
//   v = (y/w + 1) H/2 = fy Y/Z + cy   =>   y = (2 fy / H) Y + (2 cy / H - 1) Z,
// and z = a Z + b with z/w = -1 at Z = near and +1 at Z = far: a = (far + near) / (far - near),
// b = -2 far near / (far - near) (the OpenGL depth mapping, with Z forward instead of -Z).
#include <array>

#include "core/error.h"
#include "raster/internal.h"
#include "raster/raster.h"

namespace sd::raster {

Eigen::Matrix4f ClipFromWorld(const PinholeCamera& camera, const Rigid3d& T_cam_world, float near, float far) {
  SD_CHECK(camera.width > 0 && camera.height > 0, << "camera size " << camera.width << "x" << camera.height);
  SD_CHECK(near > 0 && far > near, << "near " << near << ", far " << far);
  const double W = camera.width, H = camera.height, n = near, f = far;
  Eigen::Matrix4d clip_from_cam = Eigen::Matrix4d::Zero();
  clip_from_cam(0, 0) = 2.0 * camera.fx / W;
  clip_from_cam(0, 2) = 2.0 * camera.cx / W - 1.0;
  clip_from_cam(1, 1) = 2.0 * camera.fy / H;
  clip_from_cam(1, 2) = 2.0 * camera.cy / H - 1.0;
  clip_from_cam(2, 2) = (f + n) / (f - n);
  clip_from_cam(2, 3) = -2.0 * f * n / (f - n);
  clip_from_cam(3, 2) = 1.0;
  return (clip_from_cam * T_cam_world.Matrix()).cast<float>();
}

namespace {

[[maybe_unused]] std::array<float, 16> RowMajor(const Eigen::Matrix4f& M) {
  std::array<float, 16> out;
  for (int r = 0; r < 4; ++r)
    for (int c = 0; c < 4; ++c) out[4 * r + c] = M(r, c);
  return out;
}

}  // namespace

void TransformToClip(Span<const float> positions_in, const Eigen::Matrix4f& M, Span<float> clip_in) {
  SD_CHECK(positions_in.size() % 3 == 0, << "positions: " << positions_in.size());
  const size_t num_vertices = positions_in.size() / 3;
  SD_CHECK(clip_in.size() == 4 * num_vertices, << "clip: " << clip_in.size() << " for " << num_vertices << " vertices");
  if (internal::CommonMemory("TransformToClip", positions_in, clip_in) == Memory::kDevice) {
    internal::CheckDeviceBuild("TransformToClip");
#if SYNTHDRIVE_WITH_CUDA
    cuda::TransformToClip(positions_in.data(), num_vertices, RowMajor(M).data(), clip_in.data());
#endif
    return;
  }
  const std::span<const float> positions = positions_in.host();
  const std::span<float> clip = clip_in.host();
  for (size_t v = 0; v < num_vertices; ++v) {
    const Eigen::Vector4f p(positions[3 * v], positions[3 * v + 1], positions[3 * v + 2], 1.0f);
    const Eigen::Vector4f c = M * p;
    for (int k = 0; k < 4; ++k) clip[4 * v + k] = c[k];
  }
}

void TransformToClipBackward(const Eigen::Matrix4f& M, Span<const float> grad_clip_in, Span<float> grad_positions_in) {
  SD_CHECK(grad_clip_in.size() % 4 == 0, << "grad_clip: " << grad_clip_in.size());
  const size_t num_vertices = grad_clip_in.size() / 4;
  SD_CHECK(grad_positions_in.size() == 3 * num_vertices, << "grad_positions: " << grad_positions_in.size());
  if (internal::CommonMemory("TransformToClipBackward", grad_clip_in, grad_positions_in) == Memory::kDevice) {
    internal::CheckDeviceBuild("TransformToClipBackward");
#if SYNTHDRIVE_WITH_CUDA
    cuda::TransformToClipBackward(RowMajor(M).data(), grad_clip_in.data(), num_vertices, grad_positions_in.data());
#endif
    return;
  }
  const std::span<const float> grad_clip = grad_clip_in.host();
  const std::span<float> grad_positions = grad_positions_in.host();
  // d clip / d p = M's first three columns, so dL/dp = M[:, 0:3]^T dL/dclip.
  const Eigen::Matrix<float, 3, 4> Mt = M.leftCols<3>().transpose();
  for (size_t v = 0; v < num_vertices; ++v) {
    const Eigen::Vector3f g = Mt * Eigen::Map<const Eigen::Vector4f>(&grad_clip[4 * v]);
    for (int c = 0; c < 3; ++c) grad_positions[3 * v + c] += g[c];
  }
}

}  // namespace sd::raster
