#include "assetgen/shape_prior.h"

#include <cmath>

#include <gtest/gtest.h>

#include "core/error.h"
#include "geometry/metrics.h"
#include "geometry/topology.h"
#include "geometry/test_meshes.h"

namespace sd {
namespace {

constexpr double kPi = 3.14159265358979323846;

// A traffic cone's body: a frustum (base radius 0.18, top 0.03, 0.7 m tall) on a square-ish base disc, about +z,
// base at z = 0, in metres — the asset frame the prior builds in.
TriangleMesh Frustum(double r0 = 0.18, double r1 = 0.03, double h = 0.7, int segments = 96) {
  TriangleMesh m;
  for (int ring = 0; ring < 2; ++ring)
    for (int j = 0; j < segments; ++j) {
      const double a = 2 * kPi * j / segments, r = ring ? r1 : r0;
      m.positions.emplace_back(float(r * std::cos(a)), float(r * std::sin(a)), float(ring ? h : 0.0));
    }
  m.positions.emplace_back(0.f, 0.f, 0.f);
  m.positions.emplace_back(0.f, 0.f, float(h));
  const int bottom = 2 * segments, top = bottom + 1;
  for (int j = 0; j < segments; ++j) {
    const int k = (j + 1) % segments;
    m.faces.emplace_back(j, k, segments + k);
    m.faces.emplace_back(j, segments + k, segments + j);
    m.faces.emplace_back(bottom, k, j);
    m.faces.emplace_back(top, segments + j, segments + k);
  }
  return m;
}

// A car-like solid, bilaterally symmetric (y -> -y) but not front to back: a 4 x 1.8 x 0.9 m body with a
// 2 x 1.5 x 0.6 m cabin set towards the back.
TriangleMesh Car() {
  TriangleMesh body = geometry::testing::Cube(Eigen::Vector3f(-2.0f, -0.9f, 0.0f), Eigen::Vector3f(2.0f, 0.9f, 0.9f));
  const TriangleMesh cabin =
      geometry::testing::Cube(Eigen::Vector3f(-1.6f, -0.75f, 0.9f), Eigen::Vector3f(0.4f, 0.75f, 1.5f));
  const int offset = static_cast<int>(body.positions.size());
  for (const auto& p : cabin.positions) body.positions.push_back(p);
  for (const auto& f : cabin.faces) body.faces.emplace_back(f + Eigen::Vector3i::Constant(offset));
  return body;
}

// A traffic cone as they are made: the frustum standing on a square base plate (0.4 m, 3 cm thick).
TriangleMesh ConeOnPlate() {
  TriangleMesh cone = Frustum(0.16, 0.03, 0.7);
  for (auto& p : cone.positions) p.z() += 0.03f;
  TriangleMesh plate = geometry::testing::Cube(Eigen::Vector3f(-0.2f, -0.2f, 0.0f), Eigen::Vector3f(0.2f, 0.2f, 0.03f));
  const int offset = static_cast<int>(plate.positions.size());
  for (const auto& p : cone.positions) plate.positions.push_back(p);
  for (const auto& f : cone.faces) plate.faces.emplace_back(f + Eigen::Vector3i::Constant(offset));
  return plate;
}

// The mesh photographed from (azimuth, elevation) by a 640 x 480 camera of 50 degrees vertical field of view,
// aimed at the object's centre, `distance` away: the photo (colour from a base colour) and its exact mask.
PhotoObservation Photograph(TriangleMesh mesh, double height, double azimuth_deg, double elevation_deg,
                            double distance, ViewCamera* camera_out = nullptr) {
  for (auto& p : mesh.positions) p.z() -= float(height / 2);
  mesh.colors.assign(mesh.positions.size(), Eigen::Vector4f(0.9f, 0.3f, 0.05f, 1.0f));
  const ViewCamera cam = OrbitCamera("photo", azimuth_deg, elevation_deg, distance, 50, 640, 480);
  const MultiViewSet views = RenderOracleViews(mesh, {cam}, 3);
  PhotoObservation photo;
  ImageF color = views[0].color;
  for (int y = 0; y < color.height(); ++y)
    for (int x = 0; x < color.width(); ++x)
      if (views[0].mask.at(x, y) < 0.5f)
        for (int c = 0; c < 3; ++c) color.at(x, y, c) = 0.2f;  // grey road behind it
  photo.image = ToSrgb8(color);
  photo.mask = views[0].mask;
  if (camera_out) *camera_out = cam;
  return photo;
}

// Photograph() as a log gives it: the camera's intrinsics and its elevation above the object known.
PhotoObservation PhotographKnownCamera(const TriangleMesh& mesh, double height, double azimuth_deg,
                                       double elevation_deg, double distance) {
  ViewCamera cam;
  PhotoObservation photo = Photograph(mesh, height, azimuth_deg, elevation_deg, distance, &cam);
  photo.camera = cam.camera;
  photo.elevation_deg = elevation_deg;
  return photo;
}

geometry::GeometryMetrics Compare(const TriangleMesh& pred, const TriangleMesh& truth) {
  geometry::GeometryMetricsOptions o;
  o.num_samples = 30000;
  o.iou_resolution = 64;
  return geometry::CompareMeshes(pred, truth, o);
}

TEST(ShapePrior, ChosenFromTheCategoryAndParsedByName) {
  EXPECT_EQ(DefaultShapePrior("traffic_cone"), ShapePrior::kRevolve);
  EXPECT_EQ(DefaultShapePrior("car"), ShapePrior::kMirror);
  EXPECT_EQ(DefaultShapePrior("road_sign"), ShapePrior::kExtrude);
  EXPECT_EQ(DefaultShapePrior("debris"), ShapePrior::kHull);
  for (ShapePrior p : {ShapePrior::kRevolve, ShapePrior::kMirror, ShapePrior::kExtrude, ShapePrior::kHull})
    EXPECT_EQ(ParseShapePrior(ToString(p)), p);
  EXPECT_FALSE(ParseShapePrior("sphere").has_value());
}

TEST(FitSymmetryAxis, FindsTheAxisOfASymmetricSilhouetteAndScoresAnAsymmetricOneLow) {
  ImageF triangle(100, 80, 1, 0.0f), ell(100, 80, 1, 0.0f);
  for (int y = 10; y < 70; ++y)
    for (int x = 0; x < 100; ++x) {
      const double half = 0.5 * (y - 10);  // apex at the top, centred on u = 41
      if (std::abs(x + 0.5 - 41.0) <= half) triangle.at(x, y) = 1.0f;
      if ((x >= 20 && x < 35) || (y >= 55 && x >= 20 && x < 80)) ell.at(x, y) = 1.0f;
    }
  const SilhouetteAxis t = FitSymmetryAxis(triangle);
  EXPECT_NEAR(t.a + t.b * 40, 41.0, 0.6);
  EXPECT_NEAR(t.b, 0.0, 0.02);
  EXPECT_GT(t.symmetry_iou, 0.95);
  EXPECT_LT(FitSymmetryAxis(ell).symmetry_iou, 0.6);
}

TEST(ShapeFromPhoto, RevolvesAConeFromOnePhotoWithTheElevationFromItsBase) {
  const TriangleMesh truth = Frustum();
  ViewCamera cam;
  PhotoObservation photo = Photograph(truth, 0.7, 20, 10, 2.4, &cam);
  photo.camera = cam.camera;
  ShapePriorOptions options;
  options.category = "traffic_cone";
  options.size = Eigen::Vector3d(0.36, 0.36, 0.7);
  const PhotoShape shape = ShapeFromPhoto(photo, options);
  EXPECT_EQ(shape.prior, ShapePrior::kRevolve);
  EXPECT_GT(shape.symmetry_iou, 0.95);
  EXPECT_EQ(shape.elevation_method, "base ellipse");
  EXPECT_NEAR(shape.elevation_deg, 10.0, 3.0);
  EXPECT_NEAR(shape.distance_m, 2.4, 0.2);
  EXPECT_EQ(shape.views.size(), 8u);
  EXPECT_EQ(shape.real_views, 1);
  const AlignedBox3f b = shape.coarse.Bounds();
  EXPECT_NEAR(b.min.z(), 0.0f, 1e-4f);
  EXPECT_NEAR(b.max.z(), 0.7f, 1e-3f);
  EXPECT_NEAR(b.Size().x(), 0.36f, 0.03f);
  const geometry::GeometryMetrics m = Compare(shape.coarse, truth);
  std::printf("revolve, known intrinsics: CD %.4f F %.3f IoU %.3f, elevation %.1f deg\n", m.chamfer, m.fscore,
              m.volume_iou, shape.elevation_deg);
  EXPECT_LT(m.chamfer, 0.004);  // the sampling floor is ~0.003
  EXPECT_GT(m.volume_iou, 0.95);
  // The antialiased mask's base: the side starts at the base ellipse's widest row (the cap rows below it cut),
  // so the lowest ring has the base's radius.
  double base_radius = 0;
  for (const auto& p : shape.coarse.positions)
    if (p.z() < 1e-4f) base_radius = std::max(base_radius, double(std::hypot(p.x(), p.y())));
  EXPECT_NEAR(base_radius, 0.18, 0.005);
}

TEST(ShapeFromPhoto, RevolveWithAssumedIntrinsicsStillRecoversTheProfile) {
  const TriangleMesh truth = Frustum();
  const PhotoObservation photo = Photograph(truth, 0.7, 0, 8, 3.0);  // the camera's 50 degrees are the assumed
  ShapePriorOptions options;
  options.category = "traffic_cone";
  options.size = Eigen::Vector3d(0.36, 0.36, 0.7);
  const PhotoShape shape = ShapeFromPhoto(photo, options);
  EXPECT_TRUE(shape.intrinsics_assumed);
  const geometry::GeometryMetrics m = Compare(shape.coarse, truth);
  std::printf("revolve, assumed intrinsics: CD %.4f IoU %.3f, elevation %.1f deg\n", m.chamfer, m.volume_iou,
              shape.elevation_deg);
  EXPECT_LT(m.chamfer, 0.005);
}

TEST(ShapeFromPhoto, AssumesTheElevationWhereTheBaseIsNoEllipse) {
  // A square plate seen corner-on drops below its widest row as a V, not as the lower half of an ellipse: read
  // as one it gave 36 degrees for a 10 degree view. The fit's residual rejects it and the default is used.
  const TriangleMesh truth = ConeOnPlate();
  ViewCamera cam;
  PhotoObservation photo = Photograph(truth, 0.73, 30, 10, 3.0, &cam);
  photo.camera = cam.camera;
  ShapePriorOptions options;
  options.category = "traffic_cone";
  options.size = Eigen::Vector3d(0.4, 0.4, 0.73);
  const PhotoShape shape = ShapeFromPhoto(photo, options);
  EXPECT_EQ(shape.prior, ShapePrior::kRevolve);
  EXPECT_EQ(shape.elevation_method.rfind("assumed (the base's outline is no ellipse", 0), 0u) << shape.elevation_method;
  EXPECT_DOUBLE_EQ(shape.elevation_deg, options.assumed_elevation_deg);
  const geometry::GeometryMetrics m = Compare(shape.coarse, truth);
  std::printf("cone on a square plate: CD %.4f, elevation %.1f (%s)\n", m.chamfer, shape.elevation_deg,
              shape.elevation_method.c_str());
  EXPECT_LT(m.chamfer, 0.02);
}

// The truth turned about +z so that the photo's camera has the same azimuth about it as about the prior's shape
// (a revolve builds with its camera at azimuth 0).
TriangleMesh InPriorFrame(TriangleMesh truth, const PhotoShape& shape, double truth_azimuth_deg) {
  const Eigen::Vector3d c = shape.views.front().view.T_world_cam.translation;
  truth.Transform(Rigid3d::FromYaw(std::atan2(c.y(), c.x()) - truth_azimuth_deg * kPi / 180, Eigen::Vector3d::Zero()));
  return truth;
}

TriangleMesh MirroredY(TriangleMesh m) {
  for (auto& p : m.positions) p.y() = -p.y();
  for (auto& f : m.faces) std::swap(f[1], f[2]);
  return m;
}

double SignedVolume(const TriangleMesh& m) {
  double v = 0;
  for (const auto& f : m.faces)
    v += m.positions[f[0]].cast<double>().dot(m.positions[f[1]].cast<double>().cross(m.positions[f[2]].cast<double>()));
  return v / 6;
}

TEST(SurfaceOfRevolutionOnPlate, IsOneClosedOutwardMeshWithTheCornersAsVertices) {
  const BasePlate plate{0.2, 0.15, 0.03, 0.4};
  const TriangleMesh m = SurfaceOfRevolutionOnPlate({{0.0, 0.14}, {0.03, 0.14}, {0.4, 0.09}, {0.7, 0.03}}, 62, plate);
  std::vector<Eigen::Vector3f> positions = m.positions;
  std::vector<Eigen::Vector3i> faces = m.faces;
  geometry::WeldVertices(&positions, &faces, 1e-7f);
  EXPECT_TRUE(geometry::AnalyzeTopology(int(positions.size()), faces).IsWatertight());
  // The plate's volume (a superellipse, a little under its 0.4 x 0.3 rectangle) plus a frustum's.
  // The body: the profile's radius where it meets the plate's top (0.14), then its rings, as two frustums.
  const double frustum = kPi * 0.37 / 3 * (0.14 * 0.14 + 0.14 * 0.09 + 0.09 * 0.09) +
                         kPi * 0.3 / 3 * (0.09 * 0.09 + 0.09 * 0.03 + 0.03 * 0.03);
  const double v = SignedVolume(m);
  EXPECT_GT(v, 0.96 * 0.4 * 0.3 * 0.03 + 0.995 * frustum);  // 64 sides round a circle of 0.998 its area
  EXPECT_LT(v, 0.4 * 0.3 * 0.03 + frustum);
  // Each rounded corner's apex is a vertex, on the plate's diagonal at 2^(-1/10) of the sharp corner's distance.
  const Eigen::Vector2d corner = Eigen::Rotation2Dd(plate.yaw) * Eigen::Vector2d(0.2, 0.15) * std::pow(2.0, -0.1);
  double nearest = 1;
  for (const auto& p : m.positions)
    if (p.z() == 0.0f) nearest = std::min(nearest, (p.head<2>().cast<double>() - corner).norm());
  EXPECT_LT(nearest, 1e-6);
}

TEST(ShapeFromPhoto, StandsAConeOnTheSquarePlateItsFootShows) {
  const TriangleMesh truth = ConeOnPlate();
  const PhotoObservation photo = PhotographKnownCamera(truth, 0.73, 30, 10, 3.0);
  ShapePriorOptions options;
  options.category = "traffic_cone";
  options.size = Eigen::Vector3d(0.4, 0.4, 0.73);  // the category's proportions: the plate's size is fitted
  const PhotoShape cone = ShapeFromPhoto(photo, options);
  ASSERT_TRUE(cone.base_plate.has_value()) << cone.base_plate_note;
  const BasePlate& plate = *cone.base_plate;
  EXPECT_NEAR(plate.half_x, 0.2, 0.02);
  EXPECT_NEAR(plate.half_y, 0.2, 0.02);
  EXPECT_GT(plate.thickness, 0.005);
  EXPECT_LT(plate.thickness, 0.07);
  // The shape is turned so that its plate runs along the axes, as the truth's does: the photo's camera then has
  // the truth's azimuth, 30 degrees, modulo the square's quarter turns and the mirror (left/right ambiguous).
  EXPECT_EQ(plate.yaw, 0.0);
  const double azimuth = std::fmod(cone.yaw_deg + 360, 90.0);
  EXPECT_NEAR(std::min(azimuth, 90 - azimuth), 30.0, 4.0) << cone.yaw_deg;
  EXPECT_EQ(cone.views.size(), 4u);  // quarter turns only: they show the plate as the photo does
  EXPECT_EQ(cone.yaw_method.rfind("silhouette", 0), 0u);

  // Against the disc a revolve without a plate makes (a barrel's prior, the same photo).
  options.category = "barrel";
  const PhotoShape disc = ShapeFromPhoto(photo, options);
  EXPECT_FALSE(disc.base_plate.has_value());
  const geometry::GeometryMetrics with = Compare(cone.coarse, InPriorFrame(truth, cone, 30));
  const geometry::GeometryMetrics without = Compare(disc.coarse, InPriorFrame(truth, disc, 30));
  std::printf("cone on a plate: CD %.4f IoU %.3f with the plate (%s), %.4f / %.3f as a disc\n", with.chamfer,
              with.volume_iou, cone.base_plate_note.c_str(), without.chamfer, without.volume_iou);
  EXPECT_LT(with.chamfer, 0.7 * without.chamfer);
  EXPECT_GT(with.volume_iou, without.volume_iou);

  // A measured box is the plate.
  options.category = "traffic_cone";
  options.size_measured = true;
  const PhotoShape measured = ShapeFromPhoto(photo, options);
  ASSERT_TRUE(measured.base_plate.has_value());
  EXPECT_DOUBLE_EQ(measured.base_plate->half_x, 0.2);
  EXPECT_LT(Compare(measured.coarse, InPriorFrame(truth, measured, 30)).chamfer, 0.7 * without.chamfer);
}

TEST(ShapeFromPhoto, KeepsTheDiscUnderAConeWhoseFootIsRound) {
  // The frustum on a round foot 0.44 m across and 3 cm thick: the foot flares, but a square fits it worse.
  TriangleMesh truth = SurfaceOfRevolution({{0.0, 0.22}, {0.03, 0.22}, {0.03, 0.16}, {0.73, 0.03}}, 96);
  const PhotoObservation photo = PhotographKnownCamera(truth, 0.73, 30, 10, 3.0);
  ShapePriorOptions options;
  options.category = "traffic_cone";
  options.size = Eigen::Vector3d(0.44, 0.44, 0.73);
  const PhotoShape shape = ShapeFromPhoto(photo, options);
  EXPECT_FALSE(shape.base_plate.has_value()) << shape.base_plate_note;
  EXPECT_EQ(shape.views.size(), 8u);
}

TEST(ShapeFromPhoto, AMeasuredOblongBoxMakesAnOvalSection) {
  // A flask 10 x 6 cm, 25 cm tall (an elliptic cylinder), seen from 30 degrees off its length.
  TriangleMesh truth = SurfaceOfRevolution({{0.0, 1.0}, {0.25, 1.0}}, 96);
  for (auto& p : truth.positions) p.x() *= 0.05f, p.y() *= 0.03f;
  const PhotoObservation photo = PhotographKnownCamera(truth, 0.25, 30, 10, 1.2);
  ShapePriorOptions options;
  options.category = "bottle";
  options.size = Eigen::Vector3d(0.1, 0.06, 0.25);
  const PhotoShape round = ShapeFromPhoto(photo, options);
  options.size_measured = true;
  const PhotoShape oval = ShapeFromPhoto(photo, options);
  EXPECT_EQ(oval.views.size(), 2u);
  // The oval's length along x, as the truth's, the camera at +-30 degrees (left and right are ambiguous: an oval
  // turned either way looks the same).
  EXPECT_NEAR(std::abs(oval.yaw_deg), 30.0, 5.0);
  TriangleMesh seen = InPriorFrame(truth, oval, 30);
  if (oval.yaw_deg < 0) seen = InPriorFrame(MirroredY(truth), oval, -30);  // the mirrored reading
  const double cd_oval = Compare(oval.coarse, seen).chamfer, cd_round = Compare(round.coarse, seen).chamfer;
  std::printf("oval flask: CD %.4f with the measured box, %.4f round\n", cd_oval, cd_round);
  EXPECT_LT(cd_oval, 0.5 * cd_round);
  const AlignedBox3f b = oval.coarse.Bounds();
  EXPECT_NEAR(b.Size().z(), 0.25f, 2e-3f);
}

TEST(ShapeFromPhoto, AFlattenedBottleKeepsARoundNeck) {
  // A bottle flattened as HOPE's salad dressing is: a body 8 cm wide and 4 cm deep, a round neck 3 cm across on
  // top (a ring is as deep as it is wide up to the box's depth, no deeper). One ratio for every ring made the
  // neck flat too (4.6 x 2.3 cm, CD 0.0055 against 0.0034).
  TriangleMesh truth = SurfaceOfRevolution({{0.0, 0.04}, {0.14, 0.04}, {0.17, 0.015}, {0.25, 0.015}}, 96);
  for (auto& p : truth.positions) {
    const float rho = p.head<2>().norm();
    if (rho > 0.02f) p.y() *= 0.02f / rho;  // the body's rings ellipses 2 cm deep
  }
  const PhotoObservation photo = PhotographKnownCamera(truth, 0.25, 30, 10, 1.2);
  ShapePriorOptions options;
  options.category = "bottle";
  options.size = Eigen::Vector3d(0.08, 0.04, 0.25);
  options.size_measured = true;
  const PhotoShape shape = ShapeFromPhoto(photo, options);
  EXPECT_NEAR(std::abs(shape.yaw_deg), 30.0, 5.0);
  // In the asset's own frame (x along the box's length): the neck round, the body as deep as the box.
  Eigen::Vector2f neck_lo(1e9f, 1e9f), neck_hi(-1e9f, -1e9f), body_lo = neck_lo, body_hi = neck_hi;
  const float top = shape.coarse.Bounds().max.z(), bottom = shape.coarse.Bounds().min.z();
  for (const Eigen::Vector3f& p : shape.coarse.positions) {
    const float h = (p.z() - bottom) / (top - bottom);
    if (h > 0.8f) neck_lo = neck_lo.cwiseMin(p.head<2>()), neck_hi = neck_hi.cwiseMax(p.head<2>());
    if (h > 0.2f && h < 0.5f) body_lo = body_lo.cwiseMin(p.head<2>()), body_hi = body_hi.cwiseMax(p.head<2>());
  }
  const Eigen::Vector2f neck = neck_hi - neck_lo, body = body_hi - body_lo;
  std::printf("flattened bottle: body %.3f x %.3f, neck %.3f x %.3f\n", body.x(), body.y(), neck.x(), neck.y());
  EXPECT_NEAR(neck.y() / neck.x(), 1.0, 0.1);
  EXPECT_NEAR(body.y() / body.x(), 0.5, 0.1);
  TriangleMesh seen = InPriorFrame(truth, shape, 30);
  if (shape.yaw_deg < 0) seen = InPriorFrame(MirroredY(truth), shape, -30);
  const double cd = Compare(shape.coarse, seen).chamfer;
  std::printf("flattened bottle: CD %.4f\n", cd);
  EXPECT_LT(cd, 0.0045);
}

TEST(ShapeFromPhoto, PlacesTheCameraOfALongFlatBoxSeenFromNearby) {
  // A butter pack 10.3 x 5.3 x 2.4 cm, 12 cm from the camera, the elevation known: the box fit used to
  // oscillate (aim and distance updated in turn, never settling under strong perspective) and the bounds' aspect
  // matched several azimuths.
  const TriangleMesh truth = geometry::testing::Cube(Eigen::Vector3f(-5.15f, -2.65f, 0.0f), Eigen::Vector3f(5.15f, 2.65f, 2.4f));
  ViewCamera cam;
  PhotoObservation photo = Photograph(truth, 2.4, 30, 10, 12.0, &cam);
  photo.camera = cam.camera;
  photo.elevation_deg = 10;
  ShapePriorOptions options;
  options.category = "crate";
  options.size = Eigen::Vector3d(10.3, 5.3, 2.4);
  const PhotoShape shape = ShapeFromPhoto(photo, options);
  EXPECT_EQ(shape.prior, ShapePrior::kMirror);
  Eigen::Vector3d truth_centre = cam.T_world_cam.translation;
  truth_centre.z() += 1.2;  // Photograph lowered the box by half its height
  const Eigen::Vector3d centre = shape.views.front().view.T_world_cam.translation;
  const geometry::GeometryMetrics m = Compare(shape.coarse, truth);
  std::printf("flat box: yaw %.1f, camera %s (truth %s), CD %.4f\n", shape.yaw_deg,
              (Msg() << centre.transpose()).str().c_str(), (Msg() << truth_centre.transpose()).str().c_str(), m.chamfer);
  EXPECT_NEAR(shape.yaw_deg, 30.0, 1.0);
  EXPECT_LT((centre - truth_centre).norm(), 0.05 * 12.0);
  // Carved inside the box, the hull keeps the box's faces (marching cubes used to leave it up to a voxel beyond
  // each: 10 % too tall).
  const AlignedBox3f b = shape.coarse.Bounds();
  EXPECT_NEAR(b.min.z(), 0.0f, 0.05f);
  EXPECT_NEAR(b.max.z(), 2.4f, 0.05f);
  EXPECT_NEAR(b.Size().x(), 10.3f, 0.1f);
  EXPECT_LT(m.chamfer, 0.006);
}

TEST(ShapeFromPhoto, TheMirroredViewCarvesAVehicleTighterThanTheSingleViewHull) {
  const TriangleMesh truth = Car();
  const PhotoObservation photo = Photograph(truth, 1.5, 35, 8, 12.0);
  ShapePriorOptions options;
  options.category = "car";
  options.size = Eigen::Vector3d(4.0, 1.8, 1.5);
  options.hull_resolution = 80;
  const PhotoShape mirror = ShapeFromPhoto(photo, options);
  EXPECT_EQ(mirror.prior, ShapePrior::kMirror);
  EXPECT_EQ(mirror.views.size(), 2u);
  options.prior = ShapePrior::kHull;
  const PhotoShape hull = ShapeFromPhoto(photo, options);
  EXPECT_EQ(hull.views.size(), 1u);
  const geometry::GeometryMetrics mm = Compare(mirror.coarse, truth), mh = Compare(hull.coarse, truth);
  std::printf("car: mirror CD %.4f IoU %.3f, hull CD %.4f IoU %.3f, yaw %.0f deg\n", mm.chamfer, mm.volume_iou,
              mh.chamfer, mh.volume_iou, mirror.yaw_deg);
  EXPECT_LT(mm.chamfer, mh.chamfer);
  EXPECT_GT(mm.volume_iou, mh.volume_iou);
}

TEST(ShapeFromPhoto, TheMirroredViewIsTheMirrorImageOfTheObjectSeenFromTheMirroredCamera) {
  // The mirrored view's camera (centre reflected in y = 0, x axis flipped, principal point W - cx of the crop)
  // must see any y-symmetric object exactly as the photo's camera sees it, flipped left-right: the car, not
  // symmetric front to back, drawn at both of the prior's cameras.
  const TriangleMesh car = Car();
  const PhotoObservation photo = Photograph(car, 1.5, 35, 8, 12.0);
  ShapePriorOptions options;
  options.category = "car";
  options.size = Eigen::Vector3d(4.0, 1.8, 1.5);
  const PhotoShape shape = ShapeFromPhoto(photo, options);
  ASSERT_EQ(shape.views.size(), 2u);
  const MultiViewSet drawn = RenderOracleViews(car, {shape.views[0].view, shape.views[1].view}, 3);
  const ImageF& a = drawn[0].mask;
  const ImageF& b = drawn[1].mask;
  ASSERT_EQ(a.width(), b.width());
  double inter = 0, uni = 0, area = 0;
  for (int y = 0; y < a.height(); ++y)
    for (int x = 0; x < a.width(); ++x) {
      const bool p = a.at(a.width() - 1 - x, y) > 0.5f, q = b.at(x, y) > 0.5f;
      inter += p && q, uni += p || q, area += q;
    }
  EXPECT_GT(area, 1000);
  EXPECT_GT(inter / uni, 0.995);
}

TEST(ShapeFromPhoto, RefusesWhatCannotMakeAShapeWithOneLine) {
  const PhotoObservation good = Photograph(Frustum(), 0.7, 0, 8, 3.0);
  ShapePriorOptions options;
  options.category = "traffic_cone";
  options.size = Eigen::Vector3d(0.36, 0.36, 0.7);
  auto message = [&](PhotoObservation photo, const ShapePriorOptions& o) -> std::string {
    try {
      ShapeFromPhoto(photo, o);
    } catch (const InputError& e) {
      return e.what();
    }
    return "";
  };
  PhotoObservation empty = good;
  empty.mask = ImageF(good.mask.width(), good.mask.height(), 1, 0.0f);
  EXPECT_NE(message(empty, options).find("holds no object"), std::string::npos);
  PhotoObservation whole = good;
  whole.mask = ImageF(good.mask.width(), good.mask.height(), 1, 1.0f);
  EXPECT_NE(message(whole, options).find("whole photo"), std::string::npos);
  PhotoObservation small = good;
  small.mask = ImageF(10, 10, 1, 1.0f);
  EXPECT_NE(message(small, options).find("the mask is 10x10"), std::string::npos);
  ShapePriorOptions bad_size = options;
  bad_size.size = Eigen::Vector3d(0.3, 0, 0.7);
  EXPECT_NE(message(good, bad_size).find("impossible object size"), std::string::npos);
  // An L-shaped silhouette: no surface of revolution makes it; forced, revolve refuses; chosen, it becomes hull.
  PhotoObservation ell = good;
  ell.mask = ImageF(good.mask.width(), good.mask.height(), 1, 0.0f);
  for (int y = 100; y < 400; ++y)
    for (int x = 200; x < 500; ++x)
      if (x < 280 || y >= 320) ell.mask.at(x, y) = 1.0f;
  ShapePriorOptions forced = options;
  forced.prior = ShapePrior::kRevolve;
  EXPECT_NE(message(ell, forced).find("revolve cannot fit"), std::string::npos);
  const PhotoShape demoted = ShapeFromPhoto(ell, options);
  EXPECT_EQ(demoted.prior, ShapePrior::kHull);
  EXPECT_NE(demoted.prior_reason.find("symmetry"), std::string::npos);
  // A flat ellipse on the road (a manhole a photo's labels called an object): symmetric, but as a cone standing
  // 0.7 m tall it would be metres across.
  PhotoObservation manhole = good;
  manhole.mask = ImageF(good.mask.width(), good.mask.height(), 1, 0.0f);
  for (int y = 0; y < manhole.mask.height(); ++y)
    for (int x = 0; x < manhole.mask.width(); ++x)
      if (std::pow((x + 0.5 - 320) / 150, 2) + std::pow((y + 0.5 - 300) / 40, 2) <= 1) manhole.mask.at(x, y) = 1.0f;
  const std::string flat = message(manhole, options);
  EXPECT_NE(flat.find("revolve cannot fit"), std::string::npos) << flat;
  EXPECT_NE(flat.find("times the 0.36 m of the object's box"), std::string::npos) << flat;
}

}  // namespace
}  // namespace sd
