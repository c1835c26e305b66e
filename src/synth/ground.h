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
//     returns while consecutive ground heights change by less than `max_step` + `max_slope` x distance
//     (a kerb stops it) and ends at the first obstacle point (0.25..3 m above the ground, annotated or
//     not) or at the last ground return. This bridges the wide gaps between LiDAR rings at range, where
//     a cell grid sees only isolated rings.
//  5. Local surface queries fit a plane to the ground points within `local_radius` (weighted least squares),
//     so slopes and cambers are followed; far from any data they fall back to the seed plane.
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
  double max_step = 0.08;        // height change between consecutive ground returns (kerbs are ~0.1-0.2 m)
  double max_slope = 0.04;       // plus this much per metre between them (road grade)
  int sectors = 720;             // azimuth sectors of the free-space walk
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
  static GroundModel Estimate(const std::vector<Eigen::Vector3d>& points_ego, const std::vector<Box3>& objects,
                              const GroundOptions& options = {});

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
  std::vector<Eigen::Vector3d> ground_points_;
  std::vector<int> ground_indices_;
  std::vector<std::vector<int>> cell_points_;  // ground point indices per cell, for local fits
};

}  // namespace sd
