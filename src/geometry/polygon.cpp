#include "geometry/polygon.h"

#include <algorithm>

namespace sd::geometry {

namespace {

double Cross(const Eigen::Vector2d& o, const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
  return (a.x() - o.x()) * (b.y() - o.y()) - (a.y() - o.y()) * (b.x() - o.x());
}

}  // namespace

std::vector<Eigen::Vector2d> ConvexHull2D(std::vector<Eigen::Vector2d> p) {
  std::sort(p.begin(), p.end(), [](const Eigen::Vector2d& a, const Eigen::Vector2d& b) {
    return a.x() < b.x() || (a.x() == b.x() && a.y() < b.y());
  });
  p.erase(std::unique(p.begin(), p.end()), p.end());
  if (p.size() < 3) return p;
  std::vector<Eigen::Vector2d> h(2 * p.size());
  size_t k = 0;
  for (size_t i = 0; i < p.size(); ++i) {  // lower chain
    while (k >= 2 && Cross(h[k - 2], h[k - 1], p[i]) <= 0) --k;
    h[k++] = p[i];
  }
  for (size_t i = p.size() - 1, t = k + 1; i-- > 0;) {  // upper chain
    while (k >= t && Cross(h[k - 2], h[k - 1], p[i]) <= 0) --k;
    h[k++] = p[i];
  }
  h.resize(k - 1);
  return h;
}

bool InsideConvexPolygon(const std::vector<Eigen::Vector2d>& polygon, const Eigen::Vector2d& p) {
  if (polygon.size() < 3) return false;
  for (size_t i = 0; i < polygon.size(); ++i)
    if (Cross(polygon[i], polygon[(i + 1) % polygon.size()], p) < 0) return false;
  return true;
}

bool ConvexPolygonsOverlap(const std::vector<Eigen::Vector2d>& a, const std::vector<Eigen::Vector2d>& b) {
  if (a.size() < 3 || b.size() < 3) return false;
  // Separating axis theorem: for convex shapes, some edge normal of one of them separates them if anything does.
  auto separated_along_edges_of = [](const std::vector<Eigen::Vector2d>& p, const std::vector<Eigen::Vector2d>& q) {
    for (size_t i = 0; i < p.size(); ++i) {
      const Eigen::Vector2d e = p[(i + 1) % p.size()] - p[i];
      const Eigen::Vector2d n(-e.y(), e.x());
      double p_lo = 1e300, p_hi = -1e300, q_lo = 1e300, q_hi = -1e300;
      for (const Eigen::Vector2d& v : p) p_lo = std::min(p_lo, n.dot(v)), p_hi = std::max(p_hi, n.dot(v));
      for (const Eigen::Vector2d& v : q) q_lo = std::min(q_lo, n.dot(v)), q_hi = std::max(q_hi, n.dot(v));
      const double eps = 1e-12 * std::max(1.0, n.squaredNorm());
      if (p_hi <= q_lo + eps || q_hi <= p_lo + eps) return true;
    }
    return false;
  };
  return !separated_along_edges_of(a, b) && !separated_along_edges_of(b, a);
}

}  // namespace sd::geometry
