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
  // True when `p` (parent frame) lies inside the box grown by `margin` on every side.
  bool Contains(const Eigen::Vector3d& p, double margin = 0.0) const;
  // Box expressed in another frame: T_new_frame * box.
  Box3 Transformed(const Rigid3d& T_new_frame) const;
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
