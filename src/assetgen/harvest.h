#pragma once
// One object of a driving log → everything an asset can be built from, with no learned model (docs/harvest.md):
// every camera image and frame in which the same instance is seen, each as a view with its camera pose relative to
// the object and its mask; the object's LiDAR returns and the beams that passed it, gathered over the frames;
// and its metric box.
//
// The object frame is the asset's canonical one, taken from the annotation's box: x the box's front, y left, z up,
// metres, origin at the centre of the box's bottom face. An object whose box centres (world) stay within 0.15 m
// stands still: one pose for all frames, so the annotation's jitter does not smear its returns. A moving track's
// box moves and turns from frame to frame; each frame's sensors are moved into the object frame by that frame's
// box, so a moving car is gathered as if it stood still (a rigid object; a pedestrian is not one).
//
// Views: the object's crop in each camera image (mining/log_crops.h), its mask the LiDAR returns' footprint
// refined to the image's outline by the segmenter (GrabCut seeded by the returns, inside the projected box), padded
// to a square about the object and resampled to `view_size`, with the camera shifted and scaled to match. Views in
// which the object is hidden behind nearer returns are dropped. A view in which it is cut by the image border
// still frames the whole object, its pixels past the border marked unknown: such views are used where no whole
// view sees the object from their direction. At most `max_views` are kept, spread over the directions they see it
// from, whole views first.
#include <string>
#include <utility>
#include <vector>

#include <Eigen/Core>

#include "assetgen/shape_prior.h"
#include "assetgen/views.h"
#include "core/box3.h"
#include "core/mesh.h"
#include "datasets/log.h"

namespace sd {

struct HarvestOptions {
  int view_size = 256;            // pixels, square
  double context = 0.3;           // margin about the projected box, of its size, per side (background colour)
  int min_object_px = 24;         // shorter side of the object's box in the source image
  // Views of an object cut by the image border (up to `max_truncation` of its projected box outside the image)
  // frame the whole object and mark the pixels past the border unknown (MultiView::known); they join the whole
  // views where they add a direction (a parked car the side cameras never see whole). Off: whole views only.
  bool use_truncated_views = true;
  double max_truncation = 0.5;
  double max_occlusion = 0.2;     // fraction of the object's image hidden behind nearer LiDAR returns
  int max_views = 16;
  double lidar_margin_m = 0.08;   // returns within the box grown by this are the object's
  double ground_clearance_m = 0.04;  // ... except those this close to the box's bottom (the road)
  double free_space_stop_m = 0.06;   // a beam carves space up to this short of its return (range noise)
  std::string segmenter = "classical";  // models::Segmenter::Resolve choice
  bool progress = false;
};

// Which object: the annotation in frame `frame_token` whose box is `box_ego` (the nearest centre, within 0.1 m;
// logs without annotation tokens are matched by the box), and every annotation of its track when it has one.
struct HarvestTarget {
  std::string frame_token;
  Box3 box_ego;
};

struct HarvestedView {
  std::string frame_token, camera;
  double distance_m = 0;                       // camera centre to the box centre
  double azimuth_deg = 0, elevation_deg = 0;   // of the camera, in the object frame (0 = in front, + to its left)
  double truncation = 0, occlusion = 0;
  int object_px = 0;                           // shorter side of the object's box in the source image
  std::string mask_method;
};

struct HarvestedObject {
  std::string category, dataset_category, instance_token;
  Eigen::Vector3d size = Eigen::Vector3d::Zero();  // length, width, height (median over the frames), metres
  MultiViewSet views;                              // object frame; real views only (MultiView::source says where)
  std::vector<HarvestedView> view_info;            // one per view
  std::vector<Eigen::Vector3f> points;             // the object's LiDAR returns, object frame (those inside the
                                                   // views' masks: a neighbour's returns in the box's margin go)
  int points_outside_masks = 0;                    // returns in the box dropped as not the object's
  std::vector<std::pair<Eigen::Vector3f, Eigen::Vector3f>> free_segments;  // beams near the object, object frame
  int frames = 0;             // frames in which the object is annotated
  bool static_pose = false;   // stood still: one world pose for every frame (else each frame's box)
  double world_spread_m = 0;  // largest distance of a frame's box centre (world) from their median
  int frames_with_lidar = 0;
  int candidate_views = 0;    // crops found before the truncation / occlusion / spread selection
  std::string source;         // provenance line: log, track, frames, cameras
};

// InputError naming the log for: no frame `frame_token`, no annotation near the box there, an object no camera
// shows (every crop cut by more than max_truncation, hidden or too small; or, with use_truncated_views off, none
// whole), camera images that cannot be read.
HarvestedObject HarvestObject(const Log& log, const HarvestTarget& target, const HarvestOptions& options = {});

// The axis of a surface of revolution standing upright in the object frame: the vertical line through the
// returned (x, y). Each view's silhouette symmetry axis (shape_prior.h FitSymmetryAxis), back-projected, is a plane
// the 3D axis lies in; the planes are intersected by least squares, weighted by each silhouette's symmetry and
// pulled weakly towards the box's centre (views from one direction do not fix the axis along it); then, with 30 or
// more LiDAR returns (object frame), refined with the profile to the returns (they lie at the profile's radius
// from the axis). At most a quarter of the box's smaller side from its centre.
Eigen::Vector2d RevolveAxis(const MultiViewSet& real, const Eigen::Vector3d& size,
                            const std::vector<Eigen::Vector3f>& points = {});

// A surface of revolution about the vertical axis through `axis`, its radius at each of 32 heights the median
// distance of the LiDAR returns there from the axis (at least 3), else the median over every view's silhouette
// of the narrower side's radius (the distance from the axis of the ray through the row's outline: exact for any
// camera position; rows showing a cap's ellipse — within r sin(elevation) of the outline's top or bottom — left
// out); empty heights interpolated, a 3-height median against outliers. From z = 0 to the box's height, 64
// segments, capped; the radius at most half the box's smaller side. Watertight, object frame.
TriangleMesh RevolveFromViews(const MultiViewSet& real, const std::vector<Eigen::Vector3f>& points,
                              const Eigen::Vector2d& axis, const Eigen::Vector3d& size);

// The view whose mask covers the most pixels: the one that shows the object largest. 0 for no views.
size_t LargestView(const MultiViewSet& views);

// Shape-prior views from real ones, with exact cameras (the object frame's axes are the symmetry's):
//   revolve  copies of the best real view rotated about the vertical axis through `axis` into the azimuths no real
//            view covers (every 45 degrees), up to 8;
//   mirror   each real view mirrored in the plane y = 0 (camera reflected, image flipped left-right) where no real
//            view already sees the object from there.
// The copies are marked synthetic; `limit` caps how many are added.
MultiViewSet SymmetryViews(const MultiViewSet& real, ShapePrior prior, int limit = 8,
                           const Eigen::Vector2d& axis = Eigen::Vector2d::Zero());

}  // namespace sd
