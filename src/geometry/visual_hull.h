#pragma once
// Visual hull from silhouettes: the classical coarse mesh. A voxel is kept when its projection falls inside
// the mask in every view where it lands in the image; the occupancy is smoothed into a field and meshed with
// marching cubes.
#include <utility>
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
  // The silhouettes show the whole object, so it lies in every view's frustum: nodes outside any view's
  // image are outside. Turn off for camera sets where some views see only part of the object.
  bool require_all_views = true;
  // Components enclosing less than this fraction of the largest one's volume are dropped as voxel noise.
  float min_component_fraction = 0.01f;
  // Noisy masks (a segmenter's, not a renderer's): a node stays inside while at most this many views put it
  // outside, so one view's bite out of the object does not carve it from all of them.
  int tolerated_outside_views = 0;
  // Space known to be empty — a LiDAR beam's path from its sensor to just short of its return: nodes within
  // half a voxel of a segment are outside whatever the silhouettes say (they carve concavities no silhouette
  // shows, and the parts of a box the object does not fill).
  std::vector<std::pair<Eigen::Vector3f, Eigen::Vector3f>> free_segments;
  // An object solid across one axis of the bounds (a vehicle's body across its width, 1 = y): a line of nodes
  // along that axis that the silhouettes leave less than min_column_fill inside is emptied whole. Views from
  // one side of such an object carve the side they see but leave a ridge in the middle of the width, where the
  // line of sight passes over the near side into the object's silhouette (above a car's hood, seen from a front
  // quarter, the hood nearer the camera than the cabin); the ridge is what the object is not. -1: off.
  int solid_across_axis = -1;
  float min_column_fill = 0.7f;
  // Passes of a [1 2 1] / 4 filter along each axis over the field once beams have carved it (two: a Gaussian of
  // about one voxel). A beam sets the nodes it passes to 0 outright, so an uncarved surface would keep voxel-sized
  // pits and steps; refinement turns those into folds, and the UV atlas into thousands of charts (a PandaSet car:
  // 5891 charts and 9 % of the atlas used without it, 838 and 37 % with it). 0: off; only with free segments.
  int carved_smoothing_passes = 2;
};

// Throws InputError when no view is given or a mask's size disagrees with its camera (also: a mask with other
// than 1 channel, non-positive focal lengths, resolution outside [2, 2048], mask_threshold outside (0, 1),
// bounds flat along an axis, solid_across_axis outside [-1, 2], min_column_fill outside [0, 1]).
// The field at a node is the mask's coverage of the node's footprint (one voxel, projected), so the surface
// follows the silhouettes to ~0.1 voxel rather than sitting on voxel steps. A node that no view sees is
// outside; the grid has one forced-outside node layer beyond the bounds, so the mesh is closed and clipped at
// most half a voxel outside them. With require_all_views, nodes outside any view's image are outside (where
// the bounds leave the views' frusta, regions only a few views see could not be carved and would remain as
// islands). Components below min_component_fraction of the largest one's volume are dropped; thin parts
// that break apart at the grid's resolution are kept. Result: watertight, manifold, outward CCW; positions
// and faces only.
TriangleMesh VisualHull(const std::vector<SilhouetteView>& views, const VisualHullOptions& options);

}  // namespace sd::geometry
