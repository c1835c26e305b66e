#pragma once
// Visual hull from silhouettes: the classical coarse mesh. A voxel is kept when its projection falls inside
// the mask in every view where it lands in the image; the occupancy is smoothed into a field and meshed with
// marching cubes.
#include <vector>

#include "core/camera.h"
#include "core/image.h"
#include "core/mesh.h"
#include "core/rigid3.h"

namespace sd::geometry {

struct SilhouetteView {
  PinholeCamera camera;
  Rigid3d T_cam_world;
  ImageF mask;  // 1 channel, 0..1 (1 = object), camera.width x camera.height
};

struct VisualHullOptions {
  int resolution = 96;           // voxels along the longest side of the bounds
  float mask_threshold = 0.5f;
  // Region carved; empty = the cube [-1, 1]^3 (objects normalised into the unit sphere, as the rig does).
  AlignedBox3f bounds;
};

// Throws InputError when no view is given or a mask's size disagrees with its camera (also: a mask with other
// than 1 channel, non-positive focal lengths, resolution outside [2, 2048], mask_threshold outside (0, 1),
// bounds flat along an axis).
// The field at a node is the mask's coverage of the node's footprint (one voxel, projected), so the surface
// follows the silhouettes to ~0.1 voxel rather than sitting on voxel steps. A node that no view sees is
// outside; the grid has one forced-outside node layer beyond the bounds, so the mesh is closed and clipped at
// most half a voxel outside them. Only the connected component enclosing the largest volume is returned:
// where the bounds leave the views' frusta, regions only a few views see cannot be carved and would otherwise
// remain as islands. Result: watertight, manifold, outward CCW; positions and faces only.
TriangleMesh VisualHull(const std::vector<SilhouetteView>& views, const VisualHullOptions& options);

}  // namespace sd::geometry
