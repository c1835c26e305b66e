#pragma once
// Closest points on a triangle mesh, and the point-to-surface term that pulls a mesh onto measured points
// (LiDAR returns of an object) during refinement.
//
// A bounding-volume hierarchy over the triangles (median splits, a few triangles per leaf) answers exact
// nearest-surface queries; it is rebuilt whenever the mesh changes, which costs less than one query pass.
#include <cstdint>
#include <vector>

#include <Eigen/Core>

namespace sd::geometry {

struct SurfacePoint {
  int face = -1;                  // -1 when the mesh has no faces
  Eigen::Vector3f barycentric;    // weights of the face's three vertices (sum 1, all >= 0)
  Eigen::Vector3f point;          // the closest surface point
  float squared_distance = 0;
};

class TriangleBvh {
 public:
  // Keeps references to `positions` and `faces`: they must outlive the tree and stay unchanged.
  TriangleBvh(const std::vector<Eigen::Vector3f>& positions, const std::vector<Eigen::Vector3i>& faces);
  SurfacePoint Closest(const Eigen::Vector3f& p) const;

 private:
  struct Node {
    Eigen::Vector3f lo, hi;
    int first = 0, count = 0;  // leaf: triangles order_[first, first + count); inner: count = 0, children first, first + 1
  };
  int Build(int begin, int end, std::vector<Eigen::Vector3f>& centroids);
  const std::vector<Eigen::Vector3f>& positions_;
  const std::vector<Eigen::Vector3i>& faces_;
  std::vector<int> order_;
  std::vector<Node> nodes_;
};

// Closest point of triangle (a, b, c) to p (Ericson, Real-Time Collision Detection 5.1.5), as barycentrics.
Eigen::Vector3f ClosestBarycentricOnTriangle(const Eigen::Vector3f& p, const Eigen::Vector3f& a, const Eigen::Vector3f& b,
                                             const Eigen::Vector3f& c);

// Distances (not squared) of `points` to the mesh surface, in the points' order.
std::vector<float> PointToSurfaceDistances(const std::vector<Eigen::Vector3f>& positions,
                                           const std::vector<Eigen::Vector3i>& faces,
                                           const std::vector<Eigen::Vector3f>& points);

// The point term: L = weight · mean over the points within `max_distance` of the surface of |p − q(p)|²,
// q(p) the closest surface point. Points farther away (gross outliers: a return of the road or of a
// neighbour) do not count; `counted` receives how many did. Adds dL/d(positions) to *grad (sized like
// positions): with q = Σ b_i v_i, d|p − q|²/dv_i = −2 b_i (p − q) — exact wherever the closest point is
// unique, since moving q within the surface does not change the distance to first order.
// Returns L. Deterministic: the per-point work runs in parallel, the gradient is summed in point order.
double PointToSurfaceLoss(const std::vector<Eigen::Vector3f>& positions, const std::vector<Eigen::Vector3i>& faces,
                          const std::vector<Eigen::Vector3f>& points, float weight, float max_distance,
                          std::vector<Eigen::Vector3f>* grad, size_t* counted = nullptr);

}  // namespace sd::geometry
