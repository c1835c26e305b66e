#pragma once
// Convex polygons in the plane: the hull of a point set, the inside test and the overlap test, shared by the
// canonical frame's support polygon (assetgen), the projected outline of a 3D box in an image (mining) and the
// ground shadows of boxes (synth/realism).
#include <vector>

#include <Eigen/Core>

namespace sd::geometry {

// Andrew's monotone chain: the convex hull, counter-clockwise (in a y-up plane; clockwise on screen when y
// points down), without repeated points or collinear vertices. Fewer than 3 distinct points come back as they
// are (deduplicated).
std::vector<Eigen::Vector2d> ConvexHull2D(std::vector<Eigen::Vector2d> points);

// Whether `p` lies inside (or on the boundary of) a polygon in ConvexHull2D's orientation.
bool InsideConvexPolygon(const std::vector<Eigen::Vector2d>& polygon, const Eigen::Vector2d& p);

// Whether two convex polygons' interiors overlap (no separating axis among their edge normals); polygons that
// only touch do not. Either orientation; fewer than 3 points never overlap.
bool ConvexPolygonsOverlap(const std::vector<Eigen::Vector2d>& a, const std::vector<Eigen::Vector2d>& b);

}  // namespace sd::geometry
