#pragma once
// Hiding inserted objects behind real scene geometry. docs/occlusion.md has the method and the figures.
//
// Two ways, both from the LiDAR sweep projected into the camera (ego-motion-compensated extrinsics, see
// datasets/log.h; the camera's distortion is applied):
//
//  1. ComputeVisibility (sparse, the original): a rendered pixel at depth d is hidden when real, non-ground
//     geometry is nearer than d - tol(d): between the sparse LiDAR rings, each pixel takes the verdict of the
//     nearest projected point above and below it in a narrow column strip (so an occluder's edge falls midway
//     between the rings that bound it). Ground points never occlude but count as "nothing in front" evidence.
//
//  2. DenseDepth + VisibleMask (dense): a per-camera depth map and a confidence map. The LiDAR is mounted
//     above and beside the camera, so it sees past the edges of objects the camera cannot: a point is dropped
//     when a clearly nearer point projects within a few pixels (z-buffer visibility filter). The kept points
//     are spread edge-aware: each pixel gathers the points within `max_fill_px`, weighs them by image distance
//     (on the scale of the local point spacing) and by colour similarity to the camera image (joint bilateral),
//     groups them into depth clusters (the ground as one) and takes the cluster of the best-matching point —
//     a selection, not a mean, so a pixel takes either the foreground or the background depth, never a blend,
//     and between sparse points the boundary can follow the image's colour edge instead of falling midway
//     between them (what nearest-neighbour fill does). Within the cluster, inverse depth is interpolated. Where no LiDAR point is near
//     (above the top ring, in the gaps of a sparse 32-beam sweep, below the lowest ring), priors fill in: the
//     faces of the annotated 3D boxes (ray-box intersection) and the road surface below the horizon (an
//     optional SurfaceModel), each with a fixed lower confidence. Pixels with none of these are +inf.
//     VisibleMask compares an inserted object's rendered depth with it, then mattes the one-pixel band each
//     side of the occlusion boundary from the camera image: the pixel's colour as a mix of the occluder's and
//     the background's colour nearby (two-colour matting). The edge of a real occluder across a pixel thus
//     gives a fractional, antialiased visibility, and a boundary the depth map put one pixel off is moved to
//     where the photograph has it.
#include <array>
#include <cstdint>
#include <vector>

#include <Eigen/Core>

#include "core/box3.h"
#include "core/camera.h"
#include "core/image.h"
#include "core/rigid3.h"
#include "synth/surface.h"

namespace sd {

struct ProjectedPoint {
  float u, v, depth;  // pixels, metres along the camera z axis
  bool ground;
};

// Projects ego-frame points into the camera. `is_ground[i]` marks ground points (may be empty).
std::vector<ProjectedPoint> ProjectPoints(const std::vector<Eigen::Vector3d>& points_ego, const std::vector<uint8_t>& is_ground,
                                          const PinholeCamera& camera, const Rigid3d& T_cam_ego);

struct OcclusionOptions {
  int column_half_width = 3;  // pixels either side of the pixel's column searched for LiDAR points
  int max_gap = 48;           // pixels: farther points above/below say nothing
  double tol_abs = 0.4, tol_rel = 0.04;  // an occluder must be nearer than d - max(tol_abs, tol_rel * d)
};

// Visibility (1 visible, 0 hidden) of each pixel where `object_depth` is finite; 1 elsewhere.
ImageF ComputeVisibility(const std::vector<ProjectedPoint>& points, const ImageF& object_depth,
                         const OcclusionOptions& options = {});

// ---- Dense depth -------------------------------------------------------------------------------------------

struct DenseDepthOptions {
  // Z-buffer visibility filter: a point is dropped when a point nearer than depth / (1 + hidden_rel) - 0.3 m
  // projects within `hidden_window_px` (Chebyshev) of it.
  int hidden_window_px = 3;
  double hidden_rel = 0.1;
  int max_fill_px = 24;         // LiDAR evidence spreads at most this far; a sparse 32-beam sweep has rings ~30 px apart
  // Spatial weight exp(-r^2 / 2 sigma^2), sigma = sigma_space_nn x the distance to the nearest point, within
  // 1 .. sigma_space_px pixels.
  double sigma_space_nn = 1.5;
  double sigma_space_px = 8.0;
  double sigma_color = 14.0;    // colour weight, 0..255 units (RGB Euclidean distance to the point's pixel)
  // Within this distance of a point the nearest point decides alone: where the sweep is dense (64 beams) the
  // colour only adds the camera-LiDAR misalignment (measured: docs/occlusion.md).
  double nearest_within_px = 4.0;
  double cluster_rel = 0.06;    // neighbouring candidate depths within this relative step form one surface
  bool edge_aware = true;       // false: plain nearest-neighbour fill (the baseline the figures compare with)
  // Pixel rectangle [x0, x1) x [y0, y1) to fill (all zero: the whole image); outside it depth is +inf and
  // confidence 0. Points outside it still count for the pixels inside (the result inside is the same).
  int x0 = 0, y0 = 0, x1 = 0, y1 = 0;
  // When not empty, instead of x0..y1: the union of these rectangles ({x0, y0, x1, y1}), the same inside it as
  // their bounding rectangle would give; for objects far apart, what lies between them costs nothing.
  std::vector<std::array<int, 4>> rects;
  double box_confidence = 0.5;      // of depth from the annotated boxes' faces
  double surface_confidence = 0.35; // of depth from the road surface
};

// Depth from what is known beside the sweep. Boxes in the ego frame (annotated real objects); the surface in
// the world frame, placed by T_world_ego (identity for KITTI, whose frames have no world pose).
struct DepthPriors {
  std::vector<Box3> boxes_ego;
  const SurfaceModel* surface = nullptr;
  Rigid3d T_world_ego;
};

struct DepthMap {
  ImageF depth;       // metres along the camera z axis; +inf where nothing is known (sky, beyond every prior)
  ImageF confidence;  // 0..1: LiDAR 1 at a kept point, falling with the distance to the points that voted; priors fixed
  ImageU8 ground;     // 1 where the depth is the road's (the LiDAR ground surface or the surface prior); may be empty
};

// Drops points the camera cannot see (the visibility filter above). Keeps the input order.
std::vector<ProjectedPoint> FilterHiddenPoints(const std::vector<ProjectedPoint>& points, int width, int height,
                                               const DenseDepthOptions& options = {});

// The dense depth of one camera. `points`: the sweep projected with ProjectPoints (ground points included; they
// are road depth); `image`: the camera's photograph (sRGB, 3 channels, the camera's size) that guides the fill;
// it may be empty when `options.edge_aware` is false. The visibility filter runs inside.
DepthMap DenseDepth(const std::vector<ProjectedPoint>& points, const ImageU8& image, const PinholeCamera& camera,
                    const Rigid3d& T_cam_ego, const DepthPriors& priors = {}, const DenseDepthOptions& options = {});

struct VisibleMaskOptions {
  double tol_abs = 0.3, tol_rel = 0.03;  // a real surface hides the object when nearer than d - max(tol_abs, tol_rel d)
  double min_confidence = 0.3;           // scene depth less trusted than this never hides anything
  int guide_radius = 2;       // window (pixels) the occluder and background colours are taken from; 0: hard edges
  double min_contrast = 24;   // 0..255 RGB distance below which the two colours are too alike to matte
  // The road hides nothing by default (as in ComputeVisibility): objects stand on it, and at a grazing view a
  // few centimetres of road height error move its depth by decimetres (5 cm at 15 m from a camera 1.5 m up:
  // 0.5 m), enough to cut the feet off every object. Only DepthMap::ground pixels are exempt.
  bool ground_occludes = false;
};

// Visibility (0..1) of each pixel of an inserted object: `object_depth` (metres along z, +inf off the object),
// compared with the scene's dense depth; 1 where the object depth is not finite. Hard 0/1 away from occlusion
// boundaries; on the one-pixel band each side of them, matted from the camera image (`image`, sRGB, the camera's size; may be
// empty: then the edges stay hard). The visible alpha of the object is its coverage times this.
ImageF DenseVisibility(const DepthMap& scene, const ImageU8& image, const ImageF& object_depth,
                       const VisibleMaskOptions& options = {});
// The object's visible mask: `object_coverage` (0..1, antialiased) times DenseVisibility.
ImageF VisibleMask(const DepthMap& scene, const ImageU8& image, const ImageF& object_depth, const ImageF& object_coverage,
                   const VisibleMaskOptions& options = {});

}  // namespace sd
