#pragma once
// Obstacles in one LiDAR sweep without labels: the returns that stand above the road, grouped into objects,
// each with an oriented box and a coarse class. Classical and deterministic (docs/detection.md has the method,
// its parameters and the figures measured against hidden annotations).
//
// Frames and units: every point and box is in the EGO frame (x forward, y left, z up), metres. The road is
// not estimated here: the caller gives each point's height above the road surface it already estimated
// (synth/ground.h GroundModel::HeightAboveGround for one sweep, synth/road_surface.h for a sequence), so the
// detector follows the same road the placement stands objects on, hills and cambers included.
//
// Steps, and why:
//  1. Obstacle returns: height above the road within [min_height, max_height] (below: the road, kerbs and
//     ground noise; above: canopies, wires and sign gantries, which would join everything under them),
//     horizontal range from the sensor within [min_range, max_range], and outside the ego vehicle's own body.
//  2. Clustering: Euclidean clustering in bird's-eye view (BEV, z ignored: a car's roof and its bumper are one
//     object however far apart the rings that hit them are) on an occupancy grid of `cell` metres; two occupied
//     cells join when their centres are within `cluster_distance`. Union-find over the grid, scanned in index
//     order, so the result does not depend on point order or threads. Clusters with fewer than `min_points`
//     returns (spurious returns, rain) are dropped. A cluster with a footprint longer than `max_extent` is
//     structure (walls, hedges, buildings, and whatever stands against them): it gets no object box but keep-out
//     tiles of `structure_tile` metres, so a car parked against a wall is still avoided.
//  2b. Compact low objects: a cone, bollard or drum standing against a taller object (a roller, a truck, a
//     wall, a person) is one cluster with it. Low cells (highest return at most `split_max_top` above the road)
//     that do not touch a taller cell, form a component no more than `split_max_extent` across, reach
//     `split_min_clearance` out from the taller part and stand `split_min_rise` below it, are cut out as an
//     object of their own; a bumper, a hood or a sill is a strip along a whole side, or juts out too little, or
//     is barely lower than the part it belongs to. The rest is clustered again. Not on structure.
//  3. Box: L-shape fitting by heading search (Zhang et al., "Efficient L-Shape Fitting for Vehicle Detection
//     Using Laser Scanners", IV 2017, the closeness criterion): for headings in [0, 90) degrees in
//     `heading_step` steps, the points' rectangle along that heading; each point scores 1 / max(d, d0) with d its
//     distance to the nearer of the two rectangle edges it is closest to; the heading with the largest sum wins.
//     A LiDAR sees at most two sides of an object, and this criterion rewards a rectangle whose sides hug those
//     points, where the minimum-area rectangle of a partial view is free to turn. The box is the points'
//     rectangle at that heading (its length along the longer side), from the road (height 0 above the ground
//     under the cluster) to the highest return.
//  3b. Runs: a long, thin, low cluster (barriers standing end to end, a fence) is cut along its length into
//     pieces of about 2 m, each boxed alone, so the boxes follow a curved run instead of one rectangle spanning
//     road it does not cover.
//  3c. Vehicles: the LiDAR sees a car's near faces only, so a box classed vehicle grows to at least
//     `min_vehicle_size` away from the sensor, its seen faces kept (a seen side under 3 m is taken for the car's
//     end, a longer one for its flank). For keep-out, the unseen half of a car is still a car.
//  4. Class, a heuristic from the box size alone (documented in docs/detection.md, measured in the benchmark):
//     pedestrian (at most 1.3 m across, 1.2-2.3 m tall), small object (under 1.3 m tall and either at most
//     0.9 m across or a thin piece at most 3 m long: cones, bollards, tripods, barrier segments), vehicle (a side
//     over 1.3 m and up to 20 m, 0.9-4.6 m tall), else other.
#include <cstdint>
#include <string>
#include <vector>

#include <Eigen/Core>

#include "core/box3.h"

namespace sd::perception {

enum class ObjectClass { kVehicle, kPedestrian, kSmallObject, kOther };
// "vehicle", "pedestrian", "small_object", "other".
const char* ToString(ObjectClass c);

struct DetectOptions {
  double min_height = 0.25;       // metres above the road: lower returns are road, kerbs, ground noise
  double max_height = 3.0;        // metres above the road: higher returns (canopies, gantries) are left out
  double min_range = 1.0;         // horizontal metres from the sensor
  double max_range = 50.0;        // horizontal metres from the sensor
  Eigen::Vector2d sensor_xy = Eigen::Vector2d::Zero();  // ego xy of the LiDAR
  // The ego vehicle's own body (ego frame xy, metres; a nuScenes Renault Zoe around its rear-axle origin by
  // default), grown by `ego_margin`: returns from the car itself and mirrors are no obstacle.
  Eigen::Vector2d ego_body_min = Eigen::Vector2d(-1.2, -1.1), ego_body_max = Eigen::Vector2d(3.8, 1.1);
  double ego_margin = 0.3;
  double cell = 0.1;              // BEV occupancy grid cell, metres
  double cluster_distance = 0.3;  // occupied cells whose centres are this close join one cluster (tuned on
                                  // PandaSet: 0.5 m merged cones with the road roller they stand beside)
  int min_points = 3;             // fewer returns: not an object
  double max_extent = 20.0;       // longest footprint side, metres; longer clusters are structure
  double structure_tile = 2.0;    // structure is boxed in tiles of this many metres (keep-out); 0: dropped
  // A vehicle's box grows to at least this (length, width), away from the sensor (step 3c); 0: as seen.
  Eigen::Vector2d min_vehicle_size = Eigen::Vector2d(4.4, 1.8);
  double heading_step_deg = 1.0;  // L-shape search step
  double closeness_d0 = 0.01;     // metres: the closeness criterion's floor (Zhang et al. 2017)
  int max_fit_points = 4000;      // a larger cluster is fitted on an even subsample (speed; the box still
                                  // spans every point)
  // Runs (step 3b): a cluster longer than run_min_length, narrower than run_max_width and lower than
  // run_max_height is cut into pieces of about run_piece metres (a nuScenes barrier is 2.0-2.5 m long).
  double run_min_length = 3.0, run_max_width = 1.0, run_max_height = 1.5, run_piece = 2.0;
  // Compact low objects (step 2b): a cone, bollard or drum standing against a roller, a truck, a wall or a
  // person is one BEV cluster with it. Inside a cluster, a 0.1 m cell (`cell`) whose highest return is at most
  // split_max_top above the road is low, any other taller. Low cells that touch no taller cell (side or corner:
  // those are the taller object's own low edges as often as the side of the cone touching it) form components
  // (cells touching by side or corner); one becomes an object of its own when all of these hold:
  //  - its top is split_min_top..split_max_top: cones are 0.3-0.9 m, bollards and drums up to 1 m; a car's
  //    shoulder line (0.9-1.1 m) and anything taller count as the taller part;
  //  - its returns span at least split_min_span in height: a cone's face is hit by several rings from the road
  //    up, where one ring across a bush top, a lawn or a hood is flat;
  //  - it is at most split_max_extent across (FitLShape length): above min_height a cone's body is 0.1-0.3 m
  //    across, a drum's 0.6 m; a car's bumper or hood strip runs along a whole side;
  //  - some cell of it is at least split_min_clearance (centre to centre) from every taller cell: a cone
  //    touching a roller reaches 0.3-0.4 m out from it, a car's bumper 0.1-0.25 m beyond its hood or trunk lid;
  //  - the taller cells it stands against (within split_min_clearance + `cell`) rise, by their median top, at
  //    least split_min_rise above its top: a roller, truck, wall or person stands 0.7-1.6 m over a cone, where a
  //    car's bumper tip is 0.1-0.2 m below the hood it juts out from (a median: the odd tall cell of a
  //    neighbour does not lift a bumper into a cone);
  //  - at least split_min_points returns;
  //  - the line of sight from it to the sensor (sensor_xy) crosses no taller cell of the cluster: returns seen
  //    over or through a taller part are inside it (a pickup's bed, seats through a car's windows), not beside it.
  // The rest of the cluster is clustered again (a cone between two vehicles joined them). Measured in
  // docs/detection.md; split_max_extent 0: off.
  double split_min_top = 0.3, split_max_top = 1.0, split_min_span = 0.2, split_max_extent = 0.6;
  double split_min_clearance = 0.3, split_min_rise = 0.5;
  int split_min_points = 5;
};

struct DetectedObject {
  Box3 box;                 // ego frame, geometric centre, size = (length >= width, width, height); yaw in
                            // [0, pi): a box has no front, the tracker orients it by its motion
  ObjectClass object_class = ObjectClass::kOther;
  bool structure = false;   // a tile of a cluster longer than max_extent (class other), not an object
  Eigen::Vector3d seen_center = Eigen::Vector3d::Zero();  // the centre of the returns' own rectangle, before a
                            // vehicle's completion (step 3c): what the tracker follows, as it moves with the object
  int num_points = 0;       // obstacle returns in the cluster
  double ground_z = 0;      // ego z of the road under the box centre
};

// One sweep's obstacles. `points_ego` and `height_above_ground` are parallel (one height per point, metres,
// signed; NaN: unknown, the point is skipped). Returns objects sorted by distance from the sensor, then by x,
// then by y. SD_CHECK when the two inputs differ in size; no input is an error (an empty sweep gives nothing).
std::vector<DetectedObject> DetectObjects(const std::vector<Eigen::Vector3d>& points_ego,
                                          const std::vector<float>& height_above_ground,
                                          const DetectOptions& options = {});

// The indices of the returns DetectObjects treats as obstacles (step 1), in input order.
std::vector<int> ObstaclePoints(const std::vector<Eigen::Vector3d>& points_ego,
                                const std::vector<float>& height_above_ground, const DetectOptions& options);

// Step 2: clusters of `points` (only xy used), each a list of indices into `points`, in a deterministic order
// (by the lowest grid cell they cover). No size filtering.
std::vector<std::vector<int>> ClusterBev(const std::vector<Eigen::Vector3d>& points, double cell, double cluster_distance);

// Step 2b: one cluster (indices into `points`) cut into its compact low objects and the rest. `points` and
// `height_above_ground` are parallel (metres above the road). Returns the rest first (possibly empty when every
// return was split off; the whole cluster when nothing was), then one list per object split off, ordered by
// their lowest grid cell; indices in the order of `cluster`. Does not depend on the order of `cluster`. Reads
// `options.cell`, `sensor_xy` and the split_* fields.
std::vector<std::vector<int>> SplitCompactObjects(const std::vector<Eigen::Vector3d>& points,
                                                  const std::vector<float>& height_above_ground,
                                                  const std::vector<int>& cluster, const DetectOptions& options);

// Step 3 on the footprint only: the rectangle (centre xy, length >= width, heading in [0, pi)) of `xy` by the
// closeness criterion. At least one point (one point: a zero-size rectangle at it).
struct Rectangle {
  Eigen::Vector2d center = Eigen::Vector2d::Zero();
  double length = 0, width = 0, heading = 0;
};
Rectangle FitLShape(const std::vector<Eigen::Vector2d>& xy, double heading_step_deg = 1.0, double d0 = 0.01,
                    int max_points = 4000);

// Step 4: the coarse class of a box of this size (metres).
ObjectClass ClassifyBySize(double length, double width, double height);

}  // namespace sd::perception
