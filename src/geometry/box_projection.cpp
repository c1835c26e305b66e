#include "geometry/box_projection.h"

#include <algorithm>
#include <array>
#include <limits>

#include "geometry/polygon.h"

namespace sd::geometry {
namespace {

// Box edges as corner index pairs (Box3::Corners order: bottom face 0..3, top face 4..7).
constexpr int kEdges[12][2] = {{0, 1}, {1, 2}, {2, 3}, {3, 0}, {4, 5}, {5, 6},
                               {6, 7}, {7, 4}, {0, 4}, {1, 5}, {2, 6}, {3, 7}};
// Points per edge: with lens distortion a straight edge projects to a curve, whose hull the samples follow.
constexpr int kEdgeSamples = 8;

}  // namespace

std::vector<Eigen::Vector2d> ProjectBoxOutline(const PinholeCamera& camera, const Rigid3d& T_cam_frame, const Box3& box,
                                               double near_m) {
  const auto corners = box.Corners();
  std::array<Eigen::Vector3d, 8> c;
  for (int i = 0; i < 8; ++i) c[i] = T_cam_frame * corners[i];
  std::vector<Eigen::Vector2d> pts;
  // Project with a depth floor just under the near plane so points clipped exactly onto it are kept.
  const double min_depth = near_m * (1 - 1e-9);
  for (const auto& e : kEdges) {
    Eigen::Vector3d a = c[e[0]], b = c[e[1]];
    if (a.z() < near_m && b.z() < near_m) continue;
    if (a.z() < near_m) a = a + (b - a) * ((near_m - a.z()) / (b.z() - a.z()));
    else if (b.z() < near_m) b = b + (a - b) * ((near_m - b.z()) / (a.z() - b.z()));
    const int n = camera.distortion.IsZero() ? 1 : kEdgeSamples;
    for (int s = 0; s <= n; ++s) {
      const Eigen::Vector3d p = a + (b - a) * (static_cast<double>(s) / n);
      if (auto uv = camera.Project(p, min_depth)) pts.push_back(*uv);
    }
  }
  if (pts.empty()) return {};
  return ConvexHull2D(std::move(pts));
}

std::optional<BoxInImage> ProjectBoxToImage(const PinholeCamera& camera, const Rigid3d& T_cam_frame, const Box3& box, double near_m) {
  BoxInImage b;
  b.outline = ProjectBoxOutline(camera, T_cam_frame, box, near_m);
  if (b.outline.size() < 3) return std::nullopt;
  constexpr double kInf = std::numeric_limits<double>::infinity();
  b.full = Box2{kInf, kInf, -kInf, -kInf};
  for (const Eigen::Vector2d& p : b.outline) {
    b.full.x1 = std::min(b.full.x1, p.x()), b.full.y1 = std::min(b.full.y1, p.y());
    b.full.x2 = std::max(b.full.x2, p.x()), b.full.y2 = std::max(b.full.y2, p.y());
  }
  if (b.full.Area() <= 0) return std::nullopt;
  b.clipped = Box2{std::max(b.full.x1, 0.0), std::max(b.full.y1, 0.0), std::min(b.full.x2, double(camera.width)),
                   std::min(b.full.y2, double(camera.height))};
  b.truncation = std::clamp(1.0 - b.clipped.Area() / b.full.Area(), 0.0, 1.0);
  return b;
}

}  // namespace sd::geometry
