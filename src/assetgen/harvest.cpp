#include "assetgen/harvest.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <numbers>
#include <optional>

#include <Eigen/Dense>

#include "core/error.h"
#include "core/log.h"
#include "core/stats.h"
#include "datasets/categories.h"
#include "datasets/readers.h"
#include "geometry/box_projection.h"
#include "geometry/polygon.h"
#include "mining/log_crops.h"
#include "models/grabcut.h"
#include "models/segmentation.h"

namespace sd {
namespace {

constexpr double kDeg = std::numbers::pi / 180.0;
// A view shows the object whole when at most this fraction of its projected box lies outside the image.
constexpr double kWholeTruncation = 0.01;

// The object frame in the ego frame: the box's frame moved down to the centre of its bottom face.
Rigid3d ObjectInEgo(const Box3& box) {
  return box.T_frame_box * Rigid3d(Eigen::Quaterniond::Identity(), Eigen::Vector3d(0, 0, -box.size.z() / 2));
}

const Annotation* NearestAnnotation(const Frame& frame, const Box3& box, double max_distance) {
  const Annotation* best = nullptr;
  double best_d = max_distance;
  for (const Annotation& a : frame.annotations) {
    const double d = (a.box.center() - box.center()).norm();
    if (d <= best_d) best_d = d, best = &a;
  }
  return best;
}

double Area(const ImageF& m) {
  double a = 0;
  for (float v : m.vector()) a += v > 0.5f;
  return a;
}

// The object's outline in its crop: GrabCut inside the projected box (outside it is sure background), seeded by
// the object's LiDAR returns (its colour model learnt from them), and kept inside the box polygon. The segmenter's outline follows the image; the returns only say where the object is. Falls back to
// the source's mask when the two disagree (the segmenter kept under half of it, or grew past the polygon).
ImageF RefineMask(const models::Segmenter& segmenter, const ImageU8& crop, const ImageU8& source_mask,
                  const std::vector<Eigen::Vector2d>& polygon, const std::vector<Eigen::Vector2d>& seeds,
                  const std::string& mask_source, std::string* method) {
  const int w = crop.width(), h = crop.height();
  ImageF prior(w, h, 1, 0.0f);
  Box2 box{1e18, 1e18, -1e18, -1e18};
  for (const Eigen::Vector2d& p : polygon)
    box.x1 = std::min(box.x1, p.x()), box.y1 = std::min(box.y1, p.y()), box.x2 = std::max(box.x2, p.x()),
    box.y2 = std::max(box.y2, p.y());
  box = Box2{std::max(0.0, box.x1 - 2), std::max(0.0, box.y1 - 2), std::min<double>(w, box.x2 + 2), std::min<double>(h, box.y2 + 2)};
  ImageF source(w, h, 1, 0.0f);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) source.at(x, y) = source_mask.at(x, y) > 127 ? 1.0f : 0.0f;
  if (box.Empty() || polygon.size() < 3) {
    *method = mask_source + " footprint (no box to segment in)";
    return source;
  }
  // The projected box, grown by 3 % about its centre (the box is the annotator's, not the pixels'): outside it
  // is sure background.
  Eigen::Vector2d centre = Eigen::Vector2d::Zero();
  for (const Eigen::Vector2d& p : polygon) centre += p / static_cast<double>(polygon.size());
  std::vector<Eigen::Vector2d> grown;
  for (const Eigen::Vector2d& p : polygon) grown.push_back(centre + 1.03 * (p - centre));
  // Seeds: the pixels the object's returns project to. Every point of an object projects inside its silhouette
  // (seen or not, unless something nearer hides it), so they are sure object pixels, where the footprint's splats,
  // sized for the coarsest sensor, overshoot a thin object's outline by many pixels.
  // Only the seeds in the middle of their row band count: returns at the outline are mixed (part object, part
  // what lies behind) and a camera-LiDAR misregistration of a pixel or two moves them off a thin object.
  ImageF outside(w, h, 1, 0.0f);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) outside.at(x, y) = geometry::InsideConvexPolygon(grown, {x + 0.5, y + 0.5}) ? 0.0f : 1.0f;
  // A return outside the projected box belongs to a neighbour within the box's margin (a post beside a cone).
  std::vector<Eigen::Vector2d> inside;
  for (const Eigen::Vector2d& q : seeds)
    if (geometry::InsideConvexPolygon(grown, q)) inside.push_back(q);
  // By row, so each seed's band is a short run (a vehicle's returns from twelve frames are thousands of seeds).
  std::sort(inside.begin(), inside.end(), [](const Eigen::Vector2d& a, const Eigen::Vector2d& b) { return a.y() < b.y(); });
  for (const Eigen::Vector2d& q : inside) {
    double lo_x = q.x(), hi_x = q.x();
    const auto first = std::lower_bound(inside.begin(), inside.end(), q.y() - 2.6,
                                        [](const Eigen::Vector2d& a, double y) { return a.y() < y; });
    for (auto r = first; r != inside.end() && r->y() <= q.y() + 2.6; ++r)
      if (std::abs(r->y() - q.y()) <= 2.5) lo_x = std::min(lo_x, r->x()), hi_x = std::max(hi_x, r->x());
    const double margin = 0.3 * (hi_x - lo_x);
    if (q.x() < lo_x + margin || q.x() > hi_x - margin) continue;
    const int x = static_cast<int>(std::floor(q.x())), y = static_cast<int>(std::floor(q.y()));
    if (x >= 0 && y >= 0 && x < w && y < h) prior.at(x, y) = 1.0f;
  }
  const ImageF* seeds_ptr = Area(prior) > 0 ? &prior : nullptr;
  models::GrabCutOptions grabcut;
  grabcut.foreground_from_prior = true;
  const ImageF prob = segmenter.learned() ? segmenter.Segment(crop, box).mask
                                          : models::GrabCut(crop, box, seeds_ptr, grabcut, &outside);
  ImageF out(w, h, 1, 0.0f);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) out.at(x, y) = prob.at(x, y) > 0.5f && outside.at(x, y) < 0.5f ? 1.0f : 0.0f;
  out = models::LargestComponentFilled(out);
  // The segmenter is trusted where it keeps the returns' seeds (they are surely object), or, with too few seeds
  // to judge by, where it keeps a plausible share of the projected box (a box's corners are background).
  const double seeds_area = Area(prior);
  double kept = 0;
  for (size_t i = 0; i < out.vector().size(); ++i) kept += prior.vector()[i] > 0.5f && out.vector()[i] > 0.5f;
  double polygon_area = 0;
  for (float v : outside.vector()) polygon_area += v < 0.5f;
  const double area = Area(out);
  const bool agrees = seeds_area >= 5 ? kept >= 0.5 * seeds_area : area >= 0.15 * polygon_area && area <= polygon_area;
  if (!agrees) {
    *method = Msg() << mask_source << " footprint (" << segmenter.Describe() << " disagreed: "
                    << (seeds_area >= 5 ? static_cast<int>(100 * kept / seeds_area) : static_cast<int>(100 * area / std::max(polygon_area, 1.0)))
                    << (seeds_area >= 5 ? "% of the returns' seeds kept)" : "% of the projected box)");
    return source;
  }
  *method = segmenter.Describe() + (Area(prior) > 0 ? " seeded by the object's LiDAR returns" : " in the projected box");
  return out;
}

// A window of the source image, resampled to a square view of `size` pixels: the view's colour (linear), mask and
// camera (the source camera shifted to the window and scaled). `window` is square, in source pixels; the crop (of
// `crop_rect`, resampled by `crop_scale`) supplies colour and mask, source pixels outside it are background. With
// `mark_unknown`, view pixels beyond the source image's border are marked unknown (MultiView::known).
struct SquareView {
  PinholeCamera camera;
  ImageF color, mask, known;
};
SquareView ToSquareView(const ImageU8& crop, const ImageF& mask, const PinholeCamera& source, const Box2& crop_rect,
                        double crop_scale, const Box2& window, int size, bool mark_unknown) {
  const int w = crop.width(), h = crop.height();
  const double r = static_cast<double>(size) / (window.x2 - window.x1);  // view pixels per source pixel
  SquareView v;
  v.camera = source;
  v.camera.width = v.camera.height = size;
  v.camera.fx = source.fx * r;
  v.camera.fy = source.fy * r;
  v.camera.cx = (source.cx - window.x1) * r;
  v.camera.cy = (source.cy - window.y1) * r;
  const ImageF linear = ToLinear(crop);
  v.color = ImageF(size, size, 3, 0.0f);
  v.mask = ImageF(size, size, 1, 0.0f);
  if (mark_unknown) v.known = ImageF(size, size, 1, 1.0f);
  for (int y = 0; y < size; ++y)
    for (int x = 0; x < size; ++x) {
      // The view pixel's centre in source, then in (continuous) crop coordinates.
      const double sx = window.x1 + (x + 0.5) / r, sy = window.y1 + (y + 0.5) / r;
      if (mark_unknown && (sx < 0 || sy < 0 || sx >= source.width || sy >= source.height)) {
        v.known.at(x, y) = 0.0f;
        continue;
      }
      const double u = (sx - crop_rect.x1) * crop_scale, t = (sy - crop_rect.y1) * crop_scale;
      if (u < 0 || t < 0 || u > w || t > h) continue;
      float c[3], m;
      SampleBilinear(linear, u - 0.5, t - 0.5, c);
      SampleBilinear(mask, u - 0.5, t - 0.5, &m);
      for (int k = 0; k < 3; ++k) v.color.at(x, y, k) = c[k];
      v.mask.at(x, y) = m;
    }
  return v;
}

// Farthest-point selection of viewing directions: first among the whole views (`whole`), starting from the one
// that shows the object largest; then views cut by the image border join, farthest first, where they look from a
// direction at least `min_gap` (unit-vector distance) from every whole view chosen (they add an outline where no
// whole view has one; among themselves they differ in what the border hides, so they are not spaced).
std::vector<size_t> SpreadViews(const std::vector<Eigen::Vector3d>& directions, const std::vector<int>& size_px,
                                const std::vector<bool>& whole, size_t limit, double min_gap) {
  std::vector<size_t> chosen;
  const double inf = std::numeric_limits<double>::infinity();
  std::vector<double> nearest(directions.size(), inf), nearest_whole(directions.size(), inf);
  for (bool pass_whole : {true, false}) {
    while (chosen.size() < limit) {
      size_t best = directions.size();
      double best_d = -1;
      for (size_t i = 0; i < directions.size(); ++i) {
        if (whole[i] != pass_whole || std::find(chosen.begin(), chosen.end(), i) != chosen.end()) continue;
        if (!pass_whole && nearest_whole[i] < min_gap) continue;
        // The first view: the largest; then the farthest from those chosen, ties (the same direction seen again)
        // to the larger view.
        const double d = (std::isinf(nearest[i]) ? 0.0 : nearest[i]) + 1e-6 * size_px[i];
        if (d > best_d) best_d = d, best = i;
      }
      if (best == directions.size()) break;
      chosen.push_back(best);
      for (size_t j = 0; j < directions.size(); ++j) {
        const double d = (directions[j] - directions[best]).norm();
        nearest[j] = std::min(nearest[j], d);
        if (pass_whole) nearest_whole[j] = std::min(nearest_whole[j], d);
      }
    }
  }
  std::sort(chosen.begin(), chosen.end());
  return chosen;
}


}  // namespace

HarvestedObject HarvestObject(const Log& log, const HarvestTarget& target, const HarvestOptions& o) {
  if (o.view_size < 32 || o.view_size > 2048)
    throw InputError({}, Msg() << "harvest: view size " << o.view_size << " outside [32, 2048]");
  const Frame* frame0 = nullptr;
  for (const Frame& f : log.frames)
    if (f.token == target.frame_token) frame0 = &f;
  if (!frame0) throw InputError(log.source, "no frame '" + target.frame_token + "'");
  const Annotation* a0 = NearestAnnotation(*frame0, target.box_ego, 0.1);
  if (!a0)
    throw InputError(log.source, Msg() << "frame " << frame0->token << ": no annotated object within 0.1 m of ("
                                       << target.box_ego.center().transpose() << ")");

  // The track: the same instance in every frame, or this one annotation.
  std::vector<std::pair<const Frame*, const Annotation*>> track;
  if (a0->instance_token.empty()) {
    track.emplace_back(frame0, a0);
  } else {
    for (const Frame& f : log.frames)
      for (const Annotation& a : f.annotations)
        if (a.instance_token == a0->instance_token) track.emplace_back(&f, &a);
  }

  HarvestedObject out;
  out.category = CanonicalCategory(a0->category);
  out.dataset_category = a0->category;
  out.instance_token = a0->instance_token;
  out.frames = static_cast<int>(track.size());
  for (int k = 0; k < 3; ++k) {
    std::vector<double> s;
    for (const auto& [f, a] : track) s.push_back(a->box.size[k]);
    out.size[k] = Median(std::move(s));
  }
  if (!(out.size.minCoeff() > 0) || !out.size.allFinite())
    throw InputError(log.source, Msg() << "frame " << frame0->token << ": the object's box size " << out.size.transpose()
                                       << " is not positive");

  if (!(o.max_truncation >= 0 && o.max_truncation < 1))
    throw InputError({}, Msg() << "harvest: max truncation " << o.max_truncation << " outside [0, 1)");
  const double max_cut = o.use_truncated_views ? o.max_truncation : kWholeTruncation;
  const models::Segmenter segmenter = models::Segmenter::Resolve(o.segmenter);
  mining::LogCropOptions crop_options;
  crop_options.context = o.context;
  crop_options.min_box_px = o.min_object_px;
  crop_options.max_truncation = 0.75;  // filtered below, after counting
  crop_options.max_crop_px = 2 * o.view_size;
  crop_options.box_margin_m = o.lidar_margin_m;

  // A crop that shows the object whole; its mask is refined once every frame's returns are gathered (they all
  // seed it).
  struct Candidate {
    MultiView view;  // camera: the source camera's, until the crop becomes a square view
    HarvestedView info;
    Eigen::Vector3d direction;  // unit, object centre to camera, object frame
    mining::ObjectCrop crop;
    std::vector<Eigen::Vector2d> polygon;  // the projected box, crop pixels
    Box2 outline;                          // the projected box's bounds, source pixels, past the border if cut
  };
  std::vector<Candidate> candidates;
  int refused_cut = 0, refused_hidden = 0;
  const Eigen::Vector3f lo(-0.5f * float(out.size.x()) - float(o.lidar_margin_m), -0.5f * float(out.size.y()) - float(o.lidar_margin_m),
                           float(o.ground_clearance_m));
  const Eigen::Vector3f hi(0.5f * float(out.size.x()) + float(o.lidar_margin_m), 0.5f * float(out.size.y()) + float(o.lidar_margin_m),
                           float(out.size.z()) + float(o.lidar_margin_m));
  // Beams carve only near the object: the hull's bounds are the box (scaled 1.02), a few centimetres more.
  AlignedBox3f carve;
  carve.min = Eigen::Vector3f(lo.x() - 0.05f, lo.y() - 0.05f, -0.05f), carve.max = hi + Eigen::Vector3f::Constant(0.05f);
  std::map<std::string, int> cameras_used;

  // An object that stands still keeps one pose in the world for every frame (the annotation's jitter from frame to
  // frame — centimetres — would otherwise smear the gathered returns and misregister them with each image); a
  // moving one is followed by each frame's box. Logs without world poses (KITTI's frames) are one frame each.
  std::optional<Rigid3d> T_world_obj_static;
  if (track.size() > 1 && log.sequential) {
    std::vector<Eigen::Vector3d> centres;
    for (const auto& [f, a] : track) centres.push_back(f->T_world_ego * a->box.center());
    Eigen::Vector3d median;
    for (int k = 0; k < 3; ++k) {
      std::vector<double> c;
      for (const Eigen::Vector3d& x : centres) c.push_back(x[k]);
      median[k] = Median(std::move(c));
    }
    double spread = 0;
    for (const Eigen::Vector3d& x : centres) spread = std::max(spread, (x - median).norm());
    out.world_spread_m = spread;
    if (spread < std::max(0.15, 0.1 * out.size.x())) {
      // The middle frame's box, moved to the median centre.
      const auto& [f, a] = track[track.size() / 2];
      Rigid3d T = f->T_world_ego * ObjectInEgo(a->box);
      T.translation = median - T.Rotation() * Eigen::Vector3d(0, 0, out.size.z() / 2);
      T_world_obj_static = T;
    }
  }
  out.static_pose = T_world_obj_static.has_value();

  std::optional<Progress> progress;
  if (o.progress) progress.emplace("harvest", track.size());
  for (const auto& [frame, ann] : track) {
    const Rigid3d T_obj_ego = T_world_obj_static ? T_world_obj_static->Inverse() * frame->T_world_ego
                                                 : ObjectInEgo(ann->box).Inverse();
    // LiDAR: the object's returns, and every beam that passed near it (free space).
    std::vector<Eigen::Vector3d> sweep_ego;
    if (frame->lidar) {
      try {
        const PointCloud pc = ReadLidar(*frame->lidar);
        const LidarSensor& l = *frame->lidar;
        const int sensor_feature = l.sensor_feature.empty() ? -1 : pc.FeatureIndex(l.sensor_feature);
        // Each beam starts at its own sensor (PandaSet's two LiDARs): the sensors' origins in the object frame.
        const Eigen::Vector3f first_sensor = (T_obj_ego * l.T_ego_lidar.translation).cast<float>();
        std::vector<Eigen::Vector3f> sensors;
        for (const Rigid3d& T : l.T_lidar_sensors) sensors.push_back((T_obj_ego * (l.T_ego_lidar * T.translation)).cast<float>());
        sweep_ego.resize(pc.size());
        bool any = false;
        for (size_t i = 0; i < pc.size(); ++i) {
          const Eigen::Vector3d p_lidar = pc.xyz(i).cast<double>();
          sweep_ego[i] = l.T_ego_lidar * p_lidar;
          Eigen::Vector3f origin = first_sensor;
          if (sensor_feature >= 0) {
            const int s = static_cast<int>(std::lround(pc.feature(i, sensor_feature)));
            if (s >= 0 && s < static_cast<int>(sensors.size())) origin = sensors[s];
          }
          const Eigen::Vector3f p = (T_obj_ego * sweep_ego[i]).cast<float>();
          if ((p.array() >= lo.array()).all() && (p.array() <= hi.array()).all()) {
            out.points.push_back(p);
            any = true;
          }
          const Eigen::Vector3f beam = p - origin;
          const float range = beam.norm();
          if (!(range > o.free_space_stop_m)) continue;
          const Eigen::Vector3f stop = p - beam * (float(o.free_space_stop_m) / range);
          float t0 = 0, t1 = 0;
          if (carve.ClipSegment(origin, stop, &t0, &t1)) out.free_segments.emplace_back(origin, stop);
        }
        out.frames_with_lidar += any;
      } catch (const InputError& e) {
        SD_LOG(Warn, "harvest: frame " << frame->token << ": " << e.what() << " (no LiDAR for this frame)");
        sweep_ego.clear();
      }
    }
    // Cameras: the object's crop in each, with its mask.
    const Annotation* wanted = ann;
    crop_options.select = [wanted](const Annotation& a) { return &a == wanted; };
    for (mining::ObjectCrop& crop : mining::CropFrameObjects(*frame, sweep_ego, crop_options)) {
      const CameraSensor* cam = frame->FindCamera(crop.item.camera);
      if (!cam) continue;
      ++out.candidate_views;
      Candidate c;
      c.info.frame_token = frame->token;
      c.info.camera = cam->channel;
      c.info.truncation = std::max(0.0, crop.item.truncation);
      c.info.occlusion = std::max(0.0, crop.item.occlusion);
      c.info.object_px = static_cast<int>(std::min(crop.item.box2d.x2 - crop.item.box2d.x1, crop.item.box2d.y2 - crop.item.box2d.y1));
      if (c.info.truncation > max_cut) {
        ++refused_cut;
        continue;
      }
      if (c.info.occlusion > o.max_occlusion) {
        ++refused_hidden;
        continue;
      }
      const Rigid3d T_obj_cam = T_obj_ego * cam->T_ego_cam;
      const Eigen::Vector3d to_cam = T_obj_cam.translation - Eigen::Vector3d(0, 0, out.size.z() / 2);
      c.info.distance_m = to_cam.norm();
      c.info.azimuth_deg = std::atan2(to_cam.y(), to_cam.x()) / kDeg;
      c.info.elevation_deg = std::atan2(to_cam.z(), to_cam.head<2>().norm()) / kDeg;
      c.direction = to_cam.normalized();
      // The projected box in crop pixels.
      const std::optional<geometry::BoxInImage> in_image =
          geometry::ProjectBoxToImage(cam->intrinsics, cam->T_ego_cam.Inverse(), ann->box, crop_options.near_m);
      if (!in_image) continue;
      c.polygon = in_image->outline;
      c.outline = in_image->full;
      for (Eigen::Vector2d& p : c.polygon)
        p = (p - Eigen::Vector2d(crop.item.crop_rect.x1, crop.item.crop_rect.y1)) * crop.item.crop_scale;
      c.view.view = {Msg() << "f" << frame->token << "_" << cam->channel, cam->intrinsics, T_obj_cam};
      c.view.source = Msg() << log.source.filename().string() << " frame " << frame->token << " " << cam->channel;
      c.crop = std::move(crop);
      candidates.push_back(std::move(c));
    }
    if (progress) progress->Advance();
  }
  if (progress) progress->Finish();
  if (candidates.empty())
    throw InputError(log.source, Msg() << "the object (" << out.category << ", frame " << frame0->token
                                       << ") is seen by no camera: of " << out.candidate_views << " crops at least "
                                       << o.min_object_px << " px, " << refused_cut << " more than "
                                       << static_cast<int>(std::lround(100 * max_cut)) << "% cut by the image border, "
                                       << refused_hidden << " more than "
                                       << static_cast<int>(std::lround(100 * o.max_occlusion))
                                       << "% hidden behind nearer LiDAR returns");
  std::vector<Eigen::Vector3d> directions;
  std::vector<int> sizes;
  std::vector<bool> whole;
  for (const Candidate& c : candidates)
    directions.push_back(c.direction), sizes.push_back(c.info.object_px), whole.push_back(c.info.truncation <= kWholeTruncation);
  // Views cut by the border join where they add a direction 10 degrees from every whole one.
  const double min_gap = 2 * std::sin(0.5 * 10 * kDeg);
  for (size_t i : SpreadViews(directions, sizes, whole, static_cast<size_t>(std::max(1, o.max_views)),
                              min_gap)) {
    Candidate& c = candidates[i];
    const mining::ObjectCrop& crop = c.crop;
    // Seeds: the object's returns from every frame (object frame), projected into this crop.
    std::vector<Eigen::Vector2d> seeds;
    const Rigid3d T_cam_obj = c.view.view.T_world_cam.Inverse();
    const PinholeCamera& source_camera = c.view.view.camera;
    for (const Eigen::Vector3f& p : out.points)
      if (const auto uv = source_camera.Project(T_cam_obj * p.cast<double>(), crop_options.near_m))
        seeds.push_back((*uv - Eigen::Vector2d(crop.item.crop_rect.x1, crop.item.crop_rect.y1)) * crop.item.crop_scale);
    const ImageF mask = RefineMask(segmenter, crop.image, crop.mask, c.polygon, seeds, crop.item.mask_source, &c.info.mask_method);
    // The view's window. A whole object's is its crop padded to a square (the crop is the projected box with
    // context, clipped to the image). A cut one's is the square about the whole projected box with the same
    // context, reaching past the image border: the view frames the whole object and marks the pixels it cannot see.
    const bool cut = c.info.truncation > kWholeTruncation;
    double side, cx, cy;
    if (cut) {
      side = (1 + 2 * o.context) * std::max(c.outline.x2 - c.outline.x1, c.outline.y2 - c.outline.y1);
      cx = 0.5 * (c.outline.x1 + c.outline.x2), cy = 0.5 * (c.outline.y1 + c.outline.y2);
    } else {
      // In the crop's own pixels (it may be resampled), then in source pixels.
      const double w = crop.image.width(), h = crop.image.height(), k = crop.item.crop_scale;
      side = std::max(w, h) / k;
      cx = crop.item.crop_rect.x1 + 0.5 * w / k, cy = crop.item.crop_rect.y1 + 0.5 * h / k;
    }
    const Box2 window{cx - 0.5 * side, cy - 0.5 * side, cx + 0.5 * side, cy + 0.5 * side};
    const SquareView sq = ToSquareView(crop.image, mask, source_camera, crop.item.crop_rect, crop.item.crop_scale,
                                       window, o.view_size, cut);
    c.view.view.camera = sq.camera;
    c.view.color = sq.color;
    c.view.mask = sq.mask;
    c.view.known = sq.known;
    c.view.normals = ImageF(o.view_size, o.view_size, 3, 0.0f);
    out.views.push_back(std::move(c.view));
    out.view_info.push_back(candidates[i].info);
    ++cameras_used[candidates[i].info.camera];
  }
  // Returns inside the box's margin that are not the object (a post beside a cone, a kerb): every point of the
  // object lies inside its silhouette in every view, so points outside most views' masks go.
  {
    std::vector<Eigen::Vector3f> kept;
    for (const Eigen::Vector3f& p : out.points) {
      int seen = 0, inside = 0;
      for (const MultiView& v : out.views) {
        const auto uv = v.view.camera.Project(v.view.T_world_cam.Inverse() * p.cast<double>());
        if (!uv || !v.view.camera.InImage(*uv)) continue;
        if (!v.known.empty() && v.known.at(static_cast<int>(uv->x()), static_cast<int>(uv->y())) < 0.5f) continue;
        ++seen;
        // Within two pixels of the mask: the outline's own uncertainty.
        bool in = false;
        for (int dy = -2; dy <= 2 && !in; ++dy)
          for (int dx = -2; dx <= 2 && !in; ++dx) {
            const int x = static_cast<int>(uv->x()) + dx, y = static_cast<int>(uv->y()) + dy;
            in = x >= 0 && y >= 0 && x < v.mask.width() && y < v.mask.height() && v.mask.at(x, y) > 0.5f;
          }
        inside += in;
      }
      if (seen == 0 || inside >= 0.6 * seen) kept.push_back(p);
    }
    out.points_outside_masks = static_cast<int>(out.points.size() - kept.size());
    out.points = std::move(kept);
  }
  Msg source;
  source << log.source.string() << ": " << out.dataset_category;
  if (!out.instance_token.empty()) source << " track " << out.instance_token;
  source << ", " << out.frames << " frame(s), " << out.views.size() << " view(s) from";
  for (const auto& [name, n] : cameras_used) source << " " << name << " x" << n;
  out.source = source.str();
  return out;
}

Eigen::Vector2d RevolveAxis(const MultiViewSet& real, const Eigen::Vector3d& size, const std::vector<Eigen::Vector3f>& points) {
  // Minimise sum_i w_i (n_i . (X - C_i))^2 + lambda |X_xy|^2 over X = (x, y, z) on a vertical line: for a plane
  // whose normal n_i is horizontal (a vertical plane) the z term vanishes; views looking down tilt it slightly,
  // and the z of X is taken at the box's mid-height.
  Eigen::Matrix2d A = Eigen::Matrix2d::Identity() * 0.05;
  Eigen::Vector2d b = Eigen::Vector2d::Zero();
  const double zc = size.z() / 2;
  for (const MultiView& v : real) {
    const SilhouetteAxis s = FitSymmetryAxis(v.mask);
    if (s.symmetry_iou <= 0) continue;
    const PinholeCamera& cam = v.view.camera;
    const Eigen::Matrix3d R = v.view.T_world_cam.Rotation();
    const Eigen::Vector3d C = v.view.T_world_cam.translation;
    const double v0 = 0.25 * cam.height, v1 = 0.75 * cam.height;
    const Eigen::Vector3d r0 = R * cam.RayDirection({s.a + s.b * v0, v0}), r1 = R * cam.RayDirection({s.a + s.b * v1, v1});
    Eigen::Vector3d n = r0.cross(r1);
    if (n.norm() < 1e-12) continue;
    n.normalize();
    const Eigen::Vector2d nxy = n.head<2>();
    const double rhs = n.dot(C) - n.z() * zc;
    A += s.symmetry_iou * nxy * nxy.transpose();
    b += s.symmetry_iou * rhs * nxy;
  }
  Eigen::Vector2d axis = A.ldlt().solve(b);
  const double limit = 0.25 * std::min(size.x(), size.y());
  if (axis.norm() > limit) axis *= limit / axis.norm();
  // The returns, where there are enough: they lie on the surface at the profile's radius from the axis, so the axis
  // and the profile are fitted together (alternately: each height's radius the median distance, then a Gauss-Newton
  // step of the axis on the residuals |p - a| - r(z)). A few centimetres off, the axis would turn the top of a cone
  // into a post as wide as the error.
  if (points.size() >= 30) {
    // Gauss-Newton on (a, r_1..r_K) together: residual |p - a| - r_bin(p). Alternating the two converges slowly
    // along the line of sight, where moving the axis and widening the profile nearly trade off.
    constexpr int kBins = 16;
    auto bin_of = [&](float z) { return std::clamp(static_cast<int>(z / size.z() * kBins), 0, kBins - 1); };
    std::vector<int> count(kBins, 0);
    for (const Eigen::Vector3f& p : points) ++count[bin_of(p.z())];
    std::vector<double> r(kBins, 0);
    for (const Eigen::Vector3f& p : points) r[bin_of(p.z())] += (p.head<2>().cast<double>() - axis).norm();
    for (int k = 0; k < kBins; ++k) r[k] = count[k] ? r[k] / count[k] : 0;
    for (int it = 0; it < 20; ++it) {
      Eigen::MatrixXd JtJ = Eigen::MatrixXd::Zero(2 + kBins, 2 + kBins);
      Eigen::VectorXd Jte = Eigen::VectorXd::Zero(2 + kBins);
      for (const Eigen::Vector3f& p : points) {
        const int k = bin_of(p.z());
        const Eigen::Vector2d q = p.head<2>().cast<double>() - axis;
        const double n = q.norm();
        if (n < 1e-6) continue;
        Eigen::VectorXd J = Eigen::VectorXd::Zero(2 + kBins);
        J.head<2>() = -q / n;
        J[2 + k] = -1;
        JtJ += J * J.transpose();
        Jte += J * (n - r[k]);
      }
      // Weak priors keep the system solvable: the axis near where it was, empty heights where they are.
      JtJ.diagonal().array() += 1e-6 * points.size();
      const Eigen::VectorXd step = -JtJ.ldlt().solve(Jte);
      axis += step.head<2>();
      for (int k = 0; k < kBins; ++k) r[k] += step[2 + k];
      if (axis.norm() > limit) axis *= limit / axis.norm();
      if (step.head<2>().norm() < 1e-5) break;
    }
  }
  return axis;
}

namespace {


}  // namespace

TriangleMesh RevolveFromViews(const MultiViewSet& real, const std::vector<Eigen::Vector3f>& points,
                              const Eigen::Vector2d& axis, const Eigen::Vector3d& size) {
  constexpr int kBins = 32;
  const double h = size.z(), max_r = 0.5 * std::min(size.x(), size.y());
  std::vector<std::vector<double>> from_views(kBins), from_points(kBins);
  auto bin_of = [&](double z) { return std::clamp(static_cast<int>(z / h * kBins), 0, kBins - 1); };
  const Eigen::Vector3d axis3(axis.x(), axis.y(), 0);
  for (const MultiView& v : real) {
    const PinholeCamera& cam = v.view.camera;
    const Eigen::Matrix3d R = v.view.T_world_cam.Rotation();
    const Eigen::Vector3d C = v.view.T_world_cam.translation - axis3;  // camera relative to the axis
    const Rigid3d T_cam_obj = v.view.T_world_cam.Inverse();
    // The axis in the image: the projections of its foot and its top (a line maps to a line).
    const auto p0 = cam.Project(T_cam_obj * axis3), p1 = cam.Project(T_cam_obj * (axis3 + Eigen::Vector3d(0, 0, h)));
    if (!p0 || !p1 || std::abs(p1->y() - p0->y()) < 1) continue;
    const double elevation = std::atan2(C.z() - h / 2, C.head<2>().norm());
    struct Row { int y; double u, left, right; };
    std::vector<Row> rows;
    for (int y = 0; y < cam.height; ++y) {
      const double t = (y + 0.5 - p0->y()) / (p1->y() - p0->y());
      const double u = p0->x() + t * (p1->x() - p0->x());
      double left = 0, right = 0;
      for (int x = 0; x < cam.width; ++x) {
        const double m = std::clamp(v.mask.at(x, y), 0.0f, 1.0f), c = x + 0.5;
        if (c + 0.5 <= u) left += m;
        else if (c - 0.5 >= u) right += m;
        else left += m * (u - (c - 0.5)), right += m * ((c + 0.5) - u);
      }
      if (left + right >= 1) rows.push_back({y, u, left, right});
    }
    if (rows.size() < 3) continue;
    // Rows within r sin(elevation) of the outline's top or bottom show a cap's ellipse, not the side.
    const double s = std::abs(std::sin(elevation));
    const int top = rows.front().y, bottom = rows.back().y;
    for (const Row& row : rows) {
      const double half = 0.5 * (row.left + row.right);
      if (row.y - top + 1 < half * s || bottom - row.y + 1 < half * s) continue;
      const Eigen::Vector3d wa = R * cam.RayDirection({row.u, row.y + 0.5});
      const double horiz = wa.head<2>().squaredNorm();
      if (horiz < 1e-12) continue;
      const double z = C.z() + (-C.head<2>().dot(wa.head<2>()) / horiz) * wa.z();
      if (z < 0 || z > h) continue;
      // The narrower side: a segmenter's error in a box is mostly background taken on one side (a shadow, a
      // dark wall beside the object), rarely object lost on both.
      double r = std::numeric_limits<double>::infinity();
      for (const double edge : {row.u - row.left, row.u + row.right}) {
        const Eigen::Vector3d we = R * cam.RayDirection({edge, row.y + 0.5});
        r = std::min(r, std::abs(C.x() * we.y() - C.y() * we.x()) / we.head<2>().norm());
      }
      from_views[bin_of(z)].push_back(r);
    }
  }
  for (const Eigen::Vector3f& p : points) {
    const double z = p.z();
    if (z < 0 || z > h) continue;
    from_points[bin_of(z)].push_back((p.head<2>().cast<double>() - axis).norm());
  }
  // Per bin: the returns' median where there are enough of them — they are metric and a segmenter's outline of
  // a few dozen pixels is not — else the silhouettes' median.
  std::vector<double> radius(kBins, -1);
  for (int i = 0; i < kBins; ++i) {
    if (from_points[i].size() >= 3) radius[i] = Median(from_points[i]);
    else if (!from_views[i].empty()) radius[i] = Median(from_views[i]);
  }
  // Empty bins take their nearest neighbours' (linearly between two, flat beyond the ends).
  std::vector<int> known;
  for (int i = 0; i < kBins; ++i)
    if (radius[i] >= 0) known.push_back(i);
  if (known.empty()) throw InputError({}, "revolve: no silhouette row and no LiDAR return gives a radius");
  for (int i = 0; i < kBins; ++i) {
    if (radius[i] >= 0) continue;
    const auto next = std::lower_bound(known.begin(), known.end(), i);
    if (next == known.begin()) radius[i] = radius[*next];
    else if (next == known.end()) radius[i] = radius[known.back()];
    else {
      const int a = *(next - 1), b = *next;
      radius[i] = radius[a] + (radius[b] - radius[a]) * (i - a) / double(b - a);
    }
  }
  // A 3-bin median against single outliers, a 3-bin mean against the returns' range noise, then the box's bound.
  std::vector<double> median(kBins);
  for (int i = 0; i < kBins; ++i)
    median[i] = Median({radius[std::max(0, i - 1)], radius[i], radius[std::min(kBins - 1, i + 1)]});
  std::vector<std::pair<double, double>> rings;
  for (int i = 0; i < kBins; ++i) {
    const double mean = (median[std::max(0, i - 1)] + median[i] + median[std::min(kBins - 1, i + 1)]) / 3;
    rings.emplace_back(h * (i + 0.5) / kBins, std::clamp(mean, 1e-3 * max_r, max_r));
  }
  // The ends at the box's bottom and top.
  rings.front().first = 0;
  rings.back().first = h;
  return SurfaceOfRevolution(rings, 64, axis);
}

size_t LargestView(const MultiViewSet& views) {
  size_t best = 0;
  double best_area = -1;
  for (size_t i = 0; i < views.size(); ++i) {
    const double a = Area(views[i].mask);
    if (a > best_area) best_area = a, best = i;
  }
  return best;
}

MultiViewSet SymmetryViews(const MultiViewSet& real, ShapePrior prior, int limit, const Eigen::Vector2d& axis) {
  MultiViewSet out;
  if (real.empty() || limit <= 0) return out;
  auto azimuth_of = [](const MultiView& v) {
    const Eigen::Vector3d c = v.view.T_world_cam.translation;
    return std::atan2(c.y(), c.x());
  };
  auto angle_between = [](double a, double b) {
    double d = std::fmod(std::abs(a - b), 2 * std::numbers::pi);
    return std::min(d, 2 * std::numbers::pi - d);
  };
  std::vector<double> covered;
  for (const MultiView& v : real) covered.push_back(azimuth_of(v));
  if (prior == ShapePrior::kRevolve) {
    // The view that shows the object largest stands in for every side.
    const size_t best = LargestView(real);
    const double base = azimuth_of(real[best]);
    for (int k = 1; k < 8 && static_cast<int>(out.size()) < limit; ++k) {
      const double turn = k * 45.0 * kDeg, az = base + turn;
      if (std::any_of(covered.begin(), covered.end(), [&](double c) { return angle_between(c, az) < 22.5 * kDeg; })) continue;
      MultiView v = real[best];
      // About the vertical through the axis: translate it to the origin, turn, translate back.
      const Eigen::Vector3d a(axis.x(), axis.y(), 0);
      v.view.T_world_cam = Rigid3d(Eigen::Quaterniond::Identity(), a) * Rigid3d::FromYaw(turn, Eigen::Vector3d::Zero()) *
                           Rigid3d(Eigen::Quaterniond::Identity(), -a) * v.view.T_world_cam;
      v.view.name = Msg() << real[best].view.name << "_rotated_" << k * 45;
      v.synthetic = true;
      v.source = Msg() << real[best].source << ", rotated " << k * 45 << " deg about the axis";
      covered.push_back(az);
      out.push_back(std::move(v));
    }
  } else if (prior == ShapePrior::kMirror) {
    const Eigen::Matrix3d M = Eigen::Vector3d(1, -1, 1).asDiagonal();
    const Eigen::Matrix3d F = Eigen::Vector3d(-1, 1, 1).asDiagonal();
    for (const MultiView& r : real) {
      if (static_cast<int>(out.size()) >= limit) break;
      const double az = -azimuth_of(r);
      if (std::any_of(covered.begin(), covered.end(), [&](double c) { return angle_between(c, az) < 10 * kDeg; })) continue;
      // Mirror y -> -y: the camera centre reflected, its x axis flipped (so its frame stays right-handed), the
      // image flipped left-right (principal point W - cx).
      MultiView v = r;
      v.view.T_world_cam = Rigid3d(M * r.view.T_world_cam.Rotation() * F, M * r.view.T_world_cam.translation);
      v.view.camera.cx = r.view.camera.width - r.view.camera.cx;
      for (ImageF* img : {&v.color, &v.mask, &v.normals, &v.known}) {
        if (img->empty()) continue;
        ImageF flipped(img->width(), img->height(), img->channels());
        for (int y = 0; y < img->height(); ++y)
          for (int x = 0; x < img->width(); ++x)
            for (int k = 0; k < img->channels(); ++k) flipped.at(img->width() - 1 - x, y, k) = img->at(x, y, k);
        *img = std::move(flipped);
      }
      // Normals are vectors of the object frame: mirrored too.
      if (!v.normals.empty())
        for (int y = 0; y < v.normals.height(); ++y)
          for (int x = 0; x < v.normals.width(); ++x) v.normals.at(x, y, 1) = -v.normals.at(x, y, 1);
      v.view.name = r.view.name + "_mirrored";
      v.synthetic = true;
      v.source = r.source + ", mirrored in the object's symmetry plane";
      covered.push_back(az);
      out.push_back(std::move(v));
    }
  }
  return out;
}

}  // namespace sd
