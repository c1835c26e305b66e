#include "assetgen/texture_eval.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"
#include "core/parallel.h"
#include "raster/raster.h"

namespace sd {
namespace {

constexpr double kC1 = 0.01 * 0.01, kC2 = 0.03 * 0.03;

float Wrap(float x) { return x - std::floor(x); }  // glTF's default sampler repeats

ImageF ToSrgbValues(const ImageF& linear) {
  ImageF out(linear.width(), linear.height(), linear.channels());
  for (size_t i = 0; i < linear.size(); ++i) out.data()[i] = LinearToSrgb(std::clamp(linear.data()[i], 0.0f, 1.0f));
  return out;
}

ImageF Luma(const ImageF& srgb) {
  ImageF y(srgb.width(), srgb.height(), 1);
  for (int j = 0; j < srgb.height(); ++j)
    for (int i = 0; i < srgb.width(); ++i) {
      const float* p = srgb.pixel(i, j);
      y.at(i, j) = 0.2126f * p[0] + 0.7152f * p[1] + 0.0722f * p[2];
    }
  return y;
}

// Separable 11-tap Gaussian (sigma 1.5), clamped at the border.
ImageF Gauss11(const ImageF& in) {
  float k[11], sum = 0;
  for (int i = -5; i <= 5; ++i) sum += k[i + 5] = std::exp(-0.5f * i * i / 2.25f);
  for (float& v : k) v /= sum;
  const int w = in.width(), h = in.height();
  ImageF tmp(w, h, 1), out(w, h, 1);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      float acc = 0;
      for (int i = -5; i <= 5; ++i) acc += k[i + 5] * in.at(std::clamp(x + i, 0, w - 1), y);
      tmp.at(x, y) = acc;
    }
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      float acc = 0;
      for (int i = -5; i <= 5; ++i) acc += k[i + 5] * tmp.at(x, std::clamp(y + i, 0, h - 1));
      out.at(x, y) = acc;
    }
  return out;
}

void CheckPair(const ImageF& a, const ImageF& b, const ImageF& weight) {
  SD_CHECK(a.width() == b.width() && a.height() == b.height() && a.channels() == 3 && b.channels() == 3);
  SD_CHECK(weight.width() == a.width() && weight.height() == a.height() && weight.channels() == 1);
}

}  // namespace

AlbedoRender RenderAlbedo(const TriangleMesh& mesh, const ViewCamera& view, int ss) {
  const PinholeCamera cam = Supersampled(view.camera, ss);
  const raster::RasterBuffer rast = RasterizeView(mesh, cam, view.T_world_cam, BoundingSphereOf(mesh.positions));

  const int w = view.camera.width, h = view.camera.height;
  AlbedoRender out{ImageF(w, h, 3), ImageF(w, h, 1)};
  ParallelRows(0, h, [&](int y) {
    for (int x = 0; x < w; ++x) {
      Eigen::Vector3f sum = Eigen::Vector3f::Zero();
      const int covered = VisitCoveredSamples(rast, cam.width, x, y, ss, [&](size_t p) {
        const int32_t t = rast.triangle[p];
        const Eigen::Vector3i& f = mesh.faces[t];
        const float b0 = rast.bary[2 * p], b1 = rast.bary[2 * p + 1], b2 = 1 - b0 - b1;
        Eigen::Vector3f c = Eigen::Vector3f::Ones();
        const int mi = mesh.MaterialOf(t);
        if (mi >= 0 && mi < static_cast<int>(mesh.materials.size())) {
          const Material& m = mesh.materials[mi];
          c = m.base_color_factor.head<3>();
          if (m.base_color_texture && !mesh.uvs.empty()) {
            const Eigen::Vector2f uv = b0 * mesh.uvs[f[0]] + b1 * mesh.uvs[f[1]] + b2 * mesh.uvs[f[2]];
            const ImageU8& tex = *m.base_color_texture;
            float s[4] = {0, 0, 0, 0};
            SampleBilinear(tex, Wrap(uv.x()) * tex.width(), Wrap(uv.y()) * tex.height(), s);
            for (int k = 0; k < 3; ++k) c[k] *= SrgbToLinear(s[tex.channels() >= 3 ? k : 0] / 255.0f);
          }
        }
        if (!mesh.colors.empty())
          c = c.cwiseProduct((b0 * mesh.colors[f[0]] + b1 * mesh.colors[f[1]] + b2 * mesh.colors[f[2]]).head<3>());
        sum += c;
      });
      out.mask.at(x, y) = static_cast<float>(covered) / (ss * ss);
      // Pixels are averaged over their samples, background counting as black (what a renderer composites).
      for (int k = 0; k < 3; ++k) out.color.at(x, y, k) = sum[k] / (ss * ss);
    }
  });
  return out;
}

std::vector<ViewCamera> HeldOutViews(const Eigen::Vector3f& centre, float radius, int image_size) {
  std::vector<ViewCamera> views;
  for (int i = 0; i < 8; ++i) {
    ViewCamera v = OrbitCamera("heldout_" + std::to_string(i), 45.0 * i, i % 2 == 0 ? 35.0 : 0.0, kRigDistance, 30.0,
                               image_size, image_size);
    v.T_world_cam.translation = v.T_world_cam.translation * radius + centre.cast<double>();
    views.push_back(v);
  }
  return views;
}

double MaskedPsnr(const ImageF& a, const ImageF& b, const ImageF& weight) {
  CheckPair(a, b, weight);
  double sum = 0;
  size_t n = 0;
  for (int y = 0; y < a.height(); ++y)
    for (int x = 0; x < a.width(); ++x) {
      if (weight.at(x, y) <= 0.5f) continue;
      for (int c = 0; c < 3; ++c) {
        const double d = a.at(x, y, c) - b.at(x, y, c);
        sum += d * d;
        ++n;
      }
    }
  if (n == 0) return 0;
  const double mse = sum / static_cast<double>(n);
  return mse <= 1e-12 ? 120.0 : 10.0 * std::log10(1.0 / mse);
}

double MaskedSsim(const ImageF& a, const ImageF& b, const ImageF& weight) {
  CheckPair(a, b, weight);
  const ImageF x = Luma(a), y = Luma(b);
  ImageF xx(x.width(), x.height(), 1), yy = xx, xy = xx;
  for (size_t i = 0; i < x.size(); ++i) {
    xx.data()[i] = x.data()[i] * x.data()[i];
    yy.data()[i] = y.data()[i] * y.data()[i];
    xy.data()[i] = x.data()[i] * y.data()[i];
  }
  const ImageF mx = Gauss11(x), my = Gauss11(y), sxx = Gauss11(xx), syy = Gauss11(yy), sxy = Gauss11(xy);
  double sum = 0;
  size_t n = 0;
  for (size_t i = 0; i < x.size(); ++i) {
    if (weight.data()[i] <= 0.5f) continue;
    const double ux = mx.data()[i], uy = my.data()[i];
    const double vx = sxx.data()[i] - ux * ux, vy = syy.data()[i] - uy * uy, cxy = sxy.data()[i] - ux * uy;
    sum += ((2 * ux * uy + kC1) * (2 * cxy + kC2)) / ((ux * ux + uy * uy + kC1) * (vx + vy + kC2));
    ++n;
  }
  return n == 0 ? 0 : sum / static_cast<double>(n);
}

TextureMetrics CompareTextures(const TriangleMesh& pred, const TriangleMesh& gt, int image_size) {
  if (pred.NumFaces() == 0) throw InputError({}, "texture comparison: the predicted mesh has no triangles");
  if (gt.NumFaces() == 0) throw InputError({}, "texture comparison: the ground-truth mesh has no triangles");
  const BoundingSphere sphere = BoundingSphereOf(gt.positions);
  TextureMetrics m;
  double sum_sq = 0, count = 0, ssim_sum = 0;
  for (const ViewCamera& v : HeldOutViews(sphere.centre, sphere.radius, image_size)) {
    const AlbedoRender rp = RenderAlbedo(pred, v), rg = RenderAlbedo(gt, v);
    const ImageF a = ToSrgbValues(rp.color), b = ToSrgbValues(rg.color);
    const double psnr = MaskedPsnr(a, b, rg.mask);
    const double ssim = MaskedSsim(a, b, rg.mask);
    m.psnr_per_view.push_back(psnr);
    m.ssim_per_view.push_back(ssim);
    // Pool the squared error over all views' object pixels for the overall PSNR.
    for (int y = 0; y < a.height(); ++y)
      for (int x = 0; x < a.width(); ++x) {
        if (rg.mask.at(x, y) <= 0.5f) continue;
        for (int c = 0; c < 3; ++c) {
          const double d = a.at(x, y, c) - b.at(x, y, c);
          sum_sq += d * d;
          count += 1;
        }
      }
    ssim_sum += ssim;
  }
  const double mse = count > 0 ? sum_sq / count : 1.0;
  m.psnr = mse <= 1e-12 ? 120.0 : 10.0 * std::log10(1.0 / mse);
  m.ssim = ssim_sum / static_cast<double>(m.ssim_per_view.size());
  return m;
}

std::string DescribeTextureProtocol() {
  return "8 held-out views around the GT's bounding sphere (azimuth 0..315 deg step 45, elevation +35/0 "
         "alternating, 30 deg vertical FOV, distance 4 radii; none is a Zero123++ rig view), unlit base colour "
         "(texture x factor x vertex colour), 2x2 supersampled, compared in sRGB [0,1] over pixels where the GT "
         "covers > 0.5. PSNR pooled over all views' object pixels and channels; SSIM (Wang 2004) on Rec.709 luma, "
         "11x11 Gaussian window sigma 1.5, C1 = 0.01^2, C2 = 0.03^2, averaged over the same pixels, then views.";
}

}  // namespace sd
