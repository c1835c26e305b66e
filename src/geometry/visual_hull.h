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

// Throws InputError when no view is given or a mask's size disagrees with its camera.
TriangleMesh VisualHull(const std::vector<SilhouetteView>& views, const VisualHullOptions& options);

}  // namespace sd::geometry
