#include "assetgen/generate.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <deque>
#include <memory>

#include "assetgen/texture.h"
#include "assetgen/texture_eval.h"
#include "assetgen/uv_atlas.h"
#include "core/error.h"
#include "core/log.h"
#include "models/super_resolution.h"

namespace sd {

namespace {

class StageTimer {
 public:
  explicit StageTimer(std::vector<StageReport>* reports) : reports_(reports) {}
  // Runs `body`, records its wall time under `stage` with the method it returns.
  template <typename F>
  void Run(const std::string& stage, F&& body) {
    const auto t0 = std::chrono::steady_clock::now();
    std::string method = body();
    const double s = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
    SD_LOG(Info, "generate: " << stage << " (" << method << ") " << s << " s");
    reports_->push_back({stage, std::move(method), s});
  }

 private:
  std::vector<StageReport>* reports_;
};

ColorViewSet ColorViewsOf(const MultiViewSet& views) {
  ColorViewSet out;
  for (size_t i = 0; i < views.size(); ++i) {
    if (views[i].color.empty())
      throw InputError({}, Msg() << "view '" << views[i].view.name << "' has no colour image (texturing needs one per view)");
    out.push_back({views[i].view, views[i].color, views[i].mask});
  }
  return out;
}

}  // namespace

TriangleMesh GeneratedMesh::ToAssetFrame(TriangleMesh m) const {
  for (auto& p : m.positions) p = (scale * (rotation * p.cast<double>()) + translation).cast<float>();
  const Eigen::Matrix3f R = rotation.cast<float>();
  for (auto& n : m.normals) n = R * n;
  return m;
}

namespace {

// `coarse`: a given coarse mesh (a shape prior's) instead of the views' visual hull; `coarse_method` says what it is.
GeneratedMesh Generate(const MultiViewSet& views, const GenerateOptions& options, const TriangleMesh* given_coarse,
                       const std::string& coarse_method) {
  if (views.empty()) throw InputError({}, "no views to generate from");
  if (options.texture != "bake" && options.texture != "vertex")
    throw InputError({}, Msg() << "unknown texture mode '" << options.texture << "' (bake or vertex)");
  ColorViewSet color_views = ColorViewsOf(views);
  GeneratedMesh out;
  StageTimer timer(&out.stages);

  TriangleMesh coarse;
  timer.Run("coarse_mesh", [&] {
    if (given_coarse) {
      coarse = PrepareForRefinement(*given_coarse, "the prior's coarse mesh");
      return std::string(Msg() << coarse_method << ", " << coarse.NumFaces() << " triangles");
    }
    coarse = CoarseMeshFromViews(views, options.hull_resolution);
    return std::string(Msg() << "visual hull of " << views.size() << " masks, " << options.hull_resolution << "^3, "
                             << coarse.NumFaces() << " triangles");
  });

  TriangleMesh mesh;
  if (options.refine.steps == 0) {
    mesh = coarse;
  } else {
    timer.Run("refine", [&] {
      RefineResult r = RefineMesh(coarse, views, options.refine);
      mesh = std::move(r.mesh);
      out.last_refine_step = r.log.back();
      return std::string(Msg() << (options.refine.lambda_normal > 0 ? "normal + silhouette, " : "silhouette only, ")
                               << options.refine.steps << " steps x " << options.refine.iterations_per_step
                               << " iterations, " << mesh.NumFaces() << " triangles");
    });
  }

  if (options.upscale != "none") {
    timer.Run("super_resolution", [&] {
      const models::Upscaler upscaler = models::Upscaler::Resolve(options.upscale, 2);
      color_views = SuperResolveViews(color_views, upscaler);
      return upscaler.Describe();
    });
  }

  timer.Run("texture", [&] {
    if (options.texture == "vertex") {
      const VertexFusionResult fused = FuseVertexColors(mesh, color_views);
      mesh.colors.resize(mesh.NumVertices());
      for (size_t v = 0; v < mesh.NumVertices(); ++v) mesh.colors[v] << fused.colors[v], 1.0f;
      return std::string(Msg() << "vertex colours, " << fused.propagated << " of " << mesh.NumVertices()
                               << " vertices propagated");
    }
    UvAtlasOptions atlas;
    atlas.texture_size = options.texture_size;
    UvAtlasStats stats;
    mesh = BuildUvAtlas(mesh, atlas, &stats);
    Material material;
    material.name = "baked";
    material.base_color_texture = std::make_shared<ImageU8>(BakeTexture(mesh, color_views, options.texture_size));
    material.base_color_texture_name = "baked.png";
    mesh.materials = {material};
    return std::string(Msg() << "UV atlas " << options.texture_size << "^2, " << stats.charts << " charts, "
                             << static_cast<int>(100 * stats.utilisation) << "% used");
  });

  timer.Run("canonical", [&] {
    const Eigen::Vector3f before = mesh.positions.front();
    CanonicalizeResult c = Canonicalize(mesh, options.canonical);
    out.rotation = c.rotation;
    out.scale = c.scale;
    out.translation = c.mesh.positions.front().cast<double>() - c.scale * (c.rotation * before.cast<double>());
    out.extent = c.extent;
    out.mesh = std::move(c.mesh);
    Msg method;
    method << "up " << options.canonical.up << ", front " << options.canonical.front;
    if (c.frame) method << " (" << c.frame->front_method << ")";
    method << ", scale " << c.scale << " m per view unit";
    return method.str();
  });
  return out;
}

}  // namespace

GeneratedMesh GenerateFromViews(const MultiViewSet& views, const GenerateOptions& options) {
  return Generate(views, options, nullptr, "");
}

ViewAgreement AgreementAtView(const GeneratedMesh& g, const MultiView& view, const ImageF& truth) {
  TriangleMesh back = g.mesh;
  const Eigen::Matrix3f Rt = g.rotation.transpose().cast<float>();
  for (auto& p : back.positions) p = Rt * ((p - g.translation.cast<float>()) / float(g.scale));
  back.normals.clear();
  const AlbedoRender drawn = RenderAlbedo(back, view.view, 2);
  double inter = 0, uni = 0;
  for (size_t i = 0; i < truth.vector().size(); ++i) {
    const bool p = drawn.mask.vector()[i] > 0.5f, t = truth.vector()[i] > 0.5f;
    inter += p && t, uni += p || t;
  }
  ImageF drawn_srgb = drawn.color, seen_srgb = view.color;
  for (float& v : drawn_srgb.vector()) v = LinearToSrgb(std::clamp(v, 0.0f, 1.0f));
  for (float& v : seen_srgb.vector()) v = LinearToSrgb(std::clamp(v, 0.0f, 1.0f));
  return {uni > 0 ? inter / uni : 0.0, MaskedPsnr(drawn_srgb, seen_srgb, truth)};
}

GeneratedMesh GenerateFromPhotoShape(const PhotoShape& shape, GenerateOptions options) {
  // No refinement: the prior's views carry masks only, and its coarse mesh already has every view's silhouette
  // (a revolve's views are the photo turned about the axis its profile was turned about; a hull is carved from
  // its views). Mask-only refinement has nothing to fit and only smooths what the views do not constrain
  // (bench_shape_prior, 20 steps against none: Chamfer median 0.0147 -> 0.0154 revolve, 0.0156 -> 0.0188 mirror,
  // 0.0168 -> 0.0186 hull; held-out PSNR 18.8 -> 13.3 dB on the MetaDrive cone).
  options.refine.steps = 0;
  options.canonical.up = "+z", options.canonical.front = "+x";
  // Metric already: the prior built the shape at the object's size (a revolve's width is the photo's, not the
  // category's), so refitting a target size would only distort it.
  options.canonical.scale = 1.0;
  options.canonical.front_direction.reset();
  return Generate(shape.views, options, &shape.coarse, std::string(ToString(shape.prior)) + " prior");
}

namespace {

// Labels the 4-connected components of `on`; returns the label of each pixel (-1 off) and the size of each.
std::vector<int> Components(const std::vector<uint8_t>& on, int w, int h, std::vector<size_t>* sizes) {
  std::vector<int> label(on.size(), -1);
  std::deque<int> queue;
  for (int start = 0; start < w * h; ++start) {
    if (!on[start] || label[start] >= 0) continue;
    const int id = static_cast<int>(sizes->size());
    sizes->push_back(0);
    label[start] = id;
    queue.push_back(start);
    while (!queue.empty()) {
      const int p = queue.front();
      queue.pop_front();
      ++(*sizes)[id];
      const int x = p % w, y = p / w;
      const int nbr[4][2] = {{x - 1, y}, {x + 1, y}, {x, y - 1}, {x, y + 1}};
      for (const auto& q : nbr) {
        if (q[0] < 0 || q[1] < 0 || q[0] >= w || q[1] >= h) continue;
        const int n = q[1] * w + q[0];
        if (on[n] && label[n] < 0) {
          label[n] = id;
          queue.push_back(n);
        }
      }
    }
  }
  return label;
}

// A square RGBA cut-out around `box` (a fifth of its longer side as margin on each side), alpha = the mask;
// pixels outside the image are transparent.
ImageU8 ObjectCutout(const ImageU8& image, const ImageF& mask, const Box2& box) {
  const double side = 1.4 * std::max(box.x2 - box.x1, box.y2 - box.y1);
  const int n = std::max(8, static_cast<int>(std::lround(side)));
  const double x0 = 0.5 * (box.x1 + box.x2) - 0.5 * n, y0 = 0.5 * (box.y1 + box.y2) - 0.5 * n;
  ImageU8 out(n, n, 4, 0);
  for (int y = 0; y < n; ++y)
    for (int x = 0; x < n; ++x) {
      const int sx = static_cast<int>(std::floor(x0 + x)), sy = static_cast<int>(std::floor(y0 + y));
      if (sx < 0 || sy < 0 || sx >= image.width() || sy >= image.height()) continue;
      for (int c = 0; c < 3; ++c) out.at(x, y, c) = image.at(sx, sy, std::min(c, image.channels() - 1));
      out.at(x, y, 3) = static_cast<uint8_t>(std::lround(255.0f * std::clamp(mask.at(sx, sy), 0.0f, 1.0f)));
    }
  return out;
}

}  // namespace

ImageF MaskFromFlatBackground(const ImageU8& view, uint8_t background) {
  // The generator's background is flat up to its decoder's noise; 12 of 255 clears that noise but keeps dim
  // object pixels, and the component and hole clean-up below removes what slips either way.
  constexpr int kThreshold = 12;
  const int w = view.width(), h = view.height();
  std::vector<uint8_t> on(static_cast<size_t>(w) * h, 0);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      int diff = 0;
      for (int c = 0; c < std::min(3, view.channels()); ++c) diff = std::max(diff, std::abs(view.at(x, y, c) - background));
      on[static_cast<size_t>(y) * w + x] = diff > kThreshold;
    }
  std::vector<size_t> sizes;
  const std::vector<int> label = Components(on, w, h, &sizes);
  ImageF mask(w, h, 1, 0.0f);
  if (sizes.empty()) return mask;
  const int keep = static_cast<int>(std::max_element(sizes.begin(), sizes.end()) - sizes.begin());
  // Holes: background components that do not touch the border.
  std::vector<uint8_t> off(on.size());
  for (size_t i = 0; i < on.size(); ++i) off[i] = label[i] != keep;
  std::vector<size_t> hole_sizes;
  const std::vector<int> hole = Components(off, w, h, &hole_sizes);
  std::vector<uint8_t> touches_border(hole_sizes.size(), 0);
  for (int x = 0; x < w; ++x) {
    for (int y : {0, h - 1})
      if (hole[static_cast<size_t>(y) * w + x] >= 0) touches_border[hole[static_cast<size_t>(y) * w + x]] = 1;
  }
  for (int y = 0; y < h; ++y) {
    for (int x : {0, w - 1})
      if (hole[static_cast<size_t>(y) * w + x] >= 0) touches_border[hole[static_cast<size_t>(y) * w + x]] = 1;
  }
  for (size_t i = 0; i < on.size(); ++i)
    if (label[i] == keep || (hole[i] >= 0 && !touches_border[hole[i]])) mask.vector()[i] = 1.0f;
  return mask;
}

namespace {

// The mask grown by `r` pixels (square structuring element, as two separable max filters).
std::vector<uint8_t> Grow(const ImageU8& mask, int r) {
  const int w = mask.width(), h = mask.height();
  std::vector<uint8_t> on(static_cast<size_t>(w) * h), tmp(on.size(), 0), out(on.size(), 0);
  for (size_t i = 0; i < on.size(); ++i) on[i] = mask.data()[i] > 127;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      if (on[static_cast<size_t>(y) * w + x])
        for (int dx = std::max(0, x - r); dx <= std::min(w - 1, x + r); ++dx) tmp[static_cast<size_t>(y) * w + dx] = 1;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      if (tmp[static_cast<size_t>(y) * w + x])
        for (int dy = std::max(0, y - r); dy <= std::min(h - 1, y + r); ++dy) out[static_cast<size_t>(dy) * w + x] = 1;
  return out;
}

// The segmentation stage under a coarse prior (SegmentationPrior): returns the method line.
std::string SegmentWithPrior(const ImageU8& image, const Box2& box, const ImageToViewsStages& stages,
                             const std::string& method, const SegmentationPrior& prior, ImageF& mask) {
  const int w = image.width(), h = image.height();
  const std::vector<uint8_t> grown = Grow(prior.mask, prior.grow_px);
  double x1 = w, y1 = h, x2 = 0, y2 = 0, prior_area = 0;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      if (grown[static_cast<size_t>(y) * w + x]) x1 = std::min<double>(x1, x), y1 = std::min<double>(y1, y),
                                                  x2 = std::max<double>(x2, x + 1), y2 = std::max<double>(y2, y + 1);
  for (size_t i = 0; i < prior.mask.size(); ++i) prior_area += prior.mask.data()[i] > 127;
  if (prior_area == 0) throw InputError({}, "the " + prior.source + " mask of the object is empty");
  const Box2 seg_box{std::max(box.x1, x1), std::max(box.y1, y1), std::min(box.x2, x2), std::min(box.y2, y2)};
  const ImageF prob = stages.segment(image, seg_box.Empty() ? box : seg_box);
  mask = ImageF(w, h, 1, 0.0f);
  double kept = 0;
  for (size_t i = 0; i < grown.size(); ++i)
    if (grown[i]) kept += mask.vector()[i] = prob.vector()[i];
  if (kept >= prior.min_agreement * prior_area)
    return method + " within the " + prior.source + " mask (grown " + std::to_string(prior.grow_px) + " px)";
  for (size_t i = 0; i < grown.size(); ++i) mask.vector()[i] = prior.mask.data()[i] > 127 ? 1.0f : 0.0f;
  return "the " + prior.source + " mask (" + method + " kept only " +
         std::to_string(static_cast<int>(100 * kept / prior_area)) + "% of it)";
}

}  // namespace

MultiViewSet ViewsFromImage(const ImageU8& image, const Box2& box_in, const ImageToViewsStages& stages,
                            std::vector<StageReport>* reports, const SegmentationPrior* prior) {
  if (image.empty()) throw InputError({}, "empty object image");
  Box2 box = box_in;
  box.x1 = std::max(0.0, box.x1);
  box.y1 = std::max(0.0, box.y1);
  box.x2 = std::min<double>(image.width(), box.x2);
  box.y2 = std::min<double>(image.height(), box.y2);
  if (box.Empty())
    throw InputError({}, Msg() << "object box (" << box_in.x1 << ", " << box_in.y1 << ", " << box_in.x2 << ", "
                               << box_in.y2 << ") does not overlap the " << image.width() << "x" << image.height()
                               << " image");
  std::vector<StageReport> local;
  StageTimer timer(reports ? reports : &local);
  auto method = [&](size_t i, const char* fallback) {
    return i < stages.methods.size() ? stages.methods[i] : std::string(fallback);
  };

  if (prior && (prior->mask.width() != image.width() || prior->mask.height() != image.height() ||
                prior->mask.channels() != 1))
    throw InputError({}, Msg() << "the " << prior->source << " mask is " << prior->mask.width() << "x"
                               << prior->mask.height() << "x" << prior->mask.channels() << ", the image "
                               << image.width() << "x" << image.height());
  ImageF mask;
  timer.Run("segmentation", [&] {
    if (prior && prior->source == "alpha") {
      mask = ImageF(image.width(), image.height(), 1);
      for (size_t i = 0; i < mask.size(); ++i) mask.vector()[i] = prior->mask.data()[i] / 255.0f;
      return std::string("the source's alpha mask");
    }
    if (prior) return SegmentWithPrior(image, box, stages, method(0, "segmentation"), *prior, mask);
    if (image.channels() == 4) {
      mask = ImageF(image.width(), image.height(), 1);
      for (int y = 0; y < image.height(); ++y)
        for (int x = 0; x < image.width(); ++x) mask.at(x, y) = image.at(x, y, 3) / 255.0f;
      return std::string("the image's alpha channel");
    }
    mask = stages.segment(image, box);
    return method(0, "segmentation");
  });
  double area = 0;
  for (float m : mask.vector()) area += m;
  if (area < 0.01 * box.Area()) throw InputError({}, "no object found in the box (the mask covers under 1% of it)");
  const ImageU8 cutout = ObjectCutout(image, mask, box);

  std::vector<ImageU8> generated;
  timer.Run("multiview", [&] {
    generated = stages.generate_views(cutout);
    return method(1, "multi-view generation");
  });
  if (generated.size() != 6) throw InputError({}, Msg() << "the multi-view generator returned " << generated.size() << " views, not 6");
  const int size = generated[0].width();
  for (const ImageU8& v : generated)
    if (v.width() != size || v.height() != size || v.channels() < 3)
      throw InputError({}, "the multi-view generator's views are not square RGB images of one size");
  const std::vector<ViewCamera> rig = Zero123PlusPlusRig(size);

  MultiViewSet views(6);
  timer.Run("normals", [&] {
    for (size_t i = 0; i < 6; ++i) {
      MultiView& mv = views[i];
      mv.view = rig[i];
      mv.mask = MaskFromFlatBackground(generated[i]);
      ImageF srgb(size, size, 3);
      mv.color = ImageF(size, size, 3);
      for (int y = 0; y < size; ++y)
        for (int x = 0; x < size; ++x)
          for (int c = 0; c < 3; ++c) {
            srgb.at(x, y, c) = generated[i].at(x, y, c) / 255.0f;
            mv.color.at(x, y, c) = SrgbToLinear(srgb.at(x, y, c));
          }
      const ImageF n_cam = stages.estimate_normals(srgb);
      if (n_cam.width() != size || n_cam.height() != size || n_cam.channels() != 3)
        throw InputError({}, "the normal estimator's output does not match its view's size");
      const Eigen::Matrix3f R = mv.view.T_world_cam.Rotation().cast<float>();
      mv.normals = ImageF(size, size, 3, 0.0f);
      for (int y = 0; y < size; ++y)
        for (int x = 0; x < size; ++x) {
          if (mv.mask.at(x, y) < 0.5f) continue;
          const Eigen::Vector3f n = R * Eigen::Vector3f(n_cam.at(x, y, 0), n_cam.at(x, y, 1), n_cam.at(x, y, 2));
          for (int c = 0; c < 3; ++c) mv.normals.at(x, y, c) = n[c];
        }
    }
    return method(2, "normal estimation");
  });
  return views;
}

}  // namespace sd
