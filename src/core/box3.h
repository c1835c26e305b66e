#pragma once
// Oriented 3D box. `T_frame_box` places the box frame, whose origin is the box's geometric centre and whose
// axes are the object's (x = length/front, y = width/left, z = height/up), in some parent frame (usually
// ego). `size` = (length, width, height) in metres. Datasets that use bottom centres or other yaw
// conventions are converted at their reader (see datasets/).
#include <array>

#include <Eigen/Core>

#include "core/rigid3.h"

namespace sd {

struct Box3 {
  Rigid3d T_frame_box;
  Eigen::Vector3d size = Eigen::Vector3d::Zero();

  const Eigen::Vector3d& center() const { return T_frame_box.translation; }
  double Yaw() const { return T_frame_box.Yaw(); }
  // Corners in the parent frame. Order: bottom face (z-) then top face (z+), each counter-clockwise from
  // (+x, +y) seen from above: (+,+), (-,+), (-,-), (+,-).
  std::array<Eigen::Vector3d, 8> Corners() const;
  // True when `p` (parent frame) lies inside the box grown by `margin` on every side (BoxContainment).
  bool Contains(const Eigen::Vector3d& p, double margin = 0.0) const;
  // Box expressed in another frame: T_new_frame * box.
  Box3 Transformed(const Rigid3d& T_new_frame) const;
};

// Box3::Contains for many points and one box: the box's inverse pose made once, not per point.
class BoxContainment {
 public:
  BoxContainment(const Box3& box, double margin = 0.0)
      : T_box_frame_(box.T_frame_box.Inverse()), reach_(0.5 * box.size.array() + margin) {}
  // A parent-frame point in the box's own frame (its centre at the origin, its axes along the sides).
  Eigen::Vector3d Local(const Eigen::Vector3d& p) const { return T_box_frame_ * p; }
  bool ContainsLocal(const Eigen::Vector3d& q) const { return (q.cwiseAbs().array() <= reach_).all(); }
  bool Contains(const Eigen::Vector3d& p) const { return ContainsLocal(Local(p)); }

 private:
  Rigid3d T_box_frame_;
  Eigen::Array3d reach_;
};

// Overlap test in the ground plane (oriented rectangles, separating axis theorem) of two boxes in the same
// z-up frame; z extents must also overlap. `margin` is a clearance in metres: each box grows by margin / 2
// on every side (footprint and z), so boxes whose gap is smaller than `margin` count as overlapping.
bool BoxesOverlap(const Box3& a, const Box3& b, double margin = 0.0);

// Axis-aligned 2D box in pixels, [x1, x2) x [y1, y2).
struct Box2 {
  double x1 = 0, y1 = 0, x2 = 0, y2 = 0;
  double Area() const { return x2 > x1 && y2 > y1 ? (x2 - x1) * (y2 - y1) : 0.0; }
  bool Empty() const { return !(x2 > x1 && y2 > y1); }
};
double IoU(const Box2& a, const Box2& b);

}  // namespace sd
