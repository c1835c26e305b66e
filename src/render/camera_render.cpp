#include "render/camera_render.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/error.h"
#include "core/parallel.h"
#include "core/sampling.h"
#include "core/stats.h"

namespace sd {
namespace {

constexpr float kPi = 3.14159265358979323846f;

// "lowbias32" integer hash (Chris Wellons' hash-prospector): good avalanche for counter-based sampling.
uint32_t Hash(uint32_t x) {
  x ^= x >> 16;
  x *= 0x7feb352dU;
  x ^= x >> 15;
  x *= 0x846ca68bU;
  x ^= x >> 16;
  return x;
}

// Counter-based generator: every pixel owns an independent stream keyed by (seed, x, y).
class PixelRng {
 public:
  PixelRng(uint32_t seed, int x, int y)
      : state_(Hash(seed ^ Hash(static_cast<uint32_t>(x) ^ Hash(static_cast<uint32_t>(y) + 0x68e31da4U)))) {}
  float Next() {  // uniform in [0, 1)
    state_ += 0x9e3779b9U;
    return static_cast<float>(Hash(state_) >> 8) * (1.0f / 16777216.0f);
  }

 private:
  uint32_t state_;
};

// Stratified points in [0,1)^2: the cells of a cols x rows grid of exactly n cells (StratifiedColumns), each
// jittered.
class StratifiedGrid {
 public:
  explicit StratifiedGrid(int n) : cols_(StratifiedColumns(n)), rows_(std::max(1, n / cols_)) {}
  // The k-th point.
  Eigen::Vector2f operator()(int k, PixelRng& rng) const {
    const float jx = rng.Next(), jy = rng.Next();
    return {(static_cast<float>(k % cols_) + jx) / static_cast<float>(cols_),
            (static_cast<float>(k / cols_) + jy) / static_cast<float>(rows_)};
  }

 private:
  int cols_, rows_;
};

// The frame of a unit normal (Duff et al. 2017, "Building an Orthonormal Basis, Revisited"), built once per shaded
// point, for its cosine-weighted sky directions (core/sampling.h).
class CosineLobe {
 public:
  explicit CosineLobe(const Eigen::Vector3f& n) : n_(n) {
    const float sign = std::copysign(1.0f, n.z());
    const float a = -1.0f / (sign + n.z());
    const float b = n.x() * n.y() * a;
    t_ = Eigen::Vector3f(1.0f + sign * n.x() * n.x() * a, sign * b, -sign * n.x());
    bt_ = Eigen::Vector3f(b, sign + n.y() * n.y() * a, -n.y());
  }
  Eigen::Vector3f ToScene(const Eigen::Vector3f& local) const { return local.x() * t_ + local.y() * bt_ + local.z() * n_; }

 private:
  Eigen::Vector3f n_, t_, bt_;
};

// A shaded point's `n` sky directions: the shared pattern shifted by two draws of the pixel's stream.
ShiftedCosinePattern SkyPattern(int n, PixelRng& rng) {
  const float shift_x = rng.Next();
  return ShiftedCosinePattern(n, shift_x, rng.Next());
}

// Of `n` cosine-weighted sky directions around `lobe`, how many are above the horizon (z > 0), and how many of
// those no mesh but `skip_mesh` occludes. The directions' shift is drawn from `rng` whatever the scene; the rays
// above the horizon are traced in packets.
struct SkyCount {
  int above = 0, open = 0;
};
SkyCount CountOpenSky(const RayScene& scene, const Eigen::Vector3f& origin, const CosineLobe& lobe, int n, PixelRng& rng,
                      int skip_mesh) {
  SkyCount c;
  const ShiftedCosinePattern pattern = SkyPattern(n, rng);
  OcclusionFan fan(scene, origin, skip_mesh);
  for (int k = 0; k < n; ++k) {
    const Eigen::Vector3f d = lobe.ToScene(pattern.Local(k));
    if (d.z() <= 0) continue;
    ++c.above;
    fan.Add(d);
  }
  c.open = static_cast<int>(fan.OpenWeight());  // a sum of ones: exact
  return c;
}

float Luminance(const Eigen::Vector3f& c) { return LinearLuminance(c.data()); }

// Offset for secondary rays: floats carry ~7 digits, so the offset grows with the coordinates' magnitude.
Eigen::Vector3f OffsetPoint(const Eigen::Vector3f& p, const Eigen::Vector3f& n_geom) {
  const float eps = 2e-5f * (1.0f + p.cwiseAbs().maxCoeff());
  return p + eps * n_geom;
}

struct Frame {
  Eigen::Vector3f p_offset;  // hit point pushed off the surface
  Eigen::Vector3f n_shade;   // facing the viewer
};

// Normals flipped to the side the ray came from (double-sided shading of thin or open meshes).
Frame ShadingFrame(const RayScene& scene, const RayHit& hit, const Eigen::Vector3f& dir) {
  Eigen::Vector3f n_geom = scene.GeometricNormal(hit);
  if (n_geom.squaredNorm() == 0.0f) n_geom = -dir;  // degenerate triangle: face the viewer
  if (n_geom.dot(dir) > 0) n_geom = -n_geom;
  Eigen::Vector3f n_shade = scene.ShadingNormal(hit);
  if (n_shade.squaredNorm() == 0.0f) n_shade = n_geom;
  if (n_shade.dot(n_geom) < 0) n_shade = -n_shade;
  return {OffsetPoint(scene.HitPoint(hit), n_geom), n_shade};
}


// Majority vote over a pixel's object ids; ties go to the smallest mesh id so the result is independent of
// sample order. Sorts `ids`.
int MajorityId(int* ids, int n) {
  std::sort(ids, ids + n);
  int best = ids[0], best_count = 0;
  for (int i = 0; i < n;) {
    int j = i;
    while (j < n && ids[j] == ids[i]) ++j;
    if (j - i > best_count) {
      best_count = j - i;
      best = ids[i];
    }
    i = j;
  }
  return best;
}

// What the sky-filtered path keeps of one surface seen in a pixel (the sub-samples that hit one mesh with
// normals within kSameSurfaceCos of each other; a pixel on a silhouette or a crease has two or more): its light
// but the sky's share, the rays behind that share, and the filter's guides (where the surface is, which way it
// faces, how large a pixel is there).
struct SkySurface {
  int x = 0;
  int mesh = -1;
  int samples = 0;
  Eigen::Vector3f sun = Eigen::Vector3f::Zero();  // sum over its sub-samples of a * E_sun / pi
  Eigen::Vector3f sky = Eigen::Vector3f::Zero();  // sum over its sub-samples of a * sky radiance
  float open = 0, drawn = 0;                       // open sky rays, sky rays drawn (below the horizon: closed)
  Eigen::Vector3f point = Eigen::Vector3f::Zero(), normal = Eigen::Vector3f::Zero();  // sums, then means
  float footprint = 0;                             // metres per pixel at the surface
};
constexpr float kSameSurfaceCos = 0.9f;  // 26 degrees
constexpr float kGrazing = 2.0f;          // footprints per pixel: a surface seen 60 degrees off its normal

}  // namespace

CameraRender RenderCamera(const RayScene& scene, const PinholeCamera& camera, const Rigid3d& T_scene_cam,
                          const Lighting& lighting, const CameraRenderOptions& options) {
  SD_CHECK(camera.width > 0 && camera.height > 0, << camera.width << "x" << camera.height);
  SD_CHECK(options.samples_per_pixel > 0 && options.ao_samples >= 0 && options.sky_filter_radius >= 0,
           << "spp " << options.samples_per_pixel << ", ao " << options.ao_samples << ", sky filter radius "
           << options.sky_filter_radius);
  const int w = camera.width, h = camera.height;
  CameraRender out;
  out.color = ImageF(w, h, 3, 0.0f);
  out.coverage = ImageF(w, h, 1, 0.0f);
  out.depth = ImageF(w, h, 1, std::numeric_limits<float>::infinity());
  out.object = Image<int>(w, h, 1, -1);
  out.shadow = ImageF(w, h, 1, 1.0f);

  std::vector<std::array<int, 4>> rects = options.rects;
  if (rects.empty()) {
    const bool whole = options.x0 == 0 && options.y0 == 0 && options.x1 == 0 && options.y1 == 0;
    rects.push_back(whole ? std::array<int, 4>{0, 0, w, h} : std::array<int, 4>{options.x0, options.y0, options.x1, options.y1});
  }
  const auto [y0, y1] = RowRange(rects, h);
  if (y0 >= y1) return out;

  const Eigen::Matrix3d R_scene_cam = T_scene_cam.Rotation();
  const Eigen::Vector3f origin = T_scene_cam.translation.cast<float>();
  const Eigen::Vector3f sun_dir = lighting.sun_direction.normalized();
  const Eigen::Vector3f sun = lighting.sun_irradiance, sky = lighting.sky_radiance;
  const float sun_y = Luminance(sun), sky_y = Luminance(sky);
  const int spp = options.samples_per_pixel;
  const int n_ao = options.ao_samples;
  const int receiver = options.receiver_mesh;
  const bool filter_sky = options.sky_filter_radius > 0;
  const float inf = std::numeric_limits<float>::infinity();
  const StratifiedGrid pixel_grid(spp);

  // The sub-sample's primary ray: objects first, the receiver where none (the receiver stands in for the real
  // road, which is in the photo already: it never hides an object; a patch laid on a kerb's slope rises metres
  // away from its object).
  // Its direction (scene frame) through sub-sample s's jittered position, and that direction's camera z.
  const auto sub_sample_ray = [&](int x, int y, int s, PixelRng& rng, Eigen::Vector3f* dir, float* cam_z) {
    const Eigen::Vector2f jitter = pixel_grid(s, rng);
    const Eigen::Vector3d d_cam = camera.RayDirection(Eigen::Vector2d(x + jitter.x(), y + jitter.y()));
    *dir = (R_scene_cam * d_cam).cast<float>().normalized();
    *cam_z = static_cast<float>(d_cam.z());
  };
  const auto primary = [&](int x, int y, int s, PixelRng& rng, Eigen::Vector3f* dir, float* cam_z) {
    sub_sample_ray(x, y, s, rng, dir, cam_z);
    RayHit hit = scene.Intersect(origin, *dir, 0.0f, inf, receiver);
    if (!hit.Hit() && receiver >= 0 && options.receiver_shadow) hit = scene.Intersect(origin, *dir);
    return hit;
  };
  // Light the real road got (no objects) vs what it gets now; visibility ignores the road itself.
  const auto receiver_ratio = [&](const Frame& f, float cos_sun, PixelRng& rng) {
    const bool sun_visible = cos_sun > 0 && !scene.Occluded(f.p_offset, sun_dir, 0.0f, inf, receiver);
    const SkyCount sky_count = CountOpenSky(scene, f.p_offset, CosineLobe(f.n_shade), n_ao, rng, receiver);
    const float ao_with = n_ao > 0 ? static_cast<float>(sky_count.open) / n_ao : 1.0f;
    const float ao_without = n_ao > 0 ? static_cast<float>(sky_count.above) / n_ao : 1.0f;
    const float den = sun_y * cos_sun + sky_y * kPi * ao_without;
    const float num = sun_y * cos_sun * (sun_visible ? 1.0f : 0.0f) + sky_y * kPi * ao_with;
    return den > 0 ? num / den : 1.0f;
  };
  // Object meshes have their own light where the caller gives one.
  const auto light_of = [&](int mesh) -> const Lighting& {
    return static_cast<size_t>(mesh) < options.mesh_lighting.size() ? options.mesh_lighting[static_cast<size_t>(mesh)] : lighting;
  };

  // Every sub-sample shaded by its own rays.
  const auto render_pixel = [&](int x, int y) {
    PixelRng rng(options.seed, x, y);
    Eigen::Vector3f color = Eigen::Vector3f::Zero();
    int n_obj = 0, n_recv = 0;
    float depth = inf;
    double shadow_sum = 0.0;
    std::array<int, 16> ids_small{};
    std::vector<int> ids_large(spp > 16 ? static_cast<size_t>(spp) : 0);
    int* ids = spp > 16 ? ids_large.data() : ids_small.data();
    for (int s = 0; s < spp; ++s) {
      Eigen::Vector3f dir;
      float cam_z;
      const RayHit hit = primary(x, y, s, rng, &dir, &cam_z);
      if (!hit.Hit()) continue;
      const Frame f = ShadingFrame(scene, hit, dir);
      const float cos_sun = std::max(0.0f, f.n_shade.dot(sun_dir));
      if (hit.mesh == receiver) {
        if (!options.receiver_shadow) continue;
        shadow_sum += receiver_ratio(f, cos_sun, rng);
        ++n_recv;
        continue;
      }
      // Object: Lambertian, L = a * E / pi.
      const bool own = static_cast<size_t>(hit.mesh) < options.mesh_lighting.size();
      const Lighting& l = light_of(hit.mesh);
      const Eigen::Vector3f obj_sun_dir = own ? l.sun_direction.normalized() : sun_dir;
      const float obj_cos_sun = own ? std::max(0.0f, f.n_shade.dot(obj_sun_dir)) : cos_sun;
      // Nor does the receiver shade an object: the real road below is already counted by the upper-hemisphere test.
      const bool sun_visible = obj_cos_sun > 0 && !scene.Occluded(f.p_offset, obj_sun_dir, 0.0f, inf, receiver);
      const int sky_open = CountOpenSky(scene, f.p_offset, CosineLobe(f.n_shade), n_ao, rng, receiver).open;
      const float ao = n_ao > 0 ? static_cast<float>(sky_open) / n_ao : 1.0f;
      const Eigen::Vector3f E = l.sun_irradiance * (sun_visible ? obj_cos_sun : 0.0f) + l.sky_radiance * (kPi * ao);
      const Eigen::Vector3f albedo = scene.BaseColor(hit).head<3>();
      color += albedo.cwiseProduct(E) / kPi;
      depth = std::min(depth, hit.t * cam_z);
      ids[n_obj++] = hit.mesh;
    }

    if (n_obj > 0) {
      const float inv_spp = 1.0f / static_cast<float>(spp);
      for (int c = 0; c < 3; ++c) out.color.at(x, y, c) = color[c] * inv_spp;
      out.coverage.at(x, y) = static_cast<float>(n_obj) * inv_spp;
      out.depth.at(x, y) = depth;
      out.object.at(x, y) = MajorityId(ids, n_obj);
    }
    if (n_recv > 0) out.shadow.at(x, y) = static_cast<float>(shadow_sum / n_recv);
  };

  if (!filter_sky) {
    ParallelRows(y0, y1, [&](int y) {
      for (const auto& [x0, x1] : RowSpans(rects, y, w))
        for (int x = x0; x < x1; ++x) render_pixel(x, y);
    });
    return out;
  }

  // The sky-filtered path. First pass: the pixel's primary rays as a packet, then every object sub-sample's sun ray
  // and sky rays, all of the pixel's occlusion rays in packets of RayScene::kMaxFanRays (rays from nearby points
  // share most of their way through the BVH). Each surface a pixel shows is kept for the filter, row by row.
  int fx0 = w, fx1 = 0;
  for (const auto& r : rects)
    if (r[0] < r[2] && r[1] < r[3]) fx0 = std::min(fx0, std::max(0, r[0])), fx1 = std::max(fx1, std::min(w, r[2]));
  const int bw = std::max(1, fx1 - fx0);
  std::vector<std::vector<SkySurface>> rows(static_cast<size_t>(y1 - y0));
  // Per pixel of the rectangles' bounds: its first surface in its row's list (-1: no object) and how many.
  Image<int> first(bw, y1 - y0, 1, -1), count(bw, y1 - y0, 1, 0);
  const float fx = static_cast<float>(camera.fx);

  ParallelRows(y0, y1, [&](int y) {
    std::vector<SkySurface>& surfaces = rows[static_cast<size_t>(y - y0)];
    struct Sub {  // an object sub-sample
      Eigen::Vector3f albedo, p, n;
      const Lighting* light;
      float cos_sun;
      int mesh, drawn, open;
      bool sun_open;
    };
    std::vector<Sub> subs;
    std::vector<Eigen::Vector3f> ray_origin, ray_dir;
    std::vector<int> ray_sub;  // its sub-sample k, or -1 - k for the sun ray of sub-sample k
    std::vector<int> ids(static_cast<size_t>(spp));
    std::vector<Eigen::Vector3f> primary_dir(static_cast<size_t>(spp));
    std::vector<float> primary_z(static_cast<size_t>(spp));
    std::vector<RayHit> primary_hit(static_cast<size_t>(spp));
    for (const auto& [x0, x1] : RowSpans(rects, y, w))
      for (int x = x0; x < x1; ++x) {
        PixelRng rng(options.seed, x, y);
        subs.clear(), ray_origin.clear(), ray_dir.clear(), ray_sub.clear();
        int n_obj = 0, n_recv = 0;
        float depth = inf;
        double shadow_sum = 0.0;
        // The sub-samples' primary rays first, as packets (their jitter drawn before any sky ray).
        for (int s = 0; s < spp; ++s)
          sub_sample_ray(x, y, s, rng, &primary_dir[static_cast<size_t>(s)], &primary_z[static_cast<size_t>(s)]);
        for (int s = 0; s < spp; s += RayScene::kMaxFanRays)
          scene.IntersectFan(origin, &primary_dir[static_cast<size_t>(s)], std::min(RayScene::kMaxFanRays, spp - s), 0.0f,
                             inf, receiver, &primary_hit[static_cast<size_t>(s)]);
        for (int s = 0; s < spp; ++s) {
          const Eigen::Vector3f& dir = primary_dir[static_cast<size_t>(s)];
          const float cam_z = primary_z[static_cast<size_t>(s)];
          RayHit hit = primary_hit[static_cast<size_t>(s)];
          if (!hit.Hit() && receiver >= 0 && options.receiver_shadow) hit = scene.Intersect(origin, dir);
          if (!hit.Hit()) continue;
          const Frame f = ShadingFrame(scene, hit, dir);
          if (hit.mesh == receiver) {
            if (!options.receiver_shadow) continue;
            shadow_sum += receiver_ratio(f, std::max(0.0f, f.n_shade.dot(sun_dir)), rng);
            ++n_recv;
            continue;
          }
          const Lighting& l = light_of(hit.mesh);
          const Eigen::Vector3f obj_sun_dir = l.sun_direction.normalized();
          const int k = static_cast<int>(subs.size());
          subs.push_back({scene.BaseColor(hit).head<3>(), scene.HitPoint(hit), f.n_shade, &l,
                          std::max(0.0f, f.n_shade.dot(obj_sun_dir)), hit.mesh, n_ao, 0, false});
          if (subs.back().cos_sun > 0) ray_origin.push_back(f.p_offset), ray_dir.push_back(obj_sun_dir), ray_sub.push_back(-1 - k);
          const CosineLobe lobe(f.n_shade);
          const ShiftedCosinePattern sky = SkyPattern(n_ao, rng);
          for (int a = 0; a < n_ao; ++a) {
            const Eigen::Vector3f d = lobe.ToScene(sky.Local(a));
            if (d.z() > 0) ray_origin.push_back(f.p_offset), ray_dir.push_back(d), ray_sub.push_back(k);
          }
          depth = std::min(depth, hit.t * cam_z);
          ids[static_cast<size_t>(n_obj++)] = hit.mesh;
        }
        if (n_recv > 0) out.shadow.at(x, y) = static_cast<float>(shadow_sum / n_recv);
        if (n_obj == 0) continue;
        for (size_t begin = 0; begin < ray_dir.size(); begin += RayScene::kMaxFanRays) {
          const int n = static_cast<int>(std::min<size_t>(RayScene::kMaxFanRays, ray_dir.size() - begin));
          const uint32_t occluded = scene.OccludedPacket(&ray_origin[begin], &ray_dir[begin], n, 0.0f, inf, receiver);
          for (int i = 0; i < n; ++i) {
            if (occluded >> i & 1u) continue;
            const int tag = ray_sub[begin + static_cast<size_t>(i)];
            if (tag < 0) subs[static_cast<size_t>(-1 - tag)].sun_open = true;
            else ++subs[static_cast<size_t>(tag)].open;
          }
        }
        // The pixel's surfaces: sub-samples of one mesh facing alike.
        const size_t begin = surfaces.size();
        for (const Sub& sub : subs) {
          size_t g = begin;
          for (; g < surfaces.size(); ++g)
            if (surfaces[g].mesh == sub.mesh && surfaces[g].normal.normalized().dot(sub.n) > kSameSurfaceCos) break;
          if (g == surfaces.size()) {
            surfaces.emplace_back();
            surfaces.back().x = x;
            surfaces.back().mesh = sub.mesh;
          }
          SkySurface& sf = surfaces[g];
          if (sub.sun_open) sf.sun += sub.albedo.cwiseProduct(sub.light->sun_irradiance) * (sub.cos_sun / kPi);
          sf.sky += sub.albedo.cwiseProduct(sub.light->sky_radiance);
          sf.open += static_cast<float>(sub.open);
          sf.drawn += static_cast<float>(sub.drawn);
          sf.point += sub.p;
          sf.normal += sub.n;
          ++sf.samples;
        }
        for (size_t g = begin; g < surfaces.size(); ++g) {
          SkySurface& sf = surfaces[g];
          sf.point /= static_cast<float>(sf.samples);
          sf.normal = sf.normal.squaredNorm() > 0 ? sf.normal.normalized() : Eigen::Vector3f(0, 0, 1);
          sf.footprint = std::max(1e-6f, (sf.point - origin).norm() / fx);
        }
        const float inv_spp = 1.0f / static_cast<float>(spp);
        out.coverage.at(x, y) = static_cast<float>(n_obj) * inv_spp;
        out.depth.at(x, y) = depth;
        out.object.at(x, y) = MajorityId(ids.data(), n_obj);
        first.at(x - fx0, y - y0) = static_cast<int>(begin);
        count.at(x - fx0, y - y0) = static_cast<int>(surfaces.size() - begin);
      }
  });

  // Second pass: each surface's open-sky share from the same surface in the neighbouring pixels of the window.
  // Weights: a Gaussian in pixels (sigma 0.6 radius); the neighbour's distance off the surface's tangent plane, in
  // footprints (a step in depth, another part of the object behind); how far along the surface it lies per pixel
  // (a surface seen edge-on); the angle between their normals (a crease); and the neighbour's own ray count (a
  // surface with one sub-sample in a pixel drew a quarter of the rays).
  const int radius = options.sky_filter_radius;
  const float sigma_px = std::max(1.0f, 0.6f * static_cast<float>(radius));
  const float inv_2s2 = 1.0f / (2.0f * sigma_px * sigma_px);
  ParallelRows(y0, y1, [&](int y) {
    const float inv_spp = 1.0f / static_cast<float>(spp);
    const std::vector<SkySurface>& surfaces = rows[static_cast<size_t>(y - y0)];
    for (size_t i = 0; i < surfaces.size();) {
      const int x = surfaces[i].x;
      Eigen::Vector3f color = Eigen::Vector3f::Zero();
      for (; i < surfaces.size() && surfaces[i].x == x; ++i) {
        const SkySurface& p = surfaces[i];
        double open = 0, drawn = 0;
        for (int yy = std::max(y0, y - radius); yy <= std::min(y1 - 1, y + radius); ++yy) {
          const std::vector<SkySurface>& other = rows[static_cast<size_t>(yy - y0)];
          for (int xx = std::max(fx0, x - radius); xx <= std::min(fx1 - 1, x + radius); ++xx) {
            const int k0 = first.at(xx - fx0, yy - y0);
            if (k0 < 0) continue;
            for (int k = k0; k < k0 + count.at(xx - fx0, yy - y0); ++k) {
              const SkySurface& q = other[static_cast<size_t>(k)];
              if (q.mesh != p.mesh) continue;
              const float cos_n = p.normal.dot(q.normal);
              if (cos_n <= kSameSurfaceCos) continue;
              const Eigen::Vector3f d = (q.point - p.point) / p.footprint;  // in footprints
              const float off_plane = p.normal.dot(d);
              const float c2 = cos_n * cos_n, c4 = c2 * c2;  // cos^8 of the crease: 10 deg keeps 0.89, 20 deg 0.61
              // The kernel stays round in the image (a kernel stretched along a surface seen at an angle turns the
              // rays' noise into streaks), but a neighbour further along the surface than kGrazing footprints per
              // pixel (a surface seen nearly edge-on, whose sky changes over a few of its pixels) falls off.
              const float px2 = static_cast<float>((xx - x) * (xx - x) + (yy - y) * (yy - y));
              // max(0, sqrt(ratio) - kGrazing), without the root where it is 0 (most neighbours: the same bits).
              const float ratio = d.squaredNorm() / std::max(1.0f, px2);
              const float stretch = ratio > kGrazing * kGrazing ? std::sqrt(ratio) - kGrazing : 0.0f;
              const float wgt = std::exp(-px2 * inv_2s2 - 0.5f * (off_plane * off_plane + stretch * stretch)) * c4 * c4;
              open += wgt * q.open;
              drawn += wgt * q.drawn;
            }
          }
        }
        const float share = drawn > 0 ? static_cast<float>(open / drawn) : 1.0f;
        color += p.sun + p.sky * share;
      }
      color *= inv_spp;
      for (int c = 0; c < 3; ++c) out.color.at(x, y, c) = color[c];
    }
  });
  return out;
}

std::optional<std::array<int, 4>> ProjectedRect(const PinholeCamera& camera, const Rigid3d& T_cam_scene,
                                                const std::vector<Eigen::Vector3d>& points_scene, int pad) {
  double u_min = std::numeric_limits<double>::infinity(), v_min = u_min;
  double u_max = -u_min, v_max = -u_min;
  bool any = false;
  for (const Eigen::Vector3d& p : points_scene) {
    const std::optional<Eigen::Vector2d> uv = camera.Project(T_cam_scene * p);
    if (!uv || !uv->allFinite()) continue;
    any = true;
    u_min = std::min(u_min, uv->x());
    u_max = std::max(u_max, uv->x());
    v_min = std::min(v_min, uv->y());
    v_max = std::max(v_max, uv->y());
  }
  if (!any) return std::nullopt;
  // Clamp in double before converting: projections of points near the image plane can be huge.
  const auto lo = [&](double v, int size) {
    return static_cast<int>(std::clamp(std::floor(v) - pad, 0.0, static_cast<double>(size)));
  };
  const auto hi = [&](double v, int size) {
    return static_cast<int>(std::clamp(std::floor(v) + 1.0 + pad, 0.0, static_cast<double>(size)));
  };
  const std::array<int, 4> rect = {lo(u_min, camera.width), lo(v_min, camera.height), hi(u_max, camera.width),
                                   hi(v_max, camera.height)};
  if (rect[0] >= rect[2] || rect[1] >= rect[3]) return std::nullopt;
  return rect;
}

std::pair<int, int> RowRange(const std::vector<std::array<int, 4>>& rects, int height) {
  int first = height, last = 0;
  for (const auto& r : rects)
    if (r[0] < r[2] && r[1] < r[3]) first = std::min(first, std::max(0, r[1])), last = std::max(last, std::min(height, r[3]));
  return {first, last};
}

std::vector<std::pair<int, int>> RowSpans(const std::vector<std::array<int, 4>>& rects, int y, int width) {
  std::vector<std::pair<int, int>> spans;
  for (const auto& r : rects) {
    const int a = std::max(0, r[0]), b = std::min(width, r[2]);
    if (y >= r[1] && y < r[3] && a < b) spans.emplace_back(a, b);
  }
  std::sort(spans.begin(), spans.end());
  std::vector<std::pair<int, int>> merged;
  for (const auto& s : spans) {
    if (!merged.empty() && s.first <= merged.back().second) merged.back().second = std::max(merged.back().second, s.second);
    else merged.push_back(s);
  }
  return merged;
}

}  // namespace sd
