#pragma once
// Texture quality against ground truth: both meshes rendered (unlit base colour) at held-out views, compared
// by PSNR and SSIM inside the ground truth's silhouette. The protocol (printed with every result):
//  - Views: 8 cameras around the ground truth's bounding sphere (HeldOutViews), azimuth 0°, 45°, …, 315°,
//    elevation alternating +35° / 0°, 30° vertical field of view at 4 radii — none coincides with a
//    Zero123++ rig view (azimuth 30° + k·60°, elevation +20° / -10°), so nothing is scored on the views the
//    texture was fused from.
//  - Images: base colour = texture × material factor × vertex colour, no lighting, 2×2 supersampled,
//    compared in sRGB [0, 1].
//  - PSNR: 10 log10(1 / MSE) over the pixels where the ground truth's coverage is > 0.5, all three channels,
//    pooled over the views.
//  - SSIM: Wang et al. 2004 on luma (Rec. 709 weights of the sRGB values), 11×11 Gaussian window σ = 1.5,
//    C1 = (0.01)², C2 = (0.03)², background set to 0 in both images, the SSIM map averaged over the same
//    pixels, then over the views.
#include <string>
#include <vector>

#include "assetgen/views.h"
#include "core/image.h"
#include "core/mesh.h"

namespace sd {

struct AlbedoRender {
  ImageF color;  // 3 channels, linear RGB, 0 where empty
  ImageF mask;   // 1 channel coverage 0..1
};
// Unlit base colour of a mesh at a camera (raster ops, `supersample`² samples per pixel).
AlbedoRender RenderAlbedo(const TriangleMesh& mesh, const ViewCamera& camera, int supersample = 2);

// The 8 held-out cameras described above, around the sphere (centre, radius).
std::vector<ViewCamera> HeldOutViews(const Eigen::Vector3f& centre, float radius, int image_size = 320);

struct TextureMetrics {
  double psnr = 0;  // dB
  double ssim = 0;
  std::vector<double> psnr_per_view, ssim_per_view;
};
// InputError when either mesh has no faces.
TextureMetrics CompareTextures(const TriangleMesh& pred, const TriangleMesh& gt, int image_size = 320);
std::string DescribeTextureProtocol();

// Image-level pieces, exposed for tests: PSNR and mean SSIM of two 3-channel sRGB-valued images over the
// pixels where weight > 0.5.
double MaskedPsnr(const ImageF& a, const ImageF& b, const ImageF& weight);
double MaskedSsim(const ImageF& a, const ImageF& b, const ImageF& weight);

}  // namespace sd
