#include "geometry/visual_hull.h"

#include <gtest/gtest.h>

#include <chrono>
#include <cmath>
#include <functional>

#include "core/error.h"
#include "geometry/topology.h"

namespace sd::geometry {
namespace {

constexpr double kPi = 3.14159265358979323846;
constexpr double kDistance = 4.0;  // frames the unit sphere in a 30 deg field of view: asin(1/4) = 14.5 deg
constexpr int kSize = 320;

struct Orbit {
  PinholeCamera camera;
  Rigid3d T_cam_world;
  Eigen::Vector3d centre;  // camera centre, world
};

// Looks at the origin from (azimuth, elevation) about +z, +z up in the image.
Orbit OrbitCamera(double azimuth_deg, double elevation_deg) {
  const double az = azimuth_deg * kPi / 180, el = elevation_deg * kPi / 180;
  Orbit o;
  o.centre = kDistance * Eigen::Vector3d(std::cos(el) * std::cos(az), std::cos(el) * std::sin(az), std::sin(el));
  const Eigen::Vector3d forward = -o.centre.normalized();
  const Eigen::Vector3d right = forward.cross(Eigen::Vector3d::UnitZ()).normalized();
  const Eigen::Vector3d down = forward.cross(right);
  Eigen::Matrix3d R_world_cam;
  R_world_cam << right, down, forward;
  o.T_cam_world = Rigid3d(R_world_cam.transpose(), -R_world_cam.transpose() * o.centre);
  const double f = 0.5 * kSize / std::tan(15.0 * kPi / 180);  // 30 deg vertical field of view
  o.camera.width = o.camera.height = kSize;
  o.camera.fx = o.camera.fy = f;
  o.camera.cx = o.camera.cy = 0.5 * kSize;
  return o;
}

// The Zero123++ v1.2 rig: azimuth 30, 90, ..., 330 deg, elevation +20 / -10 alternating.
std::vector<Orbit> Rig() {
  std::vector<Orbit> rig;
  for (int v = 0; v < 6; ++v) rig.push_back(OrbitCamera(30 + 60 * v, v % 2 == 0 ? 20 : -10));
  return rig;
}

// Binary masks: a pixel is object when the ray through its centre hits the shape.
using HitTest = std::function<bool(const Eigen::Vector3d& origin, const Eigen::Vector3d& direction)>;
std::vector<SilhouetteView> RenderMasks(const HitTest& hit, const std::vector<Orbit>& orbits = Rig()) {
  std::vector<SilhouetteView> views;
  for (const Orbit& o : orbits) {
    SilhouetteView v;
    v.camera = o.camera;
    v.T_cam_world = o.T_cam_world;
    v.mask = ImageF(kSize, kSize, 1);
    const Eigen::Matrix3d R_world_cam = o.T_cam_world.Rotation().transpose();
    for (int y = 0; y < kSize; ++y)
      for (int x = 0; x < kSize; ++x) {
        const Eigen::Vector3d d = R_world_cam * o.camera.RayDirection(Eigen::Vector2d(x + 0.5, y + 0.5));
        v.mask.at(x, y) = hit(o.centre, d) ? 1.0f : 0.0f;
      }
    views.push_back(std::move(v));
  }
  return views;
}

bool HitsSphere(const Eigen::Vector3d& o, const Eigen::Vector3d& d, double r) {
  const double t = -o.dot(d);  // closest approach (d is unit)
  return t > 0 && (o + t * d).squaredNorm() < r * r;
}

bool HitsBox(const Eigen::Vector3d& o, const Eigen::Vector3d& d, const Eigen::Vector3d& lo, const Eigen::Vector3d& hi) {
  double t0 = 0, t1 = 1e30;
  for (int a = 0; a < 3; ++a) {
    if (std::abs(d[a]) < 1e-15) {
      if (o[a] < lo[a] || o[a] > hi[a]) return false;
      continue;
    }
    double ta = (lo[a] - o[a]) / d[a], tb = (hi[a] - o[a]) / d[a];
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta), t1 = std::min(t1, tb);
  }
  return t0 < t1;
}

bool HitsCube(const Eigen::Vector3d& o, const Eigen::Vector3d& d, double half) {
  return HitsBox(o, d, Eigen::Vector3d::Constant(-half), Eigen::Vector3d::Constant(half));
}

// Reference volume of the exact visual hull, by counting the centres of an n^3 lattice over [-half, half]^3:
// a point is in when, in every view whose image it lands in, the ray through it hits the shape.
// With `all_views`, only points that all views see count: the rig's frusta cover the ball of radius
// 4 sin(15 deg) = 1.035, and beyond it (the corners of [-1, 1]^3) lie islands that only 1-5 views see and
// cannot carve. For the unit sphere they hold 0.46 units of volume at radii 1.07-1.74, detached from the
// body, and VisualHull drops them with its largest-component rule.
double ExactHullVolume(const HitTest& hit, double half, int n, bool all_views) {
  const std::vector<Orbit> rig = Rig();
  const double cell = 2 * half / n;
  std::vector<int> inside_per_slice(n, 0);
  for (int k = 0; k < n; ++k) {
    for (int j = 0; j < n; ++j) {
      for (int i = 0; i < n; ++i) {
        const Eigen::Vector3d p = Eigen::Vector3d(i + 0.5, j + 0.5, k + 0.5) * cell - Eigen::Vector3d::Constant(half);
        bool in = false;
        for (const Orbit& o : rig) {
          const auto uv = o.camera.Project(o.T_cam_world * p);
          if (!uv || !o.camera.InImage(*uv)) {
            if (!all_views) continue;
            in = false;
            break;
          }
          in = hit(o.centre, (p - o.centre).normalized());
          if (!in) break;
        }
        inside_per_slice[k] += in ? 1 : 0;
      }
    }
  }
  double count = 0;
  for (int c : inside_per_slice) count += c;
  return count * cell * cell * cell;
}

double SignedVolume(const TriangleMesh& m) {
  double v = 0;
  for (const auto& f : m.faces) {
    v += m.positions[f[0]].cast<double>().dot(m.positions[f[1]].cast<double>().cross(m.positions[f[2]].cast<double>())) / 6;
  }
  return v;
}

void ExpectClosedGenusZero(const TriangleMesh& m) {
  const TopologyReport t = AnalyzeTopology(int(m.NumVertices()), m.faces);
  EXPECT_TRUE(t.IsWatertight()) << t.Describe();
  EXPECT_EQ(t.components, 1);
  EXPECT_EQ(t.euler_characteristic, 2);
  EXPECT_EQ(t.unreferenced_vertices, 0);
}

TEST(VisualHull, SphereHullContainsTheSphereAndIsTight) {
  const std::vector<SilhouetteView> views = RenderMasks([](auto& o, auto& d) { return HitsSphere(o, d, 1.0); });
  VisualHullOptions options;  // 96 voxels over [-1, 1]^3
  const auto start = std::chrono::steady_clock::now();
  const TriangleMesh hull = VisualHull(views, options);
  const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
  std::printf("VisualHull 96^3, 6 views of %dx%d: %.3f s, %zu faces\n", kSize, kSize, seconds, hull.NumFaces());
  EXPECT_EQ(hull.Validate(), "");
  ExpectClosedGenusZero(hull);

  // Contains the sphere: no hull vertex lies inside it by more than a small fraction of a voxel.
  const double voxel = 2.0 / 96;
  double min_radius = 1e9, max_radius = 0;
  for (const auto& p : hull.positions) {
    min_radius = std::min(min_radius, double(p.norm()));
    max_radius = std::max(max_radius, double(p.norm()));
  }
  std::printf("hull vertex radii [%.4f, %.4f]\n", min_radius, max_radius);
  EXPECT_GT(min_radius, 1 - 0.25 * voxel);

  // Six views leave the hull of a sphere bigger than the sphere: the exact hull's body (clipped, like the
  // mesh, half a voxel outside the bounds) is 1.03 times the sphere; the mesh matches it within 0.5%.
  const double sphere = 4.0 / 3.0 * kPi;
  const double volume = SignedVolume(hull);
  const double exact = ExactHullVolume([](auto& o, auto& d) { return HitsSphere(o, d, 1.0); }, 1 + 0.5 * voxel, 200, true);
  std::printf("hull / sphere volume: %.4f, exact hull / sphere: %.4f\n", volume / sphere, exact / sphere);
  EXPECT_GT(volume / sphere, 1.0);
  EXPECT_LT(volume / sphere, 1.05);
  EXPECT_NEAR(volume / exact, 1.0, 0.005);

  // Tight: in every view the hull's outline is the sphere's. Angular radius about the view axis of each
  // vertex <= the silhouette's (asin(1/4)) plus a pixel, and some vertex reaches it.
  for (const Orbit& o : Rig()) {
    double widest = 0;
    for (const auto& p : hull.positions) {
      const Eigen::Vector3d ray = p.cast<double>() - o.centre;
      widest = std::max(widest, std::acos(std::clamp(ray.normalized().dot(-o.centre.normalized()), -1.0, 1.0)));
    }
    const double pixel = 1.0 / o.camera.fy;  // radians, near the axis
    EXPECT_NEAR(widest, std::asin(1 / kDistance), 1.5 * pixel);
  }
}

TEST(VisualHull, CubeHullContainsTheCube) {
  const double half = 0.5;
  const std::vector<SilhouetteView> views = RenderMasks([&](auto& o, auto& d) { return HitsCube(o, d, half); });
  const TriangleMesh hull = VisualHull(views, {});
  ExpectClosedGenusZero(hull);
  const double voxel = 2.0 / 96;
  double inner = 1e9;
  for (const auto& p : hull.positions) inner = std::min(inner, double(p.cwiseAbs().maxCoeff()));
  EXPECT_GT(inner, half - 0.25 * voxel);
  // The hull keeps wedges along the cube's edges, which no view sees edge-on: it is ~1.29 times the cube;
  // the mesh matches the exact hull within 1% (the hull's own edges are where voxels round it).
  const double volume = SignedVolume(hull);
  const double exact = ExactHullVolume([&](auto& o, auto& d) { return HitsCube(o, d, half); }, 1 + 0.5 * voxel, 200, false);
  std::printf("hull / cube volume: %.4f, exact hull / cube: %.4f\n", volume, exact);
  EXPECT_GT(volume, 1.0);
  EXPECT_LT(volume, 1.35);
  EXPECT_NEAR(volume / exact, 1.0, 0.01);
}

TEST(VisualHull, CustomBoundsAndResolution) {
  const std::vector<SilhouetteView> views = RenderMasks([](auto& o, auto& d) { return HitsSphere(o, d, 0.5); });
  VisualHullOptions options;
  options.resolution = 48;
  options.bounds.min = Eigen::Vector3f(-0.6f, -0.6f, -0.6f);
  options.bounds.max = Eigen::Vector3f(0.6f, 0.6f, 0.6f);
  const TriangleMesh hull = VisualHull(views, options);
  ExpectClosedGenusZero(hull);
  const double ratio = SignedVolume(hull) / (4.0 / 3.0 * kPi * 0.125);
  EXPECT_GT(ratio, 1.0);
  EXPECT_LT(ratio, 1.2);
  // Bounds that cut the object clip the hull (closed, flat where cut) half a voxel beyond them, where the
  // field drops from the last node inside to the forced-outside border layer.
  options.bounds.min = Eigen::Vector3f(-0.6f, -0.6f, 0.0f);
  const TriangleMesh clipped = VisualHull(views, options);
  ExpectClosedGenusZero(clipped);
  const float voxel = 1.2f / 48;
  float lowest = 1;
  for (const auto& p : clipped.positions) lowest = std::min(lowest, p.z());
  EXPECT_NEAR(lowest, -0.5f * voxel, 1e-5f);
}

TEST(VisualHull, ToleratedViewsSurviveOneMaskWithABiteOutOfIt) {
  std::vector<SilhouetteView> views = RenderMasks([](auto& o, auto& d) { return HitsSphere(o, d, 0.5); });
  // One view's mask loses its left half, as a segmenter sometimes bites into an object.
  for (int y = 0; y < kSize; ++y)
    for (int x = 0; x < kSize / 2; ++x) views[2].mask.at(x, y) = 0;
  VisualHullOptions options;
  const double full = SignedVolume(VisualHull(RenderMasks([](auto& o, auto& d) { return HitsSphere(o, d, 0.5); }), options));
  const double bitten = SignedVolume(VisualHull(views, options));
  options.tolerated_outside_views = 1;
  const TriangleMesh tolerant = VisualHull(views, options);
  ExpectClosedGenusZero(tolerant);
  std::printf("volume: all masks good %.4f, one bitten %.4f, one bitten and tolerated %.4f\n", full, bitten,
              SignedVolume(tolerant));
  EXPECT_LT(bitten, 0.75 * full);
  // Tolerating one view leaves each node to the other five: at least the full hull (5 views carve less).
  EXPECT_GT(SignedVolume(tolerant), 0.99 * full);
  EXPECT_LT(SignedVolume(tolerant), 1.3 * full);
}

TEST(VisualHull, FreeSegmentsCarveWhatNoSilhouetteShows) {
  // A cube's hull from the rig; then beams from above that stop 0.2 below its top face carve a pit 0.2 deep
  // into the middle of the top, which no silhouette of the rig can show.
  const double half = 0.5;
  const std::vector<SilhouetteView> views = RenderMasks([&](auto& o, auto& d) { return HitsCube(o, d, half); });
  VisualHullOptions options;
  const TriangleMesh plain = VisualHull(views, options);
  for (float x = -0.2f; x <= 0.2f; x += 0.01f)
    for (float y = -0.2f; y <= 0.2f; y += 0.01f) options.free_segments.push_back({{x, y, 3.0f}, {x, y, 0.3f}});
  const TriangleMesh carved = VisualHull(views, options);
  ExpectClosedGenusZero(carved);
  const double pit = SignedVolume(plain) - SignedVolume(carved);
  // The pit holds the 0.4 x 0.4 x 0.2 = 0.032 the beams cross inside the cube, plus the part of the hull's
  // roof above the top face that the rig's low views (20 deg) cannot carve, plus up to a voxel around it.
  std::printf("pit volume %.4f (0.032 inside the cube)\n", pit);
  EXPECT_GT(pit, 0.031);
  EXPECT_LT(pit, 0.07);
  // The pit's floor sits at the beams' ends: no vertex above z = 0.3 - a voxel within the pit's footprint.
  const double voxel = 2.0 / 96;
  for (const auto& p : carved.positions) {
    if (std::abs(p.x()) < 0.15f && std::abs(p.y()) < 0.15f) {
      EXPECT_LT(p.z(), 0.3 + voxel) << p.transpose();
    }
  }
}

// Sparse beams (one every three voxels) that stop just under a cube's top face: each sets the nodes it passes to 0,
// which left alone would pit the roof voxel by voxel; smoothed, the roof stays a plane.
TEST(VisualHull, BeamsCarveASmoothSurfaceNotVoxelPits) {
  const double half = 0.5;
  const std::vector<SilhouetteView> views = RenderMasks([&](auto& o, auto& d) { return HitsCube(o, d, half); });
  VisualHullOptions options;
  const float voxel = 2.0f / 96;
  for (float x = -0.4f; x <= 0.4f; x += 3 * voxel)
    for (float y = -0.4f; y <= 0.4f; y += 3 * voxel) options.free_segments.push_back({{x, y, 3.0f}, {x, y, 0.49f}});
  auto rough_roof = [](const TriangleMesh& m) {  // faces over the roof's middle turned more than 30 deg from +z
    int rough = 0;
    for (const auto& f : m.faces) {
      const Eigen::Vector3f a = m.positions[f[0]], b = m.positions[f[1]], c = m.positions[f[2]];
      const Eigen::Vector3f centre = (a + b + c) / 3, n = (b - a).cross(c - a).normalized();
      if (std::abs(centre.x()) < 0.35f && std::abs(centre.y()) < 0.35f && centre.z() > 0.3f && n.z() < std::cos(0.5236f)) ++rough;
    }
    return rough;
  };
  const TriangleMesh smoothed = VisualHull(views, options);
  options.carved_smoothing_passes = 0;
  const TriangleMesh pitted = VisualHull(views, options);
  ExpectClosedGenusZero(smoothed);
  std::printf("roof faces turned > 30 deg: %d pitted, %d smoothed\n", rough_roof(pitted), rough_roof(smoothed));
  EXPECT_GT(rough_roof(pitted), 100);
  EXPECT_LT(rough_roof(smoothed), rough_roof(pitted) / 10);
  options.carved_smoothing_passes = -1;
  EXPECT_THROW(VisualHull(views, options), InputError);
}

// A car-like block, seen as a road camera sees a car from a front quarter and as its mirror image: a body 2 long,
// 0.9 wide, 0.5 tall, and a cabin 0.4 tall over its rear 1.1. Above the hood the two views leave a ridge down
// the middle, where their lines of sight pass over the near side into the cabin's silhouette; across its width
// the car is solid, and solid_across_axis removes the ridge without touching the car.
TEST(VisualHull, SolidAcrossAnAxisRemovesTheRidgeTwoSideViewsLeave) {
  const Eigen::Vector3d body_lo(-1, -0.45, -0.5), body_hi(1, 0.45, 0), cabin_lo(-1, -0.45, 0), cabin_hi(0.1, 0.45, 0.4);
  const auto car = [&](auto& o, auto& d) { return HitsBox(o, d, body_lo, body_hi) || HitsBox(o, d, cabin_lo, cabin_hi); };
  const std::vector<SilhouetteView> views = RenderMasks(car, {OrbitCamera(30, 10), OrbitCamera(-30, 10)});
  VisualHullOptions options;
  options.resolution = 80;
  options.bounds.min = Eigen::Vector3f(-1, -0.45f, -0.5f);
  options.bounds.max = Eigen::Vector3f(1, 0.45f, 0.4f);
  const TriangleMesh plain = VisualHull(views, options);
  options.solid_across_axis = 1;
  const TriangleMesh solid = VisualHull(views, options);
  const auto above_hood = [](const TriangleMesh& m) {
    int n = 0;
    for (const Eigen::Vector3f& p : m.positions) n += p.x() > 0.35f && p.z() > 0.1f;
    return n;
  };
  const double truth = 2 * 0.9 * 0.5 + 1.1 * 0.9 * 0.4;
  std::printf("volume: truth %.3f, hull %.3f, solid across y %.3f; vertices above the hood %d, %d\n", truth,
              SignedVolume(plain), SignedVolume(solid), above_hood(plain), above_hood(solid));
  EXPECT_GT(above_hood(plain), 20);
  EXPECT_EQ(above_hood(solid), 0);
  // The car itself is kept: its columns are full.
  EXPECT_GT(SignedVolume(solid), 0.97 * truth);
  EXPECT_LT(SignedVolume(solid), SignedVolume(plain));
  ExpectClosedGenusZero(solid);
}

TEST(VisualHull, RejectsBadInput) {
  std::vector<SilhouetteView> views = RenderMasks([](auto& o, auto& d) { return HitsSphere(o, d, 1.0); });
  EXPECT_THROW(VisualHull({}, {}), InputError);
  {
    auto bad = views;
    bad[2].mask = ImageF(kSize, kSize - 1, 1);
    EXPECT_THROW(VisualHull(bad, {}), InputError);
  }
  {
    auto bad = views;
    bad[0].mask = ImageF(kSize, kSize, 3);
    EXPECT_THROW(VisualHull(bad, {}), InputError);
  }
  {
    auto bad = views;
    bad[1].mask = ImageF();
    EXPECT_THROW(VisualHull(bad, {}), InputError);
  }
  VisualHullOptions options;
  options.resolution = 1;
  EXPECT_THROW(VisualHull(views, options), InputError);
  options = {};
  options.mask_threshold = 1.0f;
  EXPECT_THROW(VisualHull(views, options), InputError);
  options = {};
  options.solid_across_axis = 3;
  EXPECT_THROW(VisualHull(views, options), InputError);
  options = {};
  options.min_column_fill = 1.5f;
  EXPECT_THROW(VisualHull(views, options), InputError);
  options = {};
  options.bounds.min = Eigen::Vector3f(-1, -1, 0);
  options.bounds.max = Eigen::Vector3f(1, 1, 0);
  EXPECT_THROW(VisualHull(views, options), InputError);
  try {
    auto bad = views;
    bad[2].mask = ImageF(10, 10, 1);
    VisualHull(bad, {});
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("view 2"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace sd::geometry
