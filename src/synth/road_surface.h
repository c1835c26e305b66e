#pragma once
// The road surface of a whole sequence: LiDAR sweeps aggregated in the WORLD frame (ego poses), ground
// segmented, a height field with occluded holes filled, and the drivable area. Implements SurfaceModel
// (synth/surface.h) for placement, shading and LiDAR simulation. docs/road_surface.md has the figures.
//
// Method, and why:
//  1. Points inside annotated boxes (grown by `box_margin`), nearer than `min_range` (the ego body) or
//     farther than `max_range` from their sweep's sensor are dropped: far returns graze the road and are
//     sparse and noisy.
//  2. World grid of `cell` metres. Per cell: its robust lowest point (the lowest with another point within
//     `band` above it, so a single below-ground multipath return does not count; a lone point counts) and the
//     candidate height = the median of the points within `band` above that lowest point.
//  3. Seeds: per sweep, a RANSAC plane (normal within 20 deg of +z) on the lowest points of 2 m cells within
//     `seed_radius` of the sensor; cells near the sensor whose candidate height lies within `seed_inlier` of
//     it. A single plane would not follow a hilly sequence, so it only seeds.
//  4. Region growing from the seeds: a cell joins when its candidate height differs from an accepted cell's
//     by at most `ground_max_step` + `ground_max_slope` x distance, the accepted cell being adjacent or up
//     to `grow_distance` away across cells that hold no points at all. The jumps bridge the gaps between
//     LiDAR rings (2 m apart at 20 m range for a 32-beam lidar) but never leap over a rejected obstacle.
//     Kerbs (0.1-0.2 m) pass, so sidewalks are ground; walls, vegetation and unannotated vehicles, whose
//     lowest returns sit higher, do not. We chose
//     lowest-point + growing over a cloth or morphological filter because it needs no global terrain size
//     parameter and follows slopes locally, and over a single RANSAC plane because sequences are not flat.
//  5. Ground points: within `inlier` of their cell's candidate height. Observed cells: height = median of
//     their ground points.
//  6. Holes filled (observed = false) by membrane (Laplace) interpolation, with observed cells as fixed
//     boundary: (a) every cell under an annotated object's footprint or under the ego vehicle
//     (`ego_fill_radius` around each sensor position), within `object_fill_distance` of observed ground — the
//     road is there, the object hides it; (b) every unobserved cell enclosed by observed ground: along at
//     least one of the 4 axis and diagonal directions, observed ground lies within `max_fill_distance` on
//     BOTH sides (gaps between LiDAR rings, narrow shadows of poles and pedestrians). A connected-component test
//     would not do: ring gaps connect through every shadow to the unobserved outside. Large unobserved
//     regions (buildings, long occlusion shadows, beyond the range) stay outside the surface (At = nullopt).
//     Under an object the membrane can carry a different surface seen beyond it (a lawn bank, a wall base in
//     its shadow): where it differs by more than 0.25 m from the road the sensor sees in front of the object
//     (a plane through the observed cells met walking from the footprint towards the sensor), that wins.
//  7. Normals: from the least-squares plane through the 3x3 neighbourhood's heights (central differences
//     where fewer than 5 neighbours are on the surface).
//  8. Drivable: the cells connected (4-neighbours) to the ego trajectory (cells under the sensor positions)
//     without crossing a kerb cell: a cell whose 3x3 neighbourhood departs from its least-squares plane by
//     more than `kerb_height` / 3 (a step s through the window departs by s / 3; a smooth grade by 0) or
//     whose height steps by more than `kerb_height` to a 4-neighbour, or a filled gap whose two observed
//     sides differ by more than `kerb_height` (+ 2 % of the gap) beyond the seed plane's grade (a kerb
//     hidden between two LiDAR rings, where the membrane would ramp over it). Kerb tops and sidewalks are
//     therefore not drivable; the drivable area stops about one cell short of a kerb.
//     Where a dataset has a drivable-area raster (Argoverse 2 maps), IntersectDrivableRaster narrows it.
#include <cstdint>
#include <optional>
#include <vector>

#include <Eigen/Core>
#include <Eigen/Geometry>

#include "core/box3.h"
#include "datasets/log.h"
#include "synth/surface.h"

namespace sd {

// One LiDAR sweep in the world frame.
struct SweepInWorld {
  std::vector<Eigen::Vector3d> points;                 // world frame, metres
  Eigen::Vector3d sensor_origin = Eigen::Vector3d::Zero();  // world; its xy marks the ego trajectory
  std::vector<Box3> objects;                           // annotated boxes (world frame): their points are not ground
};

struct RoadSurfaceOptions {
  double cell = 0.4;                // height-field cell, metres
  double min_range = 2.5;           // horizontal distance from the sensor below which points are the ego body
  double max_range = 50.0;          // horizontal distance from the sensor beyond which points are dropped
  double box_margin = 0.15;         // annotated boxes grow by this (footprint and top; not below the box)
  double band = 0.10;               // a cell's surface: points within this above its robust lowest point
  double inlier = 0.10;             // ground point: within this of its cell's candidate height
  double seed_cell = 2.0;           // RANSAC candidate cells
  double seed_radius = 20.0;        // RANSAC candidates and seeds within this of the sensor
  double seed_inlier = 0.15;        // RANSAC inlier distance; seeds within this of the plane
  int ransac_iterations = 200;
  uint32_t seed = 1;
  double grow_distance = 3.0;       // a growing step may jump this far over EMPTY cells (gaps between rings)
  double ground_max_step = 0.15;    // metres between accepted neighbours (kerbs pass, car bodies do not)
  double ground_max_slope = 0.12;   // plus this per metre of distance
  double max_fill_distance = 3.0;   // enclosed holes: no cell farther than this from observed ground
  double object_fill_distance = 4.0;  // object/ego footprints: filled within this of observed ground
  double ego_fill_radius = 3.0;     // around each sensor position: the road under the ego vehicle
  double kerb_height = 0.08;        // a step this high bounds the drivable area
  int fill_iterations = 400;        // Gauss-Seidel sweeps of the membrane fill
};

class RoadSurface final : public SurfaceModel {
 public:
  // InputError when nothing can be seeded (no sweep has a ground plane near its sensor). Progress is
  // reported through core/log.h.
  static RoadSurface Build(const std::vector<SweepInWorld>& sweeps, const RoadSurfaceOptions& options = {});

  // Height (bilinear between the centres of valid cells), normal and observed flag of the cell at xy.
  std::optional<SurfacePoint> At(const Eigen::Vector2d& xy_world) const override;
  bool IsDrivable(const Eigen::Vector2d& xy_world) const override;

  // Narrows the drivable area to where `raster` (row-major, width x height, non-zero = drivable) is
  // drivable; `T_pixel_world` maps world xy to pixel coordinates (column, row), e.g. Argoverse 2's
  // img_Sim2_city (Sim2ToAffine). Cells outside the raster become non-drivable. Returns the cells removed.
  size_t IntersectDrivableRaster(const std::vector<uint8_t>& raster, int width, int height,
                                 const Eigen::Affine2d& T_pixel_world);
  // p_pixel = scale * (R * p_world + t), Argoverse 2's Sim(2) convention.
  static Eigen::Affine2d Sim2ToAffine(double scale, const Eigen::Matrix2d& R, const Eigen::Vector2d& t);

  // Grid geometry, for iterating cells.
  int nx() const { return nx_; }
  int ny() const { return ny_; }
  double cell() const { return options_.cell; }
  Eigen::Vector2d CellCentre(int ix, int iy) const {
    return origin_ + options_.cell * Eigen::Vector2d(ix + 0.5, iy + 0.5);
  }
  // Per input sweep, the indices of its points classified as ground.
  const std::vector<std::vector<int>>& ground_indices() const { return ground_indices_; }

  struct Stats {
    size_t ground_points = 0;
    size_t observed_cells = 0, filled_cells = 0, drivable_cells = 0;
    double median_abs_residual = 0;  // ground points vs At() (bilinear surface), metres
  };
  const Stats& stats() const { return stats_; }

 private:
  int CellIndex(const Eigen::Vector2d& xy) const;  // -1 outside the grid
  RoadSurfaceOptions options_;
  Eigen::Vector2d origin_ = Eigen::Vector2d::Zero();  // world xy of the grid's (0, 0) corner
  int nx_ = 0, ny_ = 0;
  std::vector<float> height_;                     // NaN: not part of the surface
  std::vector<Eigen::Vector3f> normal_;
  std::vector<uint8_t> observed_, drivable_;
  std::vector<std::vector<int>> ground_indices_;
  Stats stats_;
};

// The sweeps of frames [first, last) that have a LiDAR record, moved to the world frame with
// T_world_ego * T_ego_lidar; each sweep's annotated boxes go to the world frame too. Frames without a sweep
// are skipped. `max_range` (horizontal, from the sensor) drops far points early to bound memory.
struct SweepsFromLogOptions {
  double max_range = 60.0;
};
std::vector<SweepInWorld> SweepsFromLog(const Log& log, size_t first, size_t last,
                                        const SweepsFromLogOptions& options = {});

}  // namespace sd
