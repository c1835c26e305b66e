#pragma once
// The road surface near the ego vehicle, estimated from one LiDAR sweep.
//
// Method (robust to cars, walls and vegetation, no fixed sensor height assumed):
//  1. Points are moved to the ego frame; points inside annotated boxes are ignored.
//  2. Seed plane: RANSAC over the lowest point of each coarse cell (2 m), normal within 20 deg of +z,
//     refined by least squares on its inliers.
//  3. Height field on a fine grid (0.5 m): per cell, the median height of the points within `band` of the
//     lowest point that lies near the seed plane; cells with too few points stay unobserved.
//  4. Drivable area (free space): the plane is cut into thin azimuth sectors around the sensor. Walking
//     outwards along each sector through the points in range order, the free range grows over ground
//     returns that stay within `kerb_step` (or `max_bend` x gap) of the road profile of the last
//     `profile_window` metres (a line through the accepted returns, so grades and camber are followed).
//     Where the median of the next returns (within `kerb_lookahead`) departs, a kerb begins and the walk
//     ends (a lone departing return is noise and is passed over); so does the first obstacle point (0.25..3 m
//     above the ground, annotated or not), or the last ground return. This bridges the wide gaps between
//     LiDAR rings at range, where a cell grid sees only isolated rings.
//  5. Local surface queries fit a plane to the ground points within `local_radius` (weighted least squares),
//     so slopes and cambers are followed; far from any data they fall back to the seed plane.
#include <cstdint>
#include <optional>
#include <vector>

#include <Eigen/Core>

#include "core/box3.h"
#include "core/pointcloud.h"
#include "core/rigid3.h"

namespace sd {

struct GroundOptions {
  double max_range = 50.0;       // metres from the ego origin
  double cell = 0.5;             // height-field cell size, metres
  double seed_cell = 2.0;        // cell size for seed-plane candidates
  double inlier = 0.15;          // RANSAC inlier distance, metres
  double band = 0.08;            // points within this of a cell's lowest point count as its surface
  double max_step = 0.08;        // the first return's height off the seed plane (+ max_grade x range)
  double kerb_step = 0.025;      // a departure from the sector's road profile this high is a kerb (>= 4 cm kerbs)...
  double max_bend = 0.04;        // ...unless a change of grade this steep since the last road return explains it
  double max_grade = 0.08;       // the steepest grade (off the seed plane) the road profile follows
  double profile_window = 3.0;   // metres of accepted returns the road profile is fitted to
  double kerb_lookahead = 1.0;   // a kerb: the median of the returns this far ahead departs from the profile
  int sectors = 720;             // azimuth sectors of the free-space walk
  int bridge_empty_sectors = 0;  // a sector without returns takes the nearer reach of the non-empty ones within this many
  // A sector whose walk ran out of returns (no kerb, no obstacle met) reaches on to its first obstacle return, or to
  // max_range: for a camera's stereo, whose road points stop where the parallax does, not where the road does.
  bool open_sectors_reach_obstacles = false;
  Eigen::Vector2d sensor_xy = Eigen::Vector2d::Zero();  // LiDAR position in the ego xy plane
  // Ego body footprint (ego frame, metres; nuScenes' Renault Zoe around its rear-axle origin): points on
  // the car itself never block the free-space walk.
  Eigen::Vector2d ego_body_min = Eigen::Vector2d(-1.2, -1.1), ego_body_max = Eigen::Vector2d(3.8, 1.1);
  double local_radius = 1.5;     // radius of local plane fits, metres
  int ransac_iterations = 300;
  uint32_t seed = 1;
};

struct GroundPlane {
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();  // unit, z > 0
  double d = 0;                                       // n.p + d = 0
  double HeightAt(double x, double y) const { return -(d + normal.x() * x + normal.y() * y) / normal.z(); }
};

class GroundModel {
 public:
  // `points_ego`: the sweep in the ego frame. `objects`: annotated boxes (ego frame) whose points are not ground.
  // `other_sensor` (empty, or one flag per point): points of a second LiDAR merged into the sweep (PandaSet's
  // forward PandarGT), left out: the free-space walk follows rays from the sensor at `sensor_xy`, and two
  // sensors' calibrations disagree by centimetres on the road (PandaSet: ~10 cm), more than a low kerb.
  static GroundModel Estimate(const std::vector<Eigen::Vector3d>& points_ego, const std::vector<Box3>& objects,
                              const GroundOptions& options = {}, const std::vector<uint8_t>& other_sensor = {});
  // A road known only as a plane (a frame without LiDAR whose cameras gave no stereo): no cell is observed, every
  // local query answers the plane, and everything within `max_range` of `sensor_xy` counts as drivable, since
  // nothing is known of kerbs or obstacles there (the caller reports that the road was assumed).
  static GroundModel Plane(const GroundPlane& plane, const GroundOptions& options = {});

  const GroundPlane& seed_plane() const { return seed_; }
  // Local surface at (x, y): height and unit normal from the nearby ground points (see file comment).
  struct Surface {
    double height = 0;
    Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
    int support = 0;  // ground points used; 0 = fell back to the seed plane
  };
  // `radius` <= 0 uses options.local_radius; pass the object's footprint radius so a large object sits on
  // the plane of the ground it covers rather than on an extrapolated small patch.
  Surface SurfaceAt(double x, double y, double radius = 0) const;
  // Signed height of an ego-frame point above the local ground.
  double HeightAboveGround(const Eigen::Vector3d& p) const;

  // How far the sweep's road returns scatter about their sector's profile (robust sigma, metres), and the
  // kerb height the free-space walk used: `kerb_step`, or 4 sigma for a sensor noisier than that allows.
  double road_roughness() const { return road_roughness_; }
  double kerb_step() const { return kerb_step_; }

  bool IsObserved(double x, double y) const;  // the cell holds ground points
  bool IsDrivable(double x, double y) const;  // within the free range of its sector (see file comment)
  double DrivableFraction(const Box3& footprint) const;  // fraction of footprint samples that are drivable

  const std::vector<Eigen::Vector3d>& ground_points() const { return ground_points_; }
  // Indices (into the input points) classified as ground: within `inlier` of the height field.
  const std::vector<int>& ground_indices() const { return ground_indices_; }
  int grid_size() const { return n_; }
  double cell() const { return options_.cell; }

 private:
  int CellIndex(double x, double y) const;  // -1 outside the grid
  GroundOptions options_;
  GroundPlane seed_;
  int n_ = 0;  // grid is n_ x n_ centred on the ego origin
  std::vector<float> height_;        // NaN where unobserved
  std::vector<float> free_range_;  // per azimuth sector, metres from sensor_xy
  double road_roughness_ = 0, kerb_step_ = 0;
  std::vector<Eigen::Vector3d> ground_points_;
  std::vector<int> ground_indices_;
  std::vector<std::vector<int>> cell_points_;  // ground point indices per cell, for local fits
};

}  // namespace sd
