#include "synth/occlusion.h"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>

#include <gtest/gtest.h>

#include "datasets/readers.h"
#include "io/image_io.h"
#include "synth/ground.h"
#include "testing/testing.h"

namespace sd {
namespace {

constexpr float kInf = std::numeric_limits<float>::infinity();

PinholeCamera SmallCamera(int w, int h, double f = 100) {
  PinholeCamera c;
  c.width = w, c.height = h, c.fx = c.fy = f, c.cx = w / 2.0, c.cy = h / 2.0;
  return c;
}

// A dark occluder left of x = 60, bright background right of it; LiDAR rows every 10 px, points 7 px apart
// horizontally placed so that the true edge falls 1.5 px right of the last occluder point and 5.5 px left of
// the first background point: nearest-neighbour fill puts the edge at 63, the image says 60.
struct EdgeScene {
  ImageU8 image{120, 80, 3};
  std::vector<ProjectedPoint> points;
};

EdgeScene MakeEdgeScene() {
  EdgeScene s;
  for (int y = 0; y < 80; ++y)
    for (int x = 0; x < 120; ++x)
      for (int c = 0; c < 3; ++c) s.image.at(x, y, c) = x < 60 ? 40 : 200;
  for (int row = 0; row < 8; ++row)
    for (int k = 0; k < 17; ++k) {
      const float u = 3.5f + 7 * k, v = 5.5f + 10 * row;
      s.points.push_back({u, v, u < 60 ? 5.0f : 20.0f, false});
    }
  return s;
}

TEST(DenseDepth, EdgeAwareFillSnapsTheDepthEdgeToTheImageEdge) {
  const EdgeScene s = MakeEdgeScene();
  const PinholeCamera cam = SmallCamera(120, 80);
  DenseDepthOptions opt;
  opt.max_fill_px = 12;
  opt.nearest_within_px = 0;  // colour everywhere (by default the nearest point decides within 4 px)
  const DepthMap dense = DenseDepth(s.points, s.image, cam, Rigid3d(), {}, opt);
  opt.edge_aware = false;
  const DepthMap nn = DenseDepth(s.points, ImageU8(), cam, Rigid3d(), {}, opt);
  for (int y = 0; y < 80; ++y) {
    for (int x = 40; x < 80; ++x) {
      ASSERT_NEAR(dense.depth.at(x, y), x < 60 ? 5.0f : 20.0f, 1e-4f) << x << "," << y;
      // The baseline: the edge halfway between the points that bound it (u = 59.5 and 66.5).
      ASSERT_NEAR(nn.depth.at(x, y), x < 63 ? 5.0f : 20.0f, 1e-4f) << x << "," << y;
    }
  }
  // Confidence: 1 at a point, 1 - 0.6 r / max_fill_px in between.
  EXPECT_NEAR(dense.confidence.at(3, 5), 1.0f, 1e-6f);
  EXPECT_NEAR(dense.confidence.at(3, 10), 1.0f - 0.6f * 5.0f / 12, 1e-5f);
}

TEST(DenseDepth, HiddenPointsSeenPastAnEdgeAreDropped) {
  // A background point 2 px from a near point is one the LiDAR saw past the occluder's edge; a point at a
  // similar depth, or far enough away, stays.
  const std::vector<ProjectedPoint> pts = {{50.5f, 40.5f, 5.0f, false}, {52.5f, 40.5f, 20.0f, false},
                                           {52.5f, 42.5f, 5.2f, false}, {56.5f, 40.5f, 20.0f, false}};
  const auto kept = FilterHiddenPoints(pts, 120, 80);
  ASSERT_EQ(kept.size(), 3u);
  EXPECT_EQ(kept[0].depth, 5.0f);
  EXPECT_EQ(kept[1].depth, 5.2f);
  EXPECT_EQ(kept[2].u, 56.5f);
}

TEST(DenseDepth, BoxAndRoadPriorsFillWhereTheLidarIsSilent) {
  // Camera 1.5 m above a flat road (ego z = 0), looking along ego +x; a 4 x 2 x 1.5 m box 10 m ahead.
  const PinholeCamera cam = SmallCamera(200, 120);
  Eigen::Matrix3d R_ego_cam;
  R_ego_cam << 0, 0, 1, -1, 0, 0, 0, -1, 0;  // camera x right = ego -y, y down = ego -z, z forward = ego x
  const Rigid3d T_ego_cam(R_ego_cam, Eigen::Vector3d(0, 0, 1.5));
  const Rigid3d T_cam_ego = T_ego_cam.Inverse();
  DepthPriors priors;
  Box3 box;
  box.T_frame_box = Rigid3d::FromYaw(0, Eigen::Vector3d(12, 0, 0.75));
  box.size = Eigen::Vector3d(4, 2, 1.5);
  priors.boxes_ego = {box};
  const PlaneSurface road;
  priors.surface = &road;
  priors.T_world_ego = Rigid3d::FromYaw(0.3, Eigen::Vector3d(100, -50, 0));  // any world pose of a flat road
  const DepthMap d = DenseDepth({}, ImageU8(), cam, T_cam_ego, priors, [] {
    DenseDepthOptions o;
    o.edge_aware = false;
    return o;
  }());
  // Box face at x = 10 m; the camera's principal ray passes 0.75 m above the box's centre height: inside.
  EXPECT_NEAR(d.depth.at(100, 60), 10.0f, 1e-3f);
  EXPECT_NEAR(d.confidence.at(100, 60), 0.5f, 1e-6f);
  EXPECT_EQ(d.ground.at(100, 60), 0) << "a box is not road";
  // Road: depth = f h / (v - cy) along the ray through pixel centre (v = y + 0.5).
  for (int y : {75, 90, 119}) {
    const double v = y + 0.5;
    EXPECT_NEAR(d.depth.at(20, y), 100 * 1.5 / (v - 60), 1e-3) << y;
    EXPECT_NEAR(d.confidence.at(20, y), 0.35f, 1e-6f);
    EXPECT_EQ(d.ground.at(20, y), 1) << y;
  }
  // Sky: nothing.
  EXPECT_EQ(d.depth.at(20, 10), kInf);
  EXPECT_EQ(d.confidence.at(20, 10), 0.0f);
}

// `part` (a DenseDepth over a region) equals `whole` (over the image) where `inside`, and is empty elsewhere.
template <typename Inside>
void ExpectWholeInsideEmptyOutside(const DepthMap& part, const DepthMap& whole, const Inside& inside) {
  for (int y = 0; y < whole.depth.height(); ++y)
    for (int x = 0; x < whole.depth.width(); ++x) {
      if (inside(x, y)) {
        ASSERT_EQ(part.depth.at(x, y), whole.depth.at(x, y)) << x << "," << y;
        ASSERT_EQ(part.confidence.at(x, y), whole.confidence.at(x, y)) << x << "," << y;
        ASSERT_EQ(part.ground.at(x, y), whole.ground.at(x, y)) << x << "," << y;
      } else {
        ASSERT_EQ(part.depth.at(x, y), kInf) << x << "," << y;
        ASSERT_EQ(part.confidence.at(x, y), 0.0f) << x << "," << y;
      }
    }
}

TEST(DenseDepth, ARectangleGivesTheWholeImagesValuesInsideIt) {
  EdgeScene s = MakeEdgeScene();
  for (auto& p : s.points) p.ground = p.v > 40;
  const PinholeCamera cam = SmallCamera(120, 80);
  DepthPriors priors;
  const PlaneSurface road(Eigen::Vector3d(0, -1, 0), 3);  // some prior, so that its fill is compared too
  priors.surface = &road;
  DenseDepthOptions o;
  const DepthMap whole = DenseDepth(s.points, s.image, cam, Rigid3d(), priors, o);
  o.x0 = 50, o.y0 = 30, o.x1 = 75, o.y1 = 80;
  const DepthMap part = DenseDepth(s.points, s.image, cam, Rigid3d(), priors, o);
  ExpectWholeInsideEmptyOutside(part, whole, [](int x, int y) { return x >= 50 && x < 75 && y >= 30; });
}

TEST(DenseDepth, RectanglesGiveTheWholeImagesValuesInTheirUnion) {
  EdgeScene s = MakeEdgeScene();
  for (auto& p : s.points) p.ground = p.v > 40;
  const PinholeCamera cam = SmallCamera(120, 80);
  DepthPriors priors;
  const PlaneSurface road(Eigen::Vector3d(0, -1, 0), 3);
  priors.surface = &road;
  DenseDepthOptions o;
  const DepthMap whole = DenseDepth(s.points, s.image, cam, Rigid3d(), priors, o);
  // Two apart, two overlapping, one partly off the image.
  o.rects = {{5, 5, 20, 25}, {50, 30, 75, 60}, {60, 50, 90, 70}, {110, 70, 140, 95}};
  const DepthMap part = DenseDepth(s.points, s.image, cam, Rigid3d(), priors, o);
  const auto in = [&](int x, int y) {
    for (const auto& r : o.rects)
      if (x >= r[0] && x < r[2] && y >= r[1] && y < r[3]) return true;
    return false;
  };
  ExpectWholeInsideEmptyOutside(part, whole, in);
}

TEST(DenseDepth, MarksWhereTheDepthIsTheRoads) {
  // Ground points in the lower half, an obstacle's points in the upper half: the map says which is which, from
  // the nearest point and from the winning cluster alike; the road prior counts as road, a box as not.
  EdgeScene s = MakeEdgeScene();
  for (auto& p : s.points) p.ground = p.v > 40;
  const PinholeCamera cam = SmallCamera(120, 80);
  for (const bool edge_aware : {true, false}) {
    DenseDepthOptions o;
    o.edge_aware = edge_aware;
    const DepthMap d = DenseDepth(s.points, s.image, cam, Rigid3d(), {}, o);
    ASSERT_EQ(d.ground.width(), 120);
    EXPECT_EQ(d.ground.at(10, 5), 0) << edge_aware;
    EXPECT_EQ(d.ground.at(10, 75), 1) << edge_aware;
    EXPECT_EQ(d.ground.at(100, 68), 1) << edge_aware;  // between rings: interpolated inside the ground cluster
    EXPECT_EQ(d.ground.at(100, 20), 0) << edge_aware;
  }
}

TEST(VisibleMask, OccluderEdgeAcrossAPixelGivesFractionalVisibility) {
  // Occluder (5 m, dark) left of x = 60.5: pixel column 60 is half occluder, half background in the photo.
  // The object at 10 m covers everything; its visible mask must be 0 left, 1 right and ~0.5 on column 60.
  ImageU8 image(120, 80, 3);
  for (int y = 0; y < 80; ++y)
    for (int x = 0; x < 120; ++x)
      for (int c = 0; c < 3; ++c) image.at(x, y, c) = x < 60 ? 40 : (x == 60 ? 120 : 200);
  DepthMap scene{ImageF(120, 80, 1, 30.0f), ImageF(120, 80, 1, 1.0f), ImageU8()};
  for (int y = 0; y < 80; ++y)
    for (int x = 0; x < 61; ++x) scene.depth.at(x, y) = 5.0f;  // the densified map says column 60 is occluder
  ImageF object_depth(120, 80, 1, kInf), coverage(120, 80, 1, 0.0f);
  for (int y = 20; y < 60; ++y)
    for (int x = 30; x < 90; ++x) object_depth.at(x, y) = 10.0f, coverage.at(x, y) = 1.0f;
  const ImageF hard = DenseVisibility(scene, ImageU8(), object_depth);
  EXPECT_EQ(hard.at(60, 40), 0.0f);
  EXPECT_EQ(hard.at(61, 40), 1.0f);
  const ImageF mask = VisibleMask(scene, image, object_depth, coverage);
  for (int y = 20; y < 60; ++y) {
    EXPECT_EQ(mask.at(55, y), 0.0f) << y;
    EXPECT_NEAR(mask.at(60, y), 0.5f, 0.1f) << y;
    EXPECT_EQ(mask.at(66, y), 1.0f) << y;
    EXPECT_GT(mask.at(61, y), 0.9f) << y;
    EXPECT_LT(mask.at(59, y), 0.1f) << y;
  }
  EXPECT_EQ(mask.at(10, 10), 0.0f);  // off the object
  // Far real geometry never hides the object.
  DepthMap far{ImageF(120, 80, 1, 30.0f), ImageF(120, 80, 1, 1.0f), ImageU8()};
  const ImageF all = VisibleMask(far, image, object_depth, coverage);
  EXPECT_EQ(all.vector(), coverage.vector());
}

TEST(VisibleMask, TheRoadHidesNothingUnlessAsked) {
  // A road whose depth map is 0.5 m short of an object standing on it 15 m away (5 cm of height error at a
  // grazing view): the object keeps its feet. Non-road geometry at the same depth hides it.
  DepthMap scene{ImageF(120, 80, 1, 14.5f), ImageF(120, 80, 1, 1.0f), ImageU8(120, 80, 1, 0)};
  for (int y = 40; y < 80; ++y)
    for (int x = 0; x < 120; ++x) scene.ground.at(x, y) = 1;
  ImageF object_depth(120, 80, 1, kInf);
  for (int y = 20; y < 60; ++y)
    for (int x = 30; x < 90; ++x) object_depth.at(x, y) = 15.0f;
  VisibleMaskOptions o;
  o.tol_abs = 0.3;
  o.tol_rel = 0.01;
  const ImageF vis = DenseVisibility(scene, ImageU8(), object_depth, o);
  EXPECT_EQ(vis.at(50, 30), 0.0f) << "a real obstacle 0.5 m in front hides";
  EXPECT_EQ(vis.at(50, 50), 1.0f) << "the road does not";
  o.ground_occludes = true;
  EXPECT_EQ(DenseVisibility(scene, ImageU8(), object_depth, o).at(50, 50), 0.0f);
}

// ---- Measurements on real frames ------------------------------------------------------------------------------

struct Errors {
  double abs = 0, rel = 0, abs_edge = 0, rel_edge = 0;
  size_t n = 0, n_edge = 0, missing = 0;
  double Mae() const { return abs / n; }
  double Rel() const { return rel / n; }
  double MaeEdge() const { return abs_edge / n_edge; }
  double RelEdge() const { return rel_edge / n_edge; }
};

struct Alignment {
  size_t evaluable = 0, aligned = 0;
  double Fraction() const { return evaluable ? double(aligned) / evaluable : 0; }
};

struct Scores {
  Errors dense, nn;
  Alignment dense_edges, nn_edges;
};

// The fraction of a pixel window's depth spread: max / min of the visible points within 8 px (Chebyshev).
std::vector<float> WindowRatio(const std::vector<ProjectedPoint>& pts, int w, int h) {
  std::vector<float> lo(size_t(w) * h, kInf), hi(size_t(w) * h, 0.0f), out(size_t(w) * h, 1.0f);
  for (const auto& p : pts) {
    const int px = int(p.u), py = int(p.v);
    for (int y = std::max(0, py - 8); y <= std::min(h - 1, py + 8); ++y)
      for (int x = std::max(0, px - 8); x <= std::min(w - 1, px + 8); ++x) {
        lo[size_t(y) * w + x] = std::min(lo[size_t(y) * w + x], p.depth);
        hi[size_t(y) * w + x] = std::max(hi[size_t(y) * w + x], p.depth);
      }
  }
  for (size_t i = 0; i < out.size(); ++i)
    if (std::isfinite(lo[i])) out[i] = hi[i] / lo[i];
  return out;
}

void ScoreHoldout(const std::vector<ProjectedPoint>& visible, const std::vector<ProjectedPoint>& train,
                  const std::vector<ProjectedPoint>& test, const ImageU8& image, const PinholeCamera& cam,
                  const Rigid3d& T_cam_ego, Scores* s) {
  const std::vector<float> ratio = WindowRatio(visible, cam.width, cam.height);
  DenseDepthOptions opt;
  const DepthMap dense = DenseDepth(train, image, cam, T_cam_ego, {}, opt);
  opt.edge_aware = false;
  const DepthMap nn = DenseDepth(train, image, cam, T_cam_ego, {}, opt);
  for (const auto& p : test) {
    const int x = int(p.u), y = int(p.v);
    const bool edge = ratio[size_t(y) * cam.width + x] > 1.2f;
    for (auto [map, e] : {std::pair{&dense, &s->dense}, std::pair{&nn, &s->nn}}) {
      const float d = map->depth.at(x, y);
      if (!std::isfinite(d)) {
        ++e->missing;
        continue;
      }
      const double err = std::abs(d - p.depth);
      e->abs += err, e->rel += err / p.depth, ++e->n;
      if (edge) e->abs_edge += err, e->rel_edge += err / p.depth, ++e->n_edge;
    }
  }
}

// Convex hull (Andrew's monotone chain), counter-clockwise in image coordinates (y down: clockwise on screen).
std::vector<Eigen::Vector2d> Hull(std::vector<Eigen::Vector2d> p) {
  std::sort(p.begin(), p.end(), [](const auto& a, const auto& b) { return a.x() < b.x() || (a.x() == b.x() && a.y() < b.y()); });
  std::vector<Eigen::Vector2d> h(2 * p.size());
  size_t k = 0;
  const auto cross = [](const Eigen::Vector2d& o, const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
    return (a - o).x() * (b - o).y() - (a - o).y() * (b - o).x();
  };
  for (size_t i = 0; i < p.size(); ++i) {
    while (k >= 2 && cross(h[k - 2], h[k - 1], p[i]) <= 0) --k;
    h[k++] = p[i];
  }
  for (size_t i = p.size() - 1, t = k + 1; i-- > 0;) {
    while (k >= t && cross(h[k - 2], h[k - 1], p[i]) <= 0) --k;
    h[k++] = p[i];
  }
  h.resize(k - 1);
  return h;
}

// Samples along the silhouettes of the annotated boxes: evaluable where the inside (6 px in) lies at the box's
// depth and the outside (6 px out) clearly behind it; aligned where the depth crosses the midpoint within 2 px
// of the silhouette.
void ScoreEdges(const DepthMap& dense, const DepthMap& nn, const std::vector<Annotation>& boxes, const PinholeCamera& cam,
                const Rigid3d& T_cam_ego, Alignment* a_dense, Alignment* a_nn) {
  for (const auto& ann : boxes) {
    std::vector<Eigen::Vector2d> uv;
    double zmin = 1e9, zmax = -1e9;
    bool ok = true;
    for (const auto& c : ann.box.Corners()) {
      const Eigen::Vector3d pc = T_cam_ego * c;
      const auto p = cam.Project(pc, 1.0);
      if (!p) { ok = false; break; }
      uv.push_back(*p);
      zmin = std::min(zmin, pc.z()), zmax = std::max(zmax, pc.z());
    }
    if (!ok) continue;
    const auto hull = Hull(uv);
    for (size_t i = 0; i < hull.size(); ++i) {
      const Eigen::Vector2d p0 = hull[i], p1 = hull[(i + 1) % hull.size()];
      const double len = (p1 - p0).norm();
      if (len < 1) continue;
      const Eigen::Vector2d t = (p1 - p0) / len;
      Eigen::Vector2d n(t.y(), -t.x());  // outward for this orientation; checked below against the centroid
      Eigen::Vector2d centroid = Eigen::Vector2d::Zero();
      for (const auto& q : hull) centroid += q / double(hull.size());
      if (n.dot(p0 - centroid) < 0) n = -n;
      for (double s = 1.5; s < len - 1.5; s += 3) {
        const Eigen::Vector2d q = p0 + s * t;
        const auto depth_at = [&](const DepthMap& map, double o) {
          const Eigen::Vector2d r = q + o * n;
          const int x = int(std::floor(r.x())), y = int(std::floor(r.y()));
          if (x < 0 || y < 0 || x >= cam.width || y >= cam.height) return std::numeric_limits<float>::quiet_NaN();
          return map.depth.at(x, y);
        };
        // Evaluable in both maps, so both are scored on the same samples.
        bool evaluable = true;
        for (const DepthMap* map : {&dense, &nn}) {
          const float din = depth_at(*map, -6), dout = depth_at(*map, 6);
          evaluable = evaluable && std::isfinite(din) && std::isfinite(dout) && din >= zmin - 1 && din <= zmax + 1 &&
                      dout >= zmax + 2;
        }
        if (!evaluable) continue;
        for (auto [map, a] : {std::pair{&dense, a_dense}, std::pair{&nn, a_nn}}) {
          ++a->evaluable;
          const float mid = 0.5f * (depth_at(*map, -6) + depth_at(*map, 6));
          for (int o = -2; o < 2; ++o)
            if ((depth_at(*map, o) <= mid) != (depth_at(*map, o + 1) <= mid)) {
              ++a->aligned;
              break;
            }
        }
      }
    }
  }
}

// Every camera of every frame: 20% of the visible projected points (every 5th) held out, densified from the
// rest; edge alignment on the map densified from all points. LiDAR and image only: no priors (the box prior
// would make the alignment trivial).
Scores Measure(const Log& log, size_t max_frames) {
  Scores s;
  for (size_t f = 0; f < std::min(max_frames, log.frames.size()); ++f) {
    const Frame& frame = log.frames[f];
    const PointCloud sweep = ReadLidar(*frame.lidar);
    std::vector<Eigen::Vector3d> pts(sweep.size());
    for (size_t i = 0; i < sweep.size(); ++i) pts[i] = frame.lidar->T_ego_lidar * sweep.xyz(i).cast<double>();
    std::vector<Box3> boxes;
    for (const auto& a : frame.annotations) boxes.push_back(a.box);
    GroundOptions gopt;
    gopt.sensor_xy = frame.lidar->T_ego_lidar.translation.head<2>();
    const GroundModel ground = GroundModel::Estimate(pts, boxes, gopt);
    std::vector<uint8_t> is_ground(pts.size(), 0);
    for (int i : ground.ground_indices()) is_ground[size_t(i)] = 1;
    for (const auto& cam : frame.cameras) {
      const Rigid3d T_cam_ego = cam.T_ego_cam.Inverse();
      const ImageU8 image = ReadImage(cam.image_path, 3);
      const auto projected = ProjectPoints(pts, is_ground, cam.intrinsics, T_cam_ego);
      const auto visible = FilterHiddenPoints(projected, cam.intrinsics.width, cam.intrinsics.height);
      std::vector<ProjectedPoint> train, test;
      for (size_t i = 0; i < visible.size(); ++i) (i % 5 == 2 ? test : train).push_back(visible[i]);
      ScoreHoldout(visible, train, test, image, cam.intrinsics, T_cam_ego, &s);
      DenseDepthOptions opt;
      const DepthMap dense = DenseDepth(projected, image, cam.intrinsics, T_cam_ego, {}, opt);
      opt.edge_aware = false;
      const DepthMap nn = DenseDepth(projected, image, cam.intrinsics, T_cam_ego, {}, opt);
      ScoreEdges(dense, nn, frame.annotations, cam.intrinsics, T_cam_ego, &s.dense_edges, &s.nn_edges);
    }
  }
  std::printf("held out %zu points (%zu near depth edges, %zu beyond reach)\n", s.dense.n, s.dense.n_edge, s.dense.missing);
  std::printf("  edge-aware: MAE %.3f m, rel %.4f; near edges MAE %.3f m, rel %.4f\n", s.dense.Mae(), s.dense.Rel(),
              s.dense.MaeEdge(), s.dense.RelEdge());
  std::printf("  nearest   : MAE %.3f m, rel %.4f; near edges MAE %.3f m, rel %.4f\n", s.nn.Mae(), s.nn.Rel(), s.nn.MaeEdge(),
              s.nn.RelEdge());
  std::printf("box silhouette samples %zu: depth edge within 2 px: edge-aware %.3f, nearest %.3f\n", s.dense_edges.evaluable,
              s.dense_edges.Fraction(), s.nn_edges.Fraction());
  return s;
}

TEST(DenseDepthMeasured, NuScenesKeyframeSixCameras) {
  const Log log = OpenLog(testing::RepoData("driving/nuscenes-scene0061-kf0/mmdet3d_info/n015-2018-07-24-11-22-45+0800.json"));
  ASSERT_EQ(log.frames.size(), 1u);
  ASSERT_EQ(log.frames[0].cameras.size(), 6u);
  const Scores s = Measure(log, 1);
  // Measured (docs/occlusion.md): 4391 held out, 142 near edges; rel 0.0343 (nearest 0.0309), near edges
  // 0.426 (nearest 0.468); silhouette samples 273, within 2 px 0.374 (nearest 0.333).
  ASSERT_GT(s.dense.n, 4000u);
  ASSERT_GT(s.dense.n_edge, 120u);
  ASSERT_GT(s.dense_edges.evaluable, 200u);
  EXPECT_LT(s.dense.Rel(), 0.038);
  EXPECT_LT(s.dense.RelEdge(), 0.45);
  EXPECT_LT(s.dense.RelEdge(), 0.95 * s.nn.RelEdge());
  EXPECT_GT(s.dense_edges.Fraction(), 0.35);
  EXPECT_GT(s.dense_edges.Fraction(), s.nn_edges.Fraction() + 0.02);
}

TEST(DenseDepthMeasured, KittiFrames) {
  SD_REQUIRE_SHARED(root, "driving/kitti-object-openpcdet");
  const Log log = OpenLog(root);
  ASSERT_GE(log.frames.size(), 5u);
  const Scores s = Measure(log, 5);
  // Measured: 18404 held out, 3885 near edges; rel 0.0077 (nearest 0.0076), near edges 0.0118 (nearest
  // 0.0112); silhouette samples 94, within 2 px 0.489 (nearest 0.489). A 64-beam sweep is dense enough that
  // nearest-neighbour fill is as good: the edge-aware fill must not be worse by more than 10%.
  ASSERT_GT(s.dense.n, 15000u);
  ASSERT_GT(s.dense_edges.evaluable, 60u);
  EXPECT_LT(s.dense.Rel(), 0.009);
  EXPECT_LT(s.dense.RelEdge(), 0.014);
  EXPECT_LT(s.dense.RelEdge(), 1.1 * s.nn.RelEdge());
  EXPECT_GT(s.dense_edges.Fraction(), 0.45);
  EXPECT_GT(s.dense_edges.Fraction(), s.nn_edges.Fraction() - 0.03);
}

}  // namespace
}  // namespace sd
