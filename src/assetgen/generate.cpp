#include "assetgen/generate.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <deque>
#include <memory>

#include "assetgen/asset.h"
#include "assetgen/texture.h"
#include "assetgen/texture_eval.h"
#include "assetgen/uv_atlas.h"
#include "core/error.h"
#include "core/log.h"
#include "core/stats.h"
#include "geometry/closest_point.h"
#include "geometry/topology.h"
#include "geometry/visual_hull.h"
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
    out.push_back({views[i].view, views[i].color, views[i].mask, views[i].synthetic});
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
                       const std::string& coarse_method, const std::vector<Eigen::Vector3f>& points = {}) {
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
      RefineResult r = RefineMesh(coarse, views, options.refine, points);
      mesh = std::move(r.mesh);
      out.last_refine_step = r.log.back();
      return std::string(Msg() << (options.refine.lambda_normal > 0 ? "normal + silhouette" : "silhouette")
                               << (points.empty() ? std::string(", ") : std::string(Msg() << " + " << points.size() << " LiDAR returns, "))
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
      out.texture_provenance = fused.provenance;
      mesh.colors.resize(mesh.NumVertices());
      for (size_t v = 0; v < mesh.NumVertices(); ++v) mesh.colors[v] << fused.colors[v], 1.0f;
      return std::string(Msg() << "vertex colours, " << fused.propagated << " of " << mesh.NumVertices()
                               << " vertices propagated");
    }
    UvAtlasOptions atlas;
    atlas.texture_size = options.texture_size;
    UvAtlasStats stats;
    // A mesh of many small charts may not fit the asked size with its gutters: the next size up, to 4096.
    TriangleMesh with_uvs;
    for (;;) {
      try {
        with_uvs = BuildUvAtlas(mesh, atlas, &stats);
        break;
      } catch (const InputError& e) {
        if (atlas.texture_size >= 4096 || std::string(e.what()).find("do not fit") == std::string::npos) throw;
        SD_LOG(Info, "texture: " << e.what() << "; trying " << 2 * atlas.texture_size << "^2");
        atlas.texture_size *= 2;
      }
    }
    mesh = std::move(with_uvs);
    Material material;
    material.name = "baked";
    material.base_color_texture =
        std::make_shared<ImageU8>(BakeTexture(mesh, color_views, atlas.texture_size, {}, &out.texture_provenance));
    material.base_color_texture_name = "baked.png";
    mesh.materials = {material};
    return std::string(Msg() << "UV atlas " << atlas.texture_size << "^2, " << stats.charts << " charts, "
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
  // Pixels past the source image's border (a view cut by it) are not judged.
  double inter = 0, uni = 0;
  for (size_t i = 0; i < truth.vector().size(); ++i) {
    if (!view.known.empty() && view.known.vector()[i] <= 0.5f) continue;
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

nlohmann::json MeshQuality(const GeneratedMesh& g) {
  // The atlas splits vertices along chart borders: weld before asking whether the surface is closed.
  std::vector<Eigen::Vector3f> positions = g.mesh.positions;
  std::vector<Eigen::Vector3i> faces = g.mesh.faces;
  const float diag = g.mesh.Bounds().Size().norm();
  geometry::WeldVertices(&positions, &faces, 1e-6f * std::max(diag, 1e-12f));
  const geometry::TopologyReport topo = geometry::AnalyzeTopology(static_cast<int>(positions.size()), faces);
  return {{quality::kWatertight, topo.IsWatertight() ? 1 : 0},
          {quality::kRealTextureFraction, g.texture_provenance.real},
          {"synthetic_texture_fraction", g.texture_provenance.synthetic},
          {"propagated_texture_fraction", g.texture_provenance.propagated}};
}

namespace {

// The real view in the middle of the directions seen: the most interior one, whose azimuth is the median of the
// real views' (a held-out view between others tests interpolation, not extrapolation into the unseen).
size_t MiddleView(const MultiViewSet& views) {
  std::vector<std::pair<double, size_t>> az;
  for (size_t i = 0; i < views.size(); ++i) {
    const Eigen::Vector3d c = views[i].view.T_world_cam.translation;
    az.emplace_back(std::atan2(c.y(), c.x()), i);
  }
  // Unwrap around the largest gap, so a set of views straddling +-180 degrees sorts in order.
  std::sort(az.begin(), az.end());
  size_t gap_after = az.size() - 1;
  double gap = az.front().first + 2 * 3.14159265358979323846 - az.back().first;
  for (size_t i = 0; i + 1 < az.size(); ++i)
    if (az[i + 1].first - az[i].first > gap) gap = az[i + 1].first - az[i].first, gap_after = i;
  std::rotate(az.begin(), az.begin() + (gap_after + 1) % az.size(), az.end());
  return az[az.size() / 2].second;
}

// The box priors' coarse mesh: the hull of every view inside the metric box, carved by the beams.
GeneratedMesh GenerateFromHull(const HarvestedObject& object, const MultiViewSet& views, const HarvestFit& fit,
                               const GenerateOptions& options, const std::vector<Eigen::Vector3f>& points) {
  geometry::VisualHullOptions hull;
  hull.resolution = options.hull_resolution;
  const Eigen::Vector3f half = (0.5 * object.size).cast<float>() * 1.02f;
  hull.bounds.min = Eigen::Vector3f(-half.x(), -half.y(), 0.0f);
  hull.bounds.max = Eigen::Vector3f(half.x(), half.y(), float(object.size.z()) * 1.02f);
  hull.tolerated_outside_views = fit.real_views >= 6 ? 1 : 0;
  hull.free_segments = object.free_segments;
  std::vector<geometry::SilhouetteView> silhouettes;
  // A view cut by the image border carves nothing past it.
  for (const MultiView& v : views) silhouettes.push_back({v.view.camera, v.view.T_world_cam.Inverse(), MaskOrUnknown(v)});
  TriangleMesh coarse = geometry::VisualHull(silhouettes, hull);
  std::string coarse_method = Msg() << "visual hull of " << fit.real_views << " real + " << fit.synthetic_views
                                    << " " << ToString(fit.prior) << " views in the " << object.size.x() << " x "
                                    << object.size.y() << " x " << object.size.z() << " m box, "
                                    << hull.free_segments.size() << " LiDAR beams carving, " << hull.resolution << "^3";
  if (coarse.faces.empty() && !hull.free_segments.empty()) {
    // The beams and the masks disagree so much that nothing is left (a mis-registered camera, say): the masks'
    // hull alone, said in the method.
    hull.free_segments.clear();
    coarse = geometry::VisualHull(silhouettes, hull);
    coarse_method += " (the beams carved everything away: masks only)";
  }
  if (coarse.faces.empty()) throw InputError({}, "the views' silhouettes share no volume inside the object's box");
  return Generate(views, options, &coarse, coarse_method, points);
}

// The asset's figures (asset.h namespace quality): `measured` are the returns its surface is judged against (held
// out of the fit when `held_out`).
void FillHarvestQuality(const HarvestedObject& object, const GeneratedMesh& g, const std::vector<Eigen::Vector3f>& measured,
                        bool held_out, HarvestFit* fit) {
  fit->quality = MeshQuality(g);
  fit->quality[quality::kExtentToSize] = g.extent.cwiseQuotient(object.size).maxCoeff();
  fit->quality[quality::kShapePrior] = {{"prior", ToString(fit->prior)}, {"reason", fit->prior_reason},
                                        {"real_views", fit->real_views}, {"synthetic_views", fit->synthetic_views}};
  if (!fit->held_out.empty()) {
    double iou = 0, psnr = 0;
    for (size_t i : fit->held_out) {
      const ViewAgreement a = AgreementAtView(g, object.views[i], object.views[i].mask);
      iou += a.silhouette_iou, psnr += a.masked_psnr_db;
    }
    fit->quality[quality::kHeldOutSilhouetteIou] = iou / fit->held_out.size();
    fit->quality["heldout_masked_psnr_db"] = psnr / fit->held_out.size();
    fit->quality["heldout_views"] = fit->held_out.size();
  }
  if (!measured.empty()) {
    TriangleMesh cloud;
    cloud.positions = measured;
    cloud = g.ToAssetFrame(std::move(cloud));
    const std::vector<float> d = geometry::PointToSurfaceDistances(g.mesh.positions, g.mesh.faces, cloud.positions);
    fit->quality[quality::kLidarPointToMeshMedianM] = Median(std::vector<double>(d.begin(), d.end()));
    fit->quality["lidar_points"] = object.points.size();
    fit->quality["lidar_p2m_points"] = measured.size();
    fit->quality["lidar_p2m_held_out"] = held_out;  // false: too few returns to hold any out, a fit residual
  }
}

}  // namespace

GeneratedMesh GenerateFromHarvest(const HarvestedObject& object, GenerateOptions options, HarvestFit* fit_out) {
  HarvestFit fit;
  if (object.views.empty()) throw InputError({}, "the harvested object has no views");
  // Held out: the middle one of the whole views, else of all (a view cut by the image border is scored on the
  // pixels it sees), when at least two views remain to fit.
  if (object.views.size() >= 3) {
    std::vector<size_t> from;
    for (size_t i = 0; i < object.views.size(); ++i)
      if (IsWhole(object.views[i])) from.push_back(i);
    if (from.empty())
      for (size_t i = 0; i < object.views.size(); ++i) from.push_back(i);
    MultiViewSet candidates;
    for (size_t i : from) candidates.push_back(object.views[i]);
    fit.held_out.push_back(from[MiddleView(candidates)]);
  }
  MultiViewSet views;
  for (size_t i = 0; i < object.views.size(); ++i)
    if (std::find(fit.held_out.begin(), fit.held_out.end(), i) == fit.held_out.end()) views.push_back(object.views[i]);

  // The prior: the category's, a revolve demoted when the largest silhouette is not mirror-symmetric.
  fit.prior = DefaultShapePrior(object.category);
  fit.prior_reason = "category " + object.category;
  if (fit.prior == ShapePrior::kRevolve) {
    // A profile is read off whole silhouettes only.
    MultiViewSet whole_views;
    for (const MultiView& v : views)
      if (IsWhole(v)) whole_views.push_back(v);
    if (whole_views.empty()) {
      fit.prior = ShapePrior::kHull;
      fit.prior_reason = Msg() << "category " << object.category << ", but no view shows it whole";
    } else {
      views = std::move(whole_views);
    }
  }
  fit.real_views = static_cast<int>(views.size());
  if (fit.prior == ShapePrior::kRevolve) {
    // A log's masks are a segmenter's at a few dozen pixels, shaded on one side: less symmetric than a photo's
    // (the photo path asks 0.85); what is far below is no surface of revolution (a fallen or crushed cone).
    constexpr double kMinLogSymmetry = 0.7;
    const double symmetry = FitSymmetryAxis(views[LargestView(views)].mask).symmetry_iou;
    if (symmetry < kMinLogSymmetry) {
      fit.prior = ShapePrior::kHull;
      fit.prior_reason = Msg() << "category " << object.category << ", but silhouette symmetry " << symmetry << " < "
                               << kMinLogSymmetry;
    }
  }
  // Every fifth return is held out of the fit (with 25 or more): the point-to-mesh figure is then measured on
  // returns the surface was not pulled onto, not a fit residual.
  std::vector<Eigen::Vector3f> fit_points, held_points;
  for (size_t i = 0; i < object.points.size(); ++i)
    (object.points.size() >= 25 && i % 5 == 2 ? held_points : fit_points).push_back(object.points[i]);
  // A surface of revolution turns about its own axis, which the box's centre only approximates. Its coarse mesh is
  // the profile every real silhouette and return agrees on, revolved (a hull of few, noisy masks from one side
  // would be far less round).
  const bool revolve = fit.prior == ShapePrior::kRevolve;
  const Eigen::Vector2d axis = revolve ? RevolveAxis(views, object.size, fit_points) : Eigen::Vector2d::Zero();
  const TriangleMesh revolved = revolve ? RevolveFromViews(views, fit_points, axis, object.size) : TriangleMesh{};
  const MultiViewSet synthetic = SymmetryViews(views, fit.prior, 8, axis);
  fit.synthetic_views = static_cast<int>(synthetic.size());
  views.insert(views.end(), synthetic.begin(), synthetic.end());

  options.refine.lambda_normal = 0;  // no normal maps: masks and returns
  options.canonical.up = "+z", options.canonical.front = "+x";
  options.canonical.scale = 1.0;
  options.canonical.front_direction.reset();
  options.canonical.target_size.reset();
  options.canonical.target_height.reset();
  GeneratedMesh g;
  if (revolve) {
    // The profile is already fitted to every silhouette and return (a one-dimensional fit); free-form
    // refinement would only follow the segmenter's errors out of round.
    options.refine.steps = 0;
    g = Generate(views, options, &revolved,
                 Msg() << "surface of revolution from " << fit.real_views << " silhouettes and " << fit_points.size()
                       << " LiDAR returns, axis offset (" << axis.x() << ", " << axis.y() << ") m",
                 fit_points);
  } else {
    g = GenerateFromHull(object, views, fit, options, fit_points);
  }
  FillHarvestQuality(object, g, held_points.empty() ? fit_points : held_points, !held_points.empty(), &fit);
  if (fit_out) *fit_out = std::move(fit);
  return g;
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
