#include "perception/lidar_objects.h"

#include <algorithm>
#include <cmath>
#include <random>
#include <set>
#include <tuple>

#include <gtest/gtest.h>

namespace sd::perception {
namespace {

// Returns a LiDAR at `sensor` would get from a box standing on the plane z = 0: points on the vertical faces
// that face the sensor and on the top, every `step` metres. Analytic ground truth for the detector.
void AddBoxReturns(const Box3& box, const Eigen::Vector3d& sensor, double step, std::vector<Eigen::Vector3d>* out) {
  const Eigen::Vector3d h = 0.5 * box.size;
  const Eigen::Matrix3d R = box.T_frame_box.Rotation();
  // Faces: (axis, sign).
  for (int axis = 0; axis < 3; ++axis)
    for (int sign : {-1, 1}) {
      if (axis == 2 && sign < 0) continue;  // the bottom face is on the road
      Eigen::Vector3d n = Eigen::Vector3d::Zero();
      n[axis] = sign;
      const Eigen::Vector3d face_centre = box.T_frame_box * Eigen::Vector3d(n.cwiseProduct(h));
      if ((R * n).dot(sensor - face_centre) <= 0) continue;  // faces away
      const int u = (axis + 1) % 3, v = (axis + 2) % 3;
      for (double a = -h[u]; a <= h[u] + 1e-9; a += step)
        for (double b = -h[v]; b <= h[v] + 1e-9; b += step) {
          Eigen::Vector3d q = n.cwiseProduct(h);
          q[u] = a, q[v] = b;
          out->push_back(box.T_frame_box * q);
        }
    }
}

std::vector<float> Heights(const std::vector<Eigen::Vector3d>& pts) {
  std::vector<float> h;
  for (const auto& p : pts) h.push_back(static_cast<float>(p.z()));
  return h;
}

Box3 MakeBox(double x, double y, double yaw, double l, double w, double hgt) {
  return Box3{Rigid3d::FromYaw(yaw, Eigen::Vector3d(x, y, 0.5 * hgt)), Eigen::Vector3d(l, w, hgt)};
}

// Heading difference modulo pi (a box has no front).
double AxisError(double a, double b) {
  double d = std::fmod(std::abs(a - b), M_PI);
  return std::min(d, M_PI - d);
}

TEST(FitLShape, TwoVisibleSidesGiveTheFullRectangle) {
  // Only the two sides facing a sensor at the origin of a 4.5 x 1.8 m rectangle at heading 30 degrees.
  const double yaw = 30 * M_PI / 180;
  const Box3 box = MakeBox(12, 5, yaw, 4.5, 1.8, 1.5);
  std::vector<Eigen::Vector3d> pts;
  AddBoxReturns(box, Eigen::Vector3d(0, 0, 1.8), 0.05, &pts);
  std::vector<Eigen::Vector2d> xy;
  for (const auto& p : pts) xy.push_back(p.head<2>());
  const Rectangle r = FitLShape(xy);
  EXPECT_LT(AxisError(r.heading, yaw), 1.5 * M_PI / 180);
  EXPECT_NEAR(r.length, 4.5, 0.05);
  EXPECT_NEAR(r.width, 1.8, 0.05);
  EXPECT_LT((r.center - Eigen::Vector2d(12, 5)).norm(), 0.05);
  EXPECT_GE(r.heading, 0);
  EXPECT_LT(r.heading, M_PI);
}

TEST(FitLShape, OnePointIsAZeroRectangle) {
  const Rectangle r = FitLShape({Eigen::Vector2d(3, -2)});
  EXPECT_EQ(r.length, 0);
  EXPECT_EQ(r.width, 0);
  EXPECT_EQ(r.center, Eigen::Vector2d(3, -2));
}

TEST(ClassifyBySize, CanonicalSizes) {
  EXPECT_EQ(ClassifyBySize(4.63, 1.97, 1.74), ObjectClass::kVehicle);     // car
  EXPECT_EQ(ClassifyBySize(1.9, 0.2, 1.5), ObjectClass::kVehicle);       // a car seen only from behind
  EXPECT_EQ(ClassifyBySize(11.0, 2.94, 3.47), ObjectClass::kVehicle);    // bus
  EXPECT_EQ(ClassifyBySize(0.73, 0.67, 1.77), ObjectClass::kPedestrian);
  EXPECT_EQ(ClassifyBySize(0.41, 0.41, 0.7), ObjectClass::kSmallObject);  // cone
  EXPECT_EQ(ClassifyBySize(0.3, 0.2, 2.9), ObjectClass::kOther);         // a pole cut at max_height
  EXPECT_EQ(ClassifyBySize(6.0, 0.3, 0.6), ObjectClass::kOther);         // a low wall left whole
  EXPECT_EQ(ClassifyBySize(2.0, 0.5, 1.0), ObjectClass::kSmallObject);   // a barrier segment
  EXPECT_EQ(ClassifyBySize(1.8, 0.3, 1.45), ObjectClass::kVehicle);      // a car's rear, end-on
}

TEST(ClusterBev, JoinsWithinTheDistanceAndNotBeyond) {
  // Two columns of points 0.45 m apart join at 0.5 m; a third 0.8 m further does not.
  std::vector<Eigen::Vector3d> pts;
  for (double z = 0.3; z < 1.5; z += 0.1) {
    pts.emplace_back(5.0, 0, z);
    pts.emplace_back(5.45, 0, z);
    pts.emplace_back(6.25, 0, z);
  }
  const auto clusters = ClusterBev(pts, 0.15, 0.5);
  ASSERT_EQ(clusters.size(), 2u);
  std::set<double> xs0, xs1;
  for (int i : clusters[0]) xs0.insert(pts[i].x());
  for (int i : clusters[1]) xs1.insert(pts[i].x());
  EXPECT_EQ(xs0, (std::set<double>{5.0, 5.45}));
  EXPECT_EQ(xs1, (std::set<double>{6.25}));
}

TEST(ClusterBev, DoesNotDependOnPointOrder) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<double> u(-20, 20);
  std::vector<Eigen::Vector3d> pts;
  for (int i = 0; i < 3000; ++i) pts.emplace_back(u(rng), u(rng), 1.0);
  std::vector<Eigen::Vector3d> shuffled = pts;
  std::shuffle(shuffled.begin(), shuffled.end(), rng);
  auto as_sets = [](const std::vector<Eigen::Vector3d>& p, const std::vector<std::vector<int>>& cl) {
    std::set<std::set<std::pair<double, double>>> out;
    for (const auto& c : cl) {
      std::set<std::pair<double, double>> s;
      for (int i : c) s.insert({p[i].x(), p[i].y()});
      out.insert(s);
    }
    return out;
  };
  const auto a = ClusterBev(pts, 0.15, 0.5), b = ClusterBev(shuffled, 0.15, 0.5);
  EXPECT_GT(a.size(), 10u);
  EXPECT_EQ(as_sets(pts, a), as_sets(shuffled, b));
}

// A synthetic sweep: road returns, a car, a pedestrian, a cone, a 30 m wall, a lone spurious return, the ego's
// own body and a canopy above the car.
struct Scene {
  std::vector<Eigen::Vector3d> points;
  Box3 car = MakeBox(14, 4, 0.5, 4.5, 1.9, 1.6);
  Box3 pedestrian = MakeBox(8, -4, 0.0, 0.6, 0.5, 1.75);
  Box3 cone = MakeBox(16, -2.5, 0.3, 0.4, 0.4, 0.7);
  Scene() {
    const Eigen::Vector3d sensor(0, 0, 1.8);
    for (double x = -30; x <= 30; x += 0.5)
      for (double y = -30; y <= 30; y += 0.5) points.emplace_back(x, y, 0.02 * std::sin(x + y));  // road
    AddBoxReturns(car, sensor, 0.08, &points);
    AddBoxReturns(pedestrian, sensor, 0.05, &points);
    AddBoxReturns(cone, sensor, 0.04, &points);
    AddBoxReturns(MakeBox(0, -20, 0, 30, 0.3, 2.5), sensor, 0.1, &points);  // wall
    points.emplace_back(-10, 10, 1.0);                                       // spurious return
    for (double x = -1; x < 3.5; x += 0.2) points.emplace_back(x, 1.0, 0.8);   // ego body (mirror, door)
    for (double x = 12; x < 16; x += 0.2) points.emplace_back(x, 4, 4.5);      // canopy, above max_height
  }
};

TEST(DetectObjects, SyntheticSceneGivesKnownBoxes) {
  const Scene s;
  std::vector<DetectedObject> found, tiles;
  for (const DetectedObject& d : DetectObjects(s.points, Heights(s.points))) (d.structure ? tiles : found).push_back(d);
  // The 30 m wall is structure: keep-out tiles of 2 m along it, no object box.
  ASSERT_GE(tiles.size(), 15u);
  for (const DetectedObject& t : tiles) {
    EXPECT_EQ(t.object_class, ObjectClass::kOther);
    EXPECT_LE(std::abs(t.box.center().x()), 15.0);
    EXPECT_NEAR(t.box.center().y(), -20.0, 0.2);
    EXPECT_LE(std::max(t.box.size.x(), t.box.size.y()), 2.0 + 1e-9);
  }
  ASSERT_EQ(found.size(), 3u);  // spurious return too few points, ego body and canopy ignored
  // Sorted by range: pedestrian (8.9 m), car (14.6 m), cone (16.2 m).
  const Box3* truth[3] = {&s.pedestrian, &s.car, &s.cone};
  const ObjectClass classes[3] = {ObjectClass::kPedestrian, ObjectClass::kVehicle, ObjectClass::kSmallObject};
  for (int k = 0; k < 3; ++k) {
    SCOPED_TRACE(k);
    const Box3& t = *truth[k];
    const Box3& b = found[k].box;
    EXPECT_EQ(found[k].object_class, classes[k]);
    // A box's sides are sampled every few centimetres: the fit is within a sample step of the truth.
    EXPECT_LT((b.center().head<2>() - t.center().head<2>()).norm(), 0.08);
    EXPECT_NEAR(b.size.z(), t.size.z(), 0.01);
    EXPECT_NEAR(b.center().z(), t.center().z(), 0.01);
    EXPECT_NEAR(found[k].ground_z, 0.0, 0.03);
    EXPECT_NEAR(std::max(b.size.x(), b.size.y()), std::max(t.size.x(), t.size.y()), 0.1);
    EXPECT_NEAR(std::min(b.size.x(), b.size.y()), std::min(t.size.x(), t.size.y()), 0.1);
    EXPECT_GE(b.size.x(), b.size.y());
  }
  // Headings of the elongated ones (the cone and pedestrian are near-square: any heading fits).
  EXPECT_LT(AxisError(found[1].box.Yaw(), 0.5), 2 * M_PI / 180);
}

TEST(DetectObjects, FollowsTheGivenGroundNotZ) {
  // The same car on a road 2 m higher (a hill): with its heights above that road it is found the same.
  Scene s;
  for (auto& p : s.points) p.z() += 2.0;
  std::vector<float> h = Heights(s.points);
  for (auto& v : h) v -= 2.0f;
  std::vector<DetectedObject> found;
  for (const DetectedObject& d : DetectObjects(s.points, h))
    if (!d.structure) found.push_back(d);
  ASSERT_EQ(found.size(), 3u);
  EXPECT_NEAR(found[1].ground_z, 2.0, 0.03);
  EXPECT_NEAR(found[1].box.center().z(), 2.8, 0.02);
}

TEST(DetectObjects, RangeAndEmptyInputs) {
  EXPECT_TRUE(DetectObjects({}, {}).empty());
  const Scene s;
  DetectOptions o;
  o.max_range = 12;  // only the pedestrian is within 12 m
  const auto found = DetectObjects(s.points, Heights(s.points), o);
  ASSERT_EQ(found.size(), 1u);
  EXPECT_EQ(found[0].object_class, ObjectClass::kPedestrian);
  // NaN heights (unknown ground) and non-finite points are skipped, not crashed on.
  std::vector<Eigen::Vector3d> pts = {Eigen::Vector3d(5, 0, 1), Eigen::Vector3d(NAN, 0, 1), Eigen::Vector3d(5, 0.1, 1)};
  std::vector<float> h = {1.0f, 1.0f, NAN};
  EXPECT_TRUE(ObstaclePoints(pts, h, DetectOptions{}) == std::vector<int>{0});
}

TEST(DetectObjects, AVehicleSeenEndOnIsCompletedAwayFromTheSensor) {
  // Only the rear of a car 12 m ahead (1.8 m wide, 1.45 m tall): the box grows to 4.4 m away from the sensor,
  // the seen face stays where it is.
  std::vector<Eigen::Vector3d> pts;
  for (double y = -0.9; y <= 0.9; y += 0.05)
    for (double z = 0.3; z <= 1.45; z += 0.05) pts.emplace_back(12.0, 3.0 + y, z);
  const auto found = DetectObjects(pts, Heights(pts));
  ASSERT_EQ(found.size(), 1u);
  const Box3& b = found[0].box;
  EXPECT_EQ(found[0].object_class, ObjectClass::kVehicle);
  EXPECT_NEAR(b.size.x(), 4.4, 1e-9);
  EXPECT_NEAR(b.size.y(), 1.8, 0.05);
  EXPECT_NEAR(b.center().x(), 12.0 + 2.2, 0.05);  // extends away from the sensor
  EXPECT_NEAR(b.center().y(), 3.0, 0.05);
  EXPECT_LT(AxisError(b.Yaw(), 0.0), 2 * M_PI / 180);
  EXPECT_NEAR(found[0].seen_center.x(), 12.0, 0.05);  // what the tracker follows
  DetectOptions as_seen;
  as_seen.min_vehicle_size = Eigen::Vector2d::Zero();
  EXPECT_LT(DetectObjects(pts, Heights(pts), as_seen)[0].box.size.y(), 0.2);
}

TEST(DetectObjects, ARunOfBarriersIsCutIntoPieces) {
  // Three 2 m barriers end to end along a 30-degree line: one cluster, cut into three boxes near the truth.
  std::vector<Eigen::Vector3d> pts;
  const double yaw = 30 * M_PI / 180;
  const Eigen::Vector2d dir(std::cos(yaw), std::sin(yaw)), start(8, 6);
  std::vector<Box3> truth;
  for (int k = 0; k < 3; ++k) {
    const Eigen::Vector2d c = start + (2.0 * k + 1.0) * dir;
    truth.push_back(MakeBox(c.x(), c.y(), yaw, 2.0, 0.5, 1.0));
    AddBoxReturns(truth.back(), Eigen::Vector3d(0, 0, 1.8), 0.05, &pts);
  }
  const auto found = DetectObjects(pts, Heights(pts));
  ASSERT_EQ(found.size(), 3u);
  for (const Box3& t : truth) {
    double best = 1e9;
    for (const auto& d : found) best = std::min(best, (d.box.center().head<2>() - t.center().head<2>()).norm());
    EXPECT_LT(best, 0.3);
  }
  for (const auto& d : found) {
    EXPECT_EQ(d.object_class, ObjectClass::kSmallObject);
    EXPECT_LT(AxisError(d.box.Yaw(), yaw), 3 * M_PI / 180);
  }
}

// A 0.8 m cone standing against the flank of a road roller (2.7 x 1.5 x 2.8 m), on the side facing the sensor:
// one BEV cluster, as on PandaSet 002.
struct ConeAgainstRoller {
  std::vector<Eigen::Vector3d> points;
  Box3 roller = MakeBox(12, -4, 0.0, 2.7, 1.5, 2.8);
  Box3 cone = MakeBox(11.6, -3.05, 0.0, 0.4, 0.4, 0.8);  // its far side 0.4 m out from the roller's flank
  ConeAgainstRoller() {
    AddBoxReturns(roller, Eigen::Vector3d(0, 0, 1.8), 0.05, &points);
    AddBoxReturns(cone, Eigen::Vector3d(0, 0, 1.8), 0.04, &points);
  }
};

TEST(DetectObjects, AConeAgainstATallerObjectGetsItsOwnBox) {
  const ConeAgainstRoller s;
  DetectOptions whole;
  whole.split_max_extent = 0;  // off: the cone is part of the roller's box, as before the split
  ASSERT_EQ(DetectObjects(s.points, Heights(s.points), whole).size(), 1u);
  const auto found = DetectObjects(s.points, Heights(s.points));
  ASSERT_EQ(found.size(), 2u);
  const DetectedObject& cone = found[0].box.size.z() < 1.0 ? found[0] : found[1];
  const DetectedObject& roller = found[0].box.size.z() < 1.0 ? found[1] : found[0];
  EXPECT_EQ(cone.object_class, ObjectClass::kSmallObject);
  // The cone's cells touching the roller stay with the roller: its box is the cone less one 0.1 m cell row.
  EXPECT_LT((cone.box.center().head<2>() - s.cone.center().head<2>()).norm(), 0.12);
  EXPECT_NEAR(cone.box.size.z(), 0.8, 0.01);
  EXPECT_LE(cone.box.size.x(), 0.45);
  EXPECT_EQ(roller.object_class, ObjectClass::kVehicle);
  EXPECT_LT((roller.seen_center.head<2>() - s.roller.center().head<2>()).norm(), 0.12);
  EXPECT_NEAR(roller.box.size.z(), 2.8, 0.01);
}

TEST(SplitCompactObjects, DoesNotDependOnPointOrder) {
  const ConeAgainstRoller s;
  std::vector<Eigen::Vector3d> shuffled = s.points;
  std::shuffle(shuffled.begin(), shuffled.end(), std::mt19937(5));
  DetectOptions o;
  o.sensor_xy = Eigen::Vector2d::Zero();
  const auto as_sets = [&](const std::vector<Eigen::Vector3d>& p) {
    std::vector<int> all(p.size());
    for (size_t i = 0; i < p.size(); ++i) all[i] = static_cast<int>(i);
    std::set<std::set<std::tuple<double, double, double>>> out;
    for (const std::vector<int>& piece : SplitCompactObjects(p, Heights(p), all, o)) {
      std::set<std::tuple<double, double, double>> members;
      for (int i : piece) members.insert({p[i].x(), p[i].y(), p[i].z()});
      out.insert(members);
    }
    return out;
  };
  const auto a = as_sets(s.points);
  EXPECT_EQ(a.size(), 2u);
  EXPECT_EQ(a, as_sets(shuffled));
}

TEST(DetectObjects, ACarsHoodAndBumperStayWithIt) {
  // A car built of a 1.5 m tall cabin, a 0.9 m hood in front of it and a 0.5 m bumper jutting 0.2 m beyond the
  // hood, seen from ahead, from the side and from a front corner: the low parts are strips along a whole end,
  // not compact, so the car stays one box. The same strip read as compact (split_max_extent 2 m) comes off:
  // this is what keeps it on.
  for (const double yaw : {M_PI, M_PI / 2, 3 * M_PI / 4}) {
    SCOPED_TRACE(yaw);
    const Eigen::Vector2d centre(12, 3), ahead(std::cos(yaw), std::sin(yaw));
    const auto part = [&](double along, double length, double height) {
      const Eigen::Vector2d c = centre + along * ahead;
      return MakeBox(c.x(), c.y(), yaw, length, 1.8, height);
    };
    std::vector<Eigen::Vector3d> pts;
    for (const Box3& b : {part(-0.5, 3.0, 1.5), part(1.5, 1.0, 0.9), part(2.1, 0.2, 0.5)})
      AddBoxReturns(b, Eigen::Vector3d(0, 0, 1.8), 0.05, &pts);
    std::vector<DetectedObject> found = DetectObjects(pts, Heights(pts));
    ASSERT_EQ(found.size(), 1u);
    EXPECT_EQ(found[0].object_class, ObjectClass::kVehicle);
    DetectOptions loose;
    loose.split_max_extent = 2.0;
    EXPECT_GT(DetectObjects(pts, Heights(pts), loose).size(), 1u);
  }
}

TEST(DetectObjects, Deterministic) {
  const Scene s;
  const auto a = DetectObjects(s.points, Heights(s.points)), b = DetectObjects(s.points, Heights(s.points));
  ASSERT_EQ(a.size(), b.size());
  for (size_t k = 0; k < a.size(); ++k) {
    EXPECT_EQ(a[k].box.center(), b[k].box.center());
    EXPECT_EQ(a[k].box.size, b[k].box.size);
  }
}

}  // namespace
}  // namespace sd::perception
