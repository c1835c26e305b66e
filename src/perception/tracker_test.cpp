#include "perception/tracker.h"

#include <cmath>
#include <set>

#include <gtest/gtest.h>

#include "core/error.h"

namespace sd::perception {
namespace {

DetectedObject At(const Rigid3d& T_world_ego, const Eigen::Vector3d& world, ObjectClass c, double yaw_world = 0) {
  DetectedObject d;
  const Rigid3d T_ego_world = T_world_ego.Inverse();
  d.box.T_frame_box = T_ego_world * Rigid3d::FromYaw(yaw_world, world);
  d.box.size = c == ObjectClass::kVehicle ? Eigen::Vector3d(4.5, 1.9, 1.6) : Eigen::Vector3d(0.6, 0.5, 1.7);
  d.seen_center = d.box.center();
  d.object_class = c;
  d.num_points = 50;
  return d;
}

// The ego drives a gentle left curve at 3 m/s, 10 Hz.
Rigid3d EgoPose(int k) {
  const double t = 0.1 * k, yaw = 0.05 * t;
  return Rigid3d::FromYaw(yaw, Eigen::Vector3d(3 * t, 0.2 * t * t, 0));
}

TEST(TrackObjects, MovingObjectKeepsOneIdAndGetsItsVelocity) {
  // A car crossing at 5 m/s along world +x, 2 m/s along +y; the detected centre jitters by +-5 cm (a partial
  // view's centre moves as the visible sides change), deterministic.
  std::vector<TrackFrameInput> frames;
  const Eigen::Vector2d v(5, 2);
  for (int k = 0; k < 20; ++k) {
    const double t = 0.1 * k;
    const Eigen::Vector3d c(10 + v.x() * t + 0.05 * std::sin(3.0 * k), -5 + v.y() * t + 0.05 * std::cos(5.0 * k), 0.8);
    TrackFrameInput f{t, EgoPose(k), {}};
    f.detections.push_back(At(f.T_world_ego, c, ObjectClass::kVehicle, std::atan2(v.y(), v.x())));
    // A parked pedestrian-sized object nearby, and a static car.
    f.detections.push_back(At(f.T_world_ego, Eigen::Vector3d(14, -1, 0.85), ObjectClass::kPedestrian));
    f.detections.push_back(At(f.T_world_ego, Eigen::Vector3d(25, 4, 0.8), ObjectClass::kVehicle));
    frames.push_back(f);
  }
  TrackStats st;
  const auto out = TrackObjects(frames, {}, &st);
  ASSERT_EQ(out.size(), frames.size());
  EXPECT_EQ(st.tracks, 3);
  EXPECT_EQ(st.output_boxes, 60);
  std::set<int> moving_ids;
  for (size_t k = 0; k < out.size(); ++k) {
    ASSERT_EQ(out[k].size(), 3u);
    for (const TrackedObject& o : out[k]) {
      if (o.detection != 0) continue;
      moving_ids.insert(o.track_id);
      if (k >= 8) {
        // World velocity, and the same expressed in the frame's ego axes.
        EXPECT_NEAR(o.velocity_world.x(), v.x(), 0.3) << "frame " << k;
        EXPECT_NEAR(o.velocity_world.y(), v.y(), 0.3) << "frame " << k;
        const Eigen::Vector3d v_ego = frames[k].T_world_ego.Rotation().transpose() * Eigen::Vector3d(v.x(), v.y(), 0);
        EXPECT_NEAR(o.velocity_ego.x(), v_ego.x(), 0.3);
        EXPECT_NEAR(o.velocity_ego.y(), v_ego.y(), 0.3);
        // Moving: the box heads along the motion (in ego axes).
        const double yaw_ego = std::atan2(v_ego.y(), v_ego.x());
        EXPECT_NEAR(std::remainder(o.box.Yaw() - yaw_ego, 2 * M_PI), 0.0, 0.1);
      }
    }
  }
  EXPECT_EQ(moving_ids.size(), 1u);
  // The static objects stay static.
  for (const TrackedObject& o : out.back())
    if (o.detection != 0) {
      EXPECT_LT(o.velocity_world.norm(), 0.2);
    }
}

TEST(TrackObjects, TwoHertzKeyframesStillAssociate) {
  // A car at 12 m/s seen at 2 Hz moves 6 m between frames: the gate grows with the elapsed time.
  std::vector<TrackFrameInput> frames;
  for (int k = 0; k < 8; ++k) {
    TrackFrameInput f{0.5 * k, Rigid3d(), {}};
    f.detections.push_back(At(f.T_world_ego, Eigen::Vector3d(5 + 6.0 * k, 3, 0.8), ObjectClass::kVehicle));
    frames.push_back(f);
  }
  const auto out = TrackObjects(frames);
  std::set<int> ids;
  for (const auto& f : out) {
    ASSERT_EQ(f.size(), 1u);
    ids.insert(f[0].track_id);
  }
  EXPECT_EQ(ids.size(), 1u);
  EXPECT_NEAR(out.back()[0].velocity_world.x(), 12.0, 0.5);
  // The birth frame takes the next hit's velocity rather than zero.
  EXPECT_GT(out.front()[0].velocity_world.x(), 3.0);
}

TEST(TrackObjects, BirthDeathAndMinHits) {
  // Object A seen in frames 0-2, gone in 3-7 (longer than max_misses), back at the same place in 8-9: a new id.
  // Object B seen once (frame 4): dropped with min_hits = 2, kept with the default 1.
  std::vector<TrackFrameInput> frames;
  for (int k = 0; k < 10; ++k) {
    TrackFrameInput f{0.1 * k, Rigid3d(), {}};
    if (k <= 2 || k >= 8) f.detections.push_back(At(f.T_world_ego, Eigen::Vector3d(10, 0, 0.85), ObjectClass::kPedestrian));
    if (k == 4) f.detections.push_back(At(f.T_world_ego, Eigen::Vector3d(-6, 8, 0.85), ObjectClass::kPedestrian));
    frames.push_back(f);
  }
  const auto all = TrackObjects(frames);
  ASSERT_EQ(all[4].size(), 1u);
  EXPECT_NE(all[0][0].track_id, all[8][0].track_id);
  EXPECT_EQ(all[0][0].track_id, all[2][0].track_id);
  EXPECT_EQ(all[8][0].track_id, all[9][0].track_id);
  TrackOptions o;
  o.min_hits = 2;
  TrackStats st;
  const auto confirmed = TrackObjects(frames, o, &st);
  EXPECT_TRUE(confirmed[4].empty());
  // Confirmed at its second hit, the track keeps its first frame.
  EXPECT_EQ(confirmed[0].size(), 1u);
  EXPECT_EQ(confirmed[8].size(), 1u);
  EXPECT_EQ(st.tracks, 3);
  EXPECT_EQ(st.output_tracks, 2);
}

TEST(TrackObjects, VehiclesDoNotTakeSmallObjectsTracks) {
  // A cone 2 m from a car track that lost its detection: within the vehicle gate (1.5 m + 20 m/s x 0.1 s) but
  // not within gate_m, so it starts its own track. At 1 m (a car's odd partial view) it joins.
  for (const double offset : {2.0, 1.0}) {
    std::vector<TrackFrameInput> frames;
    for (int k = 0; k < 2; ++k) {
      TrackFrameInput f{0.1 * k, Rigid3d(), {}};
      f.detections.push_back(At(f.T_world_ego, Eigen::Vector3d(10, offset * k, 0.4), k == 0 ? ObjectClass::kVehicle : ObjectClass::kSmallObject));
      frames.push_back(f);
    }
    const auto out = TrackObjects(frames);
    if (offset > 1.5) EXPECT_NE(out[0][0].track_id, out[1][0].track_id);
    else EXPECT_EQ(out[0][0].track_id, out[1][0].track_id);
  }
}

TEST(TrackObjects, JitterOfAParkedCarIsNoMotion) {
  // Two sweeps 0.1 s apart, the parked car's centre 12 cm apart (a partial view changing): 1.2 m/s of apparent
  // speed, within the filter's uncertainty, so the box keeps the heading its returns gave (along world x).
  std::vector<TrackFrameInput> frames;
  for (int k = 0; k < 2; ++k) {
    TrackFrameInput f{0.1 * k, Rigid3d(), {}};
    f.detections.push_back(At(f.T_world_ego, Eigen::Vector3d(10, 6 + 0.12 * k, 0.8), ObjectClass::kVehicle, 0.0));
    frames.push_back(f);
  }
  const auto out = TrackObjects(frames);
  ASSERT_EQ(out[1].size(), 1u);
  EXPECT_EQ(out[0][0].track_id, out[1][0].track_id);
  EXPECT_NEAR(out[1][0].box.Yaw(), 0.0, 1e-9);
  EXPECT_NEAR(out[1][0].box.size.x(), 4.5, 1e-9);
}

TEST(TrackObjects, BadSequencesAreInputErrors) {
  EXPECT_TRUE(TrackObjects({}).empty());
  std::vector<TrackFrameInput> frames(2);
  frames[0].timestamp = 1.0;
  frames[1].timestamp = 1.0;
  try {
    TrackObjects(frames);
    FAIL() << "repeated timestamp accepted";
  } catch (const InputError& e) {
    EXPECT_NE(std::string(e.what()).find("frame 1 timestamp"), std::string::npos) << e.what();
  }
  frames[1].timestamp = 2.0;
  frames[1].T_world_ego.translation.x() = NAN;
  EXPECT_THROW(TrackObjects(frames), InputError);
}

}  // namespace
}  // namespace sd::perception
