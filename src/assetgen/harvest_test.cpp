#include "assetgen/harvest.h"

#include <algorithm>
#include <cmath>

#include <gtest/gtest.h>

#include "assetgen/asset.h"
#include "assetgen/generate.h"
#include "core/error.h"
#include "datasets/categories.h"
#include "datasets/readers.h"
#include "geometry/box_projection.h"
#include "geometry/closest_point.h"
#include "io/image_io.h"
#include "testing/testing.h"

namespace sd {
namespace {

constexpr double kPi = 3.14159265358979323846;

// A cone-like body of revolution (radius 0.2 at the bottom to 0.03 at the top, 0.7 m), about the vertical through
// `axis`, base at z = 0.
TriangleMesh Frustum(const Eigen::Vector2f& axis) {
  return SurfaceOfRevolution({{0.0, 0.2}, {0.7, 0.03}}, 96, axis.cast<double>());
}

// A camera at (azimuth, elevation) `distance` from the point (0, 0, 0.35) in the object frame, looking at it.
ViewCamera CameraAt(double azimuth_deg, double elevation_deg, double distance) {
  ViewCamera c = OrbitCamera("view", azimuth_deg, elevation_deg, distance, 8, 256, 256);
  c.T_world_cam.translation.z() += 0.35;
  return c;
}

// Views from one side only, as a car driving past sees a cone: the axis (offset 6 cm from the box centre) and the
// profile come back from the silhouettes alone, and from the returns alone.
TEST(RevolveFromViews, RecoversAnOffsetAxisAndTheProfileFromOneSide) {
  const Eigen::Vector2f axis_true(0.04f, -0.045f);
  const TriangleMesh truth = Frustum(axis_true);
  std::vector<ViewCamera> cameras;
  for (int i = 0; i < 6; ++i) cameras.push_back(CameraAt(-80 + 2 * i, 8 - 0.3 * i, 11 + 0.4 * i));
  const MultiViewSet views = RenderOracleViews(truth, cameras, 3);
  const Eigen::Vector3d size(0.4, 0.4, 0.7);

  // The returns: points on the visible half (facing azimuth -80), with 1 cm of noise.
  std::vector<Eigen::Vector3f> points;
  for (int i = 0; i < 400; ++i) {
    const double z = 0.7 * (i % 40 + 0.5) / 40, a = (-80 + (i / 40 - 5) * 12) * kPi / 180;
    const double r = 0.2 + (0.03 - 0.2) * z / 0.7 + 0.01 * std::sin(13.0 * i);
    points.emplace_back(axis_true.x() + float(r * std::cos(a)), axis_true.y() + float(r * std::sin(a)), float(z));
  }
  const Eigen::Vector2d from_views = RevolveAxis(views, size);
  const Eigen::Vector2d with_points = RevolveAxis(views, size, points);
  std::printf("axis: true (%.3f, %.3f), from silhouettes (%.3f, %.3f), with returns (%.3f, %.3f)\n", axis_true.x(),
              axis_true.y(), from_views.x(), from_views.y(), with_points.x(), with_points.y());
  // Silhouettes from one side fix the axis across the line of sight (the direction (sin -80, -cos -80)), not along it.
  const Eigen::Vector2d across(std::sin(-80 * kPi / 180), -std::cos(-80 * kPi / 180));
  EXPECT_NEAR(across.dot(from_views), across.dot(axis_true.cast<double>()), 0.005);
  EXPECT_LT((with_points - axis_true.cast<double>()).norm(), 0.01);

  // The profile about the axis each found: the radius of every ring against the truth's at its height.
  for (const bool use_points : {false, true}) {
    const Eigen::Vector2d axis = use_points ? with_points : from_views;
    const TriangleMesh mesh = RevolveFromViews(views, use_points ? points : std::vector<Eigen::Vector3f>{}, axis, size);
    double worst = 0, sum = 0;
    int n = 0;
    for (const Eigen::Vector3f& v : mesh.positions) {
      if (v.z() < 0.05f || v.z() > 0.65f) continue;  // the ends: caps and the profile's first and last heights
      const double r = (v.head<2>().cast<double>() - axis).norm(), r_true = 0.2 + (0.03 - 0.2) * v.z() / 0.7;
      worst = std::max(worst, std::abs(r - r_true)), sum += std::abs(r - r_true), ++n;
    }
    std::printf("%s: profile radius error mean %.4f m, worst %.4f m\n", use_points ? "silhouettes + returns" : "silhouettes",
                sum / n, worst);
    EXPECT_LT(sum / n, use_points ? 0.006 : 0.01);
    EXPECT_LT(worst, use_points ? 0.02 : 0.025);
  }
}

// The mirror of a view in the plane y = 0 sees the mirrored object: a point (x, y, z) seen at u in the view is seen
// at W - u in the mirrored view when the point is (x, -y, z).
TEST(SymmetryViews, AMirroredViewSeesTheMirroredPointMirroredInTheImage) {
  MultiView real;
  real.view = CameraAt(-60, 10, 12);
  real.view.camera.cx = 100;  // off-centre, as a crop's principal point is
  real.mask = ImageF(256, 256, 1, 0.0f);
  real.color = ImageF(256, 256, 3, 0.5f);
  real.normals = ImageF(256, 256, 3, 0.0f);
  const MultiViewSet mirrored = SymmetryViews({real}, ShapePrior::kMirror);
  ASSERT_EQ(mirrored.size(), 1u);
  EXPECT_TRUE(mirrored[0].synthetic);
  for (const Eigen::Vector3d& p : {Eigen::Vector3d(0.3, 0.2, 0.5), Eigen::Vector3d(-0.1, -0.4, 0.1)}) {
    const auto a = real.view.camera.Project(real.view.T_world_cam.Inverse() * p);
    const auto b = mirrored[0].view.camera.Project(mirrored[0].view.T_world_cam.Inverse() * Eigen::Vector3d(p.x(), -p.y(), p.z()));
    ASSERT_TRUE(a && b);
    EXPECT_NEAR(b->x(), 256 - a->x(), 1e-6);
    EXPECT_NEAR(b->y(), a->y(), 1e-6);
  }
  // A view from the mirrored side already: no copy is made there.
  MultiView other = real;
  other.view = CameraAt(60, 10, 12);
  EXPECT_TRUE(SymmetryViews({real, other}, ShapePrior::kMirror).empty());
  // Revolve: copies about the axis into the azimuths no real view covers, 45 degrees apart.
  const MultiViewSet turned = SymmetryViews({real}, ShapePrior::kRevolve);
  EXPECT_EQ(turned.size(), 7u);
  EXPECT_TRUE(SymmetryViews({real}, ShapePrior::kHull).empty());
}

const char* kKeyframe = "driving/nuscenes-scene0061-kf0/mmdet3d_info/n015-2018-07-24-11-22-45+0800.json";

// A quick build of a harvested box prior: 10 refinement steps, a 48^3 hull, bicubic upscaling, a 512^2 atlas.
GenerateOptions QuickOptions() {
  GenerateOptions options;
  options.refine.steps = 10;
  options.refine.show_progress = false;
  options.upscale = "bicubic";
  options.hull_resolution = 48;
  options.texture_size = 512;
  return options;
}

// The annotation of `category` in `frame` whose harvest scores highest by `score(object)` (nullptr when none can
// be harvested): the best-observed object of its kind.
template <typename Score>
const Annotation* BestHarvested(const Log& log, const Frame& frame, const std::string& category, Score score) {
  const Annotation* best = nullptr;
  double best_score = -1;
  for (const Annotation& a : frame.annotations) {
    const auto c = FindCategory(a.category);
    if (!c || c->name != category) continue;
    try {
      const double s = score(HarvestObject(log, {frame.token, a.box}));
      if (s > best_score) best_score = s, best = &a;
    } catch (const InputError&) {
    }
  }
  return best;
}

// The repo's nuScenes keyframe: one frame, so a barrier is one or two views, its returns, its box.
TEST(HarvestObject, ABarrierOfTheRepoKeyframeBecomesAMetricWatertightAsset) {
  const Log log = OpenLog(testing::RepoData(kKeyframe));
  const Frame& frame = log.frames.front();
  // The barrier the most cameras see whole (then the most returns): the best-observed one of the frame.
  const Annotation* best = BestHarvested(log, frame, "barrier", [](const HarvestedObject& o) {
    return 1e6 * static_cast<double>(o.views.size()) + static_cast<double>(o.points.size());
  });
  ASSERT_NE(best, nullptr);
  const HarvestedObject object = HarvestObject(log, {frame.token, best->box});
  EXPECT_EQ(object.category, "barrier");
  EXPECT_EQ(object.frames, 1);
  ASSERT_GE(object.views.size(), 1u);
  EXPECT_GT(object.points.size(), 20u);
  EXPECT_NEAR((object.size - best->box.size).norm(), 0, 1e-9);
  // Every return lies in the box (grown by the margin) in the object frame: bottom-centre origin, x the front.
  for (const Eigen::Vector3f& p : object.points) {
    EXPECT_LE(std::abs(p.x()), 0.5 * object.size.x() + 0.081);
    EXPECT_LE(std::abs(p.y()), 0.5 * object.size.y() + 0.081);
    EXPECT_GE(p.z(), 0.039f);
    EXPECT_LE(p.z(), object.size.z() + 0.081);
  }
  // Each view is centred on the object: the box centre projects near the view's centre, and its mask holds it.
  for (const MultiView& v : object.views) {
    const auto uv = v.view.camera.Project(v.view.T_world_cam.Inverse() * Eigen::Vector3d(0, 0, object.size.z() / 2));
    ASSERT_TRUE(uv);
    EXPECT_NEAR(uv->x(), 128, 40);
    EXPECT_NEAR(uv->y(), 128, 40);
    EXPECT_FALSE(v.synthetic);
    EXPECT_FALSE(v.source.empty());
  }

  const GenerateOptions options = QuickOptions();
  HarvestFit fit;
  const GeneratedMesh g = GenerateFromHarvest(object, options, &fit);
  EXPECT_EQ(fit.prior, ShapePrior::kMirror);
  EXPECT_GT(fit.synthetic_views, 0);
  EXPECT_EQ(fit.quality[quality::kWatertight].get<int>(), 1);
  EXPECT_LT(fit.quality[quality::kLidarPointToMeshMedianM].get<double>(), 0.03);
  EXPECT_GT(fit.quality[quality::kRealTextureFraction].get<double>(), 0.2);
  // Metric: the asset fills its box (the hull is carved inside it; refinement may follow the returns a little
  // past the annotator's box).
  for (int k = 0; k < 3; ++k) {
    EXPECT_LE(g.extent[k], object.size[k] * 1.15) << k;
    EXPECT_GE(g.extent[k], object.size[k] * 0.6) << k;
  }
}

// The keyframe's best-seen barrier, its camera image cut so that the image border crosses the barrier (the
// left 35 % of its box gone; the camera's principal point moved with the cut): the view still frames the whole
// box, the pixels past the border are marked unknown, and the asset fills its box as the uncut one does (those
// pixels carve nothing; counted as background they would shave the cut end off).
TEST(HarvestObject, AnObjectCutByTheImageBorderStillFillsItsBox) {
  Log log = OpenLog(testing::RepoData(kKeyframe));
  Frame& frame = log.frames.front();
  // The barrier seen by one camera with the most returns.
  const Annotation* best = BestHarvested(log, frame, "barrier", [](const HarvestedObject& o) {
    return o.views.size() == 1 ? static_cast<double>(o.points.size()) : -1.0;
  });
  ASSERT_NE(best, nullptr);
  const Box3 box = best->box;
  const HarvestedObject uncut = HarvestObject(log, {frame.token, box});
  ASSERT_TRUE(IsWhole(uncut.views.front()));
  CameraSensor* cam = nullptr;
  for (CameraSensor& c : frame.cameras)
    if (c.channel == uncut.view_info.front().camera) cam = &c;
  ASSERT_NE(cam, nullptr);
  const auto in_image = geometry::ProjectBoxToImage(cam->intrinsics, cam->T_ego_cam.Inverse(), box, 0.1);
  ASSERT_TRUE(in_image);
  const int cut_x = static_cast<int>(in_image->clipped.x1 + 0.35 * (in_image->clipped.x2 - in_image->clipped.x1));
  const ImageU8 image = ReadImage(cam->image_path, 3);
  ImageU8 cropped(image.width() - cut_x, image.height(), 3);
  for (int y = 0; y < image.height(); ++y)
    for (int x = 0; x < cropped.width(); ++x)
      for (int c = 0; c < 3; ++c) cropped.at(x, y, c) = image.at(x + cut_x, y, c);
  testing::TempDir tmp;
  cam->image_path = tmp / "cut.png";
  WriteImage(cam->image_path, cropped);
  cam->intrinsics.cx -= cut_x;
  cam->intrinsics.width = cropped.width();

  const HarvestedObject object = HarvestObject(log, {frame.token, box});
  ASSERT_EQ(object.views.size(), 1u);
  const MultiView& v = object.views.front();
  EXPECT_FALSE(IsWhole(v));
  EXPECT_GT(object.view_info.front().truncation, 0.2);
  // The window is about the whole projected box, not the part the image shows.
  const auto uv = v.view.camera.Project(v.view.T_world_cam.Inverse() * Eigen::Vector3d(0, 0, object.size.z() / 2));
  ASSERT_TRUE(uv);
  EXPECT_NEAR(uv->x(), 128, 16);
  EXPECT_NEAR(uv->y(), 128, 16);
  // Nothing is said past the border: the unknown pixels are the view's left part, and hold no mask.
  int unknown = 0;
  for (int y = 0; y < v.mask.height(); ++y)
    for (int x = 0; x < v.mask.width(); ++x)
      if (v.known.at(x, y) < 0.5f) {
        ++unknown;
        EXPECT_LT(x, 128);
        EXPECT_EQ(v.mask.at(x, y), 0.0f);
      }
  EXPECT_GT(unknown, 256 * 20);

  const GenerateOptions options = QuickOptions();
  HarvestFit fit_uncut, fit_cut;
  const GeneratedMesh whole = GenerateFromHarvest(uncut, options, &fit_uncut);
  const GeneratedMesh cut = GenerateFromHarvest(object, options, &fit_cut);
  std::printf("box %s; extent uncut %s, cut %s; p2m uncut %.4f, cut %.4f\n", std::string(Msg() << object.size.transpose()).c_str(),
              std::string(Msg() << whole.extent.transpose()).c_str(), std::string(Msg() << cut.extent.transpose()).c_str(),
              fit_uncut.quality[quality::kLidarPointToMeshMedianM].get<double>(),
              fit_cut.quality[quality::kLidarPointToMeshMedianM].get<double>());
  EXPECT_EQ(fit_cut.quality[quality::kWatertight].get<int>(), 1);
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(cut.extent[k], whole.extent[k], 0.1 * whole.extent[k]) << k;
  EXPECT_LT(fit_cut.quality[quality::kLidarPointToMeshMedianM].get<double>(),
            1.5 * fit_uncut.quality[quality::kLidarPointToMeshMedianM].get<double>() + 0.01);
}

TEST(HarvestObject, RefusesWhatItCannotHarvestInOneLine) {
  const Log log = OpenLog(testing::RepoData(kKeyframe));
  const Frame& frame = log.frames.front();
  Box3 nowhere;
  nowhere.T_frame_box.translation = Eigen::Vector3d(500, 500, 0);
  nowhere.size = Eigen::Vector3d(1, 1, 1);
  try {
    HarvestObject(log, {frame.token, nowhere});
    FAIL() << "no object there";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("no annotated object within 0.1 m"), std::string::npos) << e.what();
  }
  EXPECT_THROW(HarvestObject(log, {"no-such-frame", frame.annotations.front().box}), InputError);
}

// PandaSet: a cone the back camera sees over 12 frames.
TEST(HarvestObject, APandaSetConeOverTwelveFramesIsRoundAndOnItsReturns) {
  const auto dir = testing::SharedData("driving/pandaset-002-f44-55");
  if (dir.empty()) GTEST_SKIP() << "../shared/data/driving/pandaset-002-f44-55 is absent";
  const Log log = OpenLog(dir);
  const Frame& frame = log.frames[6];
  const Annotation* cone = BestHarvested(log, frame, "traffic_cone",
                                          [](const HarvestedObject& o) { return static_cast<double>(o.views.size()); });
  ASSERT_NE(cone, nullptr);
  const HarvestedObject object = HarvestObject(log, {frame.token, cone->box});
  EXPECT_EQ(object.frames, 12);
  EXPECT_TRUE(object.static_pose);
  EXPECT_GE(object.views.size(), 8u);
  EXPECT_GT(object.points.size(), 200u);
  GenerateOptions options;
  options.refine.show_progress = false;
  options.upscale = "bicubic";
  options.texture_size = 512;
  HarvestFit fit;
  GenerateFromHarvest(object, options, &fit);
  std::printf("%s\n", fit.quality.dump().c_str());
  EXPECT_EQ(fit.prior, ShapePrior::kRevolve);
  EXPECT_EQ(fit.held_out.size(), 1u);
  EXPECT_LT(fit.quality[quality::kLidarPointToMeshMedianM].get<double>(), 0.02);
  EXPECT_GT(fit.quality[quality::kHeldOutSilhouetteIou].get<double>(), 0.6);
  EXPECT_EQ(fit.quality[quality::kWatertight].get<int>(), 1);
}

}  // namespace
}  // namespace sd
