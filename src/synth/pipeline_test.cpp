// End-to-end synthesis on the real nuScenes keyframe in data/: the promises of `synthdrive synth`, checked
// against the data (boxes, ground, projections, point-to-mesh distances), not against golden files.
#include "synth/batch.h"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <fstream>
#include <iostream>
#include <map>
#include <set>

#include <gtest/gtest.h>

#include "assetgen/canonical.h"
#include "core/parallel.h"
#include "io/files.h"
#include "io/json.h"
#include "io/mesh_io.h"
#include "io/pointcloud_io.h"
#include "render/ray_scene.h"
#include "synth/lidar_sim.h"
#include "synth/test_assets.h"
#include "testing/testing.h"

namespace sd {
namespace {

namespace fs = std::filesystem;

const char* kInfo = "driving/nuscenes-scene0061-kf0/mmdet3d_info/n015-2018-07-24-11-22-45+0800.json";

std::vector<Asset> DemoAssets(const testing::TempDir& dir) { return testing::ImportDemoAssets(dir.path()); }

// Distance from p to triangle abc (Ericson, Real-Time Collision Detection 5.1.5).
double PointTriangleDistance(const Eigen::Vector3d& p, const Eigen::Vector3d& a, const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return (p - a).norm();
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return (p - b).norm();
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return (p - (a + d1 / (d1 - d3) * ab)).norm();
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return (p - c).norm();
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return (p - (a + d2 / (d2 - d6) * ac)).norm();
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) return (p - (b + (d4 - d3) / ((d4 - d3) + (d5 - d6)) * (c - b))).norm();
  const double denom = 1.0 / (va + vb + vc);
  return (p - (a + ab * (vb * denom) + ac * (vc * denom))).norm();
}

class PipelineTest : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    dir_ = new testing::TempDir();
    log_ = new Log(OpenLog(testing::RepoData(kInfo)));
    assets_ = new std::vector<Asset>(DemoAssets(*dir_));
    scenario_ = new Scenario(ReadScenario(testing::RepoData("scenarios/demo.json")));
    // The default (LiDAR realism: a model fitted from the keyframe's own HDL-32E sweep) and the ideal sensor.
    outcome_ = new FrameOutcome(SynthesizeFrame(*log_, 0, *assets_, *scenario_, SynthOptions{}));
    SynthOptions ideal;
    ideal.lidar_realism = false;
    ideal_ = new FrameOutcome(SynthesizeFrame(*log_, 0, *assets_, *scenario_, ideal));
    // The same, not harmonised: what harmonisation changed.
    SynthOptions unharmonised;
    unharmonised.harmonizer = "none";
    unharmonised_ = new FrameOutcome(SynthesizeFrame(*log_, 0, *assets_, *scenario_, unharmonised));
    // The render composited as it is: what the camera's look (blur, noise, JPEG) changed.
    SynthOptions bare;
    bare.camera_look = CameraLookOptions{false, false, false, false};
    no_look_ = new FrameOutcome(SynthesizeFrame(*log_, 0, *assets_, *scenario_, bare));
  }
  static void TearDownTestSuite() {
    delete no_look_;
    delete unharmonised_;
    delete ideal_;
    delete outcome_;
    delete scenario_;
    delete assets_;
    delete log_;
    delete dir_;
  }
  static testing::TempDir* dir_;
  static Log* log_;
  static std::vector<Asset>* assets_;
  static Scenario* scenario_;
  static FrameOutcome* outcome_;
  static FrameOutcome* ideal_;
  static FrameOutcome* unharmonised_;
  static FrameOutcome* no_look_;
};
testing::TempDir* PipelineTest::dir_ = nullptr;
Log* PipelineTest::log_ = nullptr;
std::vector<Asset>* PipelineTest::assets_ = nullptr;
Scenario* PipelineTest::scenario_ = nullptr;
FrameOutcome* PipelineTest::outcome_ = nullptr;
FrameOutcome* PipelineTest::ideal_ = nullptr;
FrameOutcome* PipelineTest::unharmonised_ = nullptr;
FrameOutcome* PipelineTest::no_look_ = nullptr;

// Distance from a point (ego frame) to an outcome's object mesh k.
double DistanceToObject(const FrameOutcome& o, int k, const Eigen::Vector3d& p) {
  TriangleMesh m = o.objects[static_cast<size_t>(k)].placement.asset->mesh;
  m.Transform(o.objects[static_cast<size_t>(k)].placement.T_ego_asset);
  double best = 1e9;
  for (const auto& t : m.faces)
    best = std::min(best, PointTriangleDistance(p, m.positions[t[0]].cast<double>(), m.positions[t[1]].cast<double>(),
                                                m.positions[t[2]].cast<double>()));
  return best;
}

// The object meshes of an outcome in the LiDAR frame, for casting the sensor's beams at them.
RayScene ObjectsInLidarFrame(const FrameOutcome& o, const Rigid3d& T_ego_lidar) {
  RayScene scene;
  for (const auto& ob : o.objects) {
    auto m = std::make_shared<TriangleMesh>(ob.placement.asset->mesh);
    m->Transform(T_ego_lidar.Inverse() * ob.placement.T_ego_asset);
    scene.AddMesh(m);
  }
  scene.Commit();
  return scene;
}

// Every random stream of a frame comes from the scenario seed and the frame index alone (so a shard draws what a
// local run draws), and no two frames or streams share a seed.
TEST(FrameSeeds, DependOnTheScenarioSeedAndTheFrameAlone) {
  const FrameSeeds a = FrameSeedsOf(7, 3), again = FrameSeedsOf(7, 3);
  EXPECT_EQ(a.placement, again.placement);
  EXPECT_EQ(a.render, again.render);
  EXPECT_EQ(a.lidar, again.lidar);
  std::set<uint32_t> placement, render;
  std::set<uint64_t> lidar, sensor;
  for (uint32_t seed : {0u, 7u, 8u})
    for (size_t frame = 0; frame < 50; ++frame) {
      const FrameSeeds s = FrameSeedsOf(seed, frame);
      placement.insert(s.placement);
      render.insert(s.render);
      lidar.insert(s.lidar);
      sensor.insert(s.sensor);
      if (frame > 0) {
        EXPECT_NE(s.placement, s.render);
      }
    }
  EXPECT_EQ(lidar.size(), 150u);
  EXPECT_EQ(sensor.size(), 150u);
  EXPECT_EQ(lidar.count(FrameSeedsOf(7, 3).sensor), 0u);
  EXPECT_EQ(placement.size(), 150u);
  EXPECT_GE(render.size(), 52u);  // seed + frame: neighbouring scenario seeds overlap (kept: every recorded figure was made with it)
}

// The camera's look (synth/camera_look.h) changes the inserted pixels, their shadows and their blurred rims only,
// never the labels,
// and is recorded per camera: the keyframe is a JPEG of quality 80.
TEST_F(PipelineTest, TheCameraLookTouchesTheInsertsOnlyAndIsRecorded) {
  ASSERT_EQ(outcome_->cameras.size(), no_look_->cameras.size());
  ASSERT_EQ(outcome_->objects.size(), no_look_->objects.size());
  for (size_t k = 0; k < outcome_->objects.size(); ++k) {
    const auto& a = outcome_->objects[k].label.camera_boxes;
    const auto& b = no_look_->objects[k].label.camera_boxes;
    ASSERT_EQ(a.size(), b.size());
    for (size_t i = 0; i < a.size(); ++i) {
      EXPECT_EQ(a[i].box.x1, b[i].box.x1);
      EXPECT_EQ(a[i].box.y2, b[i].box.y2);
      EXPECT_EQ(a[i].visible_fraction, b[i].visible_fraction);
    }
  }
  for (size_t c = 0; c < outcome_->cameras.size(); ++c) {
    const CameraOutcome& on = outcome_->cameras[c];
    const CameraOutcome& off = no_look_->cameras[c];
    ASSERT_EQ(on.channel, off.channel);
    ASSERT_FALSE(on.look.is_null()) << on.channel;
    EXPECT_EQ(on.look["jpeg_quality"], 80) << on.channel;
    EXPECT_GT(on.look["blur_sigma_px"].get<double>(), 0.5) << on.channel;  // 2-4 px edges against a 1 px render
    EXPECT_TRUE(off.look.is_null());
    // Every changed pixel lies within 8 px of an inserted object's box in this camera.
    std::vector<Box2> boxes;
    for (const ObjectOutcome& o : outcome_->objects)
      for (const CameraBox& cb : o.label.camera_boxes)
        if (cb.channel == on.channel) boxes.push_back(cb.box);
    size_t changed = 0;
    for (int y = 0; y < on.after.height(); ++y)
      for (int x = 0; x < on.after.width(); ++x) {
        bool differs = false;
        for (int ch = 0; ch < 3; ++ch) differs = differs || on.after.at(x, y, ch) != off.after.at(x, y, ch);
        if (!differs) continue;
        ++changed;
        bool near = false;
        for (const Box2& b : boxes) near = near || (x >= b.x1 - 8 && x < b.x2 + 8 && y >= b.y1 - 8 && y < b.y2 + 8);
        // Or at the objects' shadows, which the look blurs too: within 8 px of a pixel the bare composite darkened.
        for (int dy = -8; dy <= 8 && !near; ++dy)
          for (int dx = -8; dx <= 8 && !near; ++dx) {
            const int xx = x + dx, yy = y + dy;
            if (xx < 0 || yy < 0 || xx >= off.after.width() || yy >= off.after.height()) continue;
            for (int ch = 0; ch < 3; ++ch) near = near || off.after.at(xx, yy, ch) != off.before.at(xx, yy, ch);
          }
        ASSERT_TRUE(near) << on.channel << " pixel " << x << "," << y << " changed away from every object and shadow";
      }
    if (!on.objects.empty()) {  // a camera with only shadows of objects keeps them as they were
      EXPECT_GT(changed, 100u) << on.channel;
    }
  }
}

TEST_F(PipelineTest, PlacesEveryRequestedObjectWithoutTouchingRealOnes) {
  ASSERT_EQ(outcome_->objects.size(), 5u);
  ASSERT_EQ(outcome_->edit.added.size(), 5u);
  const Frame& f = log_->frames[0];
  for (size_t i = 0; i < outcome_->objects.size(); ++i) {
    const Box3& b = outcome_->objects[i].placement.box;
    for (const auto& a : f.annotations) EXPECT_FALSE(BoxesOverlap(b, a.box, scenario_->margin_m)) << "object " << i;
    for (size_t j = 0; j < i; ++j) EXPECT_FALSE(BoxesOverlap(b, outcome_->objects[j].placement.box, scenario_->margin_m));
    const auto& req = scenario_->objects[outcome_->objects[i].placement.request];
    EXPECT_GE(b.center().x(), req.distance_min - 1e-9);
    EXPECT_LE(b.center().x(), req.distance_max + 1e-9);
    EXPECT_TRUE(outcome_->ground.IsDrivable(b.center().x(), b.center().y()));
  }
}

TEST_F(PipelineTest, ObjectsRestOnTheLocalLidarGround) {
  for (const auto& o : outcome_->objects) {
    const Box3& b = o.placement.box;
    // Road returns in a ring 0.2..2 m around the footprint.
    std::vector<double> dz;
    const Rigid3d T_box_ego = b.T_frame_box.Inverse();
    for (const auto& p : outcome_->ground.ground_points()) {
      const Eigen::Vector3d l = T_box_ego * p;
      const double out = std::max(std::abs(l.x()) - 0.5 * b.size.x(), std::abs(l.y()) - 0.5 * b.size.y());
      if (out < 0.2 || out > 2.0 || !outcome_->ground.IsDrivable(p.x(), p.y())) continue;
      dz.push_back(p.z() - (b.center().z() - 0.5 * b.size.z()));
    }
    ASSERT_GE(dz.size(), 5u) << o.label.asset_id;
    std::nth_element(dz.begin(), dz.begin() + dz.size() / 2, dz.end());
    EXPECT_LT(std::abs(dz[dz.size() / 2]), 0.05) << o.label.asset_id << " bottom vs local ground";
  }
}

TEST_F(PipelineTest, RenderedMasksLieInsideTheProjected3DBoxes) {
  const Frame& f = log_->frames[0];
  int boxes = 0;
  for (const auto& o : outcome_->objects) {
    for (const auto& cb : o.label.camera_boxes) {
      const CameraSensor* cam = f.FindCamera(cb.channel);
      ASSERT_NE(cam, nullptr);
      double u0 = 1e9, v0 = 1e9, u1 = -1e9, v1 = -1e9;
      for (const auto& c : o.placement.box.Corners()) {
        const auto uv = cam->intrinsics.Project(cam->T_ego_cam.Inverse() * c);
        ASSERT_TRUE(uv.has_value());
        u0 = std::min(u0, uv->x()); v0 = std::min(v0, uv->y()); u1 = std::max(u1, uv->x()); v1 = std::max(v1, uv->y());
      }
      EXPECT_GE(cb.box.x1, std::floor(u0) - 1) << cb.channel;
      EXPECT_GE(cb.box.y1, std::floor(v0) - 1) << cb.channel;
      EXPECT_LE(cb.box.x2, std::ceil(u1) + 1) << cb.channel;
      EXPECT_LE(cb.box.y2, std::ceil(v1) + 1) << cb.channel;
      // A tight box of the mask covers a real share of the projected box (the mask is not a stray pixel).
      EXPECT_GT(cb.box.Area(), 0.2 * (u1 - u0) * (v1 - v0)) << cb.channel;
      ++boxes;
    }
  }
  EXPECT_GE(boxes, 5);  // every object is seen by CAM_FRONT at least
}

TEST_F(PipelineTest, EveryLidarPointOnAnObjectLiesOnItsSurface) {
  const Frame& f = log_->frames[0];
  // The ideal sensor: on the mesh, to float precision.
  ASSERT_FALSE(ideal_->lidar_object_points.empty());
  double worst = 0;
  for (const auto& [i, k] : ideal_->lidar_object_points)
    worst = std::max(worst, DistanceToObject(*ideal_, k, f.lidar->T_ego_lidar * ideal_->edit.points->xyz(i).cast<double>()));
  EXPECT_LT(worst, 0.01) << "metres from the asset surface";
  // With realism: off the surface by at most the range error, 5 fitted sigmas at the point's range.
  ASSERT_TRUE(outcome_->lidar_model_fit.has_value());
  const LidarModel& model = *outcome_->lidar_model_fit;
  ASSERT_FALSE(outcome_->lidar_object_points.empty());
  for (const auto& [i, k] : outcome_->lidar_object_points) {
    const Eigen::Vector3f p = outcome_->edit.points->xyz(i);
    EXPECT_LT(DistanceToObject(*outcome_, k, f.lidar->T_ego_lidar * p.cast<double>()), 5 * model.RangeSigma(p.norm()) + 1e-3) << i;
  }
  for (const FrameOutcome* o : {outcome_, ideal_})
    for (size_t k = 0; k < o->objects.size(); ++k) EXPECT_EQ(o->objects[k].label.annotation.num_lidar_pts, o->objects[k].lidar_points);
}

TEST_F(PipelineTest, UntouchedLidarPointsAreBitIdentical) {
  const PointCloud& before = ideal_->sweep_before;
  const PointCloud& after = *ideal_->edit.points;
  ASSERT_EQ(after.num_features, before.num_features);
  ASSERT_GE(after.size(), before.size());
  std::vector<uint8_t> touched(after.size(), 0);
  for (const auto& [i, k] : ideal_->lidar_object_points) touched[i] = 1;
  size_t moved = 0;
  for (size_t i = 0; i < before.size(); ++i) {
    if (touched[i]) { ++moved; continue; }
    for (int c = 0; c < before.num_features; ++c) ASSERT_EQ(std::memcmp(&before.data[i * before.num_features + c], &after.data[i * after.num_features + c], 4), 0) << i;
  }
  // Moved points only get nearer: the object blocks the beam before the original return.
  for (const auto& [i, k] : ideal_->lidar_object_points)
    if (static_cast<size_t>(i) < before.size()) {
      EXPECT_LT(after.xyz(i).norm(), before.xyz(i).norm());
    }
  EXPECT_GT(moved, 0u);
}

// With realism a blocked return whose simulated return drops out leaves the cloud, so indices shift: the
// untouched points of the output are, in order, bit-identical records of the input, and the input records
// they skip are exactly the moved ones plus the dropped-out ones.
TEST_F(PipelineTest, UntouchedLidarPointsAreBitIdenticalWithRealism) {
  const PointCloud& before = outcome_->sweep_before;
  const PointCloud& after = *outcome_->edit.points;
  const int nf = before.num_features;
  ASSERT_EQ(after.num_features, nf);
  std::vector<uint8_t> touched(after.size(), 0);
  for (const auto& [i, k] : outcome_->lidar_object_points) touched[i] = 1;
  size_t j = 0, skipped = 0, untouched = 0;
  for (size_t i = 0; i < after.size(); ++i) {
    if (touched[i]) continue;
    while (j < before.size() && std::memcmp(&before.data[j * nf], &after.data[i * nf], 4 * nf) != 0) ++j, ++skipped;
    ASSERT_LT(j, before.size()) << "output point " << i << " is no input record (in order)";
    ++j;
    ++untouched;
  }
  skipped += before.size() - j;
  size_t on_objects = 0;
  for (const auto& o : outcome_->objects) on_objects += static_cast<size_t>(o.lidar_points);
  EXPECT_EQ(on_objects, outcome_->lidar_object_points.size());
  // Every input record is kept untouched, moved onto an object, or dropped: skipped ones are not kept.
  EXPECT_EQ(untouched + skipped, before.size());
  EXPECT_GT(skipped, 0u);
  // Skipped = moved onto an object (at most every object point) + dropped out (a few % of those blocked).
  EXPECT_LE(skipped, outcome_->lidar_object_points.size() + before.size() / 100);
}

// The fitted range noise shows up on the inserted objects: each object return lies on its beam (the ray from the
// sensor through it) at the mesh's range plus an error whose spread is the model's sigma at that range.
TEST_F(PipelineTest, ObjectReturnsScatterWithTheFittedRangeSigma) {
  const Frame& f = log_->frames[0];
  ASSERT_TRUE(outcome_->lidar_model_fit.has_value());
  const LidarModel& model = *outcome_->lidar_model_fit;
  EXPECT_EQ(outcome_->lidar_model, model.Summary());
  EXPECT_EQ(model.beams.size(), 32u);
  EXPECT_GT(model.RangeSigma(10), 0.005);
  EXPECT_FALSE(outcome_->lidar_ego_motion);  // one keyframe: no neighbours, no ego motion
  EXPECT_EQ(ideal_->lidar_model, "off");
  EXPECT_FALSE(ideal_->lidar_model_fit.has_value());
  auto normalised_errors = [&](const FrameOutcome& o, double* worst_abs) {
    const RayScene scene = ObjectsInLidarFrame(o, f.lidar->T_ego_lidar);
    std::vector<double> z;
    *worst_abs = 0;
    for (const auto& [i, k] : o.lidar_object_points) {
      const Eigen::Vector3f p = o.edit.points->xyz(i);
      const RayHit hit = scene.Intersect(Eigen::Vector3f::Zero(), p.normalized(), 0.3f);
      if (!hit.Hit()) continue;  // noise pushed a grazing return off the silhouette
      const double err = p.norm() - hit.t;
      *worst_abs = std::max(*worst_abs, std::abs(err));
      z.push_back(err / model.RangeSigma(hit.t));
    }
    return z;
  };
  double ideal_worst = 0, real_worst = 0;
  const std::vector<double> zi = normalised_errors(*ideal_, &ideal_worst);
  EXPECT_LT(ideal_worst, 1e-3) << "ideal sensor: returns exactly on the mesh";
  std::vector<double> z = normalised_errors(*outcome_, &real_worst);
  ASSERT_GE(z.size(), 150u);  // ~190 returns on the demo's five small objects
  double mean = 0, var = 0;
  for (double v : z) mean += v;
  mean /= z.size();
  for (double v : z) var += (v - mean) * (v - mean);
  const double sd = std::sqrt(var / (z.size() - 1));
  std::vector<double> a;
  for (double v : z) a.push_back(std::abs(v - mean));
  std::nth_element(a.begin(), a.begin() + a.size() / 2, a.end());
  const double robust = 1.4826 * a[a.size() / 2];
  std::cout << z.size() << " object returns: mean error " << mean << " sigma, sd " << sd << " sigma, robust sd " << robust
            << " sigma (model sigma(10 m) = " << model.RangeSigma(10) * 100 << " cm); worst |error| " << real_worst * 100 << " cm\n";
  // Bounds of 3-4 standard errors of each estimate for n normal samples (sd: 1/sqrt(2n); median absolute
  // deviation: about 1.65/sqrt(2n)).
  const double n = static_cast<double>(z.size());
  EXPECT_LT(std::abs(mean), 4 / std::sqrt(n));
  EXPECT_NEAR(sd, 1.0, 3 / std::sqrt(2 * n));
  EXPECT_NEAR(robust, 1.0, 3 * 1.65 / std::sqrt(2 * n));
}

// lidar_realism = false is the pipeline as it was: SimulateLidar with no realism on the same placements and
// reference intensities, bit for bit; realism changes the sweep only (same placements, same images).
TEST_F(PipelineTest, NoLidarRealismIsTheIdealSensorExactly) {
  const Frame& f = log_->frames[0];
  const PointCloud& sweep = ideal_->sweep_before;
  std::vector<Eigen::Vector3d> points_ego;
  for (size_t i = 0; i < sweep.size(); ++i) points_ego.push_back(f.lidar->T_ego_lidar * sweep.xyz(i).cast<double>());
  std::vector<std::pair<std::string, Box3>> annotated;
  for (const auto& a : f.annotations) annotated.push_back({a.category, a.box});
  std::vector<const PlacedObject*> ptrs;
  for (const auto& o : ideal_->objects) ptrs.push_back(&o.placement);
  LidarSimInput in;
  in.sweep = &sweep;
  in.T_ego_lidar = f.lidar->T_ego_lidar;
  in.objects = ptrs;
  in.reference_intensity = ReferenceIntensities(sweep, points_ego, ideal_->ground.ground_indices(), annotated, ptrs);
  const LidarSimResult plain = SimulateLidar(in);
  ASSERT_EQ(plain.cloud.data.size(), ideal_->edit.points->data.size());
  EXPECT_EQ(std::memcmp(plain.cloud.data.data(), ideal_->edit.points->data.data(), 4 * plain.cloud.data.size()), 0);
  EXPECT_EQ(plain.object_points, ideal_->lidar_object_points);

  ASSERT_EQ(outcome_->objects.size(), ideal_->objects.size());
  for (size_t k = 0; k < ideal_->objects.size(); ++k)
    EXPECT_EQ(outcome_->objects[k].placement.T_ego_asset.translation, ideal_->objects[k].placement.T_ego_asset.translation);
  ASSERT_EQ(outcome_->cameras.size(), ideal_->cameras.size());
  for (size_t c = 0; c < ideal_->cameras.size(); ++c) EXPECT_EQ(outcome_->cameras[c].after.vector(), ideal_->cameras[c].after.vector());
  EXPECT_NE(outcome_->edit.points->data, ideal_->edit.points->data);
}

TEST_F(PipelineTest, ImagesChangeOnlyNearTheObjects) {
  const Frame& f = log_->frames[0];
  ASSERT_FALSE(outcome_->cameras.empty());
  for (const auto& co : outcome_->cameras) {
    ASSERT_EQ(co.before.width(), co.after.width());
    // Pixels more than 60 px outside every object's projected box + shadow zone keep their value; here we
    // check the image's top rows (sky/buildings above every inserted object) exactly.
    const CameraSensor* cam = f.FindCamera(co.channel);
    double top = 1e9;
    for (const auto& o : outcome_->objects)
      for (const auto& c : o.placement.box.Corners()) {
        const auto uv = cam->intrinsics.Project(cam->T_ego_cam.Inverse() * c);
        if (uv) top = std::min(top, uv->y());
      }
    const int rows = std::max(0, static_cast<int>(top) - 60);
    for (int y = 0; y < rows; ++y)
      for (int x = 0; x < co.before.width(); ++x)
        for (int c = 0; c < 3; ++c) ASSERT_EQ(co.before.at(x, y, c), co.after.at(x, y, c)) << co.channel << " " << x << "," << y;
  }
  EXPECT_TRUE(outcome_->edit.images.count("CAM_FRONT"));
  EXPECT_FALSE(outcome_->edit.images.count("CAM_BACK"));
}

TEST_F(PipelineTest, SameSeedSameResult) {
  const FrameOutcome again = SynthesizeFrame(*log_, 0, *assets_, *scenario_, SynthOptions{});
  ASSERT_EQ(again.objects.size(), outcome_->objects.size());
  for (size_t i = 0; i < again.objects.size(); ++i)
    EXPECT_TRUE(again.objects[i].placement.box.center().isApprox(outcome_->objects[i].placement.box.center(), 1e-12));
  EXPECT_EQ(again.edit.points->data, outcome_->edit.points->data);  // realism's noise and dropout are seeded
  EXPECT_EQ(again.lidar_model, outcome_->lidar_model);
  ASSERT_EQ(again.cameras.size(), outcome_->cameras.size());
  for (size_t c = 0; c < again.cameras.size(); ++c)  // soft shadows and AO are seeded per pixel
    EXPECT_EQ(again.cameras[c].after.vector(), outcome_->cameras[c].after.vector()) << again.cameras[c].channel;
}

// The cameras and the LiDAR of a frame run at once, and stages within a camera split their work over threads; the
// outcome must not depend on it: one thread gives every image, label and sweep bit for bit as all of them do.
TEST_F(PipelineTest, OneThreadGivesTheSameOutcome) {
  if (MaxThreads() < 2) GTEST_SKIP() << "this machine runs one thread: nothing to compare";
  SetMaxThreads(1);
  const FrameOutcome serial = SynthesizeFrame(*log_, 0, *assets_, *scenario_, SynthOptions{});
  SetMaxThreads(0);
  EXPECT_EQ(serial.edit.points->data, outcome_->edit.points->data);
  ASSERT_EQ(serial.cameras.size(), outcome_->cameras.size());
  ASSERT_GE(serial.cameras.size(), 2u);  // at least two cameras ran at once
  for (size_t c = 0; c < serial.cameras.size(); ++c) {
    EXPECT_EQ(serial.cameras[c].channel, outcome_->cameras[c].channel);
    EXPECT_EQ(serial.cameras[c].after.vector(), outcome_->cameras[c].after.vector()) << serial.cameras[c].channel;
    EXPECT_EQ(serial.cameras[c].light, outcome_->cameras[c].light);
    EXPECT_EQ(serial.cameras[c].look.dump(), outcome_->cameras[c].look.dump());
  }
  ASSERT_EQ(serial.objects.size(), outcome_->objects.size());
  for (size_t i = 0; i < serial.objects.size(); ++i) {
    const ObjectOutcome &a = serial.objects[i], &b = outcome_->objects[i];
    EXPECT_EQ(a.rendered_pixels, b.rendered_pixels);
    EXPECT_EQ(a.visible_pixels, b.visible_pixels);
    EXPECT_EQ(a.lidar_points, b.lidar_points);
    ASSERT_EQ(a.label.camera_boxes.size(), b.label.camera_boxes.size());
    for (size_t k = 0; k < a.label.camera_boxes.size(); ++k) {
      EXPECT_EQ(a.label.camera_boxes[k].channel, b.label.camera_boxes[k].channel);
      EXPECT_EQ(a.label.camera_boxes[k].box.x1, b.label.camera_boxes[k].box.x1);
      EXPECT_EQ(a.label.camera_boxes[k].box.y2, b.label.camera_boxes[k].box.y2);
      EXPECT_EQ(a.label.camera_boxes[k].visible_fraction, b.label.camera_boxes[k].visible_fraction);
    }
  }
}

TEST_F(PipelineTest, EnvironmentLightIsRecordedPerFrameAndCamera) {
  EXPECT_EQ(outcome_->light.rfind("environment map 512x256: sun ", 0), 0u) << outcome_->light;
  EXPECT_NE(outcome_->light.find("seam error"), std::string::npos) << outcome_->light;
  ASSERT_FALSE(outcome_->cameras.empty());
  for (const auto& co : outcome_->cameras) {
    EXPECT_EQ(co.light.rfind("sun visibility ", 0), 0u) << co.channel << ": " << co.light;
    EXPECT_NE(co.light.find("road pixels"), std::string::npos) << co.light;
    // Every object drawn here with its own road in view has its own verdict, the same in every camera.
    if (co.channel == "CAM_FRONT") {
      EXPECT_NE(co.light.find("per object (sun visibility x scale): #0 "), std::string::npos) << co.light;
    }
  }
}

TEST_F(PipelineTest, ObjectsInFrontOfEveryRealOneAreFullyVisible) {
  // The road never hides an object standing on it (a few centimetres of road height error at a grazing view
  // would cut its feet off): an object with no real object nearer to the camera across its camera box keeps
  // (almost) all its pixels.
  const Frame& f = log_->frames[0];
  int checked = 0;
  for (const auto& ob : outcome_->objects)
    for (const CameraBox& cb : ob.label.camera_boxes) {
      const CameraSensor* cam = f.FindCamera(cb.channel);
      ASSERT_NE(cam, nullptr);
      const Rigid3d T_cam_ego = cam->T_ego_cam.Inverse();
      const double depth = (T_cam_ego * ob.placement.box.center()).z();
      bool occluder = false;
      for (const auto& a : f.annotations) {
        double u0 = 1e18, v0 = 1e18, u1 = -1e18, v1 = -1e18, near = 1e18;
        for (const auto& c : a.box.Corners()) {
          const Eigen::Vector3d p = T_cam_ego * c;
          near = std::min(near, p.z());
          const auto uv = cam->intrinsics.Project(p, 0.1);
          if (!uv) continue;
          u0 = std::min(u0, uv->x()), v0 = std::min(v0, uv->y()), u1 = std::max(u1, uv->x()), v1 = std::max(v1, uv->y());
        }
        if (near < depth && u0 < cb.box.x2 && cb.box.x1 < u1 && v0 < cb.box.y2 && cb.box.y1 < v1) occluder = true;
      }
      if (occluder) continue;
      EXPECT_GT(cb.visible_fraction, 0.97) << ob.label.category << " in " << cb.channel;
      ++checked;
    }
  EXPECT_GE(checked, 3);
}

TEST_F(PipelineTest, HarmonisationChangesTheObjectsOnly) {
  ASSERT_EQ(unharmonised_->cameras.size(), outcome_->cameras.size());
  size_t changed = 0;
  for (size_t c = 0; c < outcome_->cameras.size(); ++c) {
    const CameraOutcome& h = outcome_->cameras[c];
    const CameraOutcome& u = unharmonised_->cameras[c];
    ASSERT_EQ(h.channel, u.channel);
    EXPECT_NE(h.light.find("harmonised"), std::string::npos) << h.light;
    EXPECT_EQ(u.light.find("harmonised"), std::string::npos) << u.light;
    for (int y = 0; y < h.after.height(); ++y)
      for (int x = 0; x < h.after.width(); ++x) {
        bool differs = false;
        for (int k = 0; k < 3; ++k) differs |= h.after.at(x, y, k) != u.after.at(x, y, k);
        if (!differs) continue;
        ++changed;
        bool on_object = false;  // within 2 px of an object's visible box in this camera
        for (const auto& ob : outcome_->objects)
          for (const CameraBox& cb : ob.label.camera_boxes)
            on_object |= cb.channel == h.channel && x >= cb.box.x1 - 2 && x < cb.box.x2 + 2 && y >= cb.box.y1 - 2 && y < cb.box.y2 + 2;
        ASSERT_TRUE(on_object) << h.channel << " pixel " << x << "," << y << " changed off every object";
      }
  }
  EXPECT_GT(changed, 0u) << "harmonisation changed nothing";
}

TEST_F(PipelineTest, ImpossibleScenarioIsAnErrorNamingTheObject) {
  Scenario crowded = *scenario_;
  crowded.objects = {ObjectRequest{}};
  crowded.objects[0].category = "car";
  crowded.objects[0].count = 60;
  crowded.objects[0].distance_min = 6;
  crowded.objects[0].distance_max = 12;
  try {
    SynthesizeFrame(*log_, 0, *assets_, crowded, SynthOptions{});
    FAIL() << "60 cars fit in 6 m of road";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("impossible scenario"), std::string::npos) << e.what();
  }
}


// A sweep the model cannot be fitted from (its ring feature relabelled into 500 "lasers" of under 100 returns; a
// fit needs one with 100) is synthesised with the ideal sensor, "off", exactly as lidar_realism = false does,
// instead of failing the frame.
TEST(LidarRealismFallback, ASweepTooSparseToFitGetsTheIdealSensor) {
  testing::TempDir dir;
  const std::vector<Asset> assets = DemoAssets(dir);
  Log log = OpenLog(testing::RepoData(kInfo));
  PointCloud thin = ReadLidar(*log.frames[0].lidar);
  const int ring = thin.FeatureIndex("ring");
  ASSERT_GE(ring, 0);
  ASSERT_LT(thin.size(), 500u * 100u);
  for (size_t i = 0; i < thin.size(); ++i) thin.data[i * thin.num_features + ring] = static_cast<float>(i % 500);
  log.frames[0].lidar->path = dir.path() / "thin.bin";
  WritePointCloudBin(log.frames[0].lidar->path, thin);
  WriteFileAtomic(dir.path() / "cone.json",
                  R"({"seed": 3, "objects": [{"category": "traffic_cone", "count": 1, "distance_m": [6, 15], "lateral_m": [-3, 3]}]})");
  const Scenario scenario = ReadScenario(dir.path() / "cone.json");
  SynthOptions opt;
  opt.samples_per_pixel = 1;
  opt.ao_samples = 2;
  const FrameOutcome o = SynthesizeFrame(log, 0, assets, scenario, opt);
  EXPECT_EQ(o.lidar_model, "off");
  EXPECT_FALSE(o.lidar_model_fit.has_value());
  opt.lidar_realism = false;
  const FrameOutcome ideal = SynthesizeFrame(log, 0, assets, scenario, opt);
  ASSERT_EQ(o.objects.size(), 1u);
  EXPECT_GT(o.objects[0].lidar_points, 0);
  EXPECT_EQ(o.edit.points->data, ideal.edit.points->data);
  EXPECT_EQ(o.lidar_object_points, ideal.lidar_object_points);
}

// ---------------------------------------------------------------------------------------------------------
// World-fixed synthesis over several frames (one SequencePlan) and the dry run.

// A lane closure of demo cones and a barrier among the roadside clutter, placed once for the sequence.
const char* kWorldFixedScenario = R"({"seed": 5, "margin_m": 0.5, "arrangements": [
  {"type": "lane_closure", "category": "traffic_cone", "count": 3, "spacing_m": 3, "distance_m": [8, 30], "side": "right"},
  {"type": "roadside_clutter", "categories": ["barrier"], "count": 1, "distance_m": [5, 25], "lateral_m": [3, 7]}]})";

// The repo keyframe followed by a copy of it 0.5 s later with the ego 1.5 m further along and turned 2 degrees:
// the same sensor data, so any difference between the frames' labels comes from the ego pose alone.
Log TwoFrameLog() {
  Log log = OpenLog(testing::RepoData(kInfo));
  Frame second = log.frames[0];
  second.token = "moved-copy";
  second.timestamp += 0.5;
  second.T_world_ego = log.frames[0].T_world_ego * Rigid3d::FromYaw(2 * M_PI / 180, Eigen::Vector3d(1.5, 0, 0));
  log.frames.push_back(second);
  return log;
}

TEST(WorldFixedSynthesis, AnArrangedObjectHasOneWorldPoseInEveryFramesLabels) {
  testing::TempDir dir;
  const std::vector<Asset> assets = DemoAssets(dir);
  WriteFileAtomic(dir / "scenario.json", kWorldFixedScenario);
  const Scenario scenario = ReadScenario(dir / "scenario.json");
  const Log log = TwoFrameLog();
  const SynthPlan plan = PlanSynthesis(log, {0, 1}, scenario, assets, dir / "scenario.json", true);
  ASSERT_EQ(plan.sequences.size(), 1u);  // 0.5 s apart: one sequence
  EXPECT_EQ(plan.sequences[0].surface, "road_surface");
  const SequencePlan& p = plan.sequences[0].plan;
  ASSERT_EQ(p.objects.size(), 4u);
  ASSERT_EQ(plan.ForFrame(1), &p);
  SynthOptions opt;
  opt.samples_per_pixel = 1;
  opt.ao_samples = 2;
  std::map<int, int> frames_labelled;  // plan object -> frames whose labels hold it
  for (size_t fi : {0u, 1u}) {
    const FrameOutcome o = SynthesizeFrame(log, fi, assets, scenario, opt, plan.ForFrame(fi));
    const Rigid3d& T_world_ego = log.frames[fi].T_world_ego;
    EXPECT_TRUE(o.lidar_ego_motion) << "frame " << fi << ": its neighbour 0.5 s away gives the ego's motion";
    EXPECT_NE(o.lidar_model, "off");
    ASSERT_EQ(o.edit.added.size(), o.objects.size());
    for (size_t k = 0; k < o.objects.size(); ++k) {
      const ObjectOutcome& ob = o.objects[k];
      ASSERT_GE(ob.plan_object, 0);
      const PlannedObject& po = p.objects[static_cast<size_t>(ob.plan_object)];
      ++frames_labelled[ob.plan_object];
      // The label (ego frame) mapped back to the world is the plan's one world box, in every frame.
      const Box3 world = o.edit.added[k].annotation.box.Transformed(T_world_ego);
      EXPECT_LT((world.center() - po.box.center()).norm(), 1e-9) << "frame " << fi << " object " << ob.plan_object;
      EXPECT_LT(world.T_frame_box.rotation.angularDistance(po.box.T_frame_box.rotation), 1e-9);
      EXPECT_EQ(world.size, po.box.size);
      EXPECT_EQ(o.edit.added[k].asset_id, po.asset_id);
      EXPECT_TRUE(ob.lidar_points > 0 || !ob.label.camera_boxes.empty());  // unobserved objects get no label
      for (const auto& a : log.frames[fi].annotations) EXPECT_FALSE(BoxesOverlap(ob.placement.box, a.box, 0.49));
    }
  }
  // The ego moved, so the same world pose is a different ego-frame pose; every cone of the closure, 8..36 m
  // ahead, is observed in both frames.
  for (int i = 0; i < 3; ++i) EXPECT_EQ(frames_labelled[i], 2) << "cone " << i;
  const Rigid3d T0 = p.frames[0].objects[0].T_ego_object, T1 = p.frames[1].objects[0].T_ego_object;
  EXPECT_GT((T0.translation - T1.translation).norm(), 1.4);
}

TEST(WorldFixedSynthesis, AnArrangementWithoutAnAssetOfItsCategoryIsRefusedBeforeRendering) {
  testing::TempDir dir;
  const std::vector<Asset> assets = DemoAssets(dir);
  WriteFileAtomic(dir / "debris.json", R"({"arrangements": [{"type": "ego_lane_object", "category": "debris", "distance_m": [10, 30]}]})");
  const Log log = OpenLog(testing::RepoData(kInfo));
  try {
    PlanSynthesis(log, {0}, ReadScenario(dir / "debris.json"), assets, dir / "debris.json", true);
    FAIL() << "no error";
  } catch (const InputError& e) {
    const std::string m = e.what();
    EXPECT_NE(m.find("debris.json: arrangements[0] places a debris"), std::string::npos) << m;
    EXPECT_EQ(m.find('\n'), std::string::npos);
  }
  // Unsatisfiable: a closure longer than the whole visible world.
  WriteFileAtomic(dir / "long.json", R"({"arrangements": [{"type": "lane_closure", "count": 80, "spacing_m": 3, "distance_m": [8, 9]}]})");
  try {
    PlanSynthesis(log, {0}, ReadScenario(dir / "long.json"), assets, dir / "long.json", true);
    FAIL() << "no error";
  } catch (const InputError& e) {
    const std::string m = e.what();
    EXPECT_EQ(m.rfind((dir / "long.json").string() + ": impossible scenario: arrangements[0]", 0), 0u) << m;
  }
}

// Every planned object's box, in every planned frame's ego frame, against that frame's annotated boxes.
size_t CountOverlaps(const Log& log, const SynthPlan& plan, double margin, size_t* pairs) {
  size_t overlaps = 0;
  for (const auto& s : plan.sequences)
    for (const PlannedFrame& f : s.plan.frames)
      for (const auto& a : log.frames[f.frame_index].annotations)
        for (const PlannedView& v : f.objects) {
          ++*pairs;
          overlaps += BoxesOverlap(v.box_ego, a.box, margin) || FootprintsOverlap(v.box_ego, a.box, margin) ? 1 : 0;
        }
  return overlaps;
}

TEST(SynthDryRun, PlansTheRepoKeyframeOnItsLidarRoadSurface) {
  testing::TempDir dir;
  WriteFileAtomic(dir / "scenario.json", kWorldFixedScenario);
  SynthRequest r;
  r.log = testing::RepoData(kInfo);
  r.scenario = dir / "scenario.json";
  r.out = dir / "plan";
  const DryRunSummary s = RunSynthDryRun(r);  // no assets: categories at their default sizes
  ASSERT_EQ(s.plan.sequences.size(), 1u);
  EXPECT_EQ(s.plan.sequences[0].surface, "road_surface");
  EXPECT_EQ(s.objects, 4u);
  const nlohmann::json j = ReadJsonFile(dir / "plan" / "plan.json");
  ASSERT_EQ(j["sequences"].size(), 1u);
  EXPECT_EQ(j["sequences"][0]["objects"].size(), 4u);
  EXPECT_EQ(j["sequences"][0]["per_frame"].size(), 1u);
  EXPECT_EQ(j["scenario"]["seed"], 5);
  EXPECT_EQ(j["sequences"][0]["rejections"][0]["placed"], 1);
  const std::string html = ReadFileToString(dir / "plan" / "plan.html");
  EXPECT_NE(html.find("<svg"), std::string::npos);
  size_t titles = 0;  // one titled footprint per placed object
  for (size_t at = html.find("</title></polygon>"); at != std::string::npos; at = html.find("</title></polygon>", at + 1)) ++titles;
  EXPECT_EQ(titles, 4u);
  const Log log = OpenLog(testing::RepoData(kInfo));
  size_t pairs = 0;
  EXPECT_EQ(CountOverlaps(log, s.plan, 0.49, &pairs), 0u);
  EXPECT_EQ(pairs, 69u * 4u);
  // Every object stands on the LiDAR road: its ground contact within 5 cm of its box bottom, and the road near
  // the ego origin's height (nuScenes: the rear axle projected on the ground; the LiDAR is 1.84 m above it).
  for (const PlannedView& v : s.plan.sequences[0].plan.frames[0].objects) {
    const double bottom = v.box_ego.center().z() - 0.5 * v.box_ego.size.z();
    EXPECT_NEAR(bottom, v.T_ego_object.translation.z(), 0.05);
    EXPECT_LT(std::abs(bottom), 0.5);
  }
  // A second dry run into the same folder is refused, the first left as it was.
  EXPECT_THROW(RunSynthDryRun(r), InputError);
}

TEST(SynthDryRun, NuScenesMiniValInfosWithoutSensorFilesPlanBothScenesWithoutOverlaps) {
  SD_REQUIRE_SHARED(info, "driving/nuscenes-mini-val-infos/nuscenes_infos_val.json");
  testing::TempDir dir;
  WriteFileAtomic(dir / "scenario.json", R"({"seed": 11, "margin_m": 0.5, "arrangements": [
    {"type": "lane_closure", "count": 6, "spacing_m": 3, "distance_m": [125, 145], "side": "right"},
    {"type": "ego_lane_object", "category": "debris", "distance_m": [125, 160]},
    {"type": "roadside_clutter", "categories": ["traffic_cone", "a_frame_sign", "debris"], "count": 6, "distance_m": [0, 120],
     "lateral_m": [2.5, 6]},
    {"type": "breakdown", "vehicle": "car", "warning": "warning_tripod", "position": "shoulder", "side": "right",
     "distance_m": [20, 120], "setting": "city"}]})");
  SynthRequest r;
  r.log = info;
  r.scenario = dir / "scenario.json";
  r.out = dir / "plan";
  const DryRunSummary s = RunSynthDryRun(r);
  ASSERT_EQ(s.plan.sequences.size(), 2u);  // two scenes, cut at the time gap
  EXPECT_EQ(s.plan.sequences[0].plan.frame_begin, 0u);
  EXPECT_EQ(s.plan.sequences[0].plan.frame_end, 40u);
  EXPECT_EQ(s.plan.sequences[1].plan.frame_begin, 40u);
  EXPECT_EQ(s.plan.sequences[1].plan.frame_end, 81u);
  for (const auto& seq : s.plan.sequences) EXPECT_EQ(seq.surface, "ego_poses");  // no sweeps on disk
  EXPECT_EQ(s.objects, 30u);
  const Log log = OpenLog(info);
  size_t pairs = 0;
  EXPECT_EQ(CountOverlaps(log, s.plan, 0.49, &pairs), 0u);
  EXPECT_EQ(pairs, 4514u * 15u);
  const nlohmann::json j = ReadJsonFile(dir / "plan" / "plan.json");
  EXPECT_EQ(j["sequences"][1]["per_frame"].size(), 41u);
  EXPECT_TRUE(fs::exists(dir / "plan" / "plan.html"));
}

TEST(SynthDryRun, Argoverse2LogWithTwoOfItsSweepsPlansOnTheirRoadSurface) {
  SD_REQUIRE_SHARED(av2, "driving/argoverse2-av2-api/val/7fab2350-7eaf-3b7e-a39d-6937a4c1bede");
  testing::TempDir dir;
  WriteFileAtomic(dir / "scenario.json", R"({"seed": 3, "arrangements": [
    {"type": "roadside_clutter", "categories": ["traffic_cone", "debris"], "count": 4, "distance_m": [5, 60], "lateral_m": [2.5, 6]},
    {"type": "lane_closure", "count": 6, "distance_m": [80, 100]}]})");
  SynthRequest r;
  r.log = av2;
  r.scenario = dir / "scenario.json";
  r.out = dir / "plan";
  const DryRunSummary s = RunSynthDryRun(r);
  ASSERT_EQ(s.plan.sequences.size(), 1u);
  EXPECT_EQ(s.plan.sequences[0].surface, "road_surface");
  EXPECT_EQ(s.plan.sequences[0].plan.frames.size(), 156u);
  EXPECT_EQ(s.objects, 10u);
  const Log log = OpenLog(av2);
  size_t pairs = 0;
  EXPECT_EQ(CountOverlaps(log, s.plan, 0.49, &pairs), 0u);
  EXPECT_EQ(pairs, 11364u * 10u);
  // Rendering into an Argoverse 2 log is refused up front, in one line naming the log.
  r.out = dir / "synth";
  r.assets = {};
  try {
    RunSynth(r);
    FAIL() << "no error";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("writing Argoverse 2 logs is not supported"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(fs::exists(dir / "synth"));
}
}  // namespace
}  // namespace sd
