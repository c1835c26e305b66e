#include "mining/log_crops.h"

#include <algorithm>
#include <cmath>
#include <exception>
#include <limits>
#include <numbers>

#include "core/error.h"
#include "core/parallel.h"
#include "geometry/box_projection.h"
#include "geometry/polygon.h"
#include "datasets/categories.h"
#include "datasets/readers.h"
#include "io/image_io.h"

namespace sd::mining {
namespace {

using Vec2 = Eigen::Vector2d;
using Vec3 = Eigen::Vector3d;

constexpr double kDeg = std::numbers::pi / 180.0;

// Angular spacing of the LiDAR's returns (radians). The sweep file does not say which sensor made it, so it is
// taken from the channel name: KITTI's "velodyne" is an HDL-64E (64 beams over 26.9 deg: ~0.4 deg vertical,
// ~0.09 deg horizontal at 10 Hz); everything else is treated like nuScenes' HDL-32E (32 beams over 41.3 deg:
// ~1.33 deg vertical, ~0.33 deg horizontal at 20 Hz). The second is the coarser of the sensors we read
// (Lyft's 40/64-beam roof LiDARs are finer), so a finer sensor gets splats that are too large rather than too
// small: the excess lands inside the polygon clip or is removed by it, while too small splats leave the mask
// striped. The horizontal spacing is doubled to bridge single dropped returns (dark paint, glass).
struct AngularSpacing {
  double vertical, horizontal;
};
AngularSpacing SpacingOf(const Frame& frame) {
  if (frame.lidar && frame.lidar->channel == "velodyne") return {0.4 * kDeg, 2 * 0.09 * kDeg};
  return {1.33 * kDeg, 2 * 0.33 * kDeg};
}

// A return is hidden from the camera when a return this much nearer lands within a few pixels of it: less than
// the depth of most objects, more than the scatter of one surface's returns.
constexpr double kOccluderGapM = 0.5;

// Area-filter weights along one axis: output pixel o covers source [o / s, (o + 1) / s).
struct AxisWeights {
  std::vector<int> first;
  std::vector<std::vector<float>> w;
};
AxisWeights AreaWeights(int src, int dst) {
  AxisWeights a;
  a.first.resize(dst);
  a.w.resize(dst);
  const double step = static_cast<double>(src) / dst;
  for (int o = 0; o < dst; ++o) {
    const double lo = o * step, hi = std::min<double>(src, (o + 1) * step);
    const int i0 = static_cast<int>(std::floor(lo));
    a.first[o] = i0;
    for (int i = i0; i < src && i < hi; ++i) {
      const double cover = std::min<double>(hi, i + 1) - std::max<double>(lo, i);
      a.w[o].push_back(static_cast<float>(cover / (hi - lo)));
    }
  }
  return a;
}

ImageU8 ResizeArea(const ImageU8& in, int width, int height) {
  if (in.width() == width && in.height() == height) return in;
  const int c = in.channels();
  const AxisWeights wx = AreaWeights(in.width(), width), wy = AreaWeights(in.height(), height);
  ImageF tmp(width, in.height(), c);
  for (int y = 0; y < in.height(); ++y)
    for (int x = 0; x < width; ++x)
      for (size_t k = 0; k < wx.w[x].size(); ++k) {
        const uint8_t* s = in.pixel(wx.first[x] + static_cast<int>(k), y);
        float* d = tmp.pixel(x, y);
        for (int ch = 0; ch < c; ++ch) d[ch] += wx.w[x][k] * s[ch];
      }
  ImageU8 out(width, height, c);
  std::vector<float> acc(c);
  for (int y = 0; y < height; ++y)
    for (int x = 0; x < width; ++x) {
      std::fill(acc.begin(), acc.end(), 0.f);
      for (size_t k = 0; k < wy.w[y].size(); ++k) {
        const float* s = tmp.pixel(x, wy.first[y] + static_cast<int>(k));
        for (int ch = 0; ch < c; ++ch) acc[ch] += wy.w[y][k] * s[ch];
      }
      for (int ch = 0; ch < c; ++ch) out.at(x, y, ch) = static_cast<uint8_t>(std::clamp(std::lround(acc[ch]), 0L, 255L));
    }
  return out;
}

// Separable square max (dilate) or min (erode) filter of radius r on a 0/1 mask. Pixels outside the mask count
// as `outside`.
std::vector<uint8_t> MaxMin(const std::vector<uint8_t>& m, int w, int h, int r, bool dilate, uint8_t outside) {
  std::vector<uint8_t> tmp(m.size()), out(m.size());
  auto pick = [dilate](uint8_t a, uint8_t b) { return dilate ? std::max(a, b) : std::min(a, b); };
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      uint8_t v = m[static_cast<size_t>(y) * w + x];
      for (int d = -r; d <= r; ++d) {
        const int xx = x + d;
        v = pick(v, xx < 0 || xx >= w ? outside : m[static_cast<size_t>(y) * w + xx]);
      }
      tmp[static_cast<size_t>(y) * w + x] = v;
    }
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      uint8_t v = tmp[static_cast<size_t>(y) * w + x];
      for (int d = -r; d <= r; ++d) {
        const int yy = y + d;
        v = pick(v, yy < 0 || yy >= h ? outside : tmp[static_cast<size_t>(yy) * w + x]);
      }
      out[static_cast<size_t>(y) * w + x] = v;
    }
  return out;
}

// Sets the background regions not connected to the window's border (holes in the object) to 1.
void FillHoles(std::vector<uint8_t>& m, int w, int h) {
  std::vector<uint8_t> outside(m.size(), 0);
  std::vector<int> stack;
  auto push = [&](int x, int y) {
    const size_t i = static_cast<size_t>(y) * w + x;
    if (!m[i] && !outside[i]) {
      outside[i] = 1;
      stack.push_back(static_cast<int>(i));
    }
  };
  for (int x = 0; x < w; ++x) push(x, 0), push(x, h - 1);
  for (int y = 0; y < h; ++y) push(0, y), push(w - 1, y);
  while (!stack.empty()) {
    const int i = stack.back();
    stack.pop_back();
    const int x = i % w, y = i / w;
    if (x > 0) push(x - 1, y);
    if (x + 1 < w) push(x + 1, y);
    if (y > 0) push(x, y - 1);
    if (y + 1 < h) push(x, y + 1);
  }
  for (size_t i = 0; i < m.size(); ++i)
    if (!m[i] && !outside[i]) m[i] = 1;
}

struct Projected {
  Vec2 uv;
  double depth;  // camera z
  double range;  // distance from the LiDAR
};

// One camera's work: everything that needs the image or the z-buffer.
std::vector<ObjectCrop> CropCamera(const Frame& frame, const CameraSensor& cam_in, const std::vector<Vec3>& sweep_ego,
                                   const LogCropOptions& options) {
  CameraSensor cam = cam_in;
  ImageU8 image;
  auto load = [&] {
    if (image.empty()) image = ReadImage(cam.image_path, 3);
  };
  if (cam.intrinsics.width <= 0 || cam.intrinsics.height <= 0) {
    load();
    cam.intrinsics.width = image.width();
    cam.intrinsics.height = image.height();
  }
  const int W = cam.intrinsics.width, H = cam.intrinsics.height;
  const Rigid3d T_cam_ego = cam.T_ego_cam.Inverse();

  struct Candidate {
    size_t annotation;
    std::vector<Vec2> polygon;
    Box2 box2d;
    double truncation;
  };
  std::vector<Candidate> candidates;
  for (size_t i = 0; i < frame.annotations.size(); ++i) {
    const Annotation& a = frame.annotations[i];
    if (options.select && !options.select(a)) continue;
    if (!options.categories.empty()) {
      const std::string name = CanonicalCategory(a.category);
      bool keep = false;
      for (const std::string& want : options.categories) {
        const auto w = FindCategory(want);
        keep = keep || (w ? w->name : want) == name;
      }
      if (!keep || a.category.empty()) continue;
    }
    std::optional<geometry::BoxInImage> in_image = geometry::ProjectBoxToImage(cam.intrinsics, T_cam_ego, a.box, options.near_m);
    if (!in_image || in_image->clipped.Empty()) continue;
    const Box2 clipped = in_image->clipped;
    const double truncation = in_image->truncation;
    if (truncation > options.max_truncation) continue;
    if (std::min(clipped.x2 - clipped.x1, clipped.y2 - clipped.y1) < options.min_box_px) continue;
    candidates.push_back({i, std::move(in_image->outline), clipped, truncation});
  }
  if (candidates.empty()) return {};
  load();
  if (image.width() != W || image.height() != H)
    throw InputError(cam.image_path, Msg() << "image is " << image.width() << "x" << image.height() << " but its camera record says "
                                           << W << "x" << H);

  // Every return seen from this camera, and the z-buffer of the nearest return within a few pixels.
  const AngularSpacing spacing = SpacingOf(frame);
  const Vec3 lidar_origin = frame.lidar ? frame.lidar->T_ego_lidar.translation : Vec3::Zero();
  std::vector<Projected> proj(sweep_ego.size());
  std::vector<uint8_t> in_view(sweep_ego.size(), 0);
  std::vector<float> zbuf;
  const int zr = std::max(1, static_cast<int>(std::lround(0.5 * cam.intrinsics.fx * spacing.horizontal)));
  if (!sweep_ego.empty()) {
    zbuf.assign(static_cast<size_t>(W) * H, std::numeric_limits<float>::infinity());
    for (size_t k = 0; k < sweep_ego.size(); ++k) {
      const Vec3 pc = T_cam_ego * sweep_ego[k];
      const auto uv = cam.intrinsics.Project(pc, options.near_m);
      if (!uv || uv->x() < -zr || uv->y() < -zr || uv->x() >= W + zr || uv->y() >= H + zr) continue;
      in_view[k] = 1;
      proj[k] = {*uv, pc.z(), (sweep_ego[k] - lidar_origin).norm()};
      const int u = static_cast<int>(std::floor(uv->x())), v = static_cast<int>(std::floor(uv->y()));
      for (int y = std::max(0, v - zr); y <= std::min(H - 1, v + zr); ++y)
        for (int x = std::max(0, u - zr); x <= std::min(W - 1, u + zr); ++x) {
          float& z = zbuf[static_cast<size_t>(y) * W + x];
          z = std::min(z, static_cast<float>(pc.z()));
        }
    }
  }

  std::vector<ObjectCrop> out;
  for (const Candidate& c : candidates) {
    const Annotation& a = frame.annotations[c.annotation];
    ObjectCrop crop;
    MinedItem& item = crop.item;
    item.kind = SourceKind::kLog;
    item.origin = cam.image_path.string();
    item.category = CanonicalCategory(a.category);
    item.dataset_category = a.category;
    item.frame_token = frame.token;
    item.camera = cam.channel;
    item.annotation_token = a.token;
    item.instance_token = a.instance_token;
    item.box_ego = a.box;
    item.box_camera = a.box.Transformed(cam.T_ego_cam.Inverse());
    item.camera_intrinsics = cam.intrinsics;
    if (auto it = a.box2d_by_camera.find(cam.channel); it != a.box2d_by_camera.end()) item.annotated_box2d = it->second;
    item.visibility_level = a.visibility;
    item.box2d = c.box2d;
    item.truncation = c.truncation;

    // Crop window: integer pixel edges.
    const double mx = options.context * (c.box2d.x2 - c.box2d.x1), my = options.context * (c.box2d.y2 - c.box2d.y1);
    const int x1 = std::max(0, static_cast<int>(std::floor(c.box2d.x1 - mx)));
    const int y1 = std::max(0, static_cast<int>(std::floor(c.box2d.y1 - my)));
    const int x2 = std::min(W, static_cast<int>(std::ceil(c.box2d.x2 + mx)));
    const int y2 = std::min(H, static_cast<int>(std::ceil(c.box2d.y2 + my)));
    const int cw = x2 - x1, ch = y2 - y1;
    item.crop_rect = Box2{double(x1), double(y1), double(x2), double(y2)};

    // The box polygon, rasterised by pixel centres over the window.
    std::vector<uint8_t> poly_mask(static_cast<size_t>(cw) * ch, 0);
    for (int y = 0; y < ch; ++y)
      for (int x = 0; x < cw; ++x)
        poly_mask[static_cast<size_t>(y) * cw + x] = geometry::InsideConvexPolygon(c.polygon, {x1 + x + 0.5, y1 + y + 0.5});

    // LiDAR: returns in the grown box, above the ground clearance; visible ones splat into the mask.
    std::vector<uint8_t> mask(poly_mask.size(), 0);
    int visible = 0;
    if (!sweep_ego.empty()) {
      const Rigid3d T_box_ego = a.box.T_frame_box.Inverse();
      const double bottom = -a.box.size.z() / 2 + options.ground_clearance_m;
      int inside = 0, in_poly = 0, in_front = 0;
      double nearest_corner = std::numeric_limits<double>::infinity();
      for (const Vec3& corner : a.box.Corners()) nearest_corner = std::min(nearest_corner, (T_cam_ego * corner).norm());
      int splat_r = 0;
      for (size_t k = 0; k < sweep_ego.size(); ++k) {
        const Vec3& p = sweep_ego[k];
        const bool strictly_in = a.box.Contains(p);
        inside += strictly_in;
        if (!in_view[k]) continue;
        const Projected& q = proj[k];
        const bool grown_in = strictly_in || a.box.Contains(p, options.box_margin_m);
        // Occlusion counts the returns on the object's image: inside the outline and inside the image. Distances
        // are from the camera centre, which is near the LiDAR's on every rig we read.
        if (q.uv.x() >= 0 && q.uv.y() >= 0 && q.uv.x() < W && q.uv.y() < H && geometry::InsideConvexPolygon(c.polygon, q.uv)) {
          ++in_poly;
          if (!grown_in && (T_cam_ego * p).norm() < nearest_corner - options.box_margin_m) ++in_front;
        }
        if (!grown_in || (T_box_ego * p).z() < bottom) continue;
        const int u = static_cast<int>(std::floor(q.uv.x())), v = static_cast<int>(std::floor(q.uv.y()));
        if (u < 0 || v < 0 || u >= W || v >= H) continue;
        if (zbuf[static_cast<size_t>(v) * W + u] < q.depth - kOccluderGapM) continue;
        ++visible;
        // Half the beam spacing each way makes neighbouring returns' splats meet: the spacing at the return's
        // range, seen at its camera depth.
        const double scale = q.range / std::max(q.depth, options.near_m);
        const double ry = std::max(1.0, 0.5 * cam.intrinsics.fy * spacing.vertical * scale);
        const double rx = std::max(1.0, 0.5 * cam.intrinsics.fx * spacing.horizontal * scale);
        splat_r = std::max(splat_r, static_cast<int>(std::ceil(rx)));
        const double cu = q.uv.x() - x1, cv = q.uv.y() - y1;
        for (int y = std::max(0, static_cast<int>(std::floor(cv - ry))); y <= std::min(ch - 1, static_cast<int>(std::ceil(cv + ry))); ++y)
          for (int x = std::max(0, static_cast<int>(std::floor(cu - rx))); x <= std::min(cw - 1, static_cast<int>(std::ceil(cu + rx))); ++x) {
            const double du = (x + 0.5 - cu) / rx, dv = (y + 0.5 - cv) / ry;
            if (du * du + dv * dv <= 1) mask[static_cast<size_t>(y) * cw + x] = 1;
          }
      }
      item.lidar_points = inside;
      item.occlusion = in_poly > 0 ? static_cast<double>(in_front) / in_poly : -1;
      if (visible >= options.min_mask_points) {
        // Closing bridges the gaps between splats left by dropped returns; the window's outside counts as
        // object for the erosion so objects cut by the window keep their edge.
        const int r = std::max(2, splat_r);
        mask = MaxMin(MaxMin(mask, cw, ch, r, true, 0), cw, ch, r, false, 1);
        FillHoles(mask, cw, ch);
      }
    }
    const bool lidar_mask = visible >= options.min_mask_points;
    item.mask_source = lidar_mask ? "lidar" : "box";
    ImageU8 m(cw, ch, 1);
    for (size_t i = 0; i < poly_mask.size(); ++i) m.data()[i] = poly_mask[i] && (!lidar_mask || mask[i]) ? 255 : 0;
    ImageU8 rgb(cw, ch, 3);
    for (int y = 0; y < ch; ++y) std::copy_n(image.pixel(x1, y1 + y), static_cast<size_t>(cw) * 3, rgb.pixel(0, y));

    const int longer = std::max(cw, ch);
    if (longer > options.max_crop_px) {
      const double s = static_cast<double>(options.max_crop_px) / longer;
      const int ow = std::clamp(static_cast<int>(std::lround(cw * s)), 1, options.max_crop_px);
      const int oh = std::clamp(static_cast<int>(std::lround(ch * s)), 1, options.max_crop_px);
      rgb = ResizeArea(rgb, ow, oh);
      m = ResizeArea(m, ow, oh);
      // Binary again; a pixel whose centre falls outside the polygon may only come back as a mixed (< 255) one.
      for (uint8_t& v : m.vector()) v = v >= 128 ? 255 : 0;
      item.crop_scale = s;
    }
    item.crop_width = rgb.width();
    item.crop_height = rgb.height();
    crop.image = std::move(rgb);
    crop.mask = std::move(m);
    out.push_back(std::move(crop));
  }
  return out;
}

}  // namespace

std::vector<Eigen::Vector3d> SweepInEgo(const Frame& frame) {
  if (!frame.lidar) return {};
  const PointCloud pc = ReadLidar(*frame.lidar);
  std::vector<Vec3> out(pc.size());
  for (size_t i = 0; i < pc.size(); ++i) out[i] = frame.lidar->T_ego_lidar * pc.xyz(i).cast<double>();
  return out;
}

std::vector<ObjectCrop> CropFrameObjects(const Frame& frame, const std::vector<Eigen::Vector3d>& sweep_ego,
                                         const LogCropOptions& options) {
  std::vector<const CameraSensor*> cams;
  if (options.cameras.empty()) {
    for (const CameraSensor& c : frame.cameras) cams.push_back(&c);
  } else {
    for (const std::string& name : options.cameras)
      if (const CameraSensor* c = frame.FindCamera(name)) cams.push_back(c);
  }
  // Cameras are independent (own image, own z-buffer): one task each; the first camera's error is rethrown.
  std::vector<std::vector<ObjectCrop>> per_camera(cams.size());
  ParallelForRethrow(0, cams.size(), [&](size_t i) { per_camera[i] = CropCamera(frame, *cams[i], sweep_ego, options); });
  std::vector<ObjectCrop> out;
  for (auto& v : per_camera)
    for (ObjectCrop& c : v) out.push_back(std::move(c));
  return out;
}

}  // namespace sd::mining
