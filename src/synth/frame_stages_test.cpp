// The object scene of a frame: what each object's receiver patch must hold.
#include "synth/frame_stages.h"

#include <cmath>

#include <gtest/gtest.h>

#include "assetgen/asset.h"

namespace sd {
namespace {

// A box asset of the given size standing at `position` (ego frame), turned `yaw` about z.
PlacedObject Standing(const Asset& asset, const Eigen::Vector3d& position, double yaw) {
  PlacedObject o;
  o.asset = &asset;
  o.T_ego_asset = Rigid3d(Eigen::Quaterniond(Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ())), position);
  o.box.T_frame_box = Rigid3d(o.T_ego_asset.rotation, position + Eigen::Vector3d(0, 0, 0.5 * asset.info.extent.z()));
  o.box.size = asset.info.extent;
  return o;
}

Asset BoxAsset(const Eigen::Vector3d& size) {
  Asset a;
  const Eigen::Vector3f h = (0.5 * size).cast<float>();
  for (int i = 0; i < 8; ++i)
    a.mesh.positions.emplace_back((i & 1) ? h.x() : -h.x(), (i & 2) ? h.y() : -h.y(), (i & 4) ? 2 * h.z() : 0.0f);
  const int quads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4}, {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  for (const auto& q : quads) {
    a.mesh.faces.emplace_back(q[0], q[1], q[2]);
    a.mesh.faces.emplace_back(q[0], q[2], q[3]);
  }
  a.info.extent = size;
  return a;
}

// Is ego point p (on the ground) over object k's patch? The patch is a rectangle: p lies inside when some face of
// it contains p's projection.
bool OnPatch(const frame_stages::ObjectScene& s, size_t k, const Eigen::Vector2d& p) {
  const size_t first = k == 0 ? 0 : s.receiver_faces_end[k - 1];
  for (size_t f = first; f < s.receiver_faces_end[k]; ++f) {
    const auto& face = s.receiver->faces[f];
    const Eigen::Vector2d a = s.receiver->positions[face[0]].head<2>().cast<double>();
    const Eigen::Vector2d b = s.receiver->positions[face[1]].head<2>().cast<double>();
    const Eigen::Vector2d c = s.receiver->positions[face[2]].head<2>().cast<double>();
    const auto cross = [](const Eigen::Vector2d& u, const Eigen::Vector2d& v) { return u.x() * v.y() - u.y() * v.x(); };
    const double d1 = cross(b - a, p - a), d2 = cross(c - b, p - b), d3 = cross(a - c, p - c);
    if ((d1 >= -1e-9 && d2 >= -1e-9 && d3 >= -1e-9) || (d1 <= 1e-9 && d2 <= 1e-9 && d3 <= 1e-9)) return true;
  }
  return false;
}

TEST(ObjectScene, EachPatchHoldsItsSunShadowAndASkyMarginAndLittleElse) {
  const Asset cone = BoxAsset({0.4, 0.4, 0.7}), car = BoxAsset({4.5, 1.8, 1.5});
  for (const Eigen::Vector3d& sun : {Eigen::Vector3d(1, 0.5, 0.6), Eigen::Vector3d(-0.3, 1, 1.5), Eigen::Vector3d(0, 0, 1),
                                    Eigen::Vector3d(0.2, -1, 0.1)}) {
    SCOPED_TRACE(sun.transpose());
    const std::vector<PlacedObject> placed = {Standing(cone, {8, 2, 0}, 0.3), Standing(car, {15, -3, 0}, -1.1)};
    const frame_stages::ObjectScene s = frame_stages::BuildObjectScene(placed, sun.normalized());
    ASSERT_EQ(s.receiver_faces_end.size(), 2u);
    ASSERT_EQ(s.extent_of.size(), 2u);
    // The sun the patch is made for: at least 15 degrees up.
    Eigen::Vector3d l = sun.normalized();
    const double min_z = std::sin(std::asin(0.26));
    if (l.z() < min_z) l = Eigen::Vector3d(l.x(), l.y(), 0).normalized() * std::sqrt(1 - min_z * min_z) + Eigen::Vector3d(0, 0, min_z);
    for (size_t k = 0; k < placed.size(); ++k) {
      const Box3& box = placed[k].box;
      const double margin = std::max(1.0, box.size.z());
      // The shadow: each top corner of the box carried along -sun to the ground; the footprint grown by the margin.
      for (const Eigen::Vector3d& c : box.Corners()) {
        if (c.z() < 0.5 * box.size.z()) continue;
        const Eigen::Vector3d shadow = c - l * (c.z() / l.z());
        EXPECT_TRUE(OnPatch(s, k, shadow.head<2>())) << "object " << k << ": shadow corner " << shadow.transpose();
        const Eigen::Vector2d out = (c.head<2>() - box.center().head<2>()).normalized();
        EXPECT_TRUE(OnPatch(s, k, c.head<2>() + 0.95 * margin * out)) << "object " << k << ": sky margin";
      }
      // Little else: the patch reaches no further than the shadow's length and the margin from the footprint.
      const double shadow_length = box.size.z() * std::sqrt(1 - l.z() * l.z()) / l.z();
      const double reach = 0.5 * box.size.head<2>().norm() + shadow_length + margin;
      const size_t first = k == 0 ? 0 : s.receiver_faces_end[k - 1];
      for (size_t f = first; f < s.receiver_faces_end[k]; ++f)
        for (int v : {s.receiver->faces[f][0], s.receiver->faces[f][1], s.receiver->faces[f][2]})
          ASSERT_LE((s.receiver->positions[v].head<2>().cast<double>() - box.center().head<2>()).norm(), reach * std::sqrt(2.0) + 1e-6);
      // The side towards the sun gets the margin only (an overhead sun has no side).
      if (l.head<2>().norm() < 0.1) continue;
      const Eigen::Vector2d towards_sun = l.head<2>().normalized();
      const double footprint = 0.5 * box.size.head<2>().norm();
      EXPECT_FALSE(OnPatch(s, k, box.center().head<2>() + (footprint + margin + 0.3) * towards_sun)) << "object " << k;
    }
  }
}

}  // namespace
}  // namespace sd
