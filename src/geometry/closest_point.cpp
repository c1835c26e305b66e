#include "geometry/closest_point.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <numeric>

#include "core/parallel.h"

namespace sd::geometry {
namespace {

constexpr int kLeafTriangles = 4;

float BoxSquaredDistance(const Eigen::Vector3f& p, const Eigen::Vector3f& lo, const Eigen::Vector3f& hi) {
  const Eigen::Vector3f d = (lo - p).cwiseMax(Eigen::Vector3f::Zero()).cwiseMax(p - hi);
  return d.squaredNorm();
}

}  // namespace

Eigen::Vector3f ClosestBarycentricOnTriangle(const Eigen::Vector3f& p, const Eigen::Vector3f& a, const Eigen::Vector3f& b,
                                             const Eigen::Vector3f& c) {
  const Eigen::Vector3f ab = b - a, ac = c - a, ap = p - a;
  const float d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return {1, 0, 0};
  const Eigen::Vector3f bp = p - b;
  const float d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return {0, 1, 0};
  const float vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) {
    const float v = d1 - d3 != 0 ? d1 / (d1 - d3) : 0.0f;
    return {1 - v, v, 0};
  }
  const Eigen::Vector3f cp = p - c;
  const float d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return {0, 0, 1};
  const float vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) {
    const float w = d2 - d6 != 0 ? d2 / (d2 - d6) : 0.0f;
    return {1 - w, 0, w};
  }
  const float va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    const float denom = (d4 - d3) + (d5 - d6);
    const float w = denom != 0 ? (d4 - d3) / denom : 0.0f;
    return {0, 1 - w, w};
  }
  const float sum = va + vb + vc;
  if (!(sum > 0)) return {1, 0, 0};  // degenerate triangle: its first corner
  const float v = vb / sum, w = vc / sum;
  return {1 - v - w, v, w};
}

TriangleBvh::TriangleBvh(const std::vector<Eigen::Vector3f>& positions, const std::vector<Eigen::Vector3i>& faces)
    : positions_(positions), faces_(faces) {
  if (faces.empty()) return;
  order_.resize(faces.size());
  std::iota(order_.begin(), order_.end(), 0);
  std::vector<Eigen::Vector3f> centroids(faces.size());
  for (size_t f = 0; f < faces.size(); ++f)
    centroids[f] = (positions[faces[f][0]] + positions[faces[f][1]] + positions[faces[f][2]]) / 3.0f;
  nodes_.reserve(2 * faces.size() / kLeafTriangles + 2);
  Build(0, static_cast<int>(faces.size()), centroids);
}

int TriangleBvh::Build(int begin, int end, std::vector<Eigen::Vector3f>& centroids) {
  const int index = static_cast<int>(nodes_.size());
  nodes_.emplace_back();
  Eigen::Vector3f lo = Eigen::Vector3f::Constant(std::numeric_limits<float>::max()), hi = -lo;
  Eigen::Vector3f clo = lo, chi = hi;
  for (int i = begin; i < end; ++i) {
    const Eigen::Vector3i& f = faces_[order_[i]];
    for (int k = 0; k < 3; ++k) lo = lo.cwiseMin(positions_[f[k]]), hi = hi.cwiseMax(positions_[f[k]]);
    clo = clo.cwiseMin(centroids[order_[i]]), chi = chi.cwiseMax(centroids[order_[i]]);
  }
  nodes_[index].lo = lo;
  nodes_[index].hi = hi;
  if (end - begin <= kLeafTriangles) {
    nodes_[index].first = begin;
    nodes_[index].count = end - begin;
    return index;
  }
  int axis = 0;
  (chi - clo).maxCoeff(&axis);
  const int mid = (begin + end) / 2;
  std::nth_element(order_.begin() + begin, order_.begin() + mid, order_.begin() + end,
                   [&](int a, int b) { return centroids[a][axis] < centroids[b][axis]; });
  // Children are built depth first, so the left child is always index + 1; the right one's index is stored.
  Build(begin, mid, centroids);
  const int right = Build(mid, end, centroids);
  nodes_[index].first = right;
  nodes_[index].count = 0;
  return index;
}

SurfacePoint TriangleBvh::Closest(const Eigen::Vector3f& p) const {
  SurfacePoint best;
  best.squared_distance = std::numeric_limits<float>::infinity();
  if (nodes_.empty()) return best;
  int stack[128];
  int top = 0;
  stack[top++] = 0;
  while (top > 0) {
    const Node& n = nodes_[stack[--top]];
    if (BoxSquaredDistance(p, n.lo, n.hi) >= best.squared_distance) continue;
    if (n.count > 0) {
      for (int i = n.first; i < n.first + n.count; ++i) {
        const Eigen::Vector3i& f = faces_[order_[i]];
        const Eigen::Vector3f &a = positions_[f[0]], &b = positions_[f[1]], &c = positions_[f[2]];
        const Eigen::Vector3f w = ClosestBarycentricOnTriangle(p, a, b, c);
        const Eigen::Vector3f q = w[0] * a + w[1] * b + w[2] * c;
        const float d2 = (p - q).squaredNorm();
        if (d2 < best.squared_distance) best = {order_[i], w, q, d2};
      }
      continue;
    }
    // Inner node: visit the nearer child first so the farther one is more often pruned.
    const int left = static_cast<int>(&n - nodes_.data()) + 1, right = n.first;
    const float dl = BoxSquaredDistance(p, nodes_[left].lo, nodes_[left].hi);
    const float dr = BoxSquaredDistance(p, nodes_[right].lo, nodes_[right].hi);
    if (top + 2 > 128) continue;  // depth is ~log2(faces / 4): never near this
    if (dl < dr) stack[top++] = right, stack[top++] = left;
    else stack[top++] = left, stack[top++] = right;
  }
  return best;
}

std::vector<float> PointToSurfaceDistances(const std::vector<Eigen::Vector3f>& positions,
                                           const std::vector<Eigen::Vector3i>& faces,
                                           const std::vector<Eigen::Vector3f>& points) {
  const TriangleBvh bvh(positions, faces);
  std::vector<float> out(points.size(), std::numeric_limits<float>::infinity());
  ParallelFor(0, points.size(), [&](size_t i) { out[i] = std::sqrt(bvh.Closest(points[i]).squared_distance); }, 64);
  return out;
}

double PointToSurfaceLoss(const std::vector<Eigen::Vector3f>& positions, const std::vector<Eigen::Vector3i>& faces,
                          const std::vector<Eigen::Vector3f>& points, float weight, float max_distance,
                          std::vector<Eigen::Vector3f>* grad, size_t* counted) {
  if (counted) *counted = 0;
  if (points.empty() || faces.empty()) return 0;
  const TriangleBvh bvh(positions, faces);
  std::vector<SurfacePoint> closest(points.size());
  ParallelFor(0, points.size(), [&](size_t i) { closest[i] = bvh.Closest(points[i]); }, 64);
  const float max_d2 = max_distance * max_distance;
  size_t n = 0;
  for (const SurfacePoint& s : closest) n += s.squared_distance <= max_d2;
  if (counted) *counted = n;
  if (n == 0) return 0;
  const float scale = weight / static_cast<float>(n);
  double sum = 0;
  for (size_t i = 0; i < points.size(); ++i) {
    const SurfacePoint& s = closest[i];
    if (!(s.squared_distance <= max_d2)) continue;
    sum += s.squared_distance;
    if (!grad) continue;
    const Eigen::Vector3f g = -2.0f * scale * (points[i] - s.point);
    const Eigen::Vector3i& f = faces[s.face];
    for (int k = 0; k < 3; ++k) (*grad)[f[k]] += s.barycentric[k] * g;
  }
  return weight * sum / static_cast<double>(n);
}

}  // namespace sd::geometry
