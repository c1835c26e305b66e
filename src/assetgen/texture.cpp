// FuseVertexColors: the paper's per-vertex fusion (texture.h), in four passes over the welded surface:
//   1. per view: rasterise the mesh (triangle id + barycentrics) and precompute the camera depth of every vertex;
//   2. per vertex: rank the views by the cosine between the normal and the direction to the camera, take the
//      first one in which the vertex is visible, sample its colour there;
//   3. Laplacian smoothing of the seam band (vertices next to a vertex that took another view);
//   4. propagation into vertices no view saw, breadth-first from the coloured ones.
//
// Welding. Loaders split vertices at UV and normal seams, so the split copies of one surface point would get
// different normals (each sees only its own side's faces), might pick different views, and would cut the
// smoothing and propagation graph at every seam (a hidden UV island would come out grey instead of taking its
// neighbours' colour). All four passes therefore run on the welded surface (exact duplicates up to 1e-6 of the
// bounding-box diagonal, as refine.cpp welds) and the result is copied back to every split copy: copies of
// one point always get the same colour. A hard crease then gets one colour per point, sampled on the crease,
// which is what a per-vertex colour can hold there anyway.
#include "assetgen/texture.h"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include "core/error.h"
#include "core/parallel.h"
#include "geometry/edge_adjacency.h"
#include "geometry/normals.h"
#include "geometry/topology.h"
#include "models/super_resolution.h"
#include "raster/raster.h"

namespace sd {
namespace {

// Least object weight (mask or, without one, rasterised coverage) in the bilinear footprint for a sample to
// count. The colour is mask-weighted, so background pixels never enter it; the bound only rejects samples
// that rest on a sliver of object. A vertex on a straight silhouette has about 1/2, on a convex corner about
// 1/4: both must pass, or open meshes lose their rims to propagation.
constexpr float kMinCoverage = 0.2f;

// Vertex adjacency of the welded surface in compressed rows, each row sorted (binary search in IsNeighbour).
struct VertexGraph {
  std::vector<int> offset;  // num_vertices + 1
  std::vector<int> neighbour;

  int Degree(int v) const { return offset[v + 1] - offset[v]; }
  std::span<const int> Of(int v) const { return {neighbour.data() + offset[v], static_cast<size_t>(Degree(v))}; }
  bool IsNeighbour(int v, int u) const {
    const auto row = Of(v);
    return std::binary_search(row.begin(), row.end(), u);
  }
};

// Each vertex's neighbours from the mesh's undirected edges. Edges come ordered by (lower, higher) endpoint, so
// a vertex collects its lower neighbours (edges that end at it) before its higher ones (edges that start at it),
// each run ascending: every row is sorted without a sort.
VertexGraph BuildVertexGraph(int num_vertices, const std::vector<Eigen::Vector3i>& faces) {
  const geometry::EdgeAdjacency adjacency =
      geometry::BuildEdgeAdjacency(num_vertices, faces, geometry::DegenerateFaces::kKeepProperEdges);
  VertexGraph g;
  g.offset.assign(num_vertices + 1, 0);
  for (const Eigen::Vector2i& e : adjacency.edges) ++g.offset[e[0] + 1], ++g.offset[e[1] + 1];
  for (int v = 0; v < num_vertices; ++v) g.offset[v + 1] += g.offset[v];
  g.neighbour.resize(g.offset.back());
  std::vector<int> fill(g.offset.begin(), g.offset.end() - 1);
  for (const Eigen::Vector2i& e : adjacency.edges) g.neighbour[fill[e[0]]++] = e[1], g.neighbour[fill[e[1]]++] = e[0];
  return g;
}

std::string ViewLabel(const ColorView& v, size_t index) {
  return Msg() << "view " << index << " ('" << v.view.name << "')";
}

void CheckInput(const TriangleMesh& mesh, const ColorViewSet& views, const VertexFusionOptions& options) {
  if (mesh.NumFaces() == 0) throw InputError({}, "vertex colour fusion: the mesh has no triangles");
  const int n = static_cast<int>(mesh.NumVertices());
  for (size_t f = 0; f < mesh.NumFaces(); ++f) {
    const Eigen::Vector3i& t = mesh.faces[f];
    if ((t.array() < 0).any() || (t.array() >= n).any()) {
      throw InputError({}, Msg() << "vertex colour fusion: face " << f << " indexes a vertex outside [0, " << n << ")");
    }
  }
  for (const Eigen::Vector3f& p : mesh.positions) {
    if (!p.allFinite()) throw InputError({}, "vertex colour fusion: non-finite vertex position");
  }
  if (views.empty()) throw InputError({}, "vertex colour fusion: no colour views given");
  for (size_t i = 0; i < views.size(); ++i) {
    const ColorView& v = views[i];
    const PinholeCamera& cam = v.view.camera;
    if (cam.width <= 0 || cam.height <= 0 || !(cam.fx > 0) || !(cam.fy > 0) || !std::isfinite(cam.fx) ||
        !std::isfinite(cam.fy) || !std::isfinite(cam.cx) || !std::isfinite(cam.cy)) {
      throw InputError({}, Msg() << ViewLabel(v, i) << ": invalid camera " << cam.width << "x" << cam.height
                                 << " fx " << cam.fx << " fy " << cam.fy);
    }
    if (v.color.channels() != 3 || v.color.width() != cam.width || v.color.height() != cam.height) {
      throw InputError({}, Msg() << ViewLabel(v, i) << ": colour image is " << v.color.width() << "x"
                                 << v.color.height() << "x" << v.color.channels() << ", camera is " << cam.width
                                 << "x" << cam.height << " (3 channels expected)");
    }
    if (!v.mask.empty() &&
        (v.mask.channels() != 1 || v.mask.width() != cam.width || v.mask.height() != cam.height)) {
      throw InputError({}, Msg() << ViewLabel(v, i) << ": mask is " << v.mask.width() << "x" << v.mask.height()
                                 << "x" << v.mask.channels() << ", camera is " << cam.width << "x" << cam.height
                                 << " (1 channel expected)");
    }
  }
  if (!(options.depth_tolerance >= 0) || !std::isfinite(options.depth_tolerance) ||
      !(options.min_cosine >= 0 && options.min_cosine <= 1) || options.seam_smoothing_iterations < 0 ||
      !(options.seam_smoothing_weight >= 0 && options.seam_smoothing_weight <= 1)) {
    throw InputError({}, Msg() << "vertex colour fusion: invalid options (depth_tolerance "
                               << options.depth_tolerance << ", min_cosine " << options.min_cosine
                               << ", seam_smoothing_iterations " << options.seam_smoothing_iterations
                               << ", seam_smoothing_weight " << options.seam_smoothing_weight << ")");
  }
}

// What the per-vertex pass needs from one view.
struct PreparedView {
  Rigid3d T_cam_world;
  Eigen::Vector3f eye;         // camera centre, world frame
  float depth_slack = 0;       // absolute, camera-depth units
  raster::RasterBuffer rast;
  std::vector<float> depth;    // camera-frame depth (z) of every welded vertex
  // (r m, g m, b m, m) with m the mask (or the rasterised coverage when no mask is given): one bilinear
  // sample of it gives the mask-weighted colour, so background pixels at the silhouette add nothing.
  ImageF premultiplied;
};

PreparedView PrepareView(const ColorView& in, const std::vector<Eigen::Vector3f>& positions,
                         const std::vector<Eigen::Vector3i>& faces, const Eigen::Vector3f& centre, float radius,
                         float depth_tolerance) {
  PreparedView pv;
  const PinholeCamera& cam = in.view.camera;
  pv.T_cam_world = in.view.T_world_cam.Inverse();
  pv.eye = in.view.T_world_cam.translation.cast<float>();
  const float dist = (pv.eye - centre).norm();
  pv.depth_slack = depth_tolerance * dist;
  // The depth range only has to keep the whole object inside the per-pixel depth clip; visibility compares
  // interpolated camera depths, not z/w, so its precision does not matter.
  const float near = std::max(1e-4f * std::max(dist, radius), dist - 1.5f * radius);
  const float far = std::max(near * 2.0f, dist + 1.5f * radius);
  const Eigen::Matrix4f M = raster::ClipFromWorld(cam, pv.T_cam_world, near, far);
  const size_t nv = positions.size();
  std::vector<float> clip(4 * nv);
  raster::TransformToClip({reinterpret_cast<const float*>(positions.data()), 3 * nv}, M, clip);
  raster::Rasterize({clip, {reinterpret_cast<const int32_t*>(faces.data()), 3 * faces.size()}, cam.width, cam.height},
                    &pv.rast);
  pv.depth.resize(nv);
  const Eigen::Matrix3f R = pv.T_cam_world.Rotation().cast<float>();
  const Eigen::Vector3f t = pv.T_cam_world.translation.cast<float>();
  for (size_t v = 0; v < nv; ++v) pv.depth[v] = R.row(2).dot(positions[v]) + t.z();

  const int w = cam.width, h = cam.height;
  pv.premultiplied = ImageF(w, h, 4);
  for (int y = 0; y < h; ++y) {
    for (int x = 0; x < w; ++x) {
      const float m = in.mask.empty() ? (pv.rast.triangle[static_cast<size_t>(y) * w + x] >= 0 ? 1.0f : 0.0f)
                                      : std::clamp(in.mask.at(x, y), 0.0f, 1.0f);
      const float* c = in.color.pixel(x, y);
      float* out = pv.premultiplied.pixel(x, y);
      for (int k = 0; k < 3; ++k) out[k] = c[k] * m;
      out[3] = m;
    }
  }
  return pv;
}

// Visibility of welded vertex v at image point (u, px_v) and camera depth z: none of the (up to) four pixels
// that the bilinear colour sample reads may show an occluder, i.e. a surface nearer than z by more than the
// slack. Pixels showing the vertex's own neighbourhood (a triangle touching v or one of its neighbours) are
// never occluders: at grazing angles their depth at the pixel centre differs from z by more than the slack
// although they are the vertex's own surface. Requiring all four (not just the pixel the vertex falls in)
// keeps the occluder's colour out of the sample at occlusion boundaries.
bool Visible(int v, double u, double px_v, float z, const PreparedView& pv, const std::vector<Eigen::Vector3i>& faces,
             const VertexGraph& graph) {
  const raster::RasterBuffer& r = pv.rast;
  const int x0 = std::clamp(static_cast<int>(std::floor(u - 0.5)), 0, r.width - 1);
  const int y0 = std::clamp(static_cast<int>(std::floor(px_v - 0.5)), 0, r.height - 1);
  const int x1 = std::min(x0 + 1, r.width - 1), y1 = std::min(y0 + 1, r.height - 1);
  const std::array<std::array<int, 2>, 4> footprint = {{{x0, y0}, {x1, y0}, {x0, y1}, {x1, y1}}};
  for (const auto& [x, y] : footprint) {
    const size_t p = static_cast<size_t>(y) * r.width + x;
    const int32_t tri = r.triangle[p];
    if (tri < 0) continue;
    const Eigen::Vector3i& f = faces[tri];
    bool own = false;
    for (int k = 0; k < 3 && !own; ++k) own = f[k] == v || graph.IsNeighbour(v, f[k]);
    if (own) continue;
    // Perspective-correct barycentrics interpolate camera depth (affine in the world point) exactly.
    const float b0 = r.bary[2 * p], b1 = r.bary[2 * p + 1];
    const float surface = b0 * pv.depth[f[0]] + b1 * pv.depth[f[1]] + (1 - b0 - b1) * pv.depth[f[2]];
    if (surface < z - pv.depth_slack) return false;
  }
  return true;
}

}  // namespace

VertexFusionResult FuseVertexColors(const TriangleMesh& mesh, const ColorViewSet& views,
                                    const VertexFusionOptions& options) {
  CheckInput(mesh, views, options);

  // --- Weld (see the file comment) ----------------------------------------------------------------------
  std::vector<Eigen::Vector3f> positions = mesh.positions;
  std::vector<Eigen::Vector3i> faces = mesh.faces;
  const AlignedBox3f box = mesh.Bounds();
  const float diag = box.Size().norm();
  const std::vector<int> to_welded = geometry::WeldVertices(&positions, &faces, 1e-6f * std::max(diag, 1e-12f));
  if (faces.empty()) throw InputError({}, "vertex colour fusion: every triangle of the mesh is degenerate");
  const int nv = static_cast<int>(positions.size());
  const VertexGraph graph = BuildVertexGraph(nv, faces);
  const std::vector<Eigen::Vector3f> normals = geometry::VertexNormals(positions, faces);

  // --- 1. Per view: raster + vertex depths --------------------------------------------------------------
  const Eigen::Vector3f centre = box.Center();
  float radius = 0;
  for (const auto& p : positions) radius = std::max(radius, (p - centre).norm());
  std::vector<PreparedView> prepared(views.size());
  ParallelFor(0, views.size(), [&](size_t i) {
    prepared[i] = PrepareView(views[i], positions, faces, centre, radius, options.depth_tolerance);
  });

  // --- 2. Per vertex: the most head-on view that sees it ------------------------------------------------
  // The signed cosine, as the paper ranks views: on a consistently wound mesh a camera sees the outside, and
  // a back-facing vertex that slips through the depth test at a silhouette must not take colour. (The back
  // side of an open or inconsistently wound surface therefore gets propagated colour, not sampled colour.)
  std::vector<Eigen::Vector3f> color(nv, Eigen::Vector3f::Zero());
  std::vector<int> source(nv, -1);
  ParallelFor(
      0, static_cast<size_t>(nv),
      [&](size_t vi) {
        const int v = static_cast<int>(vi);
        const Eigen::Vector3f& n = normals[v];
        if (n.squaredNorm() == 0) return;  // only degenerate faces around it: no direction to rank views by
        // Candidates by decreasing cosine (ties to the lower view index): the first visible one wins, so the
        // depth test runs only until a view passes.
        std::vector<std::pair<float, int>> candidates;
        candidates.reserve(views.size());
        for (size_t i = 0; i < views.size(); ++i) {
          const Eigen::Vector3f to_eye = prepared[i].eye - positions[v];
          const float len = to_eye.norm();
          if (!(len > 0)) continue;
          const float c = n.dot(to_eye) / len;
          if (c >= options.min_cosine)
            candidates.emplace_back(-(views[i].synthetic ? kSyntheticViewWeight * c : c), static_cast<int>(i));
        }
        std::sort(candidates.begin(), candidates.end());
        for (const auto& [neg_cos, i] : candidates) {
          const PreparedView& pv = prepared[i];
          const PinholeCamera& cam = views[i].view.camera;
          const float z = pv.depth[v];
          if (!(z > 0)) continue;  // behind the camera
          const Eigen::Vector3d p_cam = pv.T_cam_world * positions[v].cast<double>();
          const double u = cam.fx * p_cam.x() / p_cam.z() + cam.cx;
          const double pv_y = cam.fy * p_cam.y() / p_cam.z() + cam.cy;
          if (!(u >= 0 && pv_y >= 0 && u < cam.width && pv_y < cam.height)) continue;
          if (!Visible(v, u, pv_y, z, pv, faces, graph)) continue;
          std::array<float, 4> s{};
          SampleBilinear(pv.premultiplied, u, pv_y, s.data());
          if (s[3] < kMinCoverage) continue;  // (almost) all background, or outside the mask
          color[v] = Eigen::Vector3f(s[0], s[1], s[2]) / s[3];
          source[v] = i;
          return;
        }
      },
      256);

  // --- 3. Seam smoothing --------------------------------------------------------------------------------
  // The band is fixed before smoothing: vertices with a view that have a neighbour with another view. Jacobi
  // updates (all from the previous iterate) keep the result independent of thread scheduling.
  std::vector<int> band;
  for (int v = 0; v < nv; ++v) {
    if (source[v] < 0) continue;
    for (int u : graph.Of(v)) {
      if (source[u] >= 0 && source[u] != source[v]) {
        band.push_back(v);
        break;
      }
    }
  }
  const float w = options.seam_smoothing_weight;
  for (int it = 0; it < options.seam_smoothing_iterations && !band.empty() && w > 0; ++it) {
    std::vector<Eigen::Vector3f> next(band.size());
    ParallelFor(0, band.size(), [&](size_t b) {
      const int v = band[b];
      Eigen::Vector3f sum = Eigen::Vector3f::Zero();
      int count = 0;
      for (int u : graph.Of(v)) {
        if (source[u] < 0) continue;  // not coloured yet: propagation comes after smoothing
        sum += color[u];
        ++count;
      }
      next[b] = count > 0 ? Eigen::Vector3f((1 - w) * color[v] + w * sum / static_cast<float>(count)) : color[v];
    });
    for (size_t b = 0; b < band.size(); ++b) color[band[b]] = next[b];
  }

  // --- 4. Propagation -------------------------------------------------------------------------------------
  // Breadth-first fronts: each round colours every uncoloured vertex that touches a coloured one with the
  // mean of its coloured neighbours (coloured before this round, so the order within a round is irrelevant).
  std::vector<uint8_t> has_color(nv);
  for (int v = 0; v < nv; ++v) has_color[v] = source[v] >= 0;
  std::vector<int> front;
  for (int v = 0; v < nv; ++v) {
    if (has_color[v]) continue;
    for (int u : graph.Of(v)) {
      if (has_color[u]) {
        front.push_back(v);
        break;
      }
    }
  }
  std::vector<uint8_t> queued(nv, 0);
  while (!front.empty()) {
    std::vector<Eigen::Vector3f> value(front.size());
    for (size_t k = 0; k < front.size(); ++k) {
      Eigen::Vector3f sum = Eigen::Vector3f::Zero();
      int count = 0;
      for (int u : graph.Of(front[k])) {
        if (!has_color[u]) continue;
        sum += color[u];
        ++count;
      }
      value[k] = sum / static_cast<float>(count);
    }
    for (size_t k = 0; k < front.size(); ++k) {
      color[front[k]] = value[k];
      has_color[front[k]] = 1;
    }
    std::vector<int> next;
    for (int v : front) {
      for (int u : graph.Of(v)) {
        if (!has_color[u] && !queued[u]) {
          queued[u] = 1;
          next.push_back(u);
        }
      }
    }
    front = std::move(next);
  }
  // Components without a single visible vertex (and vertices in no triangle): sRGB 50% grey, which reads as
  // mid grey once written to disk.
  const float grey = SrgbToLinear(0.5f);
  for (int v = 0; v < nv; ++v) {
    if (!has_color[v]) color[v] = Eigen::Vector3f::Constant(grey);
  }

  // --- Back to the mesh's own (split) vertices ----------------------------------------------------------
  VertexFusionResult result;
  const size_t n_in = mesh.NumVertices();
  result.colors.resize(n_in);
  result.source_view.resize(n_in);
  for (size_t v = 0; v < n_in; ++v) {
    const int wv = to_welded[v];
    result.colors[v] = color[wv];
    result.source_view[v] = source[wv];
    if (source[wv] < 0) ++result.propagated;
    double& share = source[wv] < 0 ? result.provenance.propagated
                                   : (views[source[wv]].synthetic ? result.provenance.synthetic : result.provenance.real);
    share += 1;
  }
  if (n_in > 0) {
    const double n = static_cast<double>(n_in);
    result.provenance.real /= n, result.provenance.synthetic /= n, result.provenance.propagated /= n;
  }
  return result;
}

ColorViewSet SuperResolveViews(const ColorViewSet& views, const models::Upscaler& upscaler) {
  ColorViewSet out;
  out.reserve(views.size());
  for (const ColorView& v : views) {
    ColorView up;
    up.view = v.view;
    up.synthetic = v.synthetic;
    up.view.camera = Supersampled(v.view.camera, upscaler.scale());
    ImageF srgb = v.color;
    for (float& c : srgb.vector()) c = LinearToSrgb(std::clamp(c, 0.0f, 1.0f));
    up.color = upscaler.Upscale(srgb);
    for (float& c : up.color.vector()) c = SrgbToLinear(c);
    if (!v.mask.empty()) {
      up.mask = models::UpscaleBicubic(v.mask, upscaler.scale());
      for (float& m : up.mask.vector()) m = std::clamp(m, 0.0f, 1.0f);
    }
    out.push_back(std::move(up));
  }
  return out;
}

}  // namespace sd
