// The light of an environment map traced at points among the inserted objects (environment.h): the sun's disk and
// the sky seen from a surface, and the share of the real road's light that the objects take (the road's shade).
// The map itself is built in environment.cpp.
#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <vector>

#include <Eigen/Dense>

#include "core/error.h"
#include "core/parallel.h"
#include "core/sampling.h"
#include "core/stats.h"
#include "synth/environment.h"

namespace sd {
namespace {

float Luma(const float* rgb) { return LinearLuminance(rgb); }
float Luma(const Eigen::Vector3f& rgb) { return LinearLuminance(rgb.data()); }

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

Eigen::Vector3f Offset(const Eigen::Vector3d& p, const Eigen::Vector3d& n, float off) {
  return (p + n.normalized() * off).cast<float>();
}
// Directions uniform on the sun's disk: the shifted pattern of the sky's rays (core/sampling.h), whose local x and
// y (the square root of a uniform radius-squared, round a uniform azimuth) are uniform on the unit disk; the basis
// round the sun built once per point.
class SunDisk {
 public:
  SunDisk(const EnvironmentLight& light, int count, uint32_t seed)
      : s_(light.sun_direction.normalized()), tan_radius_(std::tan(light.sun_angular_radius_rad)),
        pattern_(count, static_cast<float>(Hash01(seed, 0x5D15Cu)), static_cast<float>(Hash01(seed, 0x7A9E3u))) {
    Basis(s_, &t_, &b_);
  }
  Eigen::Vector3d Ray(int k) const {
    const Eigen::Vector3f l = pattern_.Local(k);
    return (s_ + tan_radius_ * (static_cast<double>(l.x()) * t_ + static_cast<double>(l.y()) * b_)).normalized();
  }

 private:
  Eigen::Vector3d s_, t_, b_;
  double tan_radius_;
  ShiftedCosinePattern pattern_;
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

// The road's sky directions round a normal (16 per road pixel): a shifted pattern (core/sampling.h) in a basis
// built once per point, in single precision (the double-precision sine and cosine of a freshly jittered direction
// per ray cost more than tracing it).
class RoadSkyLobe {
 public:
  RoadSkyLobe(const Eigen::Vector3d& normal, int count, uint32_t seed)
      : pattern_(count, static_cast<float>(Hash01(seed, 0x51ED27u)), static_cast<float>(Hash01(seed, 0xA3C59u))) {
    const Eigen::Vector3d n = normal.normalized();
    Eigen::Vector3d t, b;
    Basis(n, &t, &b);
    n_ = n.cast<float>(), t_ = t.cast<float>(), b_ = b.cast<float>();
  }
  Eigen::Vector3f Ray(int k) const {
    const Eigen::Vector3f l = pattern_.Local(k);
    return l.x() * t_ + l.y() * b_ + l.z() * n_;
  }

 private:
  ShiftedCosinePattern pattern_;
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
  const SunDisk disk(light, n, o.seed);
  OcclusionFan fan(scene, Offset(p, normal, o.ray_offset), o.skip_mesh);
  for (int k = 0; k < n; ++k) fan.Add(disk.Ray(k).cast<float>(), 1.0);
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
  const RoadSkyLobe lobe(n, ns, o.seed);
  // Per thread, reused: this runs once per road pixel.
  thread_local std::vector<Eigen::Vector3f> dirs;
  thread_local std::vector<char> blocked;
  dirs.clear();
  for (int k = 0; k < ns; ++k) {
    const Eigen::Vector3f d = lobe.Ray(k);
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

}  // namespace sd
