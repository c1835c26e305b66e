#include "geometry/visual_hull.h"

#include <algorithm>
#include <cmath>
#include <numeric>

#include "core/error.h"
#include "core/parallel.h"
#include "geometry/marching_cubes.h"

// Field: at every grid node, the minimum over the views that see it of the mask's coverage of the node's
// footprint (a box one voxel wide, projected; at least one pixel). Coverage rather than a point sample:
// binary masks would make the field a step between two nodes, and marching cubes would put the surface at
// the middle of the voxel whatever the silhouette says; a box average ramps linearly across the silhouette
// edge, so the iso-crossing lands within ~0.1 voxel of it. The surface is the iso-level mask_threshold.
//
// Rules beyond the header's:
//  - A node no view sees (behind every camera or outside every image) is outside: there is no evidence for it.
//  - Nodes on the grid border are outside, so the mesh is closed (the hull is clipped to the bounds).
//  - With require_all_views (the default), a node outside any view's image is outside too: the silhouettes
//    show the whole object, so it lies in every view's frustum. Where the bounds stick out of the frusta (the
//    rig frames the unit sphere; the default bounds' corners lie outside it) such nodes would otherwise
//    survive as islands only a few views could carve.
//  - Components enclosing less than min_component_fraction of the largest one's volume are dropped (voxel
//    noise); an object whose thin parts break at this resolution keeps all its pieces.

namespace sd::geometry {
namespace {

// Per view: the mask's summed-area table, so any axis-aligned box average costs four bilinear look-ups.
struct ViewData {
  const SilhouetteView* view;
  Eigen::Matrix3d R_cam_world;
  Eigen::Vector3d t_cam_world;
  std::vector<double> sat;  // (width + 1) x (height + 1); sat(x, y) = sum of pixels [0, x) x [0, y)
  int width, height;

  double Sat(int x, int y) const { return sat[static_cast<size_t>(y) * (width + 1) + x]; }
  // The integral of a piecewise-constant image is bilinear inside each pixel, so bilinear interpolation of
  // the table is exact at fractional positions.
  double SatAt(double u, double v) const {
    const int x = std::min(static_cast<int>(u), width - 1), y = std::min(static_cast<int>(v), height - 1);
    const double fu = u - x, fv = v - y;
    return (1 - fv) * ((1 - fu) * Sat(x, y) + fu * Sat(x + 1, y)) + fv * ((1 - fu) * Sat(x, y + 1) + fu * Sat(x + 1, y + 1));
  }
  // Mean of the mask over [u - ru, u + ru] x [v - rv, v + rv] clipped to the image.
  double BoxMean(double u, double v, double ru, double rv) const {
    const double u0 = std::max(0.0, u - ru), u1 = std::min<double>(width, u + ru);
    const double v0 = std::max(0.0, v - rv), v1 = std::min<double>(height, v + rv);
    const double area = (u1 - u0) * (v1 - v0);
    if (!(area > 0)) return 0;
    return (SatAt(u1, v1) - SatAt(u0, v1) - SatAt(u1, v0) + SatAt(u0, v0)) / area;
  }
};

ViewData Prepare(const SilhouetteView& view) {
  ViewData d;
  d.view = &view;
  d.R_cam_world = view.T_cam_world.Rotation();
  d.t_cam_world = view.T_cam_world.translation;
  d.width = view.mask.width();
  d.height = view.mask.height();
  d.sat.assign(static_cast<size_t>(d.width + 1) * (d.height + 1), 0.0);
  for (int y = 0; y < d.height; ++y) {
    double row = 0;
    for (int x = 0; x < d.width; ++x) {
      row += std::clamp(view.mask.at(x, y), 0.0f, 1.0f);
      d.sat[static_cast<size_t>(y + 1) * (d.width + 1) + x + 1] = d.Sat(x + 1, y) + row;
    }
  }
  return d;
}

void Validate(const std::vector<SilhouetteView>& views, const VisualHullOptions& options) {
  if (views.empty()) throw InputError("", "VisualHull: no views given");
  for (size_t i = 0; i < views.size(); ++i) {
    const SilhouetteView& v = views[i];
    if (v.camera.width <= 0 || v.camera.height <= 0 || !(v.camera.fx > 0) || !(v.camera.fy > 0))
      throw InputError("", Msg() << "VisualHull: view " << i << " has an invalid camera (" << v.camera.width << "x"
                                 << v.camera.height << ", fx " << v.camera.fx << ", fy " << v.camera.fy << ")");
    if (v.mask.channels() != 1)
      throw InputError("", Msg() << "VisualHull: view " << i << " mask has " << v.mask.channels() << " channels, expected 1");
    if (v.mask.width() != v.camera.width || v.mask.height() != v.camera.height)
      throw InputError("", Msg() << "VisualHull: view " << i << " mask is " << v.mask.width() << "x" << v.mask.height()
                                 << " but its camera is " << v.camera.width << "x" << v.camera.height);
  }
  if (options.carved_smoothing_passes < 0 || options.carved_smoothing_passes > 16)
    throw InputError("", Msg() << "VisualHull: carved smoothing passes must be in [0, 16], got " << options.carved_smoothing_passes);
  if (options.resolution < 2 || options.resolution > 2048)
    throw InputError("", Msg() << "VisualHull: resolution must be in [2, 2048], got " << options.resolution);
  if (!(options.mask_threshold > 0 && options.mask_threshold < 1))
    throw InputError("", Msg() << "VisualHull: mask_threshold must be in (0, 1), got " << options.mask_threshold);
  if (options.solid_across_axis < -1 || options.solid_across_axis > 2)
    throw InputError("", Msg() << "VisualHull: solid_across_axis must be -1, 0, 1 or 2, got " << options.solid_across_axis);
  if (!(options.min_column_fill >= 0 && options.min_column_fill <= 1))
    throw InputError("", Msg() << "VisualHull: min_column_fill must be in [0, 1], got " << options.min_column_fill);
  if (!options.bounds.IsEmpty() && !(options.bounds.Size().minCoeff() > 0))
    throw InputError("", "VisualHull: bounds have zero extent along some axis");
}

// Keeps the connected components (faces linked through shared vertices) enclosing at least `fraction` of
// the largest one's volume.
TriangleMesh SignificantComponents(const TriangleMesh& mesh, float fraction) {
  const size_t nv = mesh.NumVertices();
  std::vector<int> parent(nv);
  std::iota(parent.begin(), parent.end(), 0);
  auto find = [&](int v) {
    while (parent[v] != v) v = parent[v] = parent[parent[v]];
    return v;
  };
  for (const auto& f : mesh.faces) {
    const int a = find(f[0]), b = find(f[1]), c = find(f[2]);
    parent[b] = a;
    parent[find(c)] = a;
  }
  // Signed volume per component: tetrahedra to a reference point (any point works for closed components;
  // one near the mesh keeps the terms small).
  std::vector<double> volume(nv, 0.0);
  Eigen::Vector3d ref = Eigen::Vector3d::Zero();
  if (!mesh.positions.empty()) ref = mesh.positions[0].cast<double>();
  for (const auto& f : mesh.faces) {
    const Eigen::Vector3d a = mesh.positions[f[0]].cast<double>() - ref, b = mesh.positions[f[1]].cast<double>() - ref,
                          c = mesh.positions[f[2]].cast<double>() - ref;
    volume[find(f[0])] += a.dot(b.cross(c)) / 6;
  }
  double largest = 0;
  for (size_t v = 0; v < nv; ++v)
    if (find(int(v)) == int(v)) largest = std::max(largest, volume[v]);
  TriangleMesh out;
  if (!(largest > 0)) return out;
  std::vector<int> remap(nv, -1);
  for (const auto& f : mesh.faces) {
    if (volume[find(f[0])] < fraction * largest) continue;
    Eigen::Vector3i g;
    for (int k = 0; k < 3; ++k) {
      if (remap[f[k]] < 0) {
        remap[f[k]] = static_cast<int>(out.positions.size());
        out.positions.push_back(mesh.positions[f[k]]);
      }
      g[k] = remap[f[k]];
    }
    out.faces.push_back(g);
  }
  return out;
}

// Nodes within half a voxel of a free segment are set outside. The segment is walked in steps of half a voxel;
// at each step the eight nodes around the sample are tested against the segment itself.
void CarveFreeSpace(const std::vector<std::pair<Eigen::Vector3f, Eigen::Vector3f>>& segments, ScalarGrid* grid) {
  const float h = grid->voxel_size, reach2 = 0.25f * h * h;
  // The grid's nodes grown by a voxel: a beam from a sensor metres away walks only the grid's few voxels.
  AlignedBox3f reach;
  reach.min = grid->origin - Eigen::Vector3f::Constant(h);
  reach.max = grid->NodePosition(grid->dims.x() - 1, grid->dims.y() - 1, grid->dims.z() - 1) + Eigen::Vector3f::Constant(h);
  for (const auto& [from, to] : segments) {
    float t0 = 0, t1 = 0;
    if (!reach.ClipSegment(from, to, &t0, &t1)) continue;
    const Eigen::Vector3f d = to - from;
    const Eigen::Vector3f a = from + t0 * d, b = from + t1 * d;
    const Eigen::Vector3f ab = b - a;
    const float len2 = ab.squaredNorm();
    const int steps = std::max(1, static_cast<int>(std::ceil(std::sqrt(len2) / (0.5f * h))));
    for (int s = 0; s <= steps; ++s) {
      const Eigen::Vector3f q = a + ab * (float(s) / steps);
      const Eigen::Vector3f g = (q - grid->origin) / h;
      const int i0 = static_cast<int>(std::floor(g.x())), j0 = static_cast<int>(std::floor(g.y())),
                k0 = static_cast<int>(std::floor(g.z()));
      for (int dk = 0; dk < 2; ++dk)
        for (int dj = 0; dj < 2; ++dj)
          for (int di = 0; di < 2; ++di) {
            const int i = i0 + di, j = j0 + dj, k = k0 + dk;
            if (i < 0 || j < 0 || k < 0 || i >= grid->dims.x() || j >= grid->dims.y() || k >= grid->dims.z()) continue;
            const Eigen::Vector3f node = grid->NodePosition(i, j, k);
            const float t = len2 > 0 ? std::clamp((node - a).dot(ab) / len2, 0.0f, 1.0f) : 0.0f;
            if ((a + t * ab - node).squaredNorm() <= reach2) grid->at(i, j, k) = 0.0f;
          }
    }
  }
}

// `passes` of a separable [1 2 1] / 4 filter over the interior nodes (the border layer stays outside, so the mesh
// stays closed), each axis in turn, slab-parallel.
void SmoothField(int passes, ScalarGrid* grid) {
  const Eigen::Vector3i dims = grid->dims;
  for (int pass = 0; pass < passes; ++pass)
    for (int axis = 0; axis < 3; ++axis) {
      const size_t stride = axis == 0 ? 1 : axis == 1 ? size_t(dims.x()) : size_t(dims.x()) * dims.y();
      std::vector<float> next = grid->values;
      ParallelFor(1, size_t(std::max(1, dims.z() - 1)), [&](size_t k) {
        for (int j = 1; j + 1 < dims.y(); ++j)
          for (int i = 1; i + 1 < dims.x(); ++i) {
            const size_t n = grid->Index(i, j, int(k));
            next[n] = 0.25f * grid->values[n - stride] + 0.5f * grid->values[n] + 0.25f * grid->values[n + stride];
          }
      });
      grid->values = std::move(next);
    }
}

// Empties every line of nodes along `axis` that is less than `min_fill` inside (solid_across_axis).
void EmptyThinColumns(int axis, float min_fill, float threshold, ScalarGrid* grid) {
  const int a = (axis + 1) % 3, b = (axis + 2) % 3;
  const int inner = grid->dims[axis] - 2;  // the border layers are outside by construction
  for (int q = 1; q + 1 < grid->dims[b]; ++q)
    for (int p = 1; p + 1 < grid->dims[a]; ++p) {
      Eigen::Vector3i n;
      n[a] = p, n[b] = q;
      int inside = 0;
      for (n[axis] = 1; n[axis] <= inner; ++n[axis]) inside += grid->at(n.x(), n.y(), n.z()) >= threshold;
      if (inside >= min_fill * inner) continue;
      for (n[axis] = 1; n[axis] <= inner; ++n[axis]) grid->at(n.x(), n.y(), n.z()) = 0.0f;
    }
}

}  // namespace

TriangleMesh VisualHull(const std::vector<SilhouetteView>& views, const VisualHullOptions& options) {
  Validate(views, options);
  AlignedBox3f bounds = options.bounds;
  if (bounds.IsEmpty()) bounds.min = Eigen::Vector3f::Constant(-1), bounds.max = Eigen::Vector3f::Constant(1);

  // Cubic voxels, `resolution` along the longest side; the node grid is centred on the bounds and has one
  // extra layer of nodes all round, outside the bounds: those are the forced-outside border, so an object
  // filling the bounds is clipped at most half a voxel beyond them rather than half a voxel inside.
  ScalarGrid grid;
  const Eigen::Vector3f size = bounds.Size();
  grid.voxel_size = size.maxCoeff() / static_cast<float>(options.resolution);
  for (int a = 0; a < 3; ++a) grid.dims[a] = std::max(1, static_cast<int>(std::ceil(size[a] / grid.voxel_size - 1e-3f))) + 3;
  grid.origin = bounds.Center() - 0.5f * grid.voxel_size * (grid.dims - Eigen::Vector3i::Ones()).cast<float>();
  grid.values.assign(static_cast<size_t>(grid.dims.x()) * grid.dims.y() * grid.dims.z(), 0.0f);

  std::vector<ViewData> data(views.size());
  ParallelFor(0, views.size(), [&](size_t i) { data[i] = Prepare(views[i]); });

  const double half_voxel = 0.5 * grid.voxel_size;
  const int tolerated = std::max(0, options.tolerated_outside_views);
  ParallelFor(1, size_t(grid.dims.z() - 1), [&](size_t k) {
    // The (tolerated + 1) smallest coverages seen at a node; its value is the largest of them.
    std::vector<double> lowest;
    for (int j = 1; j + 1 < grid.dims.y(); ++j) {
      for (int i = 1; i + 1 < grid.dims.x(); ++i) {
        const Eigen::Vector3d p_world = grid.NodePosition(i, j, int(k)).cast<double>();
        lowest.assign(tolerated + 1, 1.0);
        auto vote = [&](double v) {
          // Insert into the sorted list of the smallest values, dropping the largest.
          if (v >= lowest.back()) return;
          lowest.back() = v;
          for (size_t q = lowest.size() - 1; q > 0 && lowest[q] < lowest[q - 1]; --q) std::swap(lowest[q], lowest[q - 1]);
        };
        bool seen = false;
        for (const ViewData& d : data) {
          const Eigen::Vector3d p_cam = d.R_cam_world * p_world + d.t_cam_world;
          const auto uv = d.view->camera.Project(p_cam);
          if (!uv || !d.view->camera.InImage(*uv)) {
            if (options.require_all_views) vote(0);
            if (lowest.back() <= 0) break;
            continue;
          }
          seen = true;
          // Footprint half-width: half a voxel at the node's depth, at least half a pixel (bilinear-like).
          const double ru = std::max(0.5, half_voxel * d.view->camera.fx / p_cam.z());
          const double rv = std::max(0.5, half_voxel * d.view->camera.fy / p_cam.z());
          vote(d.BoxMean(uv->x(), uv->y(), ru, rv));
          if (lowest.back() <= 0) break;
        }
        grid.at(i, j, int(k)) = seen ? static_cast<float>(lowest.back()) : 0.0f;
      }
    }
  });
  if (options.solid_across_axis >= 0)
    EmptyThinColumns(options.solid_across_axis, options.min_column_fill, options.mask_threshold, &grid);
  CarveFreeSpace(options.free_segments, &grid);
  if (!options.free_segments.empty()) SmoothField(options.carved_smoothing_passes, &grid);

  return SignificantComponents(MarchingCubes(grid, options.mask_threshold), options.min_component_fraction);
}

}  // namespace sd::geometry
