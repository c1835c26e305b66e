#include "assetgen/base_plate.h"

#include <algorithm>
#include <cmath>

#include <Eigen/Dense>

#include "assetgen/shape_prior.h"
#include "assetgen/texture_eval.h"
#include "core/error.h"

namespace sd {
namespace {

constexpr double kPi = 3.14159265358979323846;
// Moulded plates have rounded corners: the outline is the superellipse |x|^p + |y|^p = 1, whose corner lies
// 0.93 of a sharp square's corner distance out at p = 10 (the two benchmark cones' plates: 0.93, 0.97).
constexpr double kCornerExponent = 10;

using Ring = std::vector<Eigen::Vector2d>;

// Soft IoU of a coverage image with the mask.
double SoftIou(const ImageF& a, const ImageF& b) {
  double inter = 0, uni = 0;
  for (size_t i = 0; i < a.vector().size(); ++i) {
    const double x = std::clamp(a.vector()[i], 0.0f, 1.0f), y = std::clamp(b.vector()[i], 0.0f, 1.0f);
    inter += std::min(x, y), uni += std::max(x, y);
  }
  return uni > 0 ? inter / uni : 0.0;
}

}  // namespace

bool HasBasePlate(const std::string& category) { return category == "traffic_cone"; }

TriangleMesh SurfaceOfRevolutionOnPlate(const std::vector<std::pair<double, double>>& rings, int segments,
                                        const BasePlate& plate) {
  SD_CHECK(plate.half_x > 0 && plate.half_y > 0 && plate.thickness > 0);
  segments = std::max(4, (segments + 3) / 4 * 4);
  // Angles start at a corner (45 degrees off the plate's x axis in its own square frame), so every quarter of
  // the samples lands on one's apex.
  std::vector<double> angle(segments);
  for (int j = 0; j < segments; ++j) angle[j] = plate.yaw + kPi / 4 + 2 * kPi * j / segments;
  Ring square(segments);
  const double c = std::cos(plate.yaw), s = std::sin(plate.yaw);
  for (int j = 0; j < segments; ++j) {
    const double phi = angle[j] - plate.yaw;
    const double k = std::pow(std::pow(std::abs(std::cos(phi)), kCornerExponent) +
                                  std::pow(std::abs(std::sin(phi)), kCornerExponent),
                              -1.0 / kCornerExponent);
    const double x = plate.half_x * k * std::cos(phi), y = plate.half_y * k * std::sin(phi);
    square[j] = {c * x - s * y, s * x + c * y};
  }
  // The body stays inside the plate's top face (the flat annulus between them must not fold over).
  const double inscribed = 0.97 * std::min(plate.half_x, plate.half_y);
  auto circle = [&](double r) {
    Ring ring(segments);
    r = std::min(r, inscribed);
    for (int j = 0; j < segments; ++j) ring[j] = {r * std::cos(angle[j]), r * std::sin(angle[j])};
    return ring;
  };
  std::vector<Ring> loft = {square, square};
  std::vector<double> z = {0.0, plate.thickness};
  // The body's first ring sits on the plate's top face, at the radius the profile has there.
  double foot = rings.front().second;
  for (size_t i = 0; i + 1 < rings.size(); ++i)
    if (rings[i + 1].first >= plate.thickness) {
      const double t = (plate.thickness - rings[i].first) / std::max(1e-12, rings[i + 1].first - rings[i].first);
      foot = rings[i].second + std::clamp(t, 0.0, 1.0) * (rings[i + 1].second - rings[i].second);
      break;
    }
  loft.push_back(circle(foot)), z.push_back(plate.thickness);
  for (const auto& [zi, r] : rings)
    if (zi > plate.thickness + 1e-9) loft.push_back(circle(r)), z.push_back(zi);
  SD_CHECK(loft.size() >= 4);  // a body above the plate
  return LoftRings(loft, z);
}

BasePlateFit FitBasePlate(const std::vector<std::pair<double, double>>& rings, const ViewCamera& photo,
                          const ImageF& mask, double aspect, std::optional<Eigen::Vector2d> half_sides) {
  BasePlateFit out;
  aspect = half_sides ? half_sides->y() / half_sides->x() : std::clamp(aspect, 0.2, 5.0);
  auto iou_of = [&](const TriangleMesh& mesh) { return SoftIou(RenderAlbedo(mesh, photo, 2).mask, mask); };
  if (rings.size() < 8) {
    out.note = "too few profile rows to look for a plate";
    return out;
  }
  const double z0 = rings.front().first, h = rings.back().first - z0;

  // The body's straight line, r = a + b z, over the middle half (a cone's side; its tip may be rounded).
  Eigen::Matrix2d A = Eigen::Matrix2d::Zero();
  Eigen::Vector2d rhs = Eigen::Vector2d::Zero();
  int used = 0;
  for (const auto& [z, r] : rings)
    if (z >= z0 + 0.3 * h && z <= z0 + 0.8 * h) {
      const Eigen::Vector2d x(1, z);
      A += x * x.transpose(), rhs += x * r, ++used;
    }
  if (used < 4) {
    out.note = "too few profile rows along the body to look for a plate";
    return out;
  }
  const Eigen::Vector2d line = A.ldlt().solve(rhs);
  auto body_r = [&](double z) { return std::max(1e-4 * h, line[0] + line[1] * z); };

  // The flare: foot rows wider than the line by more than 10 % and 1.5 pixels (at the object's distance).
  const Eigen::Vector3d centre(0, 0, z0 + h / 2);
  const double pixel = (photo.T_world_cam.translation - centre).norm() / photo.camera.fy;
  double z_flare = -1, r_foot = 0;
  for (const auto& [z, r] : rings) {
    if (z >= z0 + 0.3 * h) break;
    r_foot = std::max(r_foot, r);
    if (r - body_r(z) > std::max(0.1 * body_r(z), 1.5 * pixel)) z_flare = z;
  }
  if (z_flare <= z0 || r_foot < 1.15 * body_r(z0) || r_foot - body_r(z0) < 2 * pixel) {
    out.note = "no flare at the foot";
    return out;
  }
  out.iou_disc = iou_of(SurfaceOfRevolution(rings, 64));

  // Candidates: the plate's heading psi, its thickness t and its bottom g (both in units of the flare's height
  // above the profile's lowest ring: the revolve grounds the object at its lowest side row, which for a plate seen
  // from above is not the plate's bottom edge), and a factor k on the half-sides that makes the plate as wide across
  // the line of sight as the foot's widest row (unless the half-sides were measured).
  const double camera_azimuth = std::atan2(photo.T_world_cam.translation.y(), photo.T_world_cam.translation.x());
  const double flare = z_flare - z0;
  struct Candidate {
    double psi = 0, t = 0.5, g = 0, k = 1, iou = -1;
  } best;
  // The plate, the body above it in a frame grounded at the plate's bottom (z = 0 there), and where that bottom
  // lies in the rings' z.
  struct Model {
    BasePlate plate;
    std::vector<std::pair<double, double>> body;
    double ground = 0;
  };
  auto make = [&](const Candidate& c) {
    Model m;
    const double beta = c.psi - camera_azimuth;
    const double half_x =
        half_sides ? half_sides->x() : c.k * r_foot / (std::abs(std::sin(beta)) + aspect * std::abs(std::cos(beta)));
    m.plate = {half_x, aspect * half_x, c.t * flare, c.psi};
    m.ground = z0 + c.g * flare;
    for (const auto& [z, r] : rings)
      if (z - m.ground > m.plate.thickness) m.body.emplace_back(z - m.ground, z <= z_flare ? body_r(z) : r);
    return m;
  };
  auto score = [&](Candidate c) {
    const Model m = make(c);
    if (m.body.size() < 2) return;
    TriangleMesh mesh = SurfaceOfRevolutionOnPlate(m.body, 64, m.plate);
    for (Eigen::Vector3f& p : mesh.positions) p.z() += float(m.ground);
    c.iou = iou_of(mesh);
    if (c.iou > best.iou) best = c;
  };
  // Coordinate sweeps, each from the best so far. A square plate looks the same every 90 degrees, an oblong one
  // every 180.
  const double period = std::abs(aspect - 1) < 1e-3 ? 90 : 180;
  // Every combination of the values given for some fields, the others as in the best so far.
  using Field = double Candidate::*;
  auto sweep = [&](std::vector<std::pair<Field, std::vector<double>>> grid) {
    const Candidate base = best;
    std::vector<size_t> at(grid.size(), 0);
    while (true) {
      Candidate c = base;
      for (size_t d = 0; d < grid.size(); ++d) c.*grid[d].first = grid[d].second[at[d]];
      score(c);
      size_t d = 0;
      while (d < grid.size() && ++at[d] == grid[d].second.size()) at[d++] = 0;
      if (d == grid.size()) return;
    }
  };
  auto values = [](double from, double to, double step) {
    std::vector<double> v;
    for (double x = from; x <= to + 1e-9; x += step) v.push_back(x);
    return v;
  };
  auto around = [&](double centre, double step, double lo, double hi) {
    std::vector<double> v;
    for (int i = -2; i <= 2; ++i) v.push_back(std::clamp(centre + i * step, lo, hi));
    return v;
  };
  const double deg = kPi / 180;
  // The heading first (the plate's outline turns most with it), then the thickness, the ground and the size
  // together — they trade against each other (a lower plate is a thicker one, or a wider one at its top edge) —
  // on a coarse grid, then finer about the best, then the heading again.
  best.k = half_sides ? 1 : 1.1;
  sweep({{&Candidate::psi, values(0, (period - 3) * deg, 3 * deg)}});
  const std::vector<double> sizes = half_sides ? std::vector<double>{1} : values(0.85, 1.25, 0.1);
  sweep({{&Candidate::t, values(0.1, 1.0, 0.15)}, {&Candidate::g, values(-0.4, 0.4, 0.2)}, {&Candidate::k, sizes}});
  for (int round = 0; round < 2; ++round) {
    const double f = round == 0 ? 1 : 0.5;
    sweep({{&Candidate::t, around(best.t, 0.05 * f, 0.05, 1.0)}, {&Candidate::g, around(best.g, 0.05 * f, -0.6, 0.6)}});
    if (!half_sides)
      sweep({{&Candidate::k, around(best.k, 0.025 * f, 0.7, 1.4)}, {&Candidate::g, around(best.g, 0.05 * f, -0.6, 0.6)}});
  }
  sweep({{&Candidate::psi, values(best.psi - 2 * deg, best.psi + 2 * deg, 1 * deg)}});
  out.iou_plate = best.iou;
  if (out.iou_plate < out.iou_disc) {
    out.note = Msg() << "the foot flares, but a plate fits the photo worse than a disc (IoU " << out.iou_plate
                     << " < " << out.iou_disc << ")";
    return out;
  }
  Model m = make(best);
  out.plate = m.plate, out.body = std::move(m.body), out.ground = m.ground;
  // No sizes here: the caller grounds and rescales the shape after this fit.
  out.note = Msg() << "square plate, " << (half_sides ? "its sides from the measured box" : "its sides fitted")
                   << ", at " << std::fmod(best.psi * 180 / kPi + 360, 360) << " deg to the photo's line of sight"
                   << " (photo IoU " << out.iou_plate << " against a disc's " << out.iou_disc << ")";
  return out;
}

}  // namespace sd
