#pragma once
// Mesh refinement against multi-view normal maps and silhouettes by differentiable rendering, with
// continuous remeshing (DESIGN.md, generate stage "iterative normal + silhouette mesh refinement").
//
// Loss, averaged over views:
//   L = lambda_normal * L_normal + lambda_mask * L_mask + lambda_points * L_points + lambda_lap * L_lap
//   L_normal: mean over pixels covered by both the render and the target mask (> 0.5) of
//             |n_render - n_target|^2, n_render the interpolated, re-normalised vertex normal (world frame);
//   L_mask:   sum over all pixels of (antialiased coverage - target mask)^2, divided by the target mask's
//             area (so both terms are per object pixel); the analytic edge gradients of raster::Antialias
//             move the outline;
//   L_points: (optional, measured points such as an object's LiDAR returns) mean over the points within
//             max_point_distance of the surface of their squared distance to it (geometry/closest_point.h),
//             divided by the square of the coarse mesh's bounding-sphere radius so its weight does not
//             depend on the object's size;
//   L_lap:    uniform-Laplacian smoothness sum_i |(L x)_i|^2 / n of the positions, divided by the square of
//             the mesh's mean target edge length so its weight does not depend on resolution.
// Schedule (the paper's): `steps` refinement steps, each = remesh (split / collapse / flip / smooth towards
// the per-vertex target edge lengths; the first pass brings a finer coarse mesh, e.g. a fine visual hull,
// to the shortest useful edge), then
// `iterations_per_step` optimiser steps of the continuous remesher's adaptive optimiser.
// Works in the cameras' world frame; edge lengths are relative to the coarse mesh's bounding-sphere radius.
#include <vector>

#include "assetgen/views.h"
#include "core/mesh.h"
#include "geometry/remesh.h"

namespace sd {

// The remesher's settings for refinement, in units of the coarse mesh's bounding-sphere radius. The
// shortest edge is what the rig's images can still resolve (about 4 pixels at 320x320, where the radius
// spans ~150 pixels); shorter edges only cost time.
geometry::RemeshOptions DefaultRemeshOptions();

struct RefineOptions {
  int steps = 20;
  int iterations_per_step = 10;
  float lambda_normal = 1.0f;
  float lambda_mask = 1.0f;
  float lambda_lap = 0.5f;
  // Used only when points are given. LiDAR returns are metric where a segmenter's masks of a few dozen pixels
  // are not: at 20 the surface follows the returns to about a centimetre (PandaSet cones, bench_harvest).
  float lambda_points = 20.0f;
  float max_point_distance = 0.25f;  // in bounding-sphere radii: farther points are outliers, not surface
  // Remesher settings in units of the coarse mesh's bounding-sphere radius.
  geometry::RemeshOptions remesh = DefaultRemeshOptions();
  bool show_progress = true;
};

struct RefineStepLog {
  int step = 0;
  double loss_normal = 0, loss_mask = 0, loss_lap = 0, loss_points = 0;  // at the step's last iteration, unweighted
  size_t vertices = 0, faces = 0;
  double mean_target_edge = 0;  // world units
  double seconds = 0;           // wall time of the step
  // Where the step's time went: the remeshing pass and its connectivity caches; the views' loss terms and
  // their gradients (the GPU's share on CUDA); the rest of each iteration on the CPU (vertex normals and their
  // backward, the views' gradients summed, smoothness and point terms, the optimiser step).
  double remesh_seconds = 0, views_seconds = 0, update_seconds = 0;
};

struct RefineResult {
  TriangleMesh mesh;  // positions and faces only (the refined geometry; texture comes later)
  std::vector<RefineStepLog> log;
  double seconds = 0;
};

// InputError for: an empty or non-manifold coarse mesh (weld split vertices first), no views, views of
// different sizes, masks or normal maps whose size disagrees with their camera, impossible options, points
// that are not finite. `points` (views' world frame) switch on the point term.
RefineResult RefineMesh(const TriangleMesh& coarse, const MultiViewSet& views, const RefineOptions& options,
                        const std::vector<Eigen::Vector3f>& points = {});

// The classical coarse mesh: the visual hull of the views' masks, carved over a cube that every view sees
// whole (centred on the point nearest all optical axes), `resolution` voxels along its side.
TriangleMesh CoarseMeshFromViews(const MultiViewSet& views, int resolution = 96);

// Drops attributes, welds coincident vertices (loaders split them at UV / normal seams) and checks that
// the result is manifold; InputError naming `what` otherwise.
TriangleMesh PrepareForRefinement(const TriangleMesh& mesh, const std::string& what);

}  // namespace sd
