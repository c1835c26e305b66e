#include "synth/environment.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <exception>
#include <limits>
#include <optional>

#include <Eigen/Dense>

#include "core/error.h"
#include "core/stats.h"
#include "core/log.h"
#include "core/parallel.h"
#include "synth/real_shadows.h"

namespace sd {
namespace {

constexpr double kDeg = M_PI / 180.0;

float Luma(const float* rgb) { return LinearLuminance(rgb); }
float Luma(const Eigen::Vector3f& rgb) { return LinearLuminance(rgb.data()); }

// The luminance of a map's radiance; null for an empty map.
std::shared_ptr<const ImageF> RadianceLuminance(const ImageF& radiance) {
  if (radiance.empty()) return nullptr;
  auto luminance = std::make_shared<ImageF>(radiance.width(), radiance.height(), 1);
  for (int v = 0; v < luminance->height(); ++v)
    for (int u = 0; u < luminance->width(); ++u) luminance->at(u, v) = Luma(radiance.pixel(u, v));
  return luminance;
}

// Camera image area-averaged to about the map's angular resolution, with the share of clipped pixels.
struct Downsampled {
  int factor = 1;
  ImageF linear;     // 3 channels
  ImageF saturated;  // 1 channel, share of source pixels with any channel >= saturated_level
};

Downsampled Downsample(const ImageU8& img, int factor, int saturated_level) {
  Downsampled d;
  d.factor = factor;
  const int w = img.width() / factor, h = img.height() / factor;
  d.linear = ImageF(w, h, 3, 0.0f);
  d.saturated = ImageF(w, h, 1, 0.0f);
  const float inv = 1.0f / (factor * factor);
  // SrgbByteToLinear's values, read without a call per byte (26 million of them for a surround rig).
  static const std::array<float, 256> to_linear = [] {
    std::array<float, 256> t{};
    for (int i = 0; i < 256; ++i) t[static_cast<size_t>(i)] = SrgbByteToLinear(static_cast<uint8_t>(i));
    return t;
  }();
  const size_t step = static_cast<size_t>(img.channels());
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      float acc[3] = {0, 0, 0};
      float sat = 0;
      for (int j = 0; j < factor; ++j) {
        const uint8_t* p = img.pixel(x * factor, y * factor + j);
        for (int i = 0; i < factor; ++i, p += step) {
          bool s = false;
          for (int c = 0; c < 3; ++c) {
            acc[c] += to_linear[p[c]];
            s = s || p[c] >= saturated_level;
          }
          sat += s ? 1.0f : 0.0f;
        }
      }
      for (int c = 0; c < 3; ++c) d.linear.at(x, y, c) = acc[c] * inv;
      d.saturated.at(x, y) = sat * inv;
    }
  return d;
}

// One camera projected on the map: linear colour, blend weight (0 = not seen), clipped share.
struct Layer {
  ImageF color, weight, saturated;
};

// directions: LatLongDirection of each map pixel's centre, row by row (the same for every camera).
Layer ProjectCamera(const CameraSensor& cam, const Downsampled& d, int W, int H,
                    const std::vector<Eigen::Vector3d>& directions) {
  Layer l{ImageF(W, H, 3, 0.0f), ImageF(W, H, 1, 0.0f), ImageF(W, H, 1, 0.0f)};
  const Eigen::Matrix3d R_cam_ego = cam.T_ego_cam.rotation.conjugate().toRotationMatrix();
  const PinholeCamera& K = cam.intrinsics;
  const bool distorted = !K.distortion.IsZero();
  for (int v = 0; v < H; ++v)
    for (int u = 0; u < W; ++u) {
      const Eigen::Vector3d dc = R_cam_ego * directions[static_cast<size_t>(v) * W + u];
      if (dc.z() < 0.05) continue;
      const auto uv = K.Project(dc, 1e-6);
      if (!uv || !K.InImage(*uv)) continue;
      // Strong distortion folds far off-axis rays back into the image: keep only rays that round-trip.
      if (distorted && K.RayDirection(*uv).dot(dc.normalized()) < 0.9995) continue;
      const double xn = 2.0 * uv->x() / K.width - 1.0, yn = 2.0 * uv->y() / K.height - 1.0;
      const double w = (1 - xn * xn) * (1 - yn * yn);
      if (w <= 0) continue;
      float rgb[3], s;
      SampleBilinear(d.linear, uv->x() / d.factor, uv->y() / d.factor, rgb);
      SampleBilinear(d.saturated, uv->x() / d.factor, uv->y() / d.factor, &s);
      for (int c = 0; c < 3; ++c) l.color.at(u, v, c) = rgb[c];
      l.weight.at(u, v) = static_cast<float>(w);
      l.saturated.at(u, v) = s;
    }
  return l;
}

struct PairStats {
  int i, j;
  std::vector<std::array<double, 3>> log_ratio;  // log I_j - log I_i per channel
  std::vector<std::array<float, 6>> values;      // rgb_i, rgb_j for the seam error
};

// Seam error: median relative luminance difference over all overlap pixels.
double SeamError(const std::vector<PairStats>& pairs, const std::vector<Eigen::Vector3f>& gains) {
  std::vector<double> e;
  for (const auto& p : pairs)
    for (const auto& v : p.values) {
      const Eigen::Vector3f a = Eigen::Vector3f(v[0], v[1], v[2]).cwiseProduct(gains[p.i]);
      const Eigen::Vector3f b = Eigen::Vector3f(v[3], v[4], v[5]).cwiseProduct(gains[p.j]);
      const double ya = Luma(a), yb = Luma(b);
      e.push_back(std::abs(ya - yb) / (0.5 * (ya + yb)));
    }
  return Median(e);
}

// CIE general sky (ISO 15469) gradation and indicatrix functions.
double CieGradation(double cos_z, double a, double b) { return cos_z <= 1e-6 ? 1.0 : 1.0 + a * std::exp(b / cos_z); }
double CieIndicatrix(double chi, double c, double d, double e) {
  const double cc = std::cos(chi);
  return 1.0 + c * (std::exp(d * chi) - std::exp(d * M_PI / 2)) + e * cc * cc;
}

// Connected components of fully saturated pixels above the horizon; a sun candidate is small and round.
struct Blob {
  double area_sr = 0;
  Eigen::Vector3d dir = Eigen::Vector3d::Zero();
  double fill = 0;
  double halo = 0;  // mean 8-bit luma in the ring 1.5-3 equivalent radii around the blob
};

std::vector<Blob> SaturatedBlobs(const CameraSensor& cam, const ImageU8& img, int level) {
  const int W = img.width(), H = img.height();
  std::vector<int> label(static_cast<size_t>(W) * H, -1);
  auto sat = [&](int x, int y) {
    const uint8_t* p = img.pixel(x, y);
    return p[0] >= level && p[1] >= level && p[2] >= level;
  };
  const double px_sr = 1.0 / (cam.intrinsics.fx * cam.intrinsics.fy);
  std::vector<Blob> blobs;
  std::vector<int> stack;
  for (int y0 = 0; y0 < H; ++y0)
    for (int x0 = 0; x0 < W; ++x0) {
      if (label[static_cast<size_t>(y0) * W + x0] >= 0 || !sat(x0, y0)) continue;
      const int id = static_cast<int>(blobs.size());
      Eigen::Vector3d sum = Eigen::Vector3d::Zero();
      Eigen::Vector2d pix_sum = Eigen::Vector2d::Zero();
      double area = 0, pix_count = 0;
      bool touches_border = false;
      std::vector<Eigen::Vector3d> dirs;
      stack.assign(1, y0 * W + x0);
      label[static_cast<size_t>(y0) * W + x0] = id;
      while (!stack.empty()) {
        const int q = stack.back();
        stack.pop_back();
        const int x = q % W, y = q / W;
        const Eigen::Vector3d d = cam.T_ego_cam.rotation * cam.intrinsics.RayDirection({x + 0.5, y + 0.5});
        sum += d;
        pix_sum += Eigen::Vector2d(x + 0.5, y + 0.5);
        pix_count += 1;
        area += px_sr * std::pow(d.dot(cam.T_ego_cam.rotation * Eigen::Vector3d::UnitZ()), 3);
        if (dirs.size() < 200000) dirs.push_back(d);
        if (x == 0 || y == 0 || x == W - 1 || y == H - 1) touches_border = true;
        const int nb[4][2] = {{1, 0}, {-1, 0}, {0, 1}, {0, -1}};
        for (const auto& o : nb) {
          const int nx = x + o[0], ny = y + o[1];
          if (nx < 0 || ny < 0 || nx >= W || ny >= H) continue;
          int& l = label[static_cast<size_t>(ny) * W + nx];
          if (l < 0 && sat(nx, ny)) {
            l = id;
            stack.push_back(ny * W + nx);
          }
        }
      }
      Blob b;
      b.area_sr = area;
      b.dir = sum.normalized();
      double r_max = 0;
      for (const auto& d : dirs) r_max = std::max(r_max, std::acos(std::clamp(d.dot(b.dir), -1.0, 1.0)));
      b.fill = r_max > 0 ? area / (M_PI * r_max * r_max) : 1.0;
      if (touches_border) b.fill = 0;  // cut by the frame: shape unknown, and a clipped sky reaches the border
      // A clipped sun sits in its own glare on a bright sky; a white sign or a lamp sits on anything.
      const Eigen::Vector2d c = pix_sum / pix_count;
      const double r_px = std::sqrt(pix_count / M_PI);
      double ring = 0, ring_n = 0;
      const int R = static_cast<int>(std::ceil(3 * r_px)) + 1;
      for (int y = std::max(0, static_cast<int>(c.y()) - R); y < std::min(H, static_cast<int>(c.y()) + R); ++y)
        for (int x = std::max(0, static_cast<int>(c.x()) - R); x < std::min(W, static_cast<int>(c.x()) + R); ++x) {
          const double r = std::hypot(x + 0.5 - c.x(), y + 0.5 - c.y());
          if (r < 1.5 * r_px || r > 3 * r_px) continue;
          const uint8_t* p = img.pixel(x, y);
          ring += 0.2126 * p[0] + 0.7152 * p[1] + 0.0722 * p[2];
          ring_n += 1;
        }
      b.halo = ring_n > 0 ? ring / ring_n : 0;
      blobs.push_back(b);
    }
  return blobs;
}

}  // namespace

Eigen::Vector3d LatLongDirection(double u, double v, int width, int height) {
  const double phi = M_PI - 2 * M_PI * u / width, el = M_PI / 2 - M_PI * v / height;
  return {std::cos(el) * std::cos(phi), std::cos(el) * std::sin(phi), std::sin(el)};
}

Eigen::Vector2d LatLongPixel(const Eigen::Vector3d& d, int width, int height) {
  const Eigen::Vector3d n = d.normalized();
  const double phi = std::atan2(n.y(), n.x()), el = std::asin(std::clamp(n.z(), -1.0, 1.0));
  double u = (M_PI - phi) / (2 * M_PI) * width;
  if (u >= width) u -= width;
  return {u, (M_PI / 2 - el) / M_PI * height};
}

double CieClearSky(const Eigen::Vector3d& dir, const Eigen::Vector3d& sun) {
  // Type 12, "CIE standard clear sky, low luminance turbidity": a=-1, b=-0.32, c=10, d=-3, e=0.45.
  const double cz = std::max(0.0, dir.z()), cs = std::clamp(sun.z(), 0.0, 1.0);
  const double chi = std::acos(std::clamp(dir.dot(sun), -1.0, 1.0));
  const double zs = std::acos(cs);
  return CieIndicatrix(chi, 10, -3, 0.45) * CieGradation(cz, -1, -0.32) /
         (CieIndicatrix(zs, 10, -3, 0.45) * CieGradation(1.0, -1, -0.32));
}

double CieOvercastSky(const Eigen::Vector3d& dir) {
  // Type 1, "CIE standard overcast sky": a=4, b=-0.7, indicatrix 1.
  return CieGradation(std::max(0.0, dir.z()), 4, -0.7) / CieGradation(1.0, 4, -0.7);
}

Eigen::Vector3f SkyModel::Radiance(const Eigen::Vector3d& dir) const {
  if (dir.z() <= 0) return Eigen::Vector3f::Zero();
  return clear * static_cast<float>(CieClearSky(dir, sun_direction)) + overcast * static_cast<float>(CieOvercastSky(dir));
}

Eigen::Vector3f EnvironmentMap::Lookup(const Eigen::Vector3d& dir) const {
  const Eigen::Vector2d uv = LatLongPixel(dir, width(), height());
  float rgb[3];
  SampleBilinear(radiance, uv.x(), uv.y(), rgb);
  return {rgb[0], rgb[1], rgb[2]};
}

Eigen::Vector3f EnvironmentMap::SkyIrradianceUp() const {
  Eigen::Vector3d e = Eigen::Vector3d::Zero();
  const int W = width(), H = height();
  for (int v = 0; v < H / 2; ++v) {
    const Eigen::Vector3d d = LatLongDirection(0.5, v + 0.5, W, H);
    const double dw = (2 * M_PI / W) * (M_PI / H) * std::sqrt(std::max(0.0, 1 - d.z() * d.z()));
    for (int u = 0; u < W; ++u)
      for (int c = 0; c < 3; ++c) e[c] += radiance.at(u, v, c) * d.z() * dw;
  }
  return e.cast<float>();
}

std::optional<Eigen::Vector3d> DetectSunInImages(const Frame& frame, const std::vector<ImageU8>& images, int level,
                                                 std::string* channel) {
  std::optional<Eigen::Vector3d> best;
  double best_area = 0;
  for (size_t k = 0; k < frame.cameras.size() && k < images.size(); ++k) {
    for (const Blob& b : SaturatedBlobs(frame.cameras[k], images[k], level)) {
      // The sun disk is 0.5 deg; with glare a clipped sun covers ~0.5-6 deg across.
      const double r_eq = std::sqrt(b.area_sr / M_PI) / kDeg;
      if (b.dir.z() < std::sin(3 * kDeg) || r_eq < 0.15 || r_eq > 4.0 || b.fill < 0.7 || b.halo < 190) continue;
      if (b.area_sr > best_area) {
        best_area = b.area_sr;
        best = b.dir;
        if (channel) *channel = frame.cameras[k].channel;
      }
    }
  }
  return best;
}

EnvironmentMap BuildEnvironmentMap(const Frame& frame, const std::vector<ImageU8>& images, const EnvironmentOptions& options) {
  SD_CHECK(images.size() == frame.cameras.size(), << images.size() << " images for " << frame.cameras.size() << " cameras");
  SD_CHECK(options.width >= 16 && options.width % 2 == 0, << options.width);
  const int W = options.width, H = W / 2;
  const size_t nc = frame.cameras.size();
  for (size_t k = 0; k < nc; ++k)
    if (images[k].width() != frame.cameras[k].intrinsics.width || images[k].height() != frame.cameras[k].intrinsics.height ||
        images[k].channels() < 3)
      throw InputError(frame.cameras[k].image_path, Msg() << "image is " << images[k].width() << "x" << images[k].height() << "x"
                                                          << images[k].channels() << " but the calibration says "
                                                          << frame.cameras[k].intrinsics.width << "x"
                                                          << frame.cameras[k].intrinsics.height << " RGB");

  // Per-camera layers on the map.
  // The map's loops below give each of its pixels from that pixel alone: rows in parallel, the same result.
  std::vector<Eigen::Vector3d> directions(static_cast<size_t>(W) * H);
  ParallelRows(0, H, [&](int v) {
    for (int u = 0; u < W; ++u) directions[static_cast<size_t>(v) * W + u] = LatLongDirection(u + 0.5, v + 0.5, W, H);
  });
  std::vector<Layer> layers(nc);
  ParallelForRethrow(0, nc, [&](size_t k) {
    const auto& cam = frame.cameras[k];
    const int factor = std::max(1, static_cast<int>(std::lround(cam.intrinsics.fx * 2 * M_PI / W)));
    layers[k] = ProjectCamera(cam, Downsample(images[k], factor, options.saturated_level), W, H, directions);
  });

  // Overlaps -> relative gains.
  std::vector<PairStats> pairs;
  const float dark = 2e-3f;
  for (size_t i = 0; i < nc; ++i)
    for (size_t j = i + 1; j < nc; ++j) {
      PairStats p{static_cast<int>(i), static_cast<int>(j), {}, {}};
      for (int v = 0; v < H; ++v) {
        const double el = M_PI / 2 - M_PI * (v + 0.5) / H;
        if (el < options.min_overlap_elevation_deg * kDeg) break;
        for (int u = 0; u < W; ++u) {
          if (layers[i].weight.at(u, v) <= 0 || layers[j].weight.at(u, v) <= 0) continue;
          if (layers[i].saturated.at(u, v) > 0 || layers[j].saturated.at(u, v) > 0) continue;
          const float* a = layers[i].color.pixel(u, v);
          const float* b = layers[j].color.pixel(u, v);
          if (std::min({a[0], a[1], a[2], b[0], b[1], b[2]}) < dark) continue;
          p.log_ratio.push_back({std::log(b[0] / a[0]), std::log(b[1] / a[1]), std::log(b[2] / a[2])});
          p.values.push_back({a[0], a[1], a[2], b[0], b[1], b[2]});
        }
      }
      if (p.values.size() >= 20) pairs.push_back(std::move(p));
    }
  size_t ref = 0;
  for (size_t k = 0; k < nc; ++k)
    if (frame.cameras[k].channel == options.reference_channel) ref = k;
  std::vector<Eigen::Vector3f> gains(nc, Eigen::Vector3f::Ones());
  if (options.estimate_gains && !pairs.empty()) {
    for (int c = 0; c < 3; ++c) {
      Eigen::MatrixXd A = Eigen::MatrixXd::Zero(static_cast<Eigen::Index>(nc), static_cast<Eigen::Index>(nc));
      Eigen::VectorXd rhs = Eigen::VectorXd::Zero(static_cast<Eigen::Index>(nc));
      for (const auto& p : pairs) {
        std::vector<double> r;
        for (const auto& l : p.log_ratio) r.push_back(l[c]);
        const double m = Median(r);
        const double w = std::sqrt(static_cast<double>(p.log_ratio.size()));  // more overlap, more trust (sub-linear)
        // x_i - x_j = m
        A(p.i, p.i) += w, A(p.j, p.j) += w, A(p.i, p.j) -= w, A(p.j, p.i) -= w;
        rhs(p.i) += w * m, rhs(p.j) -= w * m;
      }
      const double anchor = 1e6;
      A(static_cast<Eigen::Index>(ref), static_cast<Eigen::Index>(ref)) += anchor;
      // Cameras without any overlap keep gain 1 (a weak prior towards 0).
      for (size_t k = 0; k < nc; ++k) A(static_cast<Eigen::Index>(k), static_cast<Eigen::Index>(k)) += 1e-3;
      const Eigen::VectorXd x = A.ldlt().solve(rhs);
      for (size_t k = 0; k < nc; ++k) gains[k][c] = static_cast<float>(std::exp(x(static_cast<Eigen::Index>(k))));
    }
  }

  EnvironmentMap map;
  map.seam_error_before = SeamError(pairs, std::vector<Eigen::Vector3f>(nc, Eigen::Vector3f::Ones()));
  map.seam_error_after = SeamError(pairs, gains);
  for (const auto& p : pairs) map.overlap_pixels += static_cast<int>(p.values.size());
  for (size_t k = 0; k < nc; ++k) {
    CameraGain g;
    g.channel = frame.cameras[k].channel;
    g.exposure = Luma(gains[k]);
    g.white_balance = gains[k] / g.exposure;
    map.gains.push_back(g);
  }

  // Blend.
  map.radiance = ImageF(W, H, 3, 0.0f);
  map.coverage = ImageF(W, H, 1, 0.0f);
  ParallelRows(0, H, [&](int v) {
    for (int u = 0; u < W; ++u) {
      double acc[3] = {0, 0, 0}, wsum = 0;
      for (size_t k = 0; k < nc; ++k) {
        const float w = layers[k].weight.at(u, v);
        if (w <= 0) continue;
        for (int c = 0; c < 3; ++c) acc[c] += w * layers[k].color.at(u, v, c) * gains[k][c];
        wsum += w;
      }
      map.coverage.at(u, v) = static_cast<float>(wsum);
      if (wsum > 0)
        for (int c = 0; c < 3; ++c) map.radiance.at(u, v, c) = static_cast<float>(acc[c] / wsum);
    }
  });

  // Sun direction.
  std::string sun_channel;
  std::optional<Eigen::Vector3d> sun_img;
  if (options.detect_sun_in_images) sun_img = DetectSunInImages(frame, images, options.saturated_level, &sun_channel);
  if (sun_img) {
    map.sun_direction = *sun_img;
    map.sun_source = "image (" + sun_channel + ")";
  } else {
    map.sun_direction = options.ephemeris_sun_ego ? options.ephemeris_sun_ego->normalized() : Eigen::Vector3d::UnitZ();
    map.sun_source = options.ephemeris_sun_ego ? "ephemeris" : "default (overhead)";
  }
  map.sun_angular_radius_rad = options.sun_angular_radius_deg * kDeg;

  // Sky model fitted to the seen sky: bright, not greenish/brownish pixels above 3 deg.
  std::vector<std::pair<Eigen::Vector3d, Eigen::Vector3f>> sky_px;
  {
    std::vector<double> lum;
    for (int v = 0; v < H / 2; ++v) {
      const double el = M_PI / 2 - M_PI * (v + 0.5) / H;
      if (el < 3 * kDeg) continue;
      for (int u = 0; u < W; ++u)
        if (map.coverage.at(u, v) > 0.05f) lum.push_back(Luma(map.radiance.pixel(u, v)));
    }
    std::sort(lum.begin(), lum.end());
    const double bright = lum.empty() ? 0 : lum[static_cast<size_t>(0.95 * (lum.size() - 1))];
    for (int v = 0; v < H / 2; ++v) {
      const double el = M_PI / 2 - M_PI * (v + 0.5) / H;
      if (el < 3 * kDeg) continue;
      for (int u = 0; u < W; ++u) {
        if (map.coverage.at(u, v) <= 0.05f) continue;
        const float* p = map.radiance.pixel(u, v);
        if (Luma(p) < 0.5 * bright || p[2] < 0.85f * p[0]) continue;
        sky_px.push_back({LatLongDirection(u + 0.5, v + 0.5, W, H), Eigen::Vector3f(p[0], p[1], p[2])});
      }
    }
  }
  map.sky.sun_direction = map.sun_direction;
  if (sky_px.size() >= 20) {
    // Per channel: min |s f_clear + t f_overcast - L|^2 with s, t >= 0 (2 unknowns: try the free solution,
    // then each one alone).
    double aa = 0, ab = 0, bb = 0;
    Eigen::Vector3d ay = Eigen::Vector3d::Zero(), by = Eigen::Vector3d::Zero();
    for (const auto& [d, L] : sky_px) {
      const double fa = CieClearSky(d, map.sun_direction), fb = CieOvercastSky(d);
      aa += fa * fa, ab += fa * fb, bb += fb * fb;
      ay += fa * L.cast<double>(), by += fb * L.cast<double>();
    }
    for (int c = 0; c < 3; ++c) {
      const double det = aa * bb - ab * ab;
      double s = det > 1e-12 ? (bb * ay[c] - ab * by[c]) / det : -1, t = det > 1e-12 ? (aa * by[c] - ab * ay[c]) / det : -1;
      if (s < 0 || t < 0) {
        const double s1 = std::max(0.0, ay[c] / aa), t1 = std::max(0.0, by[c] / bb);
        // Residual comparison: |y|^2 - 2 s ay + s^2 aa (constant |y|^2 drops out).
        if (-2 * s1 * ay[c] + s1 * s1 * aa <= -2 * t1 * by[c] + t1 * t1 * bb) s = s1, t = 0;
        else s = 0, t = t1;
      }
      map.sky.clear[c] = static_cast<float>(s);
      map.sky.overcast[c] = static_cast<float>(t);
    }
  } else {
    SD_LOG(Debug, "environment: " << sky_px.size() << " sky pixels seen; sky model set from the brightest seen pixels");
    map.sky.overcast = Eigen::Vector3f::Constant(0.5f);
  }
  // Ground fill: median of the seen road band (-25..-8 deg).
  Eigen::Vector3f ground = Eigen::Vector3f::Constant(0.05f);
  {
    std::vector<double> ch[3];
    for (int v = H / 2; v < H; ++v) {
      const double el = M_PI / 2 - M_PI * (v + 0.5) / H;
      if (el > -8 * kDeg || el < -25 * kDeg) continue;
      for (int u = 0; u < W; ++u)
        if (map.coverage.at(u, v) > 0.05f)
          for (int c = 0; c < 3; ++c) ch[c].push_back(map.radiance.at(u, v, c));
    }
    if (!ch[0].empty())
      for (int c = 0; c < 3; ++c) ground[c] = static_cast<float>(Median(ch[c]));
  }
  // Feathered fill: where camera weights are small the model takes over smoothly.
  const float model_weight = 0.05f;
  ParallelRows(0, H, [&](int v) {
    for (int u = 0; u < W; ++u) {
      const Eigen::Vector3d& d = directions[static_cast<size_t>(v) * W + u];
      const Eigen::Vector3f fill = d.z() > 0 ? map.sky.Radiance(d) : ground;
      const float w = map.coverage.at(u, v);
      for (int c = 0; c < 3; ++c) map.radiance.at(u, v, c) = (map.radiance.at(u, v, c) * w + fill[c] * model_weight) / (w + model_weight);
    }
  });

  // Sun intensity from the road contrast at real shadows of annotated objects.
  const Eigen::Vector3f E_sky = map.SkyIrradianceUp();
  const double sin_el = std::max(0.1, map.sun_direction.z());
  double contrast = 0;
  if (std::any_of(frame.annotations.begin(), frame.annotations.end(), [](const Annotation& a) { return !a.detected; })) {
    const ShadowCheck check = CheckSunAgainstShadows(frame, LinearImages(images, gains), map.sun_direction);
    map.shadow_objects = static_cast<int>(check.boxes.size());
    map.shadow_agreement = check.agreement;
    std::vector<double> ratios;
    for (const auto& b : check.boxes)
      if (b.Ratio() > 1.0) ratios.push_back(b.Ratio());
    // The median over agreeing objects; the shadow polygon also holds lit ground where the box is a poor
    // outline of the object, so this under-estimates the contrast.
    if (ratios.size() >= 3) contrast = Median(ratios);
  }
  const double k = options.shadow_sky_visibility;
  double direct_over_sky;  // E_sun sin(el) / E_sky
  if (contrast > 1.0 / k) {
    direct_over_sky = k * contrast - 1;
    map.sun_road_contrast = contrast;
  } else {
    direct_over_sky = options.default_direct_fraction / (1 - options.default_direct_fraction);
  }
  // The sun's colour is not measurable from a clipped or unseen disk; take it white in map units (the
  // gains already carry the cameras' white balance) at the sky's luminance scale.
  map.sun_irradiance = Eigen::Vector3f::Constant(static_cast<float>(direct_over_sky * Luma(E_sky) / sin_el));
  map.sh = ProjectToSh(map.radiance);
  map.luminance = RadianceLuminance(map.radiance);
  return map;
}

// ---- Spherical harmonics ----

namespace {
std::array<double, 9> ShBasis(const Eigen::Vector3d& d) {
  const double x = d.x(), y = d.y(), z = d.z();
  return {0.282095, 0.488603 * y, 0.488603 * z, 0.488603 * x, 1.092548 * x * y, 1.092548 * y * z,
          0.315392 * (3 * z * z - 1), 1.092548 * x * z, 0.546274 * (x * x - y * y)};
}
}  // namespace

ShIrradiance ProjectToSh(const ImageF& img) {
  SD_CHECK(img.channels() >= 3 && img.width() == 2 * img.height(), << img.width() << "x" << img.height());
  const int W = img.width(), H = img.height();
  std::array<Eigen::Vector3d, 9> acc;
  for (auto& a : acc) a.setZero();
  for (int v = 0; v < H; ++v) {
    const double el = M_PI / 2 - M_PI * (v + 0.5) / H;
    const double dw = (2 * M_PI / W) * (M_PI / H) * std::cos(el);
    for (int u = 0; u < W; ++u) {
      const auto Y = ShBasis(LatLongDirection(u + 0.5, v + 0.5, W, H));
      const Eigen::Vector3d L(img.at(u, v, 0), img.at(u, v, 1), img.at(u, v, 2));
      for (int i = 0; i < 9; ++i) acc[i] += L * (Y[i] * dw);
    }
  }
  ShIrradiance sh;
  for (int i = 0; i < 9; ++i) sh.L[i] = acc[i].cast<float>();
  return sh;
}

Eigen::Vector3f ShIrradiance::Irradiance(const Eigen::Vector3d& n) const {
  // Convolution with the clamped cosine: A0 = pi, A1 = 2 pi / 3, A2 = pi / 4.
  static const double A[9] = {M_PI, 2 * M_PI / 3, 2 * M_PI / 3, 2 * M_PI / 3, M_PI / 4, M_PI / 4, M_PI / 4, M_PI / 4, M_PI / 4};
  const auto Y = ShBasis(n.normalized());
  Eigen::Vector3d e = Eigen::Vector3d::Zero();
  for (int i = 0; i < 9; ++i) e += L[i].cast<double>() * (A[i] * Y[i]);
  return e.cwiseMax(0.0).cast<float>();
}

ShIrradiance MapSh(const EnvironmentMap& map) { return map.sh ? *map.sh : ProjectToSh(map.radiance); }

EnvironmentLight MakeEnvironmentLight(const EnvironmentMap& map) {
  EnvironmentLight l;
  l.sh = MapSh(map);
  l.radiance = &map.radiance;
  l.radiance_luminance = map.luminance ? map.luminance : RadianceLuminance(map.radiance);
  l.sun_direction = map.sun_direction;
  l.sun_irradiance = map.sun_irradiance;
  l.sun_angular_radius_rad = map.sun_angular_radius_rad;
  return l;
}

Lighting RendererLighting(const EnvironmentMap& map, size_t k) {
  SD_CHECK(k < map.gains.size(), << k << " of " << map.gains.size());
  const Eigen::Vector3f g = map.gains[k].Gain();
  const ShIrradiance sh = MapSh(map);
  Lighting l;
  l.sun_direction = map.sun_direction.cast<float>().normalized();
  l.sun_irradiance = map.sun_irradiance.cwiseQuotient(g);
  l.sky_radiance = (sh.Irradiance(Eigen::Vector3d::UnitZ()) / static_cast<float>(M_PI)).cwiseQuotient(g);
  return l;
}

}  // namespace sd
