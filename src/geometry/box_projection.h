#pragma once
// A 3D box in a camera image: the one projection that mining's crops, harvest's views and synth's labels share,
// so a box's outline and its truncation mean the same everywhere.
#include <optional>
#include <vector>

#include <Eigen/Core>

#include "core/box3.h"
#include "core/camera.h"
#include "core/rigid3.h"

namespace sd::geometry {

// The convex outline of `box` (in the frame T_cam_frame maps from) in the image, in pixels. Edges are clipped
// to the near plane z = near_m first: the part of a box behind the camera would project through infinity. With
// lens distortion each edge is sampled, since a straight edge projects to a curve. Empty when the whole box is
// behind the near plane.
std::vector<Eigen::Vector2d> ProjectBoxOutline(const PinholeCamera& camera, const Rigid3d& T_cam_frame, const Box3& box,
                                               double near_m);

struct BoxInImage {
  std::vector<Eigen::Vector2d> outline;  // ProjectBoxOutline
  Box2 full;     // the outline's bounding rectangle; may reach past the image
  Box2 clipped;  // `full` inside the image
  // The share of `full` outside the image (KITTI's truncation), in [0, 1].
  double truncation = 1;
};
// The outline's rectangles and truncation; nullopt when the box is behind the near plane or its outline is
// degenerate. A box that projects entirely outside the image has truncation 1 and an empty `clipped`.
std::optional<BoxInImage> ProjectBoxToImage(const PinholeCamera& camera, const Rigid3d& T_cam_frame, const Box3& box, double near_m);

}  // namespace sd::geometry
