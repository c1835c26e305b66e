#include "synth/real_shadows.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <optional>
#include <utility>

#include "core/error.h"
#include "core/parallel.h"
#include "geometry/polygon.h"

namespace sd {

LinearImages::LinearImages(const std::vector<ImageF>& linear) : linear_(&linear) {}

LinearImages::LinearImages(const std::vector<ImageU8>& srgb, std::vector<Eigen::Vector3f> gains)
    : srgb_(&srgb), gains_(std::move(gains)) {
  SD_CHECK(gains_.empty() || gains_.size() == srgb.size(), << gains_.size() << " gains for " << srgb.size() << " images");
}

void LinearImages::SampleBilinear(size_t k, double u, double v, float* out) const {
  if (linear_) return sd::SampleBilinear((*linear_)[k], u, v, out);
  static const Eigen::Vector3f kOne = Eigen::Vector3f::Ones();
  sd::SampleBilinearLinear((*srgb_)[k], u, v, (gains_.empty() ? kOne : gains_[k]).data(), out);
}

namespace {

constexpr double kDeg = M_PI / 180.0;

// Visible, unoccluded ground around one annotated box: luminance per cell (NaN = not usable).
struct GroundPatch {
  size_t annotation = 0;
  std::string channel;
  Box3 box;
  double z = 0;               // ground height (box bottom)
  Eigen::Vector2d origin;     // cell (0,0) corner
  int n = 0;                  // n x n cells
  double cell = 0.1;
  std::vector<float> lum;
};

// Ray-box test: does the segment from `o` to `p` pass through the box (grown by margin)?
bool SegmentHitsBox(const Eigen::Vector3d& o, const Eigen::Vector3d& p, const Box3& box, double margin) {
  const Rigid3d inv = box.T_frame_box.Inverse();
  const Eigen::Vector3d a = inv * o, b = inv * p, d = b - a;
  const Eigen::Vector3d h = 0.5 * box.size.array() + margin;
  double t0 = 0, t1 = 1;
  for (int k = 0; k < 3; ++k) {
    if (std::abs(d[k]) < 1e-12) {
      if (std::abs(a[k]) > h[k]) return false;
      continue;
    }
    double ta = (-h[k] - a[k]) / d[k], tb = (h[k] - a[k]) / d[k];
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
    if (t0 > t1) return false;
  }
  return true;
}

// Distance from p to the segment [a, b] (2D).
double SegmentDistance(const Eigen::Vector2d& p, const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
  const Eigen::Vector2d ab = b - a;
  const double len2 = ab.squaredNorm();
  const double t = len2 > 0 ? std::clamp((p - a).dot(ab) / len2, 0.0, 1.0) : 0.0;
  return (p - (a + t * ab)).norm();
}

// How far around each box the ground is sampled, and how close to the box a cell may lie.
struct PatchSpec {
  double min_height_m = 0, max_distance_m = 0, cell_m = 0.1;
  double footprint_margin_m = 0.15;  // the box's own footprint grown by this is not ground
  std::optional<double> reach_m;     // beyond the footprint's bounding circle; empty: as far as a shadow reaches
  double own_sight_margin_m = 0.05;  // a sight line passing this close to the box itself is blocked by it
};

PatchSpec ShadowSpec(const ShadowCheckOptions& opt) {
  return {opt.min_height_m, opt.max_distance_m, opt.cell_m, opt.footprint_margin_m, std::nullopt, 0.05};
}

std::vector<GroundPatch> SampleGroundPatches(const Frame& frame, const LinearImages& linear, const PatchSpec& opt) {
  // One patch per annotation, in parallel; each cell tests only the boxes that can reach it (the answers are
  // those of testing every box: the others are farther than their bounding circle).
  std::vector<std::optional<GroundPatch>> slots(frame.annotations.size());
  ParallelFor(0, frame.annotations.size(), [&](size_t ai) {
    // Patches beside the dataset's own objects only: a detected box (synth/detected_tracks.h) may be a tile of
    // a wall or a hedge, whose shadow says little about the sun. It still blocks sight lines below.
    if (frame.annotations[ai].detected) return;
    const Box3& box = frame.annotations[ai].box;
    if (box.size.z() < opt.min_height_m || box.center().head<2>().norm() > opt.max_distance_m) return;
    // The camera that sees the box centre nearest its image centre.
    int best = -1;
    double best_r = 1e9;
    for (size_t k = 0; k < frame.cameras.size() && k < linear.size(); ++k) {
      const auto& cam = frame.cameras[k];
      const auto uv = cam.intrinsics.Project(cam.T_ego_cam.Inverse() * box.center(), 0.5);
      if (!uv || !cam.intrinsics.InImage(*uv)) continue;
      const double r = std::hypot(uv->x() / cam.intrinsics.width - 0.5, uv->y() / cam.intrinsics.height - 0.5);
      if (r < best_r) best_r = r, best = static_cast<int>(k);
    }
    if (best < 0) return;
    const auto& cam = frame.cameras[best];
    const Rigid3d T_cam_ego = cam.T_ego_cam.Inverse();
    GroundPatch g;
    g.annotation = ai;
    g.channel = cam.channel;
    g.box = box;
    g.z = box.center().z() - 0.5 * box.size.z();
    g.cell = opt.cell_m;
    // Shadows of sun elevations >= 20 deg reach at most h / tan(20 deg) from the footprint.
    const double reach = 0.5 * box.size.head<2>().norm() +
                         opt.reach_m.value_or(std::min(6.0, box.size.z() / std::tan(20 * kDeg)) + 0.2);
    g.n = static_cast<int>(std::ceil(2 * reach / g.cell));
    g.origin = box.center().head<2>() - Eigen::Vector2d::Constant(reach);
    g.lum.assign(static_cast<size_t>(g.n) * g.n, std::numeric_limits<float>::quiet_NaN());
    const Eigen::Vector3d cam_o = cam.T_ego_cam.translation;
    // Candidates: boxes (bounding circle, margins included) overlapping the patch square, and boxes near the
    // sight lines from the camera to it (within the square's half-diagonal of the line to its centre).
    const Eigen::Vector2d centre = box.center().head<2>();
    const double half_diagonal = std::sqrt(2.0) * (g.n * g.cell / 2 + g.cell);  // cell centres lie within it
    std::vector<size_t> under, between;
    for (size_t bi = 0; bi < frame.annotations.size(); ++bi) {
      const Box3& b = frame.annotations[bi].box;
      const double radius = 0.5 * b.size.norm() + std::sqrt(2.0) * std::max(opt.footprint_margin_m, 0.05) + g.cell;
      const Eigen::Vector2d c = b.center().head<2>();
      if ((c - centre).norm() <= half_diagonal + radius) under.push_back(bi);
      if (SegmentDistance(c, cam_o.head<2>(), centre) <= half_diagonal + radius) between.push_back(bi);
    }
    std::vector<BoxContainment> inside_under;
    for (size_t bi : under) inside_under.emplace_back(frame.annotations[bi].box, bi == ai ? opt.footprint_margin_m : 0.05);
    for (int j = 0; j < g.n; ++j)
      for (int i = 0; i < g.n; ++i) {
        const Eigen::Vector3d p(g.origin.x() + (i + 0.5) * g.cell, g.origin.y() + (j + 0.5) * g.cell, g.z);
        bool blocked = false;
        for (const BoxContainment& inside : inside_under)
          if (inside.Contains(p + Eigen::Vector3d(0, 0, 0.05))) {
            blocked = true;
            break;
          }
        if (blocked) continue;
        const auto uv = cam.intrinsics.Project(T_cam_ego * p, 0.5);
        if (!uv || !cam.intrinsics.InImage(*uv)) continue;
        for (size_t bi : between)
          if (SegmentHitsBox(cam_o, p + Eigen::Vector3d(0, 0, 0.02), frame.annotations[bi].box,
                             bi == ai ? opt.own_sight_margin_m : 0.05)) {
            blocked = true;
            break;
          }
        if (blocked) continue;
        float rgb[3];
        linear.SampleBilinear(static_cast<size_t>(best), uv->x(), uv->y(), rgb);
        g.lum[static_cast<size_t>(j) * g.n + i] = LinearLuminance(rgb);
      }
    slots[ai] = std::move(g);
  });
  std::vector<GroundPatch> patches;
  for (auto& slot : slots)
    if (slot) patches.push_back(std::move(*slot));
  return patches;
}

// `core`: also the 20th percentiles of both regions (ShadowCheckBox::CoreContrast), which the sun search, judging
// hundreds of directions, does not need.
ShadowCheck Judge(const std::vector<GroundPatch>& patches, const Eigen::Vector3d& sun, const ShadowCheckOptions& opt,
                  bool core) {
  ShadowCheck out;
  double sum_log = 0;
  int agree = 0;
  for (const auto& g : patches) {
    const auto hull = ShadowHull(g.box, sun, false), mirror = ShadowHull(g.box, sun, true);
    double s_sum = 0, m_sum = 0;
    int s_n = 0, m_n = 0;
    std::vector<float> s_values, m_values;
    for (int j = 0; j < g.n; ++j)
      for (int i = 0; i < g.n; ++i) {
        const float y = g.lum[static_cast<size_t>(j) * g.n + i];
        if (std::isnan(y)) continue;
        const Eigen::Vector2d p(g.origin.x() + (i + 0.5) * g.cell, g.origin.y() + (j + 0.5) * g.cell);
        const bool in_s = geometry::InsideConvexPolygon(hull, p), in_m = geometry::InsideConvexPolygon(mirror, p);
        if (in_s == in_m) continue;  // the footprint (in both) or neither
        if (in_s) s_sum += y, ++s_n;
        else m_sum += y, ++m_n;
        if (core) (in_s ? s_values : m_values).push_back(y);
      }
    if (s_n < opt.min_cells || m_n < opt.min_cells) continue;
    ShadowCheckBox b;
    b.annotation = g.annotation;
    b.channel = g.channel;
    b.shadow_luminance = s_sum / s_n;
    b.mirrored_luminance = m_sum / m_n;
    if (b.shadow_luminance <= 0 || b.mirrored_luminance <= 0) continue;
    if (core) {
      auto p20 = [](std::vector<float>& v) {
        std::nth_element(v.begin(), v.begin() + v.size() / 5, v.end());
        return static_cast<double>(v[v.size() / 5]);
      };
      b.shadow_core_luminance = p20(s_values);
      b.mirrored_core_luminance = p20(m_values);
    }
    sum_log += std::clamp(std::log(b.Ratio()), -1.0, 1.0);  // one odd object (a dark kerb, a black car) must not decide alone
    agree += b.Ratio() > 1.0 ? 1 : 0;
    out.boxes.push_back(b);
  }
  if (!out.boxes.empty()) {
    out.agreement = static_cast<double>(agree) / out.boxes.size();
    out.mean_log_ratio = sum_log / out.boxes.size();
  }
  return out;
}

}  // namespace

std::vector<Eigen::Vector2d> ShadowHull(const Box3& box, const Eigen::Vector3d& sun, bool mirrored) {
  const auto corners = box.Corners();
  const double z0 = box.center().z() - 0.5 * box.size.z();
  const Eigen::Vector3d s = sun.normalized();
  const double sz = std::max(s.z(), 0.05);
  std::vector<Eigen::Vector2d> pts;
  for (int i = 0; i < 8; ++i) {
    const Eigen::Vector3d& c = corners[i];
    Eigen::Vector2d off = -s.head<2>() * ((c.z() - z0) / sz);  // along the light, down to the ground plane
    if (mirrored) off = -off;
    pts.push_back(c.head<2>() + off);
  }
  return geometry::ConvexHull2D(std::move(pts));
}

ShadowCheck CheckSunAgainstShadows(const Frame& frame, const LinearImages& linear, const Eigen::Vector3d& sun,
                                   const ShadowCheckOptions& options) {
  return Judge(SampleGroundPatches(frame, linear, ShadowSpec(options)), sun, options, /*core=*/true);
}

std::optional<Eigen::Vector3d> EstimateSunFromShadows(const Frame& frame, const LinearImages& linear,
                                                      const ShadowCheckOptions& options, ShadowCheck* best,
                                                      std::optional<double> elevation_deg) {
  const auto patches = SampleGroundPatches(frame, linear, ShadowSpec(options));
  std::vector<double> elevations;
  if (elevation_deg) elevations.push_back(*elevation_deg);
  else
    for (int el = 20; el <= 80; el += 10) elevations.push_back(el);
  std::vector<Eigen::Vector3d> dirs;
  for (double el : elevations)
    for (int az = 0; az < 360; az += 5)
      dirs.emplace_back(std::cos(el * kDeg) * std::cos(az * kDeg), std::cos(el * kDeg) * std::sin(az * kDeg), std::sin(el * kDeg));
  std::vector<ShadowCheck> checks(dirs.size());
  ParallelFor(0, dirs.size(), [&](size_t i) { checks[i] = Judge(patches, dirs[i], options, /*core=*/false); });
  std::optional<Eigen::Vector3d> out;
  double score = -std::numeric_limits<double>::infinity();
  for (size_t i = 0; i < dirs.size(); ++i) {
    // Every direction must be judged on the same objects to compare; a direction that loses objects (too
    // little visible ground) competes with fewer votes, so weight by how many it judged.
    if (checks[i].boxes.empty()) continue;
    const double s = checks[i].mean_log_ratio * std::sqrt(static_cast<double>(checks[i].boxes.size()));
    if (s > score) {
      score = s;
      out = dirs[i];
      if (best) *best = checks[i];
    }
  }
  return out;
}

std::vector<ContactCheckBox> CheckContactDarkening(const Frame& frame, const LinearImages& linear,
                                                   const std::optional<Eigen::Vector3d>& sun_dir_ego,
                                                   const ContactCheckOptions& opt) {
  PatchSpec spec;
  spec.min_height_m = opt.min_height_m;
  spec.max_distance_m = opt.max_distance_m;
  spec.cell_m = opt.cell_m;
  spec.footprint_margin_m = 0;  // the band starts at the footprint's edge
  spec.reach_m = opt.far_to_m + opt.cell_m;
  // The road just in front of the object, seen past its own box: only the box itself, not a margin around it,
  // may hide it (the band would otherwise start where the contact darkening has already faded).
  spec.own_sight_margin_m = 0.005;
  const std::vector<GroundPatch> patches = SampleGroundPatches(frame, linear, spec);
  struct Hull {
    std::vector<Eigen::Vector2d> polygon;
    Eigen::Vector2d lo, hi;
  };
  std::vector<Hull> shadows;
  if (sun_dir_ego && sun_dir_ego->z() > 0.05)
    for (const Annotation& a : frame.annotations) {
      Hull h;
      h.polygon = ShadowHull(a.box, *sun_dir_ego);
      h.lo = h.hi = h.polygon.front();
      for (const auto& p : h.polygon) h.lo = h.lo.cwiseMin(p), h.hi = h.hi.cwiseMax(p);
      shadows.push_back(std::move(h));
    }
  std::vector<ContactCheckBox> out;
  for (const GroundPatch& g : patches) {
    const Rigid3d T_box_frame = g.box.T_frame_box.Inverse();
    const Eigen::Vector2d half = 0.5 * g.box.size.head<2>();
    const Eigen::Vector2d patch_lo = g.origin, patch_hi = g.origin + Eigen::Vector2d::Constant(g.n * g.cell);
    std::vector<const Hull*> reaching;
    for (const Hull& h : shadows)
      if ((h.lo.array() <= patch_hi.array()).all() && (h.hi.array() >= patch_lo.array()).all()) reaching.push_back(&h);
    std::vector<float> near, far;
    for (int j = 0; j < g.n; ++j)
      for (int i = 0; i < g.n; ++i) {
        const float y = g.lum[static_cast<size_t>(j) * g.n + i];
        if (std::isnan(y)) continue;
        const Eigen::Vector2d p(g.origin.x() + (i + 0.5) * g.cell, g.origin.y() + (j + 0.5) * g.cell);
        const Eigen::Vector3d q = T_box_frame * Eigen::Vector3d(p.x(), p.y(), g.z);
        const double d = Eigen::Vector2d(std::max(std::abs(q.x()) - half.x(), 0.0), std::max(std::abs(q.y()) - half.y(), 0.0)).norm();
        const bool in_near = d > opt.near_from_m && d <= opt.near_to_m, in_far = d > opt.far_from_m && d <= opt.far_to_m;
        if (!in_near && !in_far) continue;
        bool shaded = false;
        for (const Hull* h : reaching)
          if (geometry::InsideConvexPolygon(h->polygon, p)) {
            shaded = true;
            break;
          }
        if (!shaded) (in_near ? near : far).push_back(y);
      }
    if (static_cast<int>(near.size()) < opt.min_cells || static_cast<int>(far.size()) < opt.min_cells) continue;
    auto median = [](std::vector<float>& v) {
      std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
      return static_cast<double>(v[v.size() / 2]);
    };
    ContactCheckBox b;
    b.annotation = g.annotation;
    b.channel = g.channel;
    b.near_luminance = median(near);
    b.far_luminance = median(far);
    if (b.near_luminance > 0 && b.far_luminance > 0) out.push_back(b);
  }
  return out;
}

}  // namespace sd
