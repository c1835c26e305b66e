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

// Integer hash -> [0, 1): deterministic per (seed, index) sampling, independent of threads.
double Hash01(uint32_t a, uint32_t b) {
  uint32_t h = a * 0x9E3779B1u ^ (b + 0x7F4A7C15u + (a << 6) + (a >> 2));
  h ^= h >> 16;
  h *= 0x85EBCA6Bu;
  h ^= h >> 13;
  h *= 0xC2B2AE35u;
  h ^= h >> 16;
  return (h >> 8) * (1.0 / 16777216.0);
}

void Basis(const Eigen::Vector3d& n, Eigen::Vector3d* t, Eigen::Vector3d* b) {
  const Eigen::Vector3d a = std::abs(n.x()) < 0.9 ? Eigen::Vector3d::UnitX() : Eigen::Vector3d::UnitY();
  *t = n.cross(a).normalized();
  *b = n.cross(*t);
}

// Stratified sample k of n on the unit square: one in each cell of a cols x rows grid with cols x rows = n exactly
// (StratifiedColumns), so that every part of the square is drawn from whatever n is.
Eigen::Vector2d Stratified(int k, int n, uint32_t seed, uint32_t salt) {
  const int cols = StratifiedColumns(n), rows = std::max(1, n / cols);
  const int i = k % cols, j = k / cols;
  return {(i + Hash01(seed, salt * 2654435761u + 2 * k)) / cols, (j + Hash01(seed, salt * 2654435761u + 2 * k + 1)) / rows};
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
  const auto map_rows = [&](const auto& body) {
    ParallelFor(0, static_cast<size_t>(H), [&](size_t v) { body(static_cast<int>(v)); });
  };
  std::vector<Eigen::Vector3d> directions(static_cast<size_t>(W) * H);
  map_rows([&](int v) {
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
  map_rows([&](int v) {
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
  map_rows([&](int v) {
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

// ---- Ray-traced light at a point ----

namespace {
Eigen::Vector3f Offset(const Eigen::Vector3d& p, const Eigen::Vector3d& n, float off) {
  return (p + n.normalized() * off).cast<float>();
}
// Directions uniform on the sun's disk; the basis round the sun built once.
class SunDisk {
 public:
  explicit SunDisk(const EnvironmentLight& light)
      : s_(light.sun_direction.normalized()), tan_radius_(std::tan(light.sun_angular_radius_rad)) {
    Basis(s_, &t_, &b_);
  }
  Eigen::Vector3d Ray(int k, int n, uint32_t seed) const {
    const Eigen::Vector2d r = Stratified(k, n, seed, 17);
    const double rad = tan_radius_ * std::sqrt(r.x()), phi = 2 * M_PI * r.y();
    return (s_ + rad * (std::cos(phi) * t_ + std::sin(phi) * b_)).normalized();
  }

 private:
  Eigen::Vector3d s_, t_, b_;
  double tan_radius_;
};

// Cosine-weighted directions round a normal; the basis built once per shaded point.
class CosineLobe {
 public:
  explicit CosineLobe(const Eigen::Vector3d& normal) : n_(normal.normalized()) { Basis(n_, &t_, &b_); }
  Eigen::Vector3d Ray(int k, int count, uint32_t seed) const {
    const Eigen::Vector2d r = Stratified(k, count, seed, 29);
    const double rr = std::sqrt(r.x()), phi = 2 * M_PI * r.y();
    return (rr * std::cos(phi) * t_ + rr * std::sin(phi) * b_ + std::sqrt(std::max(0.0, 1 - r.x())) * n_).normalized();
  }

 private:
  Eigen::Vector3d n_, t_, b_;
};

// CosineLobe in single precision, for the road's sky rays (16 per road pixel): the double-precision sine and
// cosine save and restore the rounding mode on every call, and cost more than tracing the rays.
class CosineLobeF {
 public:
  explicit CosineLobeF(const Eigen::Vector3d& normal) {
    const Eigen::Vector3d n = normal.normalized();
    Eigen::Vector3d t, b;
    Basis(n, &t, &b);
    n_ = n.cast<float>(), t_ = t.cast<float>(), b_ = b.cast<float>();
  }
  Eigen::Vector3f Ray(int k, int count, uint32_t seed) const {
    const Eigen::Vector2d r = Stratified(k, count, seed, 29);
    const float rx = static_cast<float>(r.x()), phi = 2.0f * static_cast<float>(M_PI) * static_cast<float>(r.y());
    const float rr = std::sqrt(rx);
    return (rr * std::cos(phi) * t_ + rr * std::sin(phi) * b_ + std::sqrt(std::max(0.0f, 1.0f - rx)) * n_).normalized();
  }

 private:
  Eigen::Vector3f n_, t_, b_;
};

// LatLongPixel of a unit direction in single precision (the map is a degree or so per pixel).
Eigen::Vector2f LatLongPixelF(const Eigen::Vector3f& d, int width, int height) {
  constexpr float kPiF = static_cast<float>(M_PI);
  const float phi = std::atan2(d.y(), d.x()), el = std::asin(std::clamp(d.z(), -1.0f, 1.0f));
  float u = (kPiF - phi) / (2 * kPiF) * static_cast<float>(width);
  if (u >= static_cast<float>(width)) u -= static_cast<float>(width);
  return {u, (kPiF / 2 - el) / kPiF * static_cast<float>(height)};
}

// SampleBilinear of a one-channel image (its addressing: pixel centres at +0.5, clamped at the borders), inline.
float SampleBilinear1(const ImageF& img, float u, float v) {
  const float x = std::clamp(u - 0.5f, 0.0f, static_cast<float>(img.width() - 1));
  const float y = std::clamp(v - 0.5f, 0.0f, static_cast<float>(img.height() - 1));
  const int x0 = static_cast<int>(x), y0 = static_cast<int>(y);
  const int x1 = std::min(x0 + 1, img.width() - 1), y1 = std::min(y0 + 1, img.height() - 1);
  const float fx = x - static_cast<float>(x0), fy = y - static_cast<float>(y0);
  const float* row0 = img.pixel(0, y0);
  const float* row1 = img.pixel(0, y1);
  const float a = row0[x0] * (1 - fx) + row0[x1] * fx;
  const float b = row1[x0] * (1 - fx) + row1[x1] * fx;
  return a * (1 - fy) + b * fy;
}

}  // namespace

double SunVisibility(const RayScene& scene, const Eigen::Vector3d& p, const Eigen::Vector3d& normal, const EnvironmentLight& light,
                     const EnvShadingOptions& o) {
  const int n = std::max(1, o.sun_rays);
  const SunDisk disk(light);
  OcclusionFan fan(scene, Offset(p, normal, o.ray_offset), o.skip_mesh);
  for (int k = 0; k < n; ++k) fan.Add(disk.Ray(k, n, o.seed).cast<float>(), 1.0);
  return fan.OpenWeight() / n;
}

double AmbientOcclusion(const RayScene& scene, const Eigen::Vector3d& p, const Eigen::Vector3d& normal, const EnvShadingOptions& o) {
  const int n = std::max(1, o.sky_rays);
  const CosineLobe lobe(normal);
  OcclusionFan fan(scene, Offset(p, normal, o.ray_offset), o.skip_mesh);
  for (int k = 0; k < n; ++k) {
    const Eigen::Vector3d d = lobe.Ray(k, n, o.seed);
    if (d.z() > 0) fan.Add(d.cast<float>(), 1.0);
  }
  return fan.OpenWeight() / n;
}

Eigen::Vector3f ObjectIrradiance(const RayScene& scene, const Eigen::Vector3d& p, const Eigen::Vector3d& normal,
                                 const EnvironmentLight& light, const EnvShadingOptions& o) {
  const double cos_sun = normal.normalized().dot(light.sun_direction.normalized());
  Eigen::Vector3f e = light.sh.Irradiance(normal) * static_cast<float>(AmbientOcclusion(scene, p, normal, o));
  if (cos_sun > 0) e += light.sun_irradiance * static_cast<float>(cos_sun * SunVisibility(scene, p, normal, light, o));
  return e;
}

namespace {

// The sky's open share at a receiver point: cosine-weighted directions round `n` from `origin`, each weighted by
// the map's luminance there (the same directions for the open and the whole sky, so that their noise cancels).
// The rays are traced first: most road pixels under a shadow's rectangle see the whole sky, and there the open
// share is exactly 1 whatever the weights, so the map is read (a lat-long lookup and a bilinear sample per ray)
// only where something blocks a ray.
double SkyOpenShare(const RayScene& scene, const Eigen::Vector3f& origin, const Eigen::Vector3d& n,
                    const EnvironmentLight& light, const EnvShadingOptions& o) {
  const int ns = std::max(1, o.sky_rays);
  const CosineLobeF lobe(n);
  // Per thread, reused: this runs once per road pixel.
  thread_local std::vector<Eigen::Vector3f> dirs;
  thread_local std::vector<char> blocked;
  dirs.clear();
  for (int k = 0; k < ns; ++k) {
    const Eigen::Vector3f d = lobe.Ray(k, ns, o.seed);
    if (d.z() > 0) dirs.push_back(d);
  }
  blocked.assign(dirs.size(), 0);
  bool any_blocked = false;
  for (size_t begin = 0; begin < dirs.size(); begin += RayScene::kMaxFanRays) {
    const int count = static_cast<int>(std::min<size_t>(RayScene::kMaxFanRays, dirs.size() - begin));
    const uint32_t occluded = scene.OccludedFan(origin, &dirs[begin], count, 0.0f, std::numeric_limits<float>::infinity(), o.skip_mesh);
    for (int i = 0; i < count; ++i) blocked[begin + static_cast<size_t>(i)] = static_cast<char>(occluded >> i & 1u);
    any_blocked = any_blocked || occluded != 0;
  }
  if (!any_blocked) return 1.0;
  double sky_all = 0, sky_open = 0;
  const ImageF* luminance = light.radiance_luminance.get();
  for (size_t k = 0; k < dirs.size(); ++k) {
    double L = 1.0;
    if (luminance && !luminance->empty()) {
      const Eigen::Vector2f uv = LatLongPixelF(dirs[k], luminance->width(), luminance->height());
      L = SampleBilinear1(*luminance, uv.x(), uv.y());
    } else if (light.radiance && !light.radiance->empty()) {
      const Eigen::Vector2f uv = LatLongPixelF(dirs[k], light.radiance->width(), light.radiance->height());
      float rgb[3];
      SampleBilinear(*light.radiance, uv.x(), uv.y(), rgb);
      L = Luma(rgb);
    }
    sky_all += L;
    if (!blocked[k]) sky_open += L;
  }
  return sky_all > 0 ? sky_open / sky_all : 1.0;
}

// The road's light with the objects over without them, from the sky's open share and the sun's visible share.
// Monte Carlo estimate of the sky irradiance is pi * mean(L) over cosine-weighted directions; the SH value is the
// better-converged unoccluded total, scaled by the sampled open share.
struct ReceiverLight {
  double sky = 0, sun = 0;  // luminance of the irradiance without the objects: SH(n); sun x cos
  ReceiverLight(const EnvironmentLight& light, const Eigen::Vector3d& n) : sky(Luma(light.sh.Irradiance(n))) {
    const double cos_sun = n.dot(light.sun_direction.normalized());
    sun = cos_sun > 0 ? Luma(light.sun_irradiance) * cos_sun : 0.0;
  }
  float Ratio(double sky_open, double sun_visible) const {
    const double without = sky + sun;
    if (without <= 0) return 1.0f;
    const double with = sky * sky_open + (sun > 0 ? sun * sun_visible : 0.0);
    return static_cast<float>(std::clamp(with / without, 0.0, 1.0));
  }
};

}  // namespace

float ReceiverShadowRatio(const RayScene& scene, const Eigen::Vector3d& p, const Eigen::Vector3d& normal,
                          const EnvironmentLight& light, const EnvShadingOptions& o) {
  const Eigen::Vector3d n = normal.normalized();
  const double open_share = SkyOpenShare(scene, Offset(p, n, o.ray_offset), n, light, o);
  const ReceiverLight rl(light, n);
  return rl.Ratio(open_share, rl.sun > 0 ? SunVisibility(scene, p, n, light, o) : 0.0);
}

namespace {

// One receiver pixel.
struct RoadPixel {
  int x = 0;
  Eigen::Vector3d p, n;  // the hit point, the normal on the camera's side
  uint32_t seed = 0;
  const EnvironmentLight* light = nullptr;
  float footprint = 0;       // metres per pixel at p, seen face-on
  float sky_open = 1;        // the sky's open share
  bool sunlit_face = false;  // its light has a sun, in front of the face
  float sun = 0;             // the sun's visible share: the disk centre's 0 or 1 until the edge pass
  float sun_t = std::numeric_limits<float>::infinity();  // how far the disk centre's blocker is
};

// The widest penumbra the edge pass looks for, in pixels; beyond it (a sun a few degrees from grazing the road,
// where the sun's share of the light is small anyway) the disk is traced only this far from the hard edge.
constexpr int kMaxPenumbraPixels = 48;

// 1 where a marked cell lies within `r` cells (a square) of the cell: two passes of running counts.
Image<uint8_t> DilateSquare(const Image<uint8_t>& marked, int r) {
  const int w = marked.width(), h = marked.height();
  Image<uint8_t> rows(w, h, 1, 0), out(w, h, 1, 0);
  std::vector<int> prefix(static_cast<size_t>(std::max(w, h)) + 1);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) prefix[static_cast<size_t>(x) + 1] = prefix[static_cast<size_t>(x)] + (marked.at(x, y) ? 1 : 0);
    for (int x = 0; x < w; ++x)
      rows.at(x, y) = prefix[static_cast<size_t>(std::min(w, x + r + 1))] > prefix[static_cast<size_t>(std::max(0, x - r))];
  }
  for (int x = 0; x < w; ++x) {
    for (int y = 0; y < h; ++y) prefix[static_cast<size_t>(y) + 1] = prefix[static_cast<size_t>(y)] + (rows.at(x, y) ? 1 : 0);
    for (int y = 0; y < h; ++y)
      out.at(x, y) = prefix[static_cast<size_t>(std::min(h, y + r + 1))] > prefix[static_cast<size_t>(std::max(0, y - r))];
  }
  return out;
}

// Runs `body(row)` for rows [y0, y1) in parallel and rethrows the first row's error, if any, once all are done.
template <typename Body>
void ParallelRows(int y0, int y1, const Body& body) {
  if (y1 <= y0) return;
  ParallelForRethrow(static_cast<size_t>(y0), static_cast<size_t>(y1), [&](size_t y) { body(static_cast<int>(y)); });
}

// ReceiverShadowImage for any rule giving a hit face its light, in three passes over the rectangles' pixels:
//  1. the primary rays in packets; at each receiver hit, the sky's open share (as ReceiverShadowRatio's) and one
//     ray to the centre of the sun's disk;
//  2. the whole disk (`sun_rays`) traced only within the widest penumbra of an edge of the centre rays' hard
//     shadow: elsewhere the disk is wholly seen or wholly hidden, as its centre is;
//  3. the ratio composed.
template <typename LightOfFace>
ImageF ReceiverShadowImageWith(const RayScene& scene, const PinholeCamera& camera, const Rigid3d& T_scene_cam, int receiver_mesh,
                               const LightOfFace& light_of_face, const EnvShadingOptions& options,
                               std::vector<std::array<int, 4>> rects) {
  constexpr float inf = std::numeric_limits<float>::infinity();
  ImageF out(camera.width, camera.height, 1, 1.0f);
  if (receiver_mesh < 0 || receiver_mesh >= scene.NumMeshes()) return out;
  if (rects.empty()) rects.push_back({0, 0, camera.width, camera.height});
  const auto [y0, y1] = RowRange(rects, camera.height);
  int bx0 = camera.width, bx1 = 0;
  for (const auto& r : rects)
    if (r[0] < r[2] && r[1] < r[3]) bx0 = std::min(bx0, std::max(0, r[0])), bx1 = std::max(bx1, std::min(camera.width, r[2]));
  if (y1 <= y0 || bx1 <= bx0) return out;
  const int bw = bx1 - bx0, bh = y1 - y0;
  const Eigen::Vector3f origin = T_scene_cam.translation.cast<float>();
  const float fx = static_cast<float>(camera.fx);
  std::vector<std::vector<RoadPixel>> rows(static_cast<size_t>(bh));
  Image<int> index(bw, bh, 1, -1);  // a pixel's place in its row's list; -1: not the receiver
  const auto options_at = [&](const RoadPixel& rp) {
    EnvShadingOptions o = options;
    o.skip_mesh = receiver_mesh;
    o.seed = rp.seed;
    return o;
  };

  // Pass 1.
  ParallelRows(y0, y1, [&](int y) {
    std::vector<RoadPixel>& row = rows[static_cast<size_t>(y - y0)];
    std::vector<int> xs;
    std::vector<Eigen::Vector3f> dirs;
    for (const auto& [x0, x1] : RowSpans(rects, y, camera.width))
      for (int x = x0; x < x1; ++x) {
        xs.push_back(x);
        dirs.push_back((T_scene_cam.rotation * camera.RayDirection({x + 0.5, y + 0.5})).cast<float>());
      }
    std::array<RayHit, RayScene::kMaxFanRays> hits;
    for (size_t begin = 0; begin < xs.size(); begin += RayScene::kMaxFanRays) {
      const int count = static_cast<int>(std::min<size_t>(RayScene::kMaxFanRays, xs.size() - begin));
      scene.IntersectFan(origin, &dirs[begin], count, 0.0f, inf, -1, hits.data());
      for (int i = 0; i < count; ++i) {
        const RayHit& hit = hits[static_cast<size_t>(i)];
        if (!hit.Hit() || hit.mesh != receiver_mesh) continue;
        Eigen::Vector3d n = scene.GeometricNormal(hit).cast<double>();
        if (n.squaredNorm() == 0) continue;
        if (n.dot(dirs[begin + static_cast<size_t>(i)].cast<double>()) > 0) n = -n;  // the side the camera sees
        RoadPixel rp;
        rp.x = xs[begin + static_cast<size_t>(i)];
        rp.n = n.normalized();
        rp.p = scene.HitPoint(hit).cast<double>();
        rp.seed = options.seed * 0x9E3779B1u + static_cast<uint32_t>(y * camera.width + rp.x);
        rp.light = &light_of_face(hit.face);
        rp.footprint = std::max(1e-6f, hit.t / fx);
        const EnvShadingOptions o = options_at(rp);
        const Eigen::Vector3f from = Offset(rp.p, rp.n, o.ray_offset);
        rp.sky_open = static_cast<float>(SkyOpenShare(scene, from, rp.n, *rp.light, o));
        rp.sunlit_face = ReceiverLight(*rp.light, rp.n).sun > 0;
        if (rp.sunlit_face) {
          const RayHit block = scene.Intersect(from, rp.light->sun_direction.normalized().cast<float>(), 0.0f, inf, receiver_mesh);
          rp.sun = block.Hit() ? 0.0f : 1.0f;
          rp.sun_t = block.t;
        }
        index.at(rp.x - bx0, y - y0) = static_cast<int>(row.size());
        row.push_back(rp);
      }
    }
  });
  const auto pixel_at = [&](int x, int y) -> const RoadPixel* {
    if (x < bx0 || x >= bx1 || y < y0 || y >= y1) return nullptr;
    const int k = index.at(x - bx0, y - y0);
    return k < 0 ? nullptr : &rows[static_cast<size_t>(y - y0)][static_cast<size_t>(k)];
  };

  // Pass 2. The disk's centre leaves a hard shadow; the penumbra lies within tan(radius) x the blocker's distance
  // of its edge, stretched by the sun's slant on the road. The widest over the image, in the smallest footprint,
  // bounds how far from an edge the disk can be partly hidden.
  Image<uint8_t> edge(bw, bh, 1, 0);
  float min_footprint = inf;
  double reach_m = 0;
  for (int y = y0; y < y1; ++y)
    for (const RoadPixel& rp : rows[static_cast<size_t>(y - y0)]) {
      if (!rp.sunlit_face) continue;
      min_footprint = std::min(min_footprint, rp.footprint);
      if (std::isfinite(rp.sun_t)) {
        const double slant = std::max(0.1, rp.n.dot(rp.light->sun_direction.normalized()));
        reach_m = std::max(reach_m, std::tan(rp.light->sun_angular_radius_rad) * rp.sun_t / slant);
      }
      for (const auto& [dx, dy] : {std::pair{1, 0}, std::pair{0, 1}}) {
        const RoadPixel* q = pixel_at(rp.x + dx, y + dy);
        if (q && q->sunlit_face && q->sun != rp.sun) edge.at(rp.x - bx0, y - y0) = edge.at(q->x - bx0, y + dy - y0) = 1;
      }
    }
  const double reach_px = std::isfinite(min_footprint) ? reach_m / min_footprint : 0.0;
  const Image<uint8_t> near_edge = DilateSquare(edge, static_cast<int>(std::min<double>(kMaxPenumbraPixels, std::ceil(reach_px) + 1)));

  // Passes 2 and 3.
  ParallelRows(y0, y1, [&](int y) {
    for (RoadPixel& rp : rows[static_cast<size_t>(y - y0)]) {
      if (rp.sunlit_face && near_edge.at(rp.x - bx0, y - y0)) rp.sun = static_cast<float>(SunVisibility(scene, rp.p, rp.n, *rp.light, options_at(rp)));
      out.at(rp.x, y) = ReceiverLight(*rp.light, rp.n).Ratio(rp.sky_open, rp.sun);
    }
  });
  return out;
}

}  // namespace

ImageF ReceiverShadowImage(const RayScene& scene, const PinholeCamera& camera, const Rigid3d& T_scene_cam, int receiver_mesh,
                           const EnvironmentLight& light, const EnvShadingOptions& options, int x0, int y0, int x1, int y1) {
  return ReceiverShadowImageWith(scene, camera, T_scene_cam, receiver_mesh,
                                 [&](int) -> const EnvironmentLight& { return light; }, options,
                                 x1 > x0 && y1 > y0 ? std::vector<std::array<int, 4>>{{x0, y0, x1, y1}}
                                                    : std::vector<std::array<int, 4>>{});
}

ImageF ReceiverShadowImage(const RayScene& scene, const PinholeCamera& camera, const Rigid3d& T_scene_cam, int receiver_mesh,
                           const std::vector<const EnvironmentLight*>& light_of_face, const EnvShadingOptions& options,
                           const std::vector<std::array<int, 4>>& rects) {
  return ReceiverShadowImageWith(scene, camera, T_scene_cam, receiver_mesh,
                                 [&](int face) -> const EnvironmentLight& {
                                   SD_CHECK(face >= 0 && static_cast<size_t>(face) < light_of_face.size() && light_of_face[face],
                                            << "no light for receiver face " << face << " of " << light_of_face.size());
                                   return *light_of_face[static_cast<size_t>(face)];
                                 },
                                 options, rects);
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
