#include "assetgen/refine.h"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <exception>
#include <limits>
#include <memory>
#include <optional>

#include "core/error.h"
#include "core/log.h"
#include "core/parallel.h"
#include "geometry/closest_point.h"
#include "geometry/laplacian.h"
#include "geometry/normals.h"
#include "geometry/topology.h"
#include "geometry/visual_hull.h"
#include "raster/loss.h"
#include "raster/normals.h"
#include "raster/raster.h"

namespace sd {
namespace {

double Seconds(std::chrono::steady_clock::time_point since) {
  return std::chrono::duration<double>(std::chrono::steady_clock::now() - since).count();
}

template <typename T>
std::span<const float> Floats(const std::vector<T>& v) {
  return {reinterpret_cast<const float*>(v.data()), v.size() * sizeof(T) / sizeof(float)};
}
template <typename T>
std::span<float> MutableFloats(std::vector<T>& v) {
  return {reinterpret_cast<float*>(v.data()), v.size() * sizeof(T) / sizeof(float)};
}

void CheckViews(const MultiViewSet& views) {
  if (views.empty()) throw InputError({}, "refine: no views given");
  const int w = views[0].view.camera.width, h = views[0].view.camera.height;
  for (size_t i = 0; i < views.size(); ++i) {
    const MultiView& v = views[i];
    const PinholeCamera& c = v.view.camera;
    if (c.width != w || c.height != h)
      throw InputError({}, Msg() << "refine: view " << v.view.name << " is " << c.width << "x" << c.height << " but view "
                             << views[0].view.name << " is " << w << "x" << h << " (all views must have one size)");
    if (v.normals.width() != c.width || v.normals.height() != c.height || v.normals.channels() != 3)
      throw InputError({}, Msg() << "refine: view " << v.view.name << ": normal map is " << v.normals.width() << "x"
                             << v.normals.height() << "x" << v.normals.channels() << ", camera is " << c.width << "x"
                             << c.height << " (3 channels expected)");
    if (v.mask.width() != c.width || v.mask.height() != c.height || v.mask.channels() != 1)
      throw InputError({}, Msg() << "refine: view " << v.view.name << ": mask is " << v.mask.width() << "x" << v.mask.height()
                             << "x" << v.mask.channels() << ", camera is " << c.width << "x" << c.height
                             << " (1 channel expected)");
    if (!v.known.empty() && (v.known.width() != c.width || v.known.height() != c.height || v.known.channels() != 1))
      throw InputError({}, Msg() << "refine: view " << v.view.name << ": known-pixel mask is " << v.known.width() << "x"
                             << v.known.height() << "x" << v.known.channels() << ", camera is " << c.width << "x"
                             << c.height << " (1 channel expected)");
    if (!(c.fx > 0 && c.fy > 0)) throw InputError({}, Msg() << "refine: view " << v.view.name << ": focal length must be positive");
  }
}

void CheckOptions(const RefineOptions& o) {
  if (o.steps < 1 || o.iterations_per_step < 1)
    throw InputError({}, Msg() << "refine: steps (" << o.steps << ") and iterations per step (" << o.iterations_per_step
                           << ") must be at least 1");
  if (o.lambda_normal < 0 || o.lambda_mask < 0 || o.lambda_lap < 0 || o.lambda_points < 0)
    throw InputError({}, "refine: loss weights must not be negative");
  if (o.lambda_normal == 0 && o.lambda_mask == 0)
    throw InputError({}, "refine: with both the normal and the mask weight at 0 nothing supervises the shape");
  if (!(o.max_point_distance > 0)) throw InputError({}, "refine: the points' outlier distance must be positive");
  if (!(o.remesh.edge_length_min > 0) || o.remesh.edge_length_max < o.remesh.edge_length_min)
    throw InputError({}, Msg() << "refine: edge length limits must satisfy 0 < min <= max (got " << o.remesh.edge_length_min
                           << ", " << o.remesh.edge_length_max << ")");
}

struct Losses {
  double normal = 0, mask = 0, lap = 0, points = 0;
};

using raster::Buffer;
using raster::Memory;
using raster::Span;

// Per-view targets and buffers, on the side where the views' loss runs (the host, or the GPU when the device is
// CUDA), reused across iterations.
struct ViewState {
  explicit ViewState(Memory where)
      : normals_target(where), normals_mask(where), mask_target(where), clip(where), grad_clip(where),
        normal_img(where), grad_normal_img(where), grad_bary(where), coverage(where), aa(where), grad_aa(where),
        rast(where) {}
  Eigen::Matrix4f clip_from_world;
  size_t valid_normal_pixels = 0;
  float mask_area = 1;  // target mask area in pixels: both terms are per object pixel
  float normal_grad_scale = 0, mask_grad_scale = 0;  // 0: the term is off
  // The normal term's target and the mask it counts inside (the view's own, MultiView::mask).
  Buffer<float> normals_target, normals_mask;
  // The silhouette target: the mask, and -1 at pixels past the source image's border (MultiView::known), which
  // the silhouette term skips (what the camera did not see says nothing about the outline).
  Buffer<float> mask_target;
  Buffer<float> clip, grad_clip, normal_img, grad_normal_img, grad_bary, coverage, aa, grad_aa;
  raster::RasterBuffer rast;
  raster::AntialiasRecord aa_record;
  // On the host: this view's share of the gradients, summed in view order by the caller.
  std::vector<float> grad_positions, grad_normals;
};

// The mesh as the views' loss reads it: on the host, views of the remesher's arrays; on the device, copies.
struct LossMesh {
  Span<const float> positions, vertex_normals;  // 3 per vertex
  Span<const int32_t> tris;
  const raster::EdgeTopology& topology;
};

// What depends only on the connectivity: rebuilt after each remeshing pass, not per iteration.
struct TopologyCache {
  raster::EdgeTopology edges;
  Eigen::SparseMatrix<float> laplacian;
  // On the device: the connectivity, uploaded once per pass.
  Buffer<int32_t> device_tris{Memory::kDevice};
  raster::EdgeTopology device_edges{Buffer<int32_t>(Memory::kDevice)};
  raster::VertexFaces device_vertex_faces{Buffer<int32_t>(Memory::kDevice), Buffer<int32_t>(Memory::kDevice)};
};

// The views' loss on the GPU: the mesh's per-evaluation inputs and the summed outputs, device-resident. Only
// the positions go up and their gradient comes down: the vertex normals and their backward run there too.
struct DeviceLoss {
  Buffer<float> positions{Memory::kDevice}, vertex_normals{Memory::kDevice};
  Buffer<double> normal_sums{Memory::kDevice};
  Buffer<float> grad_positions{Memory::kDevice}, grad_normals{Memory::kDevice};
  Buffer<double> loss_sums{Memory::kDevice};  // 2 per view: normal, mask (unscaled sums)
};

// One view's share of the loss: the raster ops and the loss ops composed, on whichever side the buffers are.
// Accumulates its gradients with respect to the positions (through the clip transform) and to the vertex
// normals into grad_positions / grad_normals, and its unscaled term sums into loss_sums[0] (normal) and
// loss_sums[1] (mask). Writes only `s` and its own outputs, so host views run in parallel.
void ViewLossAndGradient(const LossMesh& mesh, int width, int height, ViewState& s, Span<float> grad_positions,
                         Span<float> grad_normals, Span<double> loss_sums) {
  const size_t nv = mesh.positions.size() / 3;
  const size_t np = static_cast<size_t>(width) * height;
  const Memory where = loss_sums.where();
  const Span<double> normal_sum(loss_sums.data(), 1, where), mask_sum(loss_sums.data() + 1, 1, where);
  s.clip.resize(4 * nv);
  raster::TransformToClip(mesh.positions, s.clip_from_world, s.clip);
  const raster::RasterizeInputs raster_in{s.clip, mesh.tris, width, height};
  raster::Rasterize(raster_in, &s.rast);
  s.grad_clip.assign(4 * nv, 0.0f);

  // Normal term: re-normalised interpolated normals against the target where both cover the pixel.
  if (s.normal_grad_scale > 0) {
    s.normal_img.resize(3 * np);
    const raster::InterpolateInputs normals_in{mesh.vertex_normals, 3, mesh.tris, s.rast};
    raster::Interpolate(normals_in, s.normal_img);
    s.grad_normal_img.resize(3 * np);
    raster::UnitVectorLoss({s.normal_img, s.rast, s.normals_target, s.normals_mask}, s.normal_grad_scale,
                           s.grad_normal_img, normal_sum);
    s.grad_bary.assign(2 * np, 0.0f);
    raster::InterpolateBackward(normals_in, s.grad_normal_img, grad_normals, s.grad_bary);
    raster::RasterizeBackward(raster_in, s.rast, s.grad_bary, {}, s.grad_clip);
  }

  // Silhouette term: antialiased coverage against the target mask.
  if (s.mask_grad_scale > 0) {
    s.coverage.resize(np);
    raster::Coverage(s.rast, s.coverage);
    s.aa.resize(np);
    const raster::AntialiasInputs coverage_in{s.coverage, 1, s.rast, s.clip, mesh.tris, mesh.topology};
    raster::Antialias(coverage_in, s.aa, &s.aa_record, /*color_gradient=*/false);
    s.grad_aa.resize(np);
    raster::SquaredErrorLoss(s.aa, s.mask_target, s.mask_grad_scale, s.grad_aa, mask_sum);
    raster::AntialiasBackward(coverage_in, s.aa_record, s.grad_aa, {}, s.grad_clip);
  }
  raster::TransformToClipBackward(s.clip_from_world, s.grad_clip, grad_positions);
}

// One evaluation of the loss and its gradient with respect to the vertex positions. On the host the views are
// evaluated in parallel and their shares summed in view order, so the result does not depend on the threads.
// On the GPU (`device` set) they are queued one after another on this thread's stream, summing into one
// gradient in view order, between the vertex normals and their backward, and the evaluation waits once, for
// the download of the position gradient and the terms.
Losses LossAndGradient(const std::vector<Eigen::Vector3f>& positions, const std::vector<Eigen::Vector3i>& faces,
                       const TopologyCache& cache, const MultiViewSet& views, std::vector<ViewState>& state,
                       const RefineOptions& o, float lap_scale, DeviceLoss* device,
                       const std::vector<Eigen::Vector3f>& points, float radius, std::vector<Eigen::Vector3f>* grad,
                       double* views_seconds) {
  const size_t nv = positions.size();
  const std::span<const int32_t> tris(reinterpret_cast<const int32_t*>(faces.data()), 3 * faces.size());
  // On the host the vertex normals and their backward run on either side of the views; on the device they
  // are part of the views' chain there (and of its time).
  std::vector<Eigen::Vector3f> vertex_normals, grad_vn;
  if (device == nullptr) vertex_normals = geometry::VertexNormals(positions, faces);
  const auto views_start = std::chrono::steady_clock::now();
  grad->resize(nv);
  std::vector<double> sums(2 * views.size(), 0.0);
  if (device != nullptr) {
    device->positions.CopyFrom(Floats(positions));
    device->vertex_normals.resize(3 * nv);
    device->normal_sums.resize(3 * nv);
    raster::VertexNormals(device->positions, cache.device_tris, cache.device_vertex_faces, device->vertex_normals,
                          device->normal_sums);
    device->grad_positions.assign(3 * nv, 0.0f);
    device->grad_normals.assign(3 * nv, 0.0f);
    device->loss_sums.assign(2 * views.size(), 0.0);
    const LossMesh mesh{device->positions, device->vertex_normals, cache.device_tris, cache.device_edges};
    for (size_t vi = 0; vi < views.size(); ++vi) {
      const PinholeCamera& c = views[vi].view.camera;
      ViewLossAndGradient(mesh, c.width, c.height, state[vi], device->grad_positions, device->grad_normals,
                          Span<double>(device->loss_sums.data() + 2 * vi, 2, Memory::kDevice));
    }
    raster::VertexNormalsBackward(device->positions, cache.device_tris, cache.device_vertex_faces,
                                  device->normal_sums, device->grad_normals, device->grad_positions);
    device->grad_positions.CopyTo(MutableFloats(*grad));
    sums = device->loss_sums.ToHost();
  } else {
    const LossMesh mesh{Floats(positions), Floats(vertex_normals), tris, cache.edges};
    ParallelForRethrow(0, views.size(), [&](size_t vi) {
      ViewState& s = state[vi];
      s.grad_positions.assign(3 * nv, 0.0f);
      s.grad_normals.assign(3 * nv, 0.0f);
      const PinholeCamera& c = views[vi].view.camera;
      ViewLossAndGradient(mesh, c.width, c.height, s, s.grad_positions, s.grad_normals,
                          std::span<double>(&sums[2 * vi], 2));
    });
    grad->assign(nv, Eigen::Vector3f::Zero());
    grad_vn.assign(nv, Eigen::Vector3f::Zero());
    for (const ViewState& s : state)
      for (size_t v = 0; v < nv; ++v) {
        (*grad)[v] += Eigen::Vector3f(&s.grad_positions[3 * v]);
        grad_vn[v] += Eigen::Vector3f(&s.grad_normals[3 * v]);
      }
  }
  *views_seconds += Seconds(views_start);
  if (device == nullptr) geometry::VertexNormalsBackward(positions, faces, grad_vn, grad);
  Losses losses;
  const float view_weight = 1.0f / static_cast<float>(views.size());
  for (size_t vi = 0; vi < views.size(); ++vi) {
    if (state[vi].normal_grad_scale > 0)
      losses.normal += sums[2 * vi] / static_cast<double>(state[vi].valid_normal_pixels) * view_weight;
    if (state[vi].mask_grad_scale > 0) losses.mask += sums[2 * vi + 1] / state[vi].mask_area * view_weight;
  }
  if (o.lambda_lap > 0) {
    losses.lap = geometry::LaplacianLoss(cache.laplacian, positions, o.lambda_lap * lap_scale, grad) / (o.lambda_lap * lap_scale);
  }
  if (!points.empty() && o.lambda_points > 0) {
    const float per_radius2 = 1.0f / (radius * radius);
    losses.points = geometry::PointToSurfaceLoss(positions, faces, points, o.lambda_points * per_radius2,
                                                 o.max_point_distance * radius, grad) / o.lambda_points;
  }
  return losses;
}

}  // namespace

geometry::RemeshOptions DefaultRemeshOptions() {
  geometry::RemeshOptions o;
  o.edge_length_min = 0.03f;
  o.edge_length_max = 0.15f;
  return o;
}

TriangleMesh CoarseMeshFromViews(const MultiViewSet& views, int resolution) {
  CheckViews(views);
  // The point nearest all optical axes (least squares), where the rig looks.
  Eigen::Matrix3d A = Eigen::Matrix3d::Zero();
  Eigen::Vector3d b = Eigen::Vector3d::Zero();
  for (const MultiView& v : views) {
    const Eigen::Vector3d o = v.view.T_world_cam.translation;
    const Eigen::Vector3d d = v.view.T_world_cam.Rotation().col(2);
    const Eigen::Matrix3d P = Eigen::Matrix3d::Identity() - d * d.transpose();
    A += P;
    b += P * o;
  }
  const Eigen::Vector3d centre = views.size() >= 2 ? Eigen::Vector3d(A.ldlt().solve(b))
                                                   : Eigen::Vector3d(views[0].view.T_world_cam * Eigen::Vector3d(0, 0, 4));
  // The object is inside every view's frustum, so inside the smallest frustum cross-section at the centre.
  double half = std::numeric_limits<double>::max();
  for (const MultiView& v : views) {
    const PinholeCamera& c = v.view.camera;
    const double depth = (v.view.T_world_cam.Inverse() * centre).z();
    if (depth <= 0) throw InputError({}, Msg() << "coarse mesh: view " << v.view.name << " looks away from the object");
    half = std::min(half, depth * std::min(std::min(c.cx, c.width - c.cx) / c.fx, std::min(c.cy, c.height - c.cy) / c.fy));
  }
  std::vector<geometry::SilhouetteView> sil;
  for (const MultiView& v : views) sil.push_back({v.view.camera, v.view.T_world_cam.Inverse(), v.mask});
  geometry::VisualHullOptions opt;
  opt.resolution = resolution;
  opt.bounds.Extend((centre - Eigen::Vector3d::Constant(half)).cast<float>());
  opt.bounds.Extend((centre + Eigen::Vector3d::Constant(half)).cast<float>());
  TriangleMesh hull = geometry::VisualHull(sil, opt);
  if (hull.NumFaces() == 0) throw InputError({}, "coarse mesh: the masks carve away everything (no common silhouette)");
  return hull;
}

TriangleMesh PrepareForRefinement(const TriangleMesh& mesh, const std::string& what) {
  if (mesh.NumFaces() == 0) throw InputError(what, Msg() << "the mesh has no triangles");
  TriangleMesh out;
  out.positions = mesh.positions;
  out.faces = mesh.faces;
  const float diag = mesh.Bounds().Size().norm();
  geometry::WeldVertices(&out.positions, &out.faces, 1e-6f * std::max(diag, 1e-12f));
  const geometry::TopologyReport topo = geometry::AnalyzeTopology(static_cast<int>(out.positions.size()), out.faces);
  if (!topo.IsManifold())
    throw InputError(what, Msg() << "the mesh is not manifold (" << topo.Describe()
                           << "); refinement needs a manifold surface (e.g. a visual hull or a repaired mesh)");
  return out;
}

RefineResult RefineMesh(const TriangleMesh& coarse_in, const MultiViewSet& views, const RefineOptions& options,
                        const std::vector<Eigen::Vector3f>& points) {
  CheckViews(views);
  CheckOptions(options);
  for (const Eigen::Vector3f& p : points)
    if (!p.allFinite()) throw InputError({}, "refine: a target point is not finite");
  const auto t0 = std::chrono::steady_clock::now();
  const TriangleMesh coarse = PrepareForRefinement(coarse_in, "refine: coarse mesh");

  // Edge lengths and the camera depth range scale with the object.
  const BoundingSphere sphere = BoundingSphereOf(coarse.positions);
  const Eigen::Vector3f centre = sphere.centre;
  const float radius = sphere.radius;
  geometry::RemeshOptions remesh = options.remesh;
  remesh.edge_length_min *= radius;
  remesh.edge_length_max *= radius;

  // The views' loss runs where the process's device says: its targets and buffers live there.
  const Memory where = raster::UseCuda() ? Memory::kDevice : Memory::kHost;
  std::unique_ptr<DeviceLoss> device;
  if (where == Memory::kDevice) device = std::make_unique<DeviceLoss>();
  const float view_weight = 1.0f / static_cast<float>(views.size());
  std::vector<ViewState> state;
  state.reserve(views.size());
  for (size_t i = 0; i < views.size(); ++i) {
    ViewState& s = state.emplace_back(where);
    const ViewCamera& v = views[i].view;
    // About the object's depth along the optical axis, not its distance: a crop of a wide camera keeps the
    // full camera's principal point, so the object can lie far off the axis.
    const float dist = static_cast<float>((v.T_world_cam.translation.cast<float>() - centre).norm());
    const float depth = static_cast<float>((v.T_world_cam.Inverse() * centre.cast<double>()).z());
    const float near = std::max(1e-3f * dist, depth - 3.0f * radius), far = std::max(near * 1.001f, depth + 3.0f * radius);
    s.clip_from_world = raster::ClipFromWorld(v.camera, v.T_world_cam.Inverse(), near, far);
    const MultiView& mv = views[i];
    std::vector<float> mask_target(mv.mask.vector().begin(), mv.mask.vector().end());
    if (!mv.known.empty())
      for (size_t p = 0; p < mask_target.size(); ++p)
        if (mv.known.vector()[p] <= 0.5f) mask_target[p] = -1.0f;
    double area = 0;
    for (float m : mask_target) area += std::max(m, 0.0f);
    s.mask_area = static_cast<float>(std::max(area, 1.0));
    for (int y = 0; y < mv.mask.height(); ++y)
      for (int x = 0; x < mv.mask.width(); ++x)
        if (mv.mask.at(x, y) > 0.5f && Eigen::Vector3f(mv.normals.pixel(x, y)).squaredNorm() >= 0.5f)
          ++s.valid_normal_pixels;
    if (options.lambda_normal > 0 && s.valid_normal_pixels > 0)
      s.normal_grad_scale = options.lambda_normal * view_weight / static_cast<float>(s.valid_normal_pixels);
    if (options.lambda_mask > 0) s.mask_grad_scale = options.lambda_mask * view_weight / s.mask_area;
    s.mask_target.CopyFrom(mask_target);
    s.normals_target.CopyFrom(mv.normals.vector());
    s.normals_mask.CopyFrom(mv.mask.vector());
  }

  geometry::ContinuousRemesher remesher(coarse.positions, coarse.faces, remesh);
  RefineResult result;
  std::optional<Progress> progress;
  if (options.show_progress) progress.emplace("refine", static_cast<size_t>(options.steps));
  std::vector<Eigen::Vector3f> grad;
  for (int step = 0; step < options.steps; ++step) {
    const auto ts = std::chrono::steady_clock::now();
    remesher.Remesh();
    const auto& faces = remesher.faces();
    TopologyCache cache;
    cache.edges = raster::BuildEdgeTopology({reinterpret_cast<const int32_t*>(faces.data()), 3 * faces.size()},
                                            static_cast<int>(remesher.positions().size()));
    if (options.lambda_lap > 0) cache.laplacian = geometry::UniformLaplacian(static_cast<int>(remesher.positions().size()), faces);
    if (device) {
      cache.device_tris.CopyFrom(std::span<const int32_t>(reinterpret_cast<const int32_t*>(faces.data()), 3 * faces.size()));
      cache.device_edges.neighbour.CopyFrom(std::span<const int32_t>(cache.edges.neighbour.host()));
      const raster::VertexFaces incidence = raster::BuildVertexFaces(
          {reinterpret_cast<const int32_t*>(faces.data()), 3 * faces.size()}, static_cast<int>(remesher.positions().size()));
      cache.device_vertex_faces.offset.CopyFrom(std::span<const int32_t>(incidence.offset.host()));
      cache.device_vertex_faces.corner.CopyFrom(std::span<const int32_t>(incidence.corner.host()));
    }
    RefineStepLog log;
    log.remesh_seconds = Seconds(ts);
    const auto iterations_start = std::chrono::steady_clock::now();
    Losses last;
    for (int it = 0; it < options.iterations_per_step; ++it) {
      // The smoothness weight is per squared edge length so that it means the same at every resolution.
      const float edge = std::max(remesher.MeanTargetEdgeLength(), 1e-6f);
      last = LossAndGradient(remesher.positions(), remesher.faces(), cache, views, state, options, 1.0f / (edge * edge),
                             device.get(), points, radius, &grad, &log.views_seconds);
      remesher.Step(grad);
    }
    log.update_seconds = Seconds(iterations_start) - log.views_seconds;
    log.step = step;
    log.loss_normal = last.normal;
    log.loss_mask = last.mask;
    log.loss_lap = last.lap;
    log.loss_points = last.points;
    log.vertices = remesher.positions().size();
    log.faces = remesher.faces().size();
    log.mean_target_edge = remesher.MeanTargetEdgeLength();
    log.seconds = Seconds(ts);
    SD_LOG(Debug, "refine step " << step << ": normal " << log.loss_normal << " mask " << log.loss_mask << " lap "
                                 << log.loss_lap << ", " << log.faces << " faces, edge " << log.mean_target_edge);
    result.log.push_back(log);
    if (progress) progress->Advance();
  }
  result.mesh.positions = remesher.positions();
  result.mesh.faces = remesher.faces();
  result.mesh.ComputeVertexNormals();
  result.seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count();
  return result;
}

}  // namespace sd
