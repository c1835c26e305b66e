#include "synth/occlusion.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <utility>

#include "core/error.h"
#include "core/parallel.h"
#include "render/camera_render.h"

namespace sd {

std::vector<ProjectedPoint> ProjectPoints(const std::vector<Eigen::Vector3d>& points_ego, const std::vector<uint8_t>& is_ground,
                                          const PinholeCamera& camera, const Rigid3d& T_cam_ego) {
  std::vector<ProjectedPoint> out;
  for (size_t i = 0; i < points_ego.size(); ++i) {
    const Eigen::Vector3d p = T_cam_ego * points_ego[i];
    const auto uv = camera.Project(p, 0.5);
    if (!uv || !camera.InImage(*uv)) continue;
    out.push_back({static_cast<float>(uv->x()), static_cast<float>(uv->y()), static_cast<float>(p.z()),
                   !is_ground.empty() && is_ground[i] != 0});
  }
  return out;
}

ImageF ComputeVisibility(const std::vector<ProjectedPoint>& points, const ImageF& object_depth, const OcclusionOptions& options) {
  const int W = object_depth.width(), H = object_depth.height();
  ImageF vis(W, H, 1, 1.0f);
  // Bucket points by column for the strip searches; each column sorted by v.
  std::vector<std::vector<const ProjectedPoint*>> columns(W);
  for (const auto& p : points) {
    const int x = std::clamp(static_cast<int>(p.u), 0, W - 1);
    columns[x].push_back(&p);
  }
  for (auto& col : columns) std::sort(col.begin(), col.end(), [](auto* a, auto* b) { return a->v < b->v; });

  ParallelRows(0, H, [&](int y) {
    const float vc = y + 0.5f;
    for (int x = 0; x < W; ++x) {
      const float d = object_depth.at(x, y);
      if (!std::isfinite(d)) continue;
      const float tol = static_cast<float>(std::max(options.tol_abs, options.tol_rel * d));
      // Nearest point above (v <= vc) and below (v > vc) in the strip.
      const ProjectedPoint* above = nullptr;
      const ProjectedPoint* below = nullptr;
      for (int cx = std::max(0, x - options.column_half_width); cx <= std::min(W - 1, x + options.column_half_width); ++cx) {
        const auto& col = columns[cx];
        auto it = std::lower_bound(col.begin(), col.end(), vc, [](const ProjectedPoint* p, float v) { return p->v <= v; });
        if (it != col.end() && (*it)->v - vc <= options.max_gap && (!below || (*it)->v < below->v)) below = *it;
        if (it != col.begin()) {
          const ProjectedPoint* a = *(it - 1);
          if (vc - a->v <= options.max_gap && (!above || a->v > above->v)) above = a;
        }
      }
      auto occludes = [&](const ProjectedPoint* p) { return p && !p->ground && p->depth < d - tol; };
      bool hidden = false;
      if (above && below) {
        hidden = (vc - above->v <= below->v - vc) ? occludes(above) : occludes(below);
        if (occludes(above) && occludes(below)) hidden = true;
      } else if (above || below) {
        const ProjectedPoint* p = above ? above : below;
        hidden = occludes(p) && std::abs(p->v - vc) <= 0.5f * options.max_gap;
      }
      if (hidden) vis.at(x, y) = 0.0f;
    }
  });
  return vis;
}


// ---- Dense depth ----------------------------------------------------------------------------------------------

namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();

size_t Idx(int x, int y, int w) { return static_cast<size_t>(y) * w + x; }

// Separable running minimum over a (2r+1)^2 window.
std::vector<float> MinFilter(const std::vector<float>& in, int w, int h, int r) {
  std::vector<float> tmp(in.size(), kInf), out(in.size(), kInf);
  ParallelRows(0, h, [&](int y) {
    for (int x = 0; x < w; ++x) {
      float m = kInf;
      for (int k = std::max(0, x - r); k <= std::min(w - 1, x + r); ++k) m = std::min(m, in[Idx(k, y, w)]);
      tmp[Idx(x, y, w)] = m;
    }
  });
  ParallelRows(0, h, [&](int y) {
    for (int x = 0; x < w; ++x) {
      float m = kInf;
      for (int k = std::max(0, y - r); k <= std::min(h - 1, y + r); ++k) m = std::min(m, tmp[Idx(x, k, w)]);
      out[Idx(x, y, w)] = m;
    }
  });
  return out;
}

struct Candidate {
  float u, v, depth;
  float rgb[3];
  bool ground;
};

struct Vote {
  float depth;
  float r2;       // squared image distance to the pixel
  double cd2;     // squared colour distance to the pixel
  bool ground;
  double weight = 0;  // bilateral: picks the surface
  double near = 0;    // inverse distance (power 8): interpolates within it, dominated by the nearest points
};

// Depth along the camera ray `dir_cam` (unit) where it first enters the box; +inf when it misses or starts inside.
float RayBoxDepth(const Rigid3d& T_box_cam, const Eigen::Vector3d& half, const Eigen::Vector3d& dir_cam) {
  const Eigen::Vector3d o = T_box_cam.translation, d = T_box_cam.rotation * dir_cam;
  double t0 = -std::numeric_limits<double>::infinity(), t1 = std::numeric_limits<double>::infinity();
  for (int a = 0; a < 3; ++a) {
    if (std::abs(d[a]) < 1e-12) {
      if (std::abs(o[a]) > half[a]) return kInf;
      continue;
    }
    double ta = (-half[a] - o[a]) / d[a], tb = (half[a] - o[a]) / d[a];
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
  }
  if (!(t0 > 0 && t1 >= t0)) return kInf;
  return static_cast<float>(t0 * dir_cam.z());
}

// Depth along the camera ray where it meets the surface (fixed-point iteration on the local height); +inf if
// it looks above the horizon, leaves the surface's extent or does not settle.
float RaySurfaceDepth(const SurfaceModel& surface, const Rigid3d& T_world_cam, const Eigen::Vector3d& dir_cam) {
  const Eigen::Vector3d dir = T_world_cam.rotation * dir_cam, o = T_world_cam.translation;
  if (dir.z() > -1e-4) return kInf;
  const auto below = surface.At(o.head<2>());
  double h = below ? below->height : o.z() - 1.5;
  for (int it = 0; it < 8; ++it) {
    const double t = (o.z() - h) / -dir.z();
    if (!(t > 0 && t < 250)) return kInf;
    const Eigen::Vector3d p = o + t * dir;
    const auto s = surface.At(p.head<2>());
    if (!s) return kInf;
    if (std::abs(s->height - h) < 0.02) return static_cast<float>(t * dir_cam.z());
    h = s->height;
  }
  return kInf;
}

// FilterHiddenPoints for the points that project into the pixels [x0, x1) x [y0, y1) only: the z-buffer and its
// minimum filter cover that box grown by the window, not the whole image, and each point's answer is the one the
// whole image gives (its window lies in the grown box).
std::vector<ProjectedPoint> FilterHiddenPointsIn(const std::vector<ProjectedPoint>& points, int width, int height, int x0,
                                                 int y0, int x1, int y1, const DenseDepthOptions& options) {
  const int r = std::max(0, options.hidden_window_px);
  const int zx0 = std::max(0, x0 - r), zy0 = std::max(0, y0 - r);
  const int zx1 = std::min(width, x1 + r), zy1 = std::min(height, y1 + r);
  const int zw = zx1 - zx0, zh = zy1 - zy0;
  if (zw <= 0 || zh <= 0) return {};
  std::vector<float> zb(static_cast<size_t>(zw) * zh, kInf);
  const auto pixel_of = [&](const ProjectedPoint& p, int* x, int* y) {
    *x = static_cast<int>(std::floor(p.u));
    *y = static_cast<int>(std::floor(p.v));
    return *x >= 0 && *y >= 0 && *x < width && *y < height && std::isfinite(p.depth) && p.depth > 0;
  };
  int x = 0, y = 0;
  for (const auto& p : points)
    if (pixel_of(p, &x, &y) && x >= zx0 && x < zx1 && y >= zy0 && y < zy1) {
      float& z = zb[Idx(x - zx0, y - zy0, zw)];
      z = std::min(z, p.depth);
    }
  const std::vector<float> nearest = MinFilter(zb, zw, zh, r);
  std::vector<ProjectedPoint> kept;
  kept.reserve(points.size());
  for (const auto& p : points) {
    if (!pixel_of(p, &x, &y) || x < x0 || x >= x1 || y < y0 || y >= y1) continue;
    if (nearest[Idx(x - zx0, y - zy0, zw)] < p.depth / (1.0 + options.hidden_rel) - 0.3) continue;
    kept.push_back(p);
  }
  return kept;
}
}  // namespace

std::vector<ProjectedPoint> FilterHiddenPoints(const std::vector<ProjectedPoint>& points, int width, int height,
                                               const DenseDepthOptions& options) {
  return FilterHiddenPointsIn(points, width, height, 0, 0, width, height, options);
}

DepthMap DenseDepth(const std::vector<ProjectedPoint>& points, const ImageU8& image, const PinholeCamera& camera,
                    const Rigid3d& T_cam_ego, const DepthPriors& priors, const DenseDepthOptions& options) {
  const int W = camera.width, H = camera.height;
  SD_CHECK(W > 0 && H > 0, << W << "x" << H);
  if (options.edge_aware && (image.width() != W || image.height() != H || image.channels() < 3))
    throw InputError({}, Msg() << "dense depth: the guide image is " << image.width() << "x" << image.height() << "x"
                               << image.channels() << " but the camera is " << W << "x" << H << " RGB");
  if (options.max_fill_px < 1 || !(options.sigma_space_px > 0) || !(options.sigma_color > 0) || !(options.cluster_rel > 0))
    throw InputError({}, "dense depth: max_fill_px, sigma_space_px, sigma_color and cluster_rel must be positive");
  const bool whole = options.rects.empty() && options.x0 == 0 && options.y0 == 0 && options.x1 == 0 && options.y1 == 0;
  std::vector<std::array<int, 4>> rects;  // clamped to the image, none empty
  if (whole) rects.push_back({0, 0, W, H});
  else if (options.rects.empty()) rects.push_back({options.x0, options.y0, options.x1, options.y1});
  else rects = options.rects;
  for (auto& r : rects) r = {std::clamp(r[0], 0, W), std::clamp(r[1], 0, H), std::clamp(r[2], 0, W), std::clamp(r[3], 0, H)};
  const auto empty = [](const std::array<int, 4>& r) { return r[0] >= r[2] || r[1] >= r[3]; };
  rects.erase(std::remove_if(rects.begin(), rects.end(), empty), rects.end());
  // Their bounds: the candidates are gathered for these, so that a pixel's candidates, and their order, are its own
  // whatever else is filled.
  int rx0 = rects.empty() ? 0 : W, ry0 = rects.empty() ? 0 : H, rx1 = 0, ry1 = 0;
  for (const auto& r : rects)
    rx0 = std::min(rx0, r[0]), ry0 = std::min(ry0, r[1]), rx1 = std::max(rx1, r[2]), ry1 = std::max(ry1, r[3]);

  // Points reach the pixels within max_fill_px of them: only those projecting into the region grown by that much
  // (and a pixel) can be candidates, so the hidden-point filter and the per-pixel map cover that box alone.
  const int reach = options.max_fill_px + 1;
  const int bx0 = std::max(0, rx0 - reach), by0 = std::max(0, ry0 - reach);
  const int bx1 = std::min(W, rx1 + reach), by1 = std::min(H, ry1 + reach);
  const int bw = std::max(0, bx1 - bx0), bh = std::max(0, by1 - by0);
  const std::vector<ProjectedPoint> kept = FilterHiddenPointsIn(points, W, H, bx0, by0, bx1, by1, options);
  // One candidate per pixel: its nearest kept point.
  std::vector<int> at(static_cast<size_t>(bw) * bh, -1);
  for (size_t i = 0; i < kept.size(); ++i) {
    const size_t k = Idx(static_cast<int>(kept[i].u) - bx0, static_cast<int>(kept[i].v) - by0, bw);
    if (at[k] < 0 || kept[i].depth < kept[static_cast<size_t>(at[k])].depth) at[k] = static_cast<int>(i);
  }
  // The guide colour is the image's own 0..255 values. Not smoothed: at an edge, smoothing gives the pixels beside
  // it a colour between both sides, which no point matches.
  std::vector<Candidate> cands;
  for (size_t k = 0; k < at.size(); ++k) {
    if (at[k] < 0) continue;
    const ProjectedPoint& p = kept[static_cast<size_t>(at[k])];
    Candidate c{p.u, p.v, p.depth, {0, 0, 0}, p.ground};
    if (options.edge_aware)
      for (int ch = 0; ch < 3; ++ch) c.rgb[ch] = image.at(bx0 + static_cast<int>(k % bw), by0 + static_cast<int>(k / bw), ch);
    cands.push_back(c);
  }
  constexpr int kCell = 16;
  const int gw = (W + kCell - 1) / kCell, gh = (H + kCell - 1) / kCell;
  std::vector<std::vector<int>> grid(static_cast<size_t>(gw) * gh);
  for (size_t i = 0; i < cands.size(); ++i)
    grid[Idx(static_cast<int>(cands[i].u) / kCell, static_cast<int>(cands[i].v) / kCell, gw)].push_back(static_cast<int>(i));

  DepthMap out{ImageF(W, H, 1, kInf), ImageF(W, H, 1, 0.0f), ImageU8(W, H, 1, 0)};
  const float R = static_cast<float>(options.max_fill_px), R2 = R * R;
  const double inv_sc = 1.0 / (2 * options.sigma_color * options.sigma_color);
  ParallelRows(ry0, ry1, [&](int y) {
    const float pv = y + 0.5f;
    std::vector<Vote> votes;
    const int cy0 = std::max(0, static_cast<int>((pv - R) / kCell)), cy1 = std::min(gh - 1, static_cast<int>((pv + R) / kCell));
    for (const auto& [sx0, sx1] : RowSpans(rects, y, W)) for (int x = sx0; x < sx1; ++x) {
      const float pu = x + 0.5f;
      const int cx0 = std::max(0, static_cast<int>((pu - R) / kCell)), cx1 = std::min(gw - 1, static_cast<int>((pu + R) / kCell));
      votes.clear();
      float best_r2 = kInf, nn_depth = kInf;
      bool nn_ground = false;
      float guide[3] = {0, 0, 0};
      if (options.edge_aware)
        for (int ch = 0; ch < 3; ++ch) guide[ch] = image.at(x, y, ch);
      const float* rgb = options.edge_aware ? guide : nullptr;
      for (int cy = cy0; cy <= cy1; ++cy)
        for (int cx = cx0; cx <= cx1; ++cx)
          for (int i : grid[Idx(cx, cy, gw)]) {
            const Candidate& c = cands[static_cast<size_t>(i)];
            const float du = c.u - pu, dv = c.v - pv, r2 = du * du + dv * dv;
            if (r2 > R2) continue;
            if (r2 < best_r2) best_r2 = r2, nn_depth = c.depth, nn_ground = c.ground;
            if (!rgb) continue;
            double cd2 = 0;
            for (int ch = 0; ch < 3; ++ch) cd2 += double(rgb[ch] - c.rgb[ch]) * (rgb[ch] - c.rgb[ch]);
            votes.push_back({c.depth, r2, cd2, c.ground});
          }
      if (!std::isfinite(best_r2)) continue;
      out.confidence.at(x, y) = 1.0f - 0.6f * std::sqrt(best_r2) / R;
      if (!rgb || best_r2 <= options.nearest_within_px * options.nearest_within_px) {
        out.depth.at(x, y) = nn_depth;
        out.ground.at(x, y) = nn_ground;
        continue;
      }
      // The spatial scale follows the local point spacing: colour arbitrates between surfaces whose points are
      // at comparable distances, not against a much nearer point.
      const double sigma_s = std::clamp(options.sigma_space_nn * std::sqrt(double(best_r2)), 1.0, options.sigma_space_px);
      const double inv_ss = 1.0 / (2 * sigma_s * sigma_s);
      for (Vote& v : votes) {
        v.weight = std::exp(-v.r2 * inv_ss - v.cd2 * inv_sc);
        const double q = (v.r2 + 0.5) * (v.r2 + 0.5);
        v.near = 1.0 / (q * q);
      }
      float depth = nn_depth;
      // The ground as one surface (its depth changes smoothly across the rings), the rest split into clusters
      // at relative depth gaps; the cluster holding the best-matching point (highest bilateral weight) wins — a
      // sum would favour whichever surface has more points in reach — and its depth at the pixel is the
      // inverse-distance (power 8: the nearest decide, equidistant rings interpolate) mean of its inverse depths.
      const auto mid = std::partition(votes.begin(), votes.end(), [](const Vote& v) { return !v.ground; });
      std::sort(votes.begin(), mid, [](const Vote& a, const Vote& b) { return a.depth < b.depth; });
      double best_score = 0, best_inv = 0;
      bool best_ground = false;
      double w = 0, k = 0, ki = 0;
      const auto consider = [&](bool ground) {
        if (w > best_score && k > 0) best_score = w, best_inv = ki / k, best_ground = ground;
        w = k = ki = 0;
      };
      for (auto it = votes.begin(); it != mid; ++it) {
        if (it != votes.begin() && it->depth > (it - 1)->depth * (1 + options.cluster_rel)) consider(false);
        w = std::max(w, it->weight);
        k += it->near, ki += it->near / it->depth;
      }
      consider(false);
      for (auto it = mid; it != votes.end(); ++it) w = std::max(w, it->weight), k += it->near, ki += it->near / it->depth;
      consider(true);
      bool ground = nn_ground;
      if (best_score > 1e-30) depth = static_cast<float>(1.0 / best_inv), ground = best_ground;
      out.depth.at(x, y) = depth;
      out.ground.at(x, y) = ground;
    }
  });

  if (priors.boxes_ego.empty() && !priors.surface) return out;
  // Priors fill only where no LiDAR point is within reach: boxes first (they stand on the road, in front of it).
  const Rigid3d T_ego_cam = T_cam_ego.Inverse();
  const Rigid3d T_world_cam = priors.T_world_ego * T_ego_cam;
  std::vector<std::pair<Rigid3d, Eigen::Vector3d>> boxes;  // T_box_cam, half size
  for (const auto& b : priors.boxes_ego) boxes.push_back({(T_cam_ego * b.T_frame_box).Inverse(), 0.5 * b.size});
  ParallelRows(ry0, ry1, [&](int y) {
    for (const auto& [sx0, sx1] : RowSpans(rects, y, W)) for (int x = sx0; x < sx1; ++x) {
      if (out.confidence.at(x, y) > 0) continue;
      const Eigen::Vector3d dir = camera.RayDirection(Eigen::Vector2d(x + 0.5, y + 0.5));
      float d = kInf;
      for (const auto& [T_box_cam, half] : boxes) d = std::min(d, RayBoxDepth(T_box_cam, half, dir));
      if (std::isfinite(d)) {
        out.depth.at(x, y) = d;
        out.confidence.at(x, y) = static_cast<float>(options.box_confidence);
        continue;
      }
      if (!priors.surface) continue;
      d = RaySurfaceDepth(*priors.surface, T_world_cam, dir);
      if (std::isfinite(d)) {
        out.depth.at(x, y) = d;
        out.confidence.at(x, y) = static_cast<float>(options.surface_confidence);
        out.ground.at(x, y) = 1;
      }
    }
  });
  return out;
}

ImageF DenseVisibility(const DepthMap& scene, const ImageU8& image, const ImageF& object_depth, const VisibleMaskOptions& options) {
  const int W = object_depth.width(), H = object_depth.height();
  SD_CHECK(scene.depth.width() == W && scene.depth.height() == H && scene.confidence.width() == W &&
               scene.confidence.height() == H,
           << "scene depth " << scene.depth.width() << "x" << scene.depth.height() << " vs object " << W << "x" << H);
  ImageF vis(W, H, 1, 1.0f);
  int x0 = W, y0 = H, x1 = -1, y1 = -1;
  for (int y = 0; y < H; ++y)
    for (int x = 0; x < W; ++x)
      if (std::isfinite(object_depth.at(x, y))) x0 = std::min(x0, x), x1 = std::max(x1, x), y0 = std::min(y0, y), y1 = std::max(y1, y);
  if (x1 < 0) return vis;
  const auto hidden = [&](int x, int y, float d) {
    const double tol = std::max(options.tol_abs, options.tol_rel * d);
    if (!options.ground_occludes && !scene.ground.empty() && scene.ground.at(x, y)) return false;
    return scene.confidence.at(x, y) >= options.min_confidence && scene.depth.at(x, y) < d - tol;
  };
  // Every loop below writes each pixel from its own neighbourhood of the inputs: rows in parallel, the same result.
  ParallelRows(y0, y1 + 1, [&](int y) {
    for (int x = x0; x <= x1; ++x) {
      const float d = object_depth.at(x, y);
      if (std::isfinite(d) && hidden(x, y, d)) vis.at(x, y) = 0.0f;
    }
  });
  const int r = options.guide_radius;
  if (r <= 0 || image.empty()) return vis;
  SD_CHECK(image.width() == W && image.height() == H && image.channels() >= 3, << "guide image " << image.width() << "x" << image.height());

  // The region: the object's box grown by 2r. Outside the object its depth is carried outwards (r passes of a
  // 3x3 "farthest finite neighbour"), so the filter sees the occluder's edge on both sides of the outline too.
  const int bx0 = std::max(0, x0 - 2 * r), by0 = std::max(0, y0 - 2 * r);
  const int bx1 = std::min(W - 1, x1 + 2 * r), by1 = std::min(H - 1, y1 + 2 * r);
  const int bw = bx1 - bx0 + 1, bh = by1 - by0 + 1;
  std::vector<float> depth(static_cast<size_t>(bw) * bh);
  for (int y = 0; y < bh; ++y)
    for (int x = 0; x < bw; ++x) depth[Idx(x, y, bw)] = object_depth.at(bx0 + x, by0 + y);
  for (int pass = 0; pass < 2 * r; ++pass) {
    std::vector<float> next = depth;
    ParallelRows(0, bh, [&](int y) {
      for (int x = 0; x < bw; ++x) {
        if (std::isfinite(depth[Idx(x, y, bw)])) continue;
        float m = -kInf;
        for (int yy = std::max(0, y - 1); yy <= std::min(bh - 1, y + 1); ++yy)
          for (int xx = std::max(0, x - 1); xx <= std::min(bw - 1, x + 1); ++xx)
            if (std::isfinite(depth[Idx(xx, yy, bw)])) m = std::max(m, depth[Idx(xx, yy, bw)]);
        if (m > -kInf) next[Idx(x, y, bw)] = m;
      }
    });
    depth.swap(next);
  }
  std::vector<float> hard(depth.size(), 1.0f);
  ParallelRows(0, bh, [&](int y) {
    for (int x = 0; x < bw; ++x) {
      const float d = depth[Idx(x, y, bw)];
      if (std::isfinite(d) && hidden(bx0 + x, by0 + y, d)) hard[Idx(x, y, bw)] = 0.0f;
    }
  });
  // Two-colour matting on the one-pixel band each side of the hard boundary: the pixel's colour as a mix of the
  // occluder's and the background's (per-channel medians of the hidden and the visible pixels within r),
  // projected on the line between them. Where the two colours are too alike to tell, the hard verdict stays.
  ParallelRows(0, bh, [&](int y) {
    std::vector<float> c0, c1;
    for (int x = 0; x < bw; ++x) {
      const int gx = bx0 + x, gy = by0 + y;
      if (!std::isfinite(object_depth.at(gx, gy))) continue;
      const float h0 = hard[Idx(x, y, bw)];
      bool band = false;
      for (const auto& [dx, dy] : {std::pair{-1, 0}, std::pair{1, 0}, std::pair{0, -1}, std::pair{0, 1}}) {
        const int xx = x + dx, yy = y + dy;
        band = band || (xx >= 0 && yy >= 0 && xx < bw && yy < bh && hard[Idx(xx, yy, bw)] != h0);
      }
      if (!band) continue;
      float mean[2][3];
      bool ok = true;
      for (int side = 0; side < 2 && ok; ++side)
        for (int c = 0; c < 3 && ok; ++c) {
          std::vector<float>& v = side ? c1 : c0;
          v.clear();
          for (int yy = std::max(0, y - r); yy <= std::min(bh - 1, y + r); ++yy)
            for (int xx = std::max(0, x - r); xx <= std::min(bw - 1, x + r); ++xx)
              if (hard[Idx(xx, yy, bw)] == static_cast<float>(side)) v.push_back(image.at(bx0 + xx, by0 + yy, c));
          ok = !v.empty();
          if (!ok) break;
          std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
          mean[side][c] = v[v.size() / 2];
        }
      if (!ok) continue;
      double num = 0, den = 0;
      for (int c = 0; c < 3; ++c) {
        const double axis = mean[1][c] - mean[0][c];
        num += (image.at(gx, gy, c) - mean[0][c]) * axis;
        den += axis * axis;
      }
      if (den < options.min_contrast * options.min_contrast) continue;
      vis.at(gx, gy) = static_cast<float>(std::clamp(num / den, 0.0, 1.0));
    }
  });
  return vis;
}

ImageF VisibleMask(const DepthMap& scene, const ImageU8& image, const ImageF& object_depth, const ImageF& object_coverage,
                   const VisibleMaskOptions& options) {
  SD_CHECK(object_coverage.width() == object_depth.width() && object_coverage.height() == object_depth.height(),
           << "coverage and depth sizes differ");
  ImageF vis = DenseVisibility(scene, image, object_depth, options);
  for (int y = 0; y < vis.height(); ++y)
    for (int x = 0; x < vis.width(); ++x) vis.at(x, y) *= std::clamp(object_coverage.at(x, y), 0.0f, 1.0f);
  return vis;
}
}  // namespace sd
