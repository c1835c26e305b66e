#include "render/camera_render.h"

#include <algorithm>
#include <cmath>
#include <limits>

#include "core/error.h"
#include "core/parallel.h"

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

// k-th of n stratified points in [0,1)^2: cells of a cols x rows grid (cols = ceil(sqrt(n))), jittered.
Eigen::Vector2f Stratified(int k, int n, PixelRng& rng) {
  const int cols = static_cast<int>(std::ceil(std::sqrt(static_cast<double>(n))));
  const int rows = (n + cols - 1) / cols;
  const float jx = rng.Next(), jy = rng.Next();
  return {(static_cast<float>(k % cols) + jx) / static_cast<float>(cols),
          (static_cast<float>(k / cols) + jy) / static_cast<float>(rows)};
}

// Cosine-weighted direction around unit `n` from a point in [0,1)^2 (Malley's method); the orthonormal
// basis is Duff et al. 2017, "Building an Orthonormal Basis, Revisited".
Eigen::Vector3f CosineDirection(const Eigen::Vector3f& n, const Eigen::Vector2f& xi) {
  const float r = std::sqrt(xi.x());
  const float phi = 2.0f * kPi * xi.y();
  const float lx = r * std::cos(phi), ly = r * std::sin(phi), lz = std::sqrt(std::max(0.0f, 1.0f - xi.x()));
  const float sign = std::copysign(1.0f, n.z());
  const float a = -1.0f / (sign + n.z());
  const float b = n.x() * n.y() * a;
  const Eigen::Vector3f t(1.0f + sign * n.x() * n.x() * a, sign * b, -sign * n.x());
  const Eigen::Vector3f bt(b, sign + n.y() * n.y() * a, -n.y());
  return (lx * t + ly * bt + lz * n).normalized();
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

// The light of a pixel traced in full whose sub-samples all hit one object (RenderCamera's adaptive mode).
struct LightAnchor {
  int mesh = -1;  // -1: not an anchor (edge, background, several objects)
  float sun = 0;  // sun visibility, mean over the sub-samples
  float sky = 0;  // open sky share, mean over the sub-samples
  Eigen::Vector3f normal = Eigen::Vector3f::Zero();  // mean shading normal, unit
};
// The light a pixel between four alike anchors takes instead of tracing it.
struct LightHint {
  int mesh;
  float sun, sky;
  Eigen::Vector3f normal;
};
// Anchors and sub-samples must face within ~18 degrees of each other for the light to carry over: across a crease
// the sky a surface sees changes at once.
constexpr float kHintNormalCos = 0.95f;

}  // namespace

CameraRender RenderCamera(const RayScene& scene, const PinholeCamera& camera, const Rigid3d& T_scene_cam,
                          const Lighting& lighting, const CameraRenderOptions& options) {
  SD_CHECK(camera.width > 0 && camera.height > 0, << camera.width << "x" << camera.height);
  SD_CHECK(options.samples_per_pixel > 0 && options.ao_samples >= 0,
           << "spp " << options.samples_per_pixel << ", ao " << options.ao_samples);
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
  int y0 = h, y1 = 0;
  for (const auto& r : rects)
    if (r[0] < r[2] && r[1] < r[3]) y0 = std::min(y0, std::max(0, r[1])), y1 = std::max(y1, std::min(h, r[3]));
  if (y0 >= y1) return out;

  const Eigen::Matrix3d R_scene_cam = T_scene_cam.Rotation();
  const Eigen::Vector3f origin = T_scene_cam.translation.cast<float>();
  const Eigen::Vector3f sun_dir = lighting.sun_direction.normalized();
  const Eigen::Vector3f sun = lighting.sun_irradiance, sky = lighting.sky_radiance;
  const float sun_y = Luminance(sun), sky_y = Luminance(sky);
  const int spp = options.samples_per_pixel;
  const int n_ao = options.ao_samples;
  const int receiver = options.receiver_mesh;
  const float inf = std::numeric_limits<float>::infinity();

  const bool adaptive = options.light_blend_tolerance > 0;

  // One pixel. With `hint`, sub-samples on the hint's mesh facing its way take its light (sun visibility and
  // open sky) instead of tracing it; with `anchor`, a pixel whose sub-samples all hit one object records its light.
  const auto render_pixel = [&](int x, int y, const LightHint* hint, LightAnchor* anchor, bool write) {
    PixelRng rng(options.seed, x, y);
    Eigen::Vector3f color = Eigen::Vector3f::Zero();
    int n_obj = 0, n_recv = 0;
    float depth = inf;
    double shadow_sum = 0.0;
    std::array<int, 16> ids_small{};
    std::vector<int> ids_large(spp > 16 ? static_cast<size_t>(spp) : 0);
    int* ids = spp > 16 ? ids_large.data() : ids_small.data();
    float anchor_sun = 0, anchor_sky = 0;
    Eigen::Vector3f anchor_normal = Eigen::Vector3f::Zero();
    for (int s = 0; s < spp; ++s) {
      const Eigen::Vector2f jitter = Stratified(s, spp, rng);
      const Eigen::Vector3d d_cam = camera.RayDirection(Eigen::Vector2d(x + jitter.x(), y + jitter.y()));
      const Eigen::Vector3f dir = (R_scene_cam * d_cam).cast<float>().normalized();
      // The receiver stands in for the real road, which is in the photo already: it never hides an object (a
      // patch laid on a kerb's slope rises metres away from its object). Objects first, the receiver where none.
      RayHit hit = scene.Intersect(origin, dir, 0.0f, inf, receiver);
      if (!hit.Hit() && receiver >= 0 && options.receiver_shadow) hit = scene.Intersect(origin, dir);
      if (!hit.Hit()) continue;
      const Frame f = ShadingFrame(scene, hit, dir);
      const float cos_sun = std::max(0.0f, f.n_shade.dot(sun_dir));

      if (hit.mesh == receiver) {
        if (!options.receiver_shadow) continue;
        // Light the real road got (no objects) vs what it gets now; visibility ignores the road itself.
        const bool sun_visible = cos_sun > 0 && !scene.Occluded(f.p_offset, sun_dir, 0.0f, inf, receiver);
        int sky_with = 0, sky_without = 0;
        for (int k = 0; k < n_ao; ++k) {
          const Eigen::Vector3f d = CosineDirection(f.n_shade, Stratified(k, n_ao, rng));
          if (d.z() <= 0) continue;
          ++sky_without;
          if (!scene.Occluded(f.p_offset, d, 0.0f, inf, receiver)) ++sky_with;
        }
        const float ao_with = n_ao > 0 ? static_cast<float>(sky_with) / n_ao : 1.0f;
        const float ao_without = n_ao > 0 ? static_cast<float>(sky_without) / n_ao : 1.0f;
        const float den = sun_y * cos_sun + sky_y * kPi * ao_without;
        const float num = sun_y * cos_sun * (sun_visible ? 1.0f : 0.0f) + sky_y * kPi * ao_with;
        shadow_sum += den > 0 ? num / den : 1.0f;
        ++n_recv;
        continue;
      }

      // Object: Lambertian, L = a * E / pi, under its own light where the caller gives one.
      const bool own = static_cast<size_t>(hit.mesh) < options.mesh_lighting.size();
      const Lighting& l = own ? options.mesh_lighting[static_cast<size_t>(hit.mesh)] : lighting;
      const Eigen::Vector3f obj_sun_dir = own ? l.sun_direction.normalized() : sun_dir;
      const float obj_cos_sun = own ? std::max(0.0f, f.n_shade.dot(obj_sun_dir)) : cos_sun;
      float sun_visible = 0, ao = 1;
      if (hint && hit.mesh == hint->mesh && f.n_shade.dot(hint->normal) >= kHintNormalCos) {
        sun_visible = hint->sun;
        ao = hint->sky;
      } else {
        // Nor does the receiver shade an object: the real road below is already counted by the upper-hemisphere
        // test. An anchor traces the sun where it faces away too: its neighbours may face it.
        sun_visible = (obj_cos_sun > 0 || anchor) && !scene.Occluded(f.p_offset, obj_sun_dir, 0.0f, inf, receiver) ? 1.0f : 0.0f;
        int sky_open = 0;
        for (int k = 0; k < n_ao; ++k) {
          const Eigen::Vector3f d = CosineDirection(f.n_shade, Stratified(k, n_ao, rng));
          if (d.z() > 0 && !scene.Occluded(f.p_offset, d, 0.0f, inf, receiver)) ++sky_open;
        }
        ao = n_ao > 0 ? static_cast<float>(sky_open) / n_ao : 1.0f;
      }
      anchor_sun += sun_visible, anchor_sky += ao, anchor_normal += f.n_shade;
      const Eigen::Vector3f E = l.sun_irradiance * (obj_cos_sun * sun_visible) + l.sky_radiance * (kPi * ao);
      const Eigen::Vector3f albedo = scene.BaseColor(hit).head<3>();
      color += albedo.cwiseProduct(E) / kPi;
      depth = std::min(depth, hit.t * static_cast<float>(d_cam.z()));
      ids[n_obj++] = hit.mesh;
    }

    if (n_obj > 0) {
      const float inv_spp = 1.0f / static_cast<float>(spp);
      // Majority vote; ties go to the smallest mesh id so the result is independent of sample order.
      std::sort(ids, ids + n_obj);
      int best = ids[0], best_count = 0;
      for (int i = 0; i < n_obj;) {
        int j = i;
        while (j < n_obj && ids[j] == ids[i]) ++j;
        if (j - i > best_count) {
          best_count = j - i;
          best = ids[i];
        }
        i = j;
      }
      if (anchor && n_obj == spp && best_count == spp && anchor_normal.squaredNorm() > 0)
        *anchor = {best, anchor_sun / spp, anchor_sky / spp, anchor_normal.normalized()};
      if (write) {
        for (int c = 0; c < 3; ++c) out.color.at(x, y, c) = color[c] * inv_spp;
        out.coverage.at(x, y) = static_cast<float>(n_obj) * inv_spp;
        out.depth.at(x, y) = depth;
        out.object.at(x, y) = best;
      }
    }
    if (write && n_recv > 0) out.shadow.at(x, y) = static_cast<float>(shadow_sum / n_recv);
  };

  if (!adaptive) {
    ParallelFor(static_cast<size_t>(y0), static_cast<size_t>(y1), [&](size_t row) {
      const int y = static_cast<int>(row);
      for (const auto& [x0, x1] : RowSpans(rects, y, w))
        for (int x = x0; x < x1; ++x) render_pixel(x, y, nullptr, nullptr, true);
    });
    return out;
  }

  // Adaptive: the light of an object changes slowly across its surface but for shadow edges and creases. Pixels of
  // even row and column (over the rectangles grown by the 2 pixels a neighbour reads, so a pixel's result does not
  // depend on the rectangles) are traced in full and anchor their light; a pixel between four anchors on one
  // object, facing alike, with the same sun visibility and open sky within the tolerance, takes their bilinear
  // blend for its sub-samples on that object, and traces only its camera rays.
  std::vector<std::array<int, 4>> grown;
  for (const auto& r : rects) grown.push_back({r[0] - 2, r[1] - 2, r[2] + 2, r[3] + 2});
  std::vector<LightAnchor> anchors(static_cast<size_t>((w + 1) / 2) * ((h + 1) / 2));
  const auto anchor_at = [&](int gx, int gy) -> LightAnchor& { return anchors[static_cast<size_t>(gy / 2) * ((w + 1) / 2) + gx / 2]; };
  const int gy0 = std::max(0, y0 - 2) & ~1, gy1 = std::min(h, y1 + 2);
  ParallelFor(static_cast<size_t>(gy0 / 2), static_cast<size_t>((gy1 + 1) / 2), [&](size_t half_row) {
    const int y = static_cast<int>(half_row) * 2;
    if (y >= h) return;
    // Anchors outside the rectangles only anchor: their pixels stay "nothing" in `out`.
    for (const auto& [x0, x1] : RowSpans(grown, y, w))
      for (int x = x0 + (x0 % 2); x < x1; x += 2) {
        const bool inside = std::any_of(rects.begin(), rects.end(),
                                        [&](const auto& r) { return x >= r[0] && x < r[2] && y >= r[1] && y < r[3]; });
        render_pixel(x, y, nullptr, &anchor_at(x, y), inside);
      }
  });
  ParallelFor(static_cast<size_t>(y0), static_cast<size_t>(y1), [&](size_t row) {
    const int y = static_cast<int>(row);
    for (const auto& [x0, x1] : RowSpans(rects, y, w))
      for (int x = x0; x < x1; ++x) {
        if (x % 2 == 0 && y % 2 == 0) continue;  // an anchor, done
        const int ax0 = x & ~1, ay0 = y & ~1, ax1 = x % 2 ? ax0 + 2 : ax0, ay1 = y % 2 ? ay0 + 2 : ay0;
        std::optional<LightHint> hint;
        if (ax1 < w && ay1 < h) {
          const LightAnchor* a[4] = {&anchor_at(ax0, ay0), &anchor_at(ax1, ay0), &anchor_at(ax0, ay1), &anchor_at(ax1, ay1)};
          bool alike = a[0]->mesh >= 0;
          float lo = 2, hi = -1;
          for (const LightAnchor* q : a) {
            alike = alike && q->mesh == a[0]->mesh && q->sun == a[0]->sun && q->normal.dot(a[0]->normal) >= kHintNormalCos;
            lo = std::min(lo, q->sky), hi = std::max(hi, q->sky);
          }
          if (alike && hi - lo <= options.light_blend_tolerance) {
            const float fx = 0.5f * static_cast<float>(x - ax0), fy = 0.5f * static_cast<float>(y - ay0);
            const auto blend = [&](float v00, float v10, float v01, float v11) {
              return (1 - fy) * ((1 - fx) * v00 + fx * v10) + fy * ((1 - fx) * v01 + fx * v11);
            };
            hint = LightHint{a[0]->mesh, a[0]->sun, blend(a[0]->sky, a[1]->sky, a[2]->sky, a[3]->sky),
                             (a[0]->normal + a[1]->normal + a[2]->normal + a[3]->normal).normalized()};
          }
        }
        render_pixel(x, y, hint ? &*hint : nullptr, nullptr, true);
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
