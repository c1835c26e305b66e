// The per-camera stage of SynthesizeFrame (synth/frame_stages.h): light, render, receiver depth, occlusion,
// composite, harmonisation, 2D boxes.
#include <algorithm>
#include <cmath>
#include <limits>
#include <map>
#include <string>

#include "core/log.h"
#include "core/parallel.h"
#include "datasets/categories.h"
#include "geometry/box_projection.h"
#include "models/harmonization.h"
#include "render/camera_render.h"
#include "synth/camera_look.h"
#include "synth/frame_stages.h"
#include "synth/lighting.h"
#include "synth/object_light.h"
#include "synth/occlusion.h"
#include "synth/realism.h"
#include "synth/surface.h"

namespace sd {
namespace frame_stages {
namespace {

// Pixels of dense depth around the rendered rectangle: DenseVisibility reads the scene depth up to twice its
// guide radius (2) beyond an object's box.
constexpr int kDepthMargin = 8;

// Shadow rays over the sun's disk per road pixel near a shadow's edge (elsewhere one ray to the disk's centre tells
// all: ReceiverShadowImage): soft edges, but grainy (bench_camera_look: the shadowed road's residual 2.8-7.6x its
// own) until the camera look blurs the shade (kShadeBlurSigma).
constexpr int kShadowSunRays = 8;

// The least blur of the shade map when the camera look blurs (pixels).
constexpr double kShadeBlurSigma = 1.5;

// The pixel rectangle a camera redraws: [x0, x1) x [y0, y1).
struct Rect {
  int x0 = 0, y0 = 0, x1 = 0, y1 = 0;
};

// Per object, the pixel rectangles {x0, y0, x1, y1} of its box, and of its box with its shadow's receiver patch.
struct PixelRects {
  std::vector<std::array<int, 4>> boxes, with_shadows;
};

// Side of the square tiles, on the image's grid, that the stages after the render visit (pixels): small enough to
// follow the objects' outlines, large enough that a blur's reach around a row of tiles adds little.
constexpr int kTile = 32;

// Runs of kTile tiles along each row of tiles, clipped to `bounds`: disjoint rectangles {x0, y0, x1, y1} holding
// every pixel of `bounds` within `reach` (on each axis) of a pixel of `bounds` where `inside(x, y)`. A stage whose
// input is constant away from those pixels, and which reads no further than `reach`, needs to visit these alone:
// the objects' own pixels, not the rectangle of all of them.
template <typename Inside>
std::vector<std::array<int, 4>> TileRunsAround(const Rect& bounds, int reach, const Inside& inside) {
  std::vector<std::array<int, 4>> runs;
  if (bounds.x0 >= bounds.x1 || bounds.y0 >= bounds.y1) return runs;
  const int tx0 = bounds.x0 / kTile, ty0 = bounds.y0 / kTile;
  const int tw = (bounds.x1 - 1) / kTile - tx0 + 1, th = (bounds.y1 - 1) / kTile - ty0 + 1;
  std::vector<char> marked(static_cast<size_t>(tw) * th, 0);
  for (int y = bounds.y0; y < bounds.y1; ++y)
    for (int x = bounds.x0; x < bounds.x1; ++x) {
      if (!inside(x, y)) continue;
      const int ax = std::max(bounds.x0, x - reach) / kTile - tx0, bx = std::min(tw - 1, (x + reach) / kTile - tx0);
      const int ay = std::max(bounds.y0, y - reach) / kTile - ty0, by = std::min(th - 1, (y + reach) / kTile - ty0);
      for (int ty = ay; ty <= by; ++ty)
        for (int tx = ax; tx <= bx; ++tx) marked[static_cast<size_t>(ty) * tw + tx] = 1;
    }
  for (int ty = 0; ty < th; ++ty)
    for (int tx = 0; tx < tw; ++tx) {
      if (!marked[static_cast<size_t>(ty) * tw + tx]) continue;
      const int start = tx;
      while (tx + 1 < tw && marked[static_cast<size_t>(ty) * tw + tx + 1]) ++tx;
      runs.push_back({std::max(bounds.x0, (tx0 + start) * kTile), std::max(bounds.y0, (ty0 + ty) * kTile),
                      std::min(bounds.x1, (tx0 + tx + 1) * kTile), std::min(bounds.y1, (ty0 + ty + 1) * kTile)});
    }
  return runs;
}

// The light at the objects in one camera. With the environment map, each object under its own sun verdict,
// its level from its road in this view, else from all objects' road; without, one calibration from the road.
struct CameraLight {
  Lighting lighting;
  std::optional<ObjectLight> object_light;  // the map's light at all objects (kEnvironment)
  std::vector<ObjectLight> of_object;       // per object (kEnvironment)
};
CameraLight LightOfCamera(const CameraStageInput& st, size_t cam_index, const ImageF& linear) {
  const CameraSensor& cam = st.in->frame->cameras[cam_index];
  const FrameLight& fl = *st.light;
  const std::vector<PlacedObject>& placed = *st.placed;
  CameraLight cl;
  if (!fl.env) {
    cl.lighting = CalibrateLighting(linear, cam, fl.road_points, fl.sun_dir);
    return cl;
  }
  const EnvironmentMap& env = *fl.env;
  cl.object_light = LightAtObjects(env, cam_index, cam, linear, fl.road_points, {}, fl.sun_at_objects);
  cl.lighting = cl.object_light->lighting;
  for (size_t k = 0; k < placed.size(); ++k) {
    // The level from the object's nearest road this camera sees (the rings of kOwnRoadMargins), else all.
    ObjectLight own = LightAtObjects(env, cam_index, cam, linear, fl.road_points_of[k], {}, fl.sun_at_object[k]);
    for (double margin : kOwnRoadMargins) {
      if (own.road_samples > 0) break;
      own = LightAtObjects(env, cam_index, cam, linear, RoadPointsNear(*st.in->ground, {placed[k]}, margin), {}, fl.sun_at_object[k]);
    }
    if (own.road_samples == 0) own = LightAtObjects(env, cam_index, cam, linear, fl.road_points, {}, fl.sun_at_object[k]);
    cl.of_object.push_back(own);
  }
  return cl;
}

// The objects' render (colour, coverage, depth, ids) and the shadow ratio on their road. The renderer's hard,
// one-ray shadow is the road light's; the map's light has a sun disk and a sky with bright and dark sides.
struct ObjectRender {
  CameraRender render;
  ImageF shadow;
};
ObjectRender RenderObjects(const CameraStageInput& st, const CameraSensor& cam, const CameraLight& cl, const PixelRects& rects) {
  const ObjectScene& s = *st.scene;
  CameraRenderOptions ropt;
  ropt.samples_per_pixel = st.options->samples_per_pixel;
  ropt.ao_samples = st.options->ao_samples;
  ropt.sky_filter_radius = st.options->sky_filter_radius;
  ropt.receiver_mesh = s.receiver_id;
  ropt.receiver_shadow = !cl.object_light;  // the map's light shades the road below (ReceiverShadowImage)
  // Filtered, the objects' sky rays are a pixel's, spread over its sub-samples (at least one each). Not under the
  // road's light: there the renderer also shades the road below with each sub-sample's rays, unfiltered, and
  // fewer would be grain in the shadows.
  if (ropt.sky_filter_radius > 0 && !ropt.receiver_shadow)
    ropt.ao_samples = std::max(1, st.options->ao_samples / std::max(1, ropt.samples_per_pixel));
  for (const ObjectLight& l : cl.of_object) ropt.mesh_lighting.push_back(l.lighting);  // mesh k = object k
  // Under the map's light the renderer draws only the objects; under the road's it shades their road too.
  ropt.rects = ropt.receiver_shadow ? rects.with_shadows : rects.boxes;
  ropt.seed = st.in->seeds.render;
  ObjectRender r;
  ScopedStage render_stage(st.times, "camera render");
  r.render = RenderCamera(s.scene, cam.intrinsics, cam.T_ego_cam, cl.lighting, ropt);
  render_stage.Stop();
  r.shadow = r.render.shadow;
  if (cl.object_light) {
    ScopedStage shadow_stage(st.times, "camera shadows");
    EnvShadingOptions so;
    so.sun_rays = kShadowSunRays;
    so.sky_rays = st.options->ao_samples;
    so.seed = ropt.seed;
    so.skip_mesh = s.receiver_id;
    std::vector<const EnvironmentLight*> light_of_face(s.receiver->faces.size());
    for (size_t k = 0, f = 0; k < st.placed->size(); ++k)
      for (; f < s.receiver_faces_end[k]; ++f) light_of_face[f] = &cl.of_object[k].shading;
    r.shadow = ReceiverShadowImage(s.scene, cam.intrinsics, cam.T_ego_cam, s.receiver_id, light_of_face, so, rects.with_shadows);
  }
  return r;
}

// The camera depth of the road under the shadows (the ground plane), so the real scene can hide it too: the
// ground under a shadow must not be hidden by a real object, nor shown through one. Only the shadows' rectangles
// are visited: elsewhere the shadow is 1 (RenderCamera, ReceiverShadowImage).
ImageF ReceiverDepth(const CameraSensor& cam, const GroundPlane& plane, const ObjectRender& r,
                     const std::vector<std::array<int, 4>>& with_shadows) {
  ImageF depth(r.render.depth.width(), r.render.depth.height(), 1, std::numeric_limits<float>::infinity());
  const auto [y0, y1] = RowRange(with_shadows, depth.height());
  for (int y = y0; y < y1; ++y)
    for (const auto& [x0, x1] : RowSpans(with_shadows, y, depth.width()))
      for (int x = x0; x < x1; ++x) {
        if (r.shadow.at(x, y) >= 0.999f) continue;
        const Eigen::Vector3d d_cam = cam.intrinsics.RayDirection(Eigen::Vector2d(x + 0.5, y + 0.5));
        const Eigen::Vector3d o = cam.T_ego_cam.translation, d = cam.T_ego_cam.rotation * d_cam;
        const double denom = plane.normal.dot(d);
        if (std::abs(denom) < 1e-6) continue;
        const double t = -(plane.normal.dot(o) + plane.d) / denom;
        if (t > 0) depth.at(x, y) = static_cast<float>(t * d_cam.z());
      }
  return depth;
}

// Occlusion by the real scene, of the objects and of the road their shadows fall on.
struct OcclusionMasks {
  ImageF objects, receiver;  // visibility in [0, 1]
};
OcclusionMasks OccludeByScene(const CameraStageInput& st, const CameraSensor& cam, const ImageU8& original,
                              const ObjectRender& r, const ImageF& receiver_depth, const Rect& rect) {
  const FrameInputs& in = *st.in;
  const Rigid3d T_cam_ego = cam.T_ego_cam.Inverse();
  const auto projected = ProjectPoints(in.points_ego, in.is_ground, cam.intrinsics, T_cam_ego);
  OcclusionMasks m;
  if (!st.options->dense_occlusion) {
    m.objects = ComputeVisibility(projected, r.render.depth);
    m.receiver = ComputeVisibility(projected, receiver_depth);
    return m;
  }
  const GroundPlane& gp = in.ground->seed_plane();
  const PlaneSurface ground_plane(gp.normal, gp.d);
  DepthPriors priors;
  priors.boxes_ego = in.real_boxes;
  priors.surface = &ground_plane;  // ego frame: T_world_ego stays identity
  // Only where objects or their shadows are, plus the band the visibility mattes from (guide radius 2): the
  // visibility reads the scene depth nowhere else.
  DenseDepthOptions dopt;
  const Rect around{std::max(0, rect.x0 - kDepthMargin), std::max(0, rect.y0 - kDepthMargin),
                    std::min(cam.intrinsics.width, rect.x1 + kDepthMargin),
                    std::min(cam.intrinsics.height, rect.y1 + kDepthMargin)};
  dopt.rects = TileRunsAround(around, kDepthMargin, [&](int x, int y) {
    return std::isfinite(r.render.depth.at(x, y)) || std::isfinite(receiver_depth.at(x, y));
  });
  const DepthMap scene_depth = DenseDepth(projected, original, cam.intrinsics, T_cam_ego, priors, dopt);
  m.objects = DenseVisibility(scene_depth, original, r.render.depth);
  m.receiver = DenseVisibility(scene_depth, original, receiver_depth);
  return m;
}

// The composite in linear light: objects over the photo; what their shadows take from it is kept apart, to be
// applied after harmonisation. The visible layer (colour and coverage, both times visibility) and the shade are
// blurred by `blur_sigma` first, so the objects' edges rise as the photograph's do (synth/camera_look.h). Counts each
// object's rendered and visible pixels and its visible box from the sharp render, so labels do not move.
struct Composite {
  bool changed = false;
  ImageF object_alpha;      // coverage x visibility, blurred as composited
  ImageF shadow_only_loss;  // what the shadows take from the photo
  ImageF shadow_noise;      // the share of a darkened real pixel's noise its shadow took: sqrt(1 - shade^2)
  std::vector<double> rendered, visible;
  std::vector<Box2> boxes;
  // Disjoint rectangles {x0, y0, x1, y1} holding every pixel the composite changed (TileRunsAround the objects'
  // and their shadows' pixels, by the blur's reach): the later stages visit these alone.
  std::vector<std::array<int, 4>> regions;
};

// At least kShadeBlurSigma takes the grain of the 8 sun rays and the sky rays out of a shade map wherever the look
// blurs at all: a shade map is smooth but for its penumbra.
double ShadeBlurSigma(double blur_sigma) { return blur_sigma > 0 ? std::max(blur_sigma, kShadeBlurSigma) : 0.0; }

// CompositeObjects within one of its regions, `region`, blurred from the pixels of `context` around it.
// Writes the region's pixels of `linear` and of `c`'s images; counts its objects' pixels, boxes and whether it
// changed anything in `counts`.
void CompositeRegionInto(const ObjectRender& r, const OcclusionMasks& occ, size_t n_objects, const Rect& region,
                         const Rect& context, double blur_sigma, ImageF* linear, Composite* c, Composite* counts) {
  // Premultiplied colour and alpha, in `context`'s coordinates.
  ImageF layer(context.x1 - context.x0, context.y1 - context.y0, 4, 0.0f);
  for (int y = context.y0; y < context.y1; ++y)
    for (int x = context.x0; x < context.x1; ++x) {
      const float a = r.render.coverage.at(x, y);
      if (a <= 0) continue;
      const float vis = occ.objects.at(x, y);
      for (int ch = 0; ch < 3; ++ch) layer.at(x - context.x0, y - context.y0, ch) = r.render.color.at(x, y, ch) * vis;
      layer.at(x - context.x0, y - context.y0, 3) = a * vis;
      const int id = r.render.object.at(x, y);
      const bool own = x >= region.x0 && x < region.x1 && y >= region.y0 && y < region.y1;  // counted once
      if (own && id >= 0 && id < static_cast<int>(n_objects) && a >= 0.5f) {
        counts->rendered[id] += 1;
        if (vis > 0.5f) {
          counts->visible[id] += 1;
          Box2& b = counts->boxes[id];
          b.x1 = std::min<double>(b.x1, x);
          b.y1 = std::min<double>(b.y1, y);
          b.x2 = std::max<double>(b.x2, x + 1);
          b.y2 = std::max<double>(b.y2, y + 1);
        }
      }
    }
  // The shade on the real road the camera sees, blurred alike: the camera's optics soften shadow edges too, and
  // the blur takes the sampling grain of the soft-shadow rays with it.
  ImageF shade(context.x1 - context.x0, context.y1 - context.y0, 1, 1.0f);
  for (int y = context.y0; y < context.y1; ++y)
    for (int x = context.x0; x < context.x1; ++x)
      if (occ.receiver.at(x, y) > 0.5f) shade.at(x - context.x0, y - context.y0) = r.shadow.at(x, y);
  const int bx0 = region.x0 - context.x0, by0 = region.y0 - context.y0;
  const int bx1 = region.x1 - context.x0, by1 = region.y1 - context.y0;
  GaussianBlurRegion(&layer, blur_sigma, bx0, by0, bx1, by1);
  GaussianBlurRegion(&shade, ShadeBlurSigma(blur_sigma), bx0, by0, bx1, by1);
  for (int y = region.y0; y < region.y1; ++y)
    for (int x = region.x0; x < region.x1; ++x) {
      const float* l = layer.pixel(x - context.x0, y - context.y0);
      const float av = l[3];
      const float shade_here = std::min(1.0f, shade.at(x - context.x0, y - context.y0));
      // A camera whose objects are all hidden still counts as drawn (changed): its image is written, unchanged.
      if (av <= 0 && r.render.coverage.at(x, y) <= 0 && shade_here >= 1.0f) continue;
      c->object_alpha.at(x, y) = av;
      float* px = linear->pixel(x, y);
      for (int ch = 0; ch < 3; ++ch) {
        c->shadow_only_loss.at(x, y, ch) = px[ch] * (1 - av) * (1 - shade_here);
        px[ch] = l[ch] + px[ch] * (1 - av);  // shadows are taken away below
      }
      counts->changed = true;
      if (shade_here < 1.0f) c->shadow_noise.at(x, y) = (1 - av) * std::sqrt(std::max(0.0f, 1 - shade_here * shade_here));
    }
}

// `bounds`: the rectangle that holds all objects and their shadows.
Composite CompositeObjects(const ObjectRender& r, const OcclusionMasks& occ, size_t n_objects, const Rect& bounds,
                           double blur_sigma, ImageF* linear) {
  Composite c;
  c.object_alpha = ImageF(linear->width(), linear->height(), 1, 0.0f);
  c.shadow_only_loss = ImageF(linear->width(), linear->height(), 3, 0.0f);
  c.shadow_noise = ImageF(linear->width(), linear->height(), 1, 0.0f);
  c.rendered.assign(n_objects, 0);
  c.visible.assign(n_objects, 0);
  c.boxes.assign(n_objects, Box2{1e9, 1e9, -1e9, -1e9});
  // Only around the pixels an object covers or its shadow darkens: beyond the blur's reach of them the layer is 0
  // and the shade 1, which the blur keeps exactly, so nothing changes there. Each region is blurred from its own
  // surroundings out to that reach, clamped where `bounds` ends: what one blur over `bounds` gives, bit for bit.
  const int reach = std::max(GaussianBlurReach(blur_sigma), GaussianBlurReach(ShadeBlurSigma(blur_sigma)));
  c.regions = TileRunsAround(bounds, reach, [&](int x, int y) {
    return r.render.coverage.at(x, y) > 0 || (occ.receiver.at(x, y) > 0.5f && r.shadow.at(x, y) != 1.0f);
  });
  // The regions are disjoint and each blurs its own layer and shade, made from the render and the occlusion masks
  // (never from `linear`), so they go in parallel; each counts its own objects' pixels, added in region order.
  std::vector<Composite> parts(c.regions.size());
  ParallelFor(0, c.regions.size(), [&](size_t i) {
    const auto& g = c.regions[i];
    const Rect region{g[0], g[1], g[2], g[3]};
    const Rect context{std::max(bounds.x0, g[0] - reach), std::max(bounds.y0, g[1] - reach),
                       std::min(bounds.x1, g[2] + reach), std::min(bounds.y1, g[3] + reach)};
    Composite& part = parts[i];
    part.rendered.assign(n_objects, 0);
    part.visible.assign(n_objects, 0);
    part.boxes.assign(n_objects, Box2{1e9, 1e9, -1e9, -1e9});
    CompositeRegionInto(r, occ, n_objects, region, context, blur_sigma, linear, &c, &part);
  });
  for (const Composite& part : parts) {
    c.changed = c.changed || part.changed;
    for (size_t k = 0; k < n_objects; ++k) {
      c.rendered[k] += part.rendered[k];
      c.visible[k] += part.visible[k];
      Box2& b = c.boxes[k];
      const Box2& pb = part.boxes[k];
      b.x1 = std::min(b.x1, pb.x1), b.y1 = std::min(b.y1, pb.y1), b.x2 = std::max(b.x2, pb.x2), b.y2 = std::max(b.y2, pb.y2);
    }
  }
  return c;
}

// The 10-90 % rise of the render's own silhouette edges (its anti-aliasing), median over the edges of its coverage;
// a pixel's box filter (0.8 px) when the objects are too small to show one.
double RenderEdgeRise(const ObjectRender& r, const Rect& rect) {
  ImageU8 coverage(rect.x1 - rect.x0, rect.y1 - rect.y0, 1);
  for (int y = rect.y0; y < rect.y1; ++y)
    for (int x = rect.x0; x < rect.x1; ++x)
      coverage.at(x - rect.x0, y - rect.y0) = static_cast<uint8_t>(std::lround(255 * std::clamp(r.render.coverage.at(x, y), 0.0f, 1.0f)));
  const std::vector<double> widths = EdgeRiseWidths(coverage);
  return widths.size() >= 5 ? widths[widths.size() / 2] : 0.8;
}

// Harmonisation sees the objects over the unshadowed photo (their own shadow would otherwise count as the
// surroundings they are matched to), one object at a time. Returns how many objects it harmonised.
int HarmonizeObjects(const models::Harmonizer& harmonizer, const ObjectRender& r, const Composite& c, size_t n_objects,
                     ImageF* linear) {
  // Each object's pixel bounds in the render.
  std::vector<Rect> bounds(n_objects, Rect{linear->width(), linear->height(), -1, -1});
  for (const auto& g : c.regions)
    for (int y = g[1]; y < g[3]; ++y)
      for (int x = g[0]; x < g[2]; ++x) {
        const int id = r.render.object.at(x, y);
        if (id < 0 || id >= static_cast<int>(n_objects)) continue;
        Rect& b = bounds[static_cast<size_t>(id)];
        b.x0 = std::min(b.x0, x), b.y0 = std::min(b.y0, y), b.x1 = std::max(b.x1, x + 1), b.y1 = std::max(b.y1, y + 1);
      }
  int harmonized = 0;
  for (size_t k = 0; k < n_objects; ++k) {
    const Rect& b = bounds[k];
    if (c.visible[k] < 4 || b.x1 <= b.x0) continue;
    // On a crop of the object's bounds grown by more than the widest background ring the classical transfer reads
    // (max(4, 0.25 sqrt(object pixels)), HarmonizeOptions::ring_px): the result is the same as on the whole image,
    // which costs a conversion of the photograph per object.
    const double area = static_cast<double>(b.x1 - b.x0) * (b.y1 - b.y0);
    const int margin = 2 + std::max(4, static_cast<int>(std::ceil(0.25 * std::sqrt(area))));
    const int cx0 = std::max(0, b.x0 - margin), cy0 = std::max(0, b.y0 - margin);
    const int cx1 = std::min(linear->width(), b.x1 + margin), cy1 = std::min(linear->height(), b.y1 + margin);
    ImageF composite(cx1 - cx0, cy1 - cy0, 3);
    ImageF mask(composite.width(), composite.height(), 1, 0.0f);
    // Three sRGB conversions a pixel of a crop that grows with the object: rows in parallel (the same result).
    ParallelRows(cy0, cy1, [&](int y) {
      for (int x = cx0; x < cx1; ++x) {
        for (int ch = 0; ch < 3; ++ch) composite.at(x - cx0, y - cy0, ch) = LinearToSrgb(std::clamp(linear->at(x, y, ch), 0.0f, 1.0f));
        if (x >= b.x0 && x < b.x1 && y >= b.y0 && y < b.y1 && r.render.object.at(x, y) == static_cast<int>(k))
          mask.at(x - cx0, y - cy0) = c.object_alpha.at(x, y);
      }
    });
    const ImageF out = harmonizer.Harmonize(composite, mask);
    // Back to linear only where the object is: elsewhere the harmoniser returned the composite bit for bit, and the
    // round trip through sRGB would not be.
    ParallelRows(b.y0, b.y1, [&](int y) {
      for (int x = b.x0; x < b.x1; ++x)
        if (mask.at(x - cx0, y - cy0) > 0)
          for (int ch = 0; ch < 3; ++ch) linear->at(x, y, ch) = SrgbToLinear(out.at(x - cx0, y - cy0, ch));
    });
    ++harmonized;
  }
  return harmonized;
}

// Colour (camera_look.h CapSaturation): each visible insert no more saturated than the real objects of its category
// (the stage's colour reference, realism.h RealSaturation: the frame's or the planned sequence's), or,
// where none is seen, than the image's most colourful pixels (ImageSaturationCeiling). Returns one record per
// insert: its reference, ceiling, saturation before and after, and the chroma scale applied.
nlohmann::json CapInsertSaturation(const CameraStageInput& st, const CameraSensor& cam, const ImageU8& original, const ObjectRender& r,
                                   const Composite& c, const Rect& rect, ImageF* linear) {
  const std::vector<PlacedObject>& placed = *st.placed;
  SD_CHECK(st.colour_reference != nullptr);
  const std::map<std::string, SaturationReference>& reference = *st.colour_reference;
  const char* scope = st.sequence ? "sequence" : "frame";
  double image_ceiling = -1;  // computed on first need
  nlohmann::json out = nlohmann::json::array();
  for (size_t k = 0; k < placed.size(); ++k) {
    if (c.visible[k] < 4) continue;
    const std::string category = CanonicalCategory(placed[k].asset->info.category);
    const auto it = reference.find(category);
    const SaturationReference ref = it == reference.end() ? SaturationReference{} : it->second;
    nlohmann::json rec = {{"object", k}, {"category", category}, {"reference", scope}, {"real_views", ref.views},
                          {"statistic", ref.statistic}};
    double ceiling = ref.ceiling;
    if (ref.views == 0) {  // no real object of the category: the image's own most colourful pixels bound it
      if (image_ceiling < 0) image_ceiling = ImageSaturationCeiling(original);
      ceiling = image_ceiling;
      rec["reference"] = "image";
      rec["note"] = std::string("no real ") + category + " in the " + scope + "'s images: capped at the image's 99.5th percentile";
    }
    // The outline's pixels with the insert's share of each: this object's pixels of the render.
    std::vector<OutlinePixel> pixels;
    for (const auto& [x, y] : ObjectOutlinePixels(cam, placed[k].box)) {
      const bool mine = x >= rect.x0 && x < rect.x1 && y >= rect.y0 && y < rect.y1 && r.render.object.at(x, y) == static_cast<int>(k);
      pixels.push_back({x, y, mine ? c.object_alpha.at(x, y) : 0.0f});
    }
    const SaturationCap cap = CapSaturation(linear, pixels, ceiling);
    rec["saturation_ceiling"] = cap.ceiling;
    rec["saturation_before"] = cap.before;
    rec["saturation_after"] = cap.after;
    rec["chroma_scale"] = cap.scale;
    out.push_back(rec);
  }
  return out;
}

// For people: the light at the objects in this camera.
std::string DescribeCameraLight(const CameraLight& cl, const Composite& c, const FrameLight& fl) {
  if (!cl.object_light) return "road calibration";
  const ObjectLight& ol = *cl.object_light;
  std::string text = Msg() << "sun visibility " << Fixed(ol.sun_visibility, 2) << ", scale " << Fixed(ol.scale, 2) << " ("
                           << ol.road_samples << " road pixels)";
  std::string own;
  for (size_t k = 0; k < cl.of_object.size(); ++k)
    if (fl.own_verdict[k] && c.visible[k] >= 4)
      own += Msg() << (own.empty() ? "" : ", ") << "#" << k << " " << Fixed(cl.of_object[k].sun_visibility, 2) << " x"
                   << Fixed(cl.of_object[k].scale, 2);
  if (!own.empty()) text += "; per object (sun visibility x scale): " + own;
  return text;
}

// Real objects whose edges say how soft an object of this image is: those covering at least this many pixels.
constexpr int kMinRealObjectPixels = 400;

// The near plane of a label's box projection: a box reaching behind the camera is clipped there (its truncation
// is then the share of the clipped outline's rectangle outside the image), as mining's crops are.
constexpr double kLabelNearM = 0.1;

}  // namespace

std::optional<CameraOutcome> SynthesizeCamera(const CameraStageInput& st, size_t cam_index, std::vector<CameraObjectView>* views) {
  const CameraSensor& cam = st.in->frame->cameras[cam_index];
  const std::vector<PlacedObject>& placed = *st.placed;
  views->assign(placed.size(), CameraObjectView{});
  const auto projected_rect = ProjectedRect(cam.intrinsics, cam.T_ego_cam.Inverse(), st.scene->extent_points, 2);
  if (!projected_rect) return std::nullopt;
  const Rect rect{(*projected_rect)[0], (*projected_rect)[1], (*projected_rect)[2], (*projected_rect)[3]};
  // Each object's own rectangles, for the stages that trace rays per pixel: its box's, and its box's with its
  // shadow's patch (the shadow stages).
  PixelRects rects;
  const Rigid3d T_cam_ego = cam.T_ego_cam.Inverse();
  for (size_t k = 0; k < placed.size(); ++k) {
    const auto corners = placed[k].box.Corners();
    if (const auto r = ProjectedRect(cam.intrinsics, T_cam_ego, {corners.begin(), corners.end()}, 2)) rects.boxes.push_back(*r);
    if (const auto r = ProjectedRect(cam.intrinsics, T_cam_ego, st.scene->extent_of[k], 2)) rects.with_shadows.push_back(*r);
  }

  ScopedStage read_stage(st.times, "camera read");
  const ImageU8& original = st.in->Image(cam_index);
  ImageF linear = ToLinear(original);
  read_stage.Stop();
  const CameraLookOptions& look_options = st.options->camera_look;
  const bool any_look = look_options.blur || look_options.noise || look_options.jpeg || look_options.colour;
  // The camera's look is read from the photograph alone: it is estimated (one thread) while the objects render.
  CameraLight cl;
  ObjectRender r;
  CameraLook look;
  StageTimes look_times;
  ParallelForRethrow(0, 2, [&](size_t task) {
    if (task == 0) {
      ScopedStage light_stage(st.times, "camera light");
      cl = LightOfCamera(st, cam_index, linear);
      light_stage.Stop();
      r = RenderObjects(st, cam, cl, rects);
    } else if (any_look) {
      ScopedStage look_stage(&look_times, "camera look");
      // The dataset's own objects only: a detected box (synth/detected_tracks.h) is often a tile of a wall.
      std::vector<Box3> labelled;
      for (const Annotation& a : st.in->frame->annotations)
        if (!a.detected) labelled.push_back(a.box);
      const ImageF real_objects = ObjectOutlinesMask(cam, labelled, kMinRealObjectPixels);
      look = EstimateCameraLook(original, st.in->JpegQuality(cam_index), &real_objects);
    }
  });
  ScopedStage occlusion_stage(st.times, "camera occlusion");
  const ImageF receiver_depth = ReceiverDepth(cam, st.in->ground->seed_plane(), r, rects.with_shadows);
  const OcclusionMasks occ = OccludeByScene(st, cam, original, r, receiver_depth, rect);
  occlusion_stage.Stop();
  if (st.times) st.times->Merge(look_times);
  ScopedStage look_stage(st.times, "camera look");
  const double render_rise = look_options.blur ? RenderEdgeRise(r, rect) : 0;
  const double blur = look_options.blur ? ExtraBlurSigma(render_rise, look.TargetEdgeRise()) : 0;
  look_stage.Stop();
  ScopedStage composite_stage(st.times, "camera composite");
  const Composite c = CompositeObjects(r, occ, placed.size(), rect, blur, &linear);
  composite_stage.Stop();
  if (!c.changed) return std::nullopt;
  std::string harmonized;
  if (st.harmonizer) {
    ScopedStage harmonize_stage(st.times, "camera harmonise");
    const int n = HarmonizeObjects(*st.harmonizer, r, c, placed.size(), &linear);
    harmonized = Msg() << "; harmonised: " << n << " object(s) (" << (st.harmonizer->learned() ? "learned" : "classical") << ")";
  }
  ScopedStage colour_stage(st.times, "camera colour");
  ParallelFor(0, c.regions.size(), [&](size_t i) {  // no shadow reaches beyond them; they are disjoint
    const auto& g = c.regions[i];
    for (int y = g[1]; y < g[3]; ++y)
      for (int x = g[0]; x < g[2]; ++x)
        for (int ch = 0; ch < 3; ++ch)
          linear.at(x, y, ch) = std::max(0.0f, linear.at(x, y, ch) - c.shadow_only_loss.at(x, y, ch));
  });

  const nlohmann::json colour = st.colour_reference ? CapInsertSaturation(st, cam, original, r, c, rect, &linear) : nlohmann::json();
  colour_stage.Stop();

  ScopedStage sensor_stage(st.times, "camera sensor");
  CameraOutcome co;
  co.channel = cam.channel;
  co.before = original;
  // Only the redrawn regions are converted back: every other pixel keeps the photograph's own byte, which is also
  // what converting it back would give (the sRGB round trip of each of the 256 values is exact).
  co.after = original;
  for (const auto& g : c.regions) ToSrgb8Region(linear, g[0], g[1], g[2], g[3], &co.after);
  // The sensor's last steps, on the inserted pixels only: its noise, then its compression.
  const uint64_t sensor_seed = st.in->seeds.sensor ^ (0x9E3779B97F4A7C15ull * (cam_index + 1));
  ApplySensorToInserts(&co.after, c.object_alpha, &c.shadow_noise, rect.x0, rect.y0, rect.x1, rect.y1, c.regions, look,
                       look_options, sensor_seed);
  sensor_stage.Stop();
  co.light = DescribeCameraLight(cl, c, *st.light) + harmonized;
  if (any_look) {
    co.look = look.ToJson();
    co.look["render_edge_rise_px"] = render_rise;
    co.look["blur_sigma_px"] = blur;
    co.look["applied"] = {{"blur", look_options.blur}, {"noise", look_options.noise}, {"jpeg", look_options.jpeg},
                          {"colour", look_options.colour}};
    if (look_options.colour) co.look["colour"] = colour;
  }
  for (size_t k = 0; k < placed.size(); ++k) {
    CameraObjectView& view = (*views)[k];
    view.rendered_pixels = c.rendered[k];
    view.visible_pixels = c.visible[k];
    if (c.visible[k] < 4) continue;  // a few pixels are not a labelable object
    CameraBox cb;
    cb.channel = cam.channel;
    cb.box = c.boxes[k];
    cb.visible_fraction = c.rendered[k] > 0 ? c.visible[k] / c.rendered[k] : 0;
    const auto in_image = geometry::ProjectBoxToImage(cam.intrinsics, cam.T_ego_cam.Inverse(), placed[k].box, kLabelNearM);
    cb.truncation = in_image ? in_image->truncation : 1.0;
    view.box = cb;
    co.objects.push_back(static_cast<int>(k));
  }
  return co;
}

void AddCameraViews(const std::vector<CameraObjectView>& views, std::vector<ObjectOutcome>* objects) {
  SD_CHECK(views.empty() || views.size() == objects->size(), << views.size() << " views of " << objects->size() << " objects");
  for (size_t k = 0; k < views.size(); ++k) {
    ObjectOutcome& oc = (*objects)[k];
    oc.rendered_pixels += views[k].rendered_pixels;
    oc.visible_pixels += views[k].visible_pixels;
    if (views[k].box) oc.label.camera_boxes.push_back(*views[k].box);
  }
}

}  // namespace frame_stages
}  // namespace sd
