#pragma once
// Geometry metrics against ground truth. The protocol (documented here, printed with every result):
//  - Normalisation: both meshes are expressed in the ground truth's frame, translated by the centre of the
//    GT's bounding box and scaled by 1 / (longest side of the GT's bounding box), so the GT fits the unit
//    cube [-0.5, 0.5]^3. The prediction gets the same transform (no alignment: our assets are metric).
//  - Surface samples: `num_samples` points per mesh, uniform by area (fixed seed; the two meshes draw from
//    independent streams, so identical meshes score the sampling-noise floor — Chamfer ~0.003 at 100k
//    samples on a sphere — not an exact 0).
//  - Chamfer distance: mean nearest-neighbour distance pred->gt plus gt->pred, halved (L2, not squared),
//    in normalised units.
//  - F-score at threshold tau (normalised units): harmonic mean of precision (fraction of pred samples
//    within tau, i.e. distance <= tau, of the GT samples) and recall (the converse).
//  - Volume IoU: both meshes voxelised on a grid of `iou_resolution` cells along each axis of their joint
//    bounds (cells may be anisotropic); a voxel centre is inside when rays along +x, +y and +z agree by
//    majority on odd crossing parity (tolerates small holes). Ray origins carry a deterministic jitter of
//    at most 1e-3 voxel so that grid-aligned meshes do not put rays through vertices or along edges.
//  - Normal consistency: mean |n_pred . n_gt| of the face normals at nearest-neighbour sample pairs, both
//    directions, averaged.
#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/mesh.h"

namespace sd::geometry {

struct GeometryMetricsOptions {
  int num_samples = 100000;
  float fscore_threshold = 0.01f;  // tau, normalised units (1% of the GT's longest side)
  int iou_resolution = 128;
  uint64_t seed = 1;
};

struct GeometryMetrics {
  double chamfer = 0;
  double fscore = 0, precision = 0, recall = 0;
  double volume_iou = 0;
  double normal_consistency = 0;
};

// Points on the surface, uniform by area, with the unit normal of the face each came from. Deterministic for
// a given seed on every platform; empty when the mesh has no area.
struct SurfaceSamples {
  std::vector<Eigen::Vector3f> points, normals;
};
SurfaceSamples SampleSurface(const TriangleMesh& mesh, int count, uint64_t seed);

// Throws InputError when either mesh has no faces, no area or invalid indices, when the GT has zero extent,
// or when num_samples or iou_resolution is < 1. Cost at the defaults: ~0.7 s on 2 cores.
GeometryMetrics CompareMeshes(const TriangleMesh& pred, const TriangleMesh& gt, const GeometryMetricsOptions& options);

// The protocol as one paragraph, with the option values filled in.
std::string DescribeProtocol(const GeometryMetricsOptions& options);

}  // namespace sd::geometry
