#include "synth/sequence_plan.h"

#include <cmath>
#include <fstream>

#include <gtest/gtest.h>

#include "core/error.h"
#include "datasets/readers.h"
#include "io/geometry_json.h"
#include "testing/testing.h"

namespace sd {
namespace {

constexpr double kPi = 3.14159265358979323846;

Scenario Parse(const std::string& text) {
  testing::TempDir dir;
  const auto p = dir / "scenario.json";
  std::ofstream(p) << text;
  return ReadScenario(p);
}

// A straight drive along world +x at `speed` m/s, 2 Hz keyframes, no cameras (every in-range object counts
// as visible), boxes known in every frame.
Log StraightLog(int frames, double speed) {
  Log log;
  log.format = LogFormat::kNuScenesTables;
  for (int k = 0; k < frames; ++k) {
    Frame f;
    f.token = Msg() << "f" << k;  // (not "f" + to_string: GCC 12 warns -Wrestrict on it here, falsely)
    f.timestamp = 0.5 * k;
    f.T_world_ego = Rigid3d::FromYaw(0, Eigen::Vector3d(speed * f.timestamp, 0, 0));
    f.has_annotations = true;
    log.frames.push_back(f);
  }
  return log;
}

// A car driving along world +y across x = `x` at 20 m/s: at y = -5 in frame 3 and y = +5 in frame 4, so
// its keyframe boxes (4.6 m long) leave y in (-2.7, 2.7) free: only interpolation sees it cross y = 0.
void AddCrossingCar(Log* log, double x, bool track_ids, bool velocity) {
  for (size_t k = 0; k < log->frames.size(); ++k) {
    Frame& f = log->frames[k];
    Annotation a;
    a.category = "car";
    const Box3 world{Rigid3d::FromYaw(kPi / 2, Eigen::Vector3d(x, -5 + 10.0 * (static_cast<double>(k) - 3), 0.85)),
                     Eigen::Vector3d(4.6, 1.9, 1.7)};
    a.box = world.Transformed(f.T_world_ego.Inverse());
    if (track_ids) a.instance_token = "crossing-car";
    if (velocity) a.velocity = (f.T_world_ego.rotation.conjugate() * Eigen::Vector3d(0, 20, 0)).head<2>();
    f.annotations.push_back(a);
  }
}

const char* kOneCone = R"({"seed": 3, "margin_m": 0.5, "arrangements": [
    {"type": "ego_lane_object", "category": "traffic_cone", "distance_m": [40, 40], "lateral_m": [0, 0], "yaw": 0}]})";

std::string PlanError(const Log& log, const Scenario& s) {
  try {
    PlanSequence(log, s, PlaneSurface());
  } catch (const InputError& e) {
    return e.what();
  }
  return "";
}

TEST(EgoPath, ArcLengthAndLateralRoundTripAndExtendStraight) {
  // An L: 10 m east, then 10 m north (knots closer than 1 m merge).
  std::vector<Rigid3d> poses;
  for (int i = 0; i <= 10; ++i) poses.push_back(Rigid3d::FromYaw(0, Eigen::Vector3d(i, 0, 0)));
  poses.push_back(Rigid3d::FromYaw(0, Eigen::Vector3d(10, 0.4, 0)));
  for (int i = 1; i <= 10; ++i) poses.push_back(Rigid3d::FromYaw(kPi / 2, Eigen::Vector3d(10, i, 0)));
  const EgoPath path(poses);
  EXPECT_DOUBLE_EQ(path.length(), 20.0);
  EXPECT_TRUE(path.At(5, 2).isApprox(Eigen::Vector2d(5, 2)));
  EXPECT_TRUE(path.At(15, 2).isApprox(Eigen::Vector2d(8, 5)));    // left of north = west
  EXPECT_TRUE(path.At(30, -1).isApprox(Eigen::Vector2d(11, 20)));  // extended straight north
  EXPECT_TRUE(path.At(-4, 1).isApprox(Eigen::Vector2d(-4, 1)));    // and straight back west of the start
  EXPECT_NEAR(path.Heading(15), kPi / 2, 1e-12);
  for (const Eigen::Vector2d& sl : {Eigen::Vector2d(5, 2), Eigen::Vector2d(15, -1.5), Eigen::Vector2d(30, 1), Eigen::Vector2d(-4, 1)})
    EXPECT_TRUE(path.Project(path.At(sl.x(), sl.y())).isApprox(sl, 1e-12)) << sl.transpose();
  // A standing ego: a straight line along its heading.
  const EgoPath still({Rigid3d::FromYaw(kPi / 2, Eigen::Vector3d(3, 4, 0)), Rigid3d::FromYaw(kPi / 2, Eigen::Vector3d(3, 4.2, 0))});
  EXPECT_DOUBLE_EQ(still.length(), 0.0);
  EXPECT_TRUE(still.At(10, 1).isApprox(Eigen::Vector2d(2, 14)));
}

TEST(SequencePlan, ACarCrossingTheSpotBetweenKeyframesRejectsIt) {
  const Scenario s = Parse(kOneCone);
  // Control: the crossing car passes 20 m further on; the cone stands exactly at s = 40 on the path.
  {
    Log log = StraightLog(10, 4.0);
    AddCrossingCar(&log, 60, true, false);
    const SequencePlan plan = PlanSequence(log, s, PlaneSurface());
    ASSERT_EQ(plan.objects.size(), 1u);
    EXPECT_NEAR(plan.objects[0].T_world_object.translation.x(), 40, 1e-12);
    EXPECT_NEAR(plan.objects[0].T_world_object.translation.y(), 0, 1e-12);
    EXPECT_EQ(plan.tracks, 1u);
    EXPECT_EQ(plan.annotated_boxes, 10u);
    EXPECT_GT(plan.swept_boxes, 9u * 30u);  // 10 m between keyframes at 0.25 m steps
  }
  // The car's keyframe boxes leave the spot free; its track (instance tokens) crosses it.
  {
    Log log = StraightLog(10, 4.0);
    AddCrossingCar(&log, 40, false, false);
    EXPECT_EQ(PlanSequence(log, s, PlaneSurface()).objects.size(), 1u) << "keyframe boxes alone tunnel";
  }
  for (const bool tracks : {true, false}) {
    Log log = StraightLog(10, 4.0);
    AddCrossingCar(&log, 40, tracks, /*velocity=*/!tracks);
    const std::string msg = PlanError(log, s);
    EXPECT_NE(msg.find("arrangements[0]"), std::string::npos) << msg;
    EXPECT_NE(msg.find("2000 candidates tried"), std::string::npos) << msg;
    EXPECT_NE(msg.find("2000 overlapping annotated objects"), std::string::npos) << msg;
  }
  // A car standing on the spot in a single frame (no track, no velocity) rejects it too.
  {
    Log log = StraightLog(10, 4.0);
    Annotation a;
    a.category = "car";
    a.box = Box3{Rigid3d::FromYaw(0.3, Eigen::Vector3d(40.5, 1.0, 0.85)), Eigen::Vector3d(4.6, 1.9, 1.7)}.Transformed(
        log.frames[7].T_world_ego.Inverse());
    log.frames[7].annotations.push_back(a);
    EXPECT_NE(PlanError(log, s).find("2000 overlapping annotated objects"), std::string::npos);
  }
}

TEST(SequencePlan, TheEgoNeverDrivesThroughAnInsertedObject) {
  const Log log = StraightLog(10, 4.0);  // ego origin reaches x = 18, its front 18 + 1.35 + 2.15 = 21.5
  Scenario s = Parse(kOneCone);
  s.arrangements[0].distance_min = 5, s.arrangements[0].distance_max = 21.5 + 0.5 + 0.205 - 0.01;
  const std::string msg = PlanError(log, s);
  EXPECT_NE(msg.find("2000 in the ego vehicle's swept path"), std::string::npos) << msg;
  EXPECT_NE(msg.find("front reaches s = 21.5 m"), std::string::npos) << msg;
  s.arrangements[0].distance_max = 22.3;  // just beyond the reach + margin + cone half length
  const SequencePlan plan = PlanSequence(log, s, PlaneSurface());
  ASSERT_EQ(plan.objects.size(), 1u);
  EXPECT_GT(plan.objects[0].path_s, 21.5 + 0.5 + 0.205);
  EXPECT_EQ(plan.stats[0].placed, 1);
  EXPECT_GT(plan.stats[0].hits_ego_path, 0);
  // Off the drivable rectangle: every candidate is rejected by the surface, and the message says so.
  const PlaneSurface narrow = PlaneSurface().WithDrivableBox(Eigen::AlignedBox2d(Eigen::Vector2d(-10, -5), Eigen::Vector2d(30, 5)));
  s.arrangements[0].distance_min = s.arrangements[0].distance_max = 40;
  try {
    PlanSequence(log, s, narrow);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("2000 off the drivable area"), std::string::npos) << e.what();
  }
}

TEST(SequencePlan, StandsOnTheSurfaceAndGatesByRange) {
  const Log log = StraightLog(30, 5.0);  // 72.5 m of path
  // A 5% slope up along +x: height 0.05 x, normal tilted back.
  const PlaneSurface slope(Eigen::Vector3d(-0.05, 0, 1), 0);
  const Scenario s = Parse(R"({"seed": 1, "arrangements": [{"type": "ego_lane_object", "category": "car",
                               "distance_m": [100, 100], "lateral_m": [0, 0], "yaw": 0}]})");
  SequencePlanOptions opt;
  opt.range_m = 50;
  const SequencePlan plan = PlanSequence(log, s, slope, {}, opt);
  ASSERT_EQ(plan.objects.size(), 1u);
  const PlannedObject& o = plan.objects[0];
  EXPECT_NEAR(o.T_world_object.translation.z(), 5.0, 1e-9);
  const Eigen::Vector3d up = o.T_world_object.rotation * Eigen::Vector3d::UnitZ();
  EXPECT_NEAR(up.dot(Eigen::Vector3d(-0.05, 0, 1).normalized()), 1.0, 1e-12);
  EXPECT_TRUE(o.box.center().isApprox(o.T_world_object * Eigen::Vector3d(0, 0, 0.5 * 1.74)));
  // In range (<= 50 m) from frame 20 on (ego at x = 50).
  ASSERT_EQ(plan.frames.size(), 30u);
  for (const PlannedFrame& f : plan.frames) {
    const double expected = std::hypot(o.box.center().x() - 2.5 * static_cast<double>(f.frame_index), o.box.center().y());
    EXPECT_NEAR(f.objects[0].distance_m, expected, 1e-9);
    EXPECT_EQ(f.objects[0].visible, f.frame_index >= 20) << f.frame_index;
  }
  // Nothing at 130 m ever comes within 50 m of the ego (its last position is x = 72.5).
  Scenario far = s;
  far.arrangements[0].distance_min = far.arrangements[0].distance_max = 130;
  try {
    PlanSequence(log, far, slope, {}, opt);
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("2000 seen in no frame"), std::string::npos) << e.what();
  }
}

TEST(SequencePlan, ClutterStaysOutOfTheEgoLaneAndPlainObjectsArePlannedToo) {
  const Log log = StraightLog(10, 4.0);
  Scenario s = Parse(R"({"seed": 5, "arrangements": [{"type": "roadside_clutter", "categories": ["barrier"], "count": 4,
                          "distance_m": [0, 40], "lateral_m": [0, 2.2], "side": "left", "yaw": 0}],
                         "objects": [{"category": "car", "count": 2, "distance_m": [25, 45], "lateral_m": [-6, 6]}]})");
  // A 0.5 m wide barrier along the path needs |lateral| >= 1.75 + 0.25: only 2.0..2.2 of 0..2.2 qualifies.
  const SequencePlan plan = PlanSequence(log, s, PlaneSurface());
  ASSERT_EQ(plan.objects.size(), 6u);
  for (int i = 0; i < 4; ++i) {
    EXPECT_GE(plan.objects[static_cast<size_t>(i)].path_lateral, 2.0 - 1e-9);
    EXPECT_LE(plan.objects[static_cast<size_t>(i)].path_lateral, 2.2);
    EXPECT_EQ(plan.objects[static_cast<size_t>(i)].arrangement, 0);
  }
  EXPECT_GT(plan.stats[0].in_ego_lane, 4 * 5);  // ~91% of draws land inside the lane
  EXPECT_EQ(plan.objects[4].request, 0);
  EXPECT_EQ(plan.objects[4].source, "objects[0]");
  EXPECT_EQ(plan.objects[5].category, "car");
  ASSERT_EQ(plan.stats.size(), 2u);
  EXPECT_EQ(plan.stats[1].placed, 2);
  // A sized asset replaces the category's default size.
  SequencePlanOptions opt;
  opt.assets = {{"big_barrier", "barrier", Eigen::Vector3d(3.0, 0.8, 1.2)}};
  const SequencePlan sized = PlanSequence(log, s, PlaneSurface(), {}, opt);
  EXPECT_EQ(sized.objects[0].asset_id, "big_barrier");
  EXPECT_EQ(sized.objects[0].box.size, Eigen::Vector3d(3.0, 0.8, 1.2));
  EXPECT_GE(sized.objects[0].path_lateral, 1.75 + 0.4 - 1e-9);
  s.arrangements[0].lateral_max = 1.9;
  try {
    PlanSequence(log, s, PlaneSurface());
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("2000 inside the ego lane"), std::string::npos) << e.what();
  }
}

// plan.json's poses are the geometry codec's (io/geometry_json.h), with the heading added for people: each reads
// back bit for bit, so a tool reading plan.json gets the planner's own poses.
TEST(SequencePlan, PlanJsonPosesReadBackBitForBit) {
  const Log log = StraightLog(10, 4.0);
  const Scenario s = Parse(R"({"seed": 5, "objects": [{"category": "car", "count": 3, "distance_m": [15, 45], "lateral_m": [-6, 6]}]})");
  const SequencePlan plan = PlanSequence(log, s, PlaneSurface());
  ASSERT_EQ(plan.objects.size(), 3u);
  const nlohmann::json j = nlohmann::json::parse(PlanToJson(plan).dump());
  const JsonReader r(j, "plan.json");
  for (size_t i = 0; i < plan.objects.size(); ++i) {
    const JsonReader pose = r["objects"][i]["T_world_object"];
    const Rigid3d back = ReadRigid3d(pose);
    EXPECT_EQ(back.rotation.coeffs(), plan.objects[i].T_world_object.rotation.coeffs()) << i;
    EXPECT_EQ(back.translation, plan.objects[i].T_world_object.translation) << i;
    EXPECT_DOUBLE_EQ(pose["yaw_deg"].Number(), plan.objects[i].T_world_object.Yaw() * 180 / kPi);
    nlohmann::json codec = Rigid3dJson(plan.objects[i].T_world_object);
    codec["yaw_deg"] = pose["yaw_deg"].raw();
    EXPECT_EQ(pose.raw(), codec);
    const Rigid3d ego = ReadRigid3d(r["per_frame"][9]["objects"][i]["T_ego_object"]);
    EXPECT_EQ(ego.rotation.coeffs(), plan.frames[9].objects[i].T_ego_object.rotation.coeffs()) << i;
    EXPECT_EQ(ego.translation, plan.frames[9].objects[i].T_ego_object.translation) << i;
  }
}

TEST(SequencePlan, RefusesRangesAcrossSequencesAndEmptyRanges) {
  Log log = StraightLog(10, 4.0);
  for (size_t k = 5; k < 10; ++k) log.frames[k].timestamp += 1000;
  const Scenario s = Parse(kOneCone);
  try {
    PlanSequence(log, s, PlaneSurface());
    FAIL();
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("frames 4 and 5 are 1000.5 s apart"), std::string::npos) << e.what();
  }
  EXPECT_EQ(PlanSequence(log, s, PlaneSurface(), {0, 5}).frames.size(), 5u);
  EXPECT_THROW(PlanSequence(log, s, PlaneSurface(), {10, 20}), InputError);
}

// ---- nuScenes mini val (mmdet3d v0 infos: no track ids, velocities known) ----

struct Scene {
  size_t begin, end;
};
constexpr Scene kScenes[] = {{0, 40}, {40, 81}};  // scene-0103 (Boston), scene-0916 (Singapore)

const Log& NuScenes(const std::filesystem::path& info) {
  static const Log log = OpenLog(info);
  return log;
}

// The road plane at the median bottom of the scene's boxes.
PlaneSurface SceneGround(const Log& log, Scene scene) {
  std::vector<double> z;
  for (size_t k = scene.begin; k < scene.end; ++k)
    for (const auto& a : log.frames[k].annotations)
      z.push_back((log.frames[k].T_world_ego * a.box.center()).z() - 0.5 * a.box.size.z());
  std::nth_element(z.begin(), z.begin() + static_cast<long>(z.size() / 2), z.end());
  return PlaneSurface(Eigen::Vector3d::UnitZ(), -z[z.size() / 2]);
}

const char* kAllArrangements = R"({"seed": 11, "margin_m": 0.5, "arrangements": [
    {"type": "lane_closure", "count": 6, "spacing_m": 3, "distance_m": [125, 145], "side": "right"},
    {"type": "ego_lane_object", "category": "debris", "distance_m": [125, 160]},
    {"type": "roadside_clutter", "categories": ["traffic_cone", "a_frame_sign", "debris"], "count": 6, "distance_m": [0, 120],
     "lateral_m": [2.5, 6]},
    {"type": "breakdown", "vehicle": "car", "warning": "warning_tripod", "position": "shoulder", "side": "right",
     "distance_m": [20, 120], "setting": "city"}
  ]})";

TEST(SequencePlanNuScenes, WorldFixedCollisionFreeAndEachArrangementsGeometry) {
  SD_REQUIRE_SHARED(info, "driving/nuscenes-mini-val-infos/nuscenes_infos_val.json");
  const Log& log = NuScenes(info);
  ASSERT_EQ(log.frames.size(), 81u);
  const Scenario s = Parse(kAllArrangements);
  const SequencePlanOptions opt;
  size_t boxes_checked = 0, pairs_checked = 0;
  for (const Scene& scene : kScenes) {
    SCOPED_TRACE(scene.begin);
    const PlaneSurface ground = SceneGround(log, scene);
    const SequencePlan plan = PlanSequence(log, s, ground, {scene.begin, scene.end}, opt);
    ASSERT_EQ(plan.objects.size(), 6u + 1u + 6u + 2u);
    ASSERT_EQ(plan.frames.size(), scene.end - scene.begin);
    EXPECT_TRUE(plan.unannotated_frames.empty());
    std::vector<Rigid3d> poses;
    for (size_t k = scene.begin; k < scene.end; ++k) poses.push_back(log.frames[k].T_world_ego);
    const EgoPath path(poses);

    // World-fixed: every frame's ego-frame pose is inv(T_world_ego) * T_world_object, mapping back to one world pose.
    for (const PlannedFrame& f : plan.frames) {
      const Rigid3d& T_world_ego = log.frames[f.frame_index].T_world_ego;
      for (size_t i = 0; i < plan.objects.size(); ++i) {
        const Rigid3d expected = T_world_ego.Inverse() * plan.objects[i].T_world_object;
        EXPECT_EQ(f.objects[i].T_ego_object.translation, expected.translation);
        EXPECT_EQ(f.objects[i].T_ego_object.rotation.coeffs(), expected.rotation.coeffs());
        const Rigid3d back = T_world_ego * f.objects[i].T_ego_object;
        EXPECT_LT((back.translation - plan.objects[i].T_world_object.translation).norm(), 1e-9);
        EXPECT_LT(back.rotation.angularDistance(plan.objects[i].T_world_object.rotation), 1e-9);
      }
    }
    // Collision-free against every box of every frame (3D and footprint), in each frame's ego frame, and
    // clear of the ego box itself.
    for (const PlannedFrame& f : plan.frames) {
      for (const auto& a : log.frames[f.frame_index].annotations) {
        ++boxes_checked;
        for (const PlannedView& v : f.objects) {
          ++pairs_checked;
          EXPECT_FALSE(BoxesOverlap(v.box_ego, a.box, 0.49));
          EXPECT_FALSE(FootprintsOverlap(v.box_ego, a.box, 0.49));
        }
      }
      for (const PlannedView& v : f.objects) EXPECT_FALSE(FootprintsOverlap(v.box_ego, opt.ego_box, 0.49));
    }
    // Every object's (s, lateral) is where it stands.
    for (const auto& o : plan.objects)
      EXPECT_TRUE(path.Project(o.T_world_object.translation.head<2>()).isApprox(Eigen::Vector2d(o.path_s, o.path_lateral), 1e-6));
    // Lane closure: 6 cones 3 m apart, tapering from the right lane edge (-1.75) to the left one (+1.75).
    for (int i = 0; i < 6; ++i) {
      const PlannedObject& c = plan.objects[static_cast<size_t>(i)];
      EXPECT_EQ(c.role, "cone");
      EXPECT_EQ(c.category, "traffic_cone");
      EXPECT_NEAR(c.path_s - plan.objects[0].path_s, 3.0 * i, 1e-9);
      EXPECT_NEAR(c.path_lateral, -1.75 + 3.5 * i / 5.0, 1e-9);
    }
    EXPECT_GE(plan.objects[0].path_s, 125);
    EXPECT_LE(plan.objects[0].path_s, 145);
    // Ego lane object: within +-0.5 m of the path, beyond the ego's reach.
    const PlannedObject& debris = plan.objects[6];
    EXPECT_EQ(debris.category, "debris");
    EXPECT_LE(std::abs(debris.path_lateral), 0.5);
    EXPECT_GT(debris.path_s, plan.ego_path_length_m);
    // Clutter: outside the ego lane (footprint entirely beyond 1.75 m), within 2.5..6 m of the path.
    for (size_t i = 7; i < 13; ++i) {
      const PlannedObject& c = plan.objects[i];
      EXPECT_EQ(c.role, "clutter");
      EXPECT_GE(std::abs(c.path_lateral), 2.5);
      EXPECT_LE(std::abs(c.path_lateral), 6.0);
      double inner = 1e9;
      for (const auto& p : c.box.Corners()) inner = std::min(inner, std::abs(path.Project(p.head<2>()).y()));
      EXPECT_GE(inner, 1.75 - 1e-6) << c.category;
    }
    // Breakdown: the car on the right shoulder, the tripod 10..50 m behind its rear along the direction of travel.
    const PlannedObject& car = plan.objects[13];
    const PlannedObject& tripod = plan.objects[14];
    EXPECT_EQ(car.role, "vehicle");
    EXPECT_EQ(tripod.category, "warning_tripod");
    EXPECT_LE(car.path_lateral, -(1.75 + 0.5 * 1.97 + 0.1) + 1e-9);
    const double gap = car.path_s - 0.5 * 4.63 - tripod.path_s;
    EXPECT_GE(gap, 10);
    EXPECT_LE(gap, 50);
    const Eigen::Vector2d car_forward = (car.T_world_object.rotation * Eigen::Vector3d::UnitX()).head<2>();
    EXPECT_LT(car_forward.dot((tripod.T_world_object.translation - car.T_world_object.translation).head<2>()), -10.0);
    EXPECT_LT(std::abs(tripod.path_lateral - car.path_lateral), 0.3 + 1e-9);
    // Every object is seen (in range, in a camera image) in at least one frame.
    for (size_t i = 0; i < plan.objects.size(); ++i) {
      int seen = 0;
      for (const PlannedFrame& f : plan.frames) seen += f.objects[i].visible ? 1 : 0;
      EXPECT_GT(seen, 0) << i;
    }
  }
  EXPECT_EQ(boxes_checked, 4514u);
  EXPECT_EQ(pairs_checked, 4514u * 15u);
}

TEST(SequencePlanNuScenes, SameSeedSamePlanOtherSeedOtherPlan) {
  SD_REQUIRE_SHARED(info, "driving/nuscenes-mini-val-infos/nuscenes_infos_val.json");
  const Log& log = NuScenes(info);
  Scenario s = Parse(kAllArrangements);
  const PlaneSurface ground = SceneGround(log, kScenes[0]);
  const nlohmann::json a = PlanToJson(PlanSequence(log, s, ground, {0, 40}));
  const nlohmann::json b = PlanToJson(PlanSequence(log, s, ground, {0, 40}));
  EXPECT_EQ(a.dump(), b.dump());
  s.seed = 12;
  const SequencePlan other = PlanSequence(log, s, ground, {0, 40});
  const nlohmann::json c = PlanToJson(other);
  ASSERT_EQ(c["objects"].size(), a["objects"].size());
  for (size_t i = 0; i < a["objects"].size(); ++i)
    EXPECT_NE(a["objects"][i]["T_world_object"]["translation"], c["objects"][i]["T_world_object"]["translation"]) << i;
  // The dry-run report: one entry per frame with every object's ego-frame pose and gates.
  EXPECT_EQ(a["frames"], nlohmann::json::array({0, 40}));
  EXPECT_EQ(a["seed"], 11);
  ASSERT_EQ(a["per_frame"].size(), 40u);
  EXPECT_EQ(a["per_frame"][0]["objects"].size(), 15u);
  EXPECT_EQ(a["rejections"].size(), 4u);
  EXPECT_EQ(a["rejections"][1]["placed"], 1);
  EXPECT_EQ(a["obstacles"]["annotated_boxes"], 2090);  // scene-0103 (scene-0916 has the other 2,424)
  const auto& v = c["per_frame"][39]["objects"][14];
  const Rigid3d T_ego_object = log.frames[39].T_world_ego.Inverse() * other.objects[14].T_world_object;
  EXPECT_NEAR(v["T_ego_object"]["translation"][0].get<double>(), T_ego_object.translation.x(), 1e-9);
  EXPECT_NEAR(v["distance_m"].get<double>(), other.frames[39].objects[14].box_ego.center().head<2>().norm(), 1e-9);
}

}  // namespace
}  // namespace sd
