#pragma once
// Cosine-weighted hemisphere directions for sky-visibility rays, cheap enough to draw by the million.
//
// A fixed pattern of n points on the unit square, shifted per shading point (a Cranley-Patterson rotation), and
// mapped to the hemisphere by Malley's method. The pattern is correlated multi-jittered (Kensler 2013, "Correlated
// Multi-Jittered Sampling"): one point in each cell of a cols x rows grid of exactly n cells (StratifiedColumns)
// and one in each of the n columns and n rows, so that a shifted copy still stratifies the square and its n radii
// and n azimuths all differ. The shift makes each point's estimate unbiased; the pattern's radii and azimuth
// cosines are computed once per n, so a direction costs two square roots and a rotation, where a freshly jittered
// point costs two hashes, a sine and a cosine (most of the time of the road's sky before this).
#include <algorithm>
#include <cmath>
#include <cstdint>
#include <vector>

#include <Eigen/Core>

namespace sd {

class ShiftedCosinePattern {
 public:
  // n >= 1 directions; `shift_x`, `shift_azimuth` in [0, 1) (uniform per shading point, for an unbiased estimate).
  ShiftedCosinePattern(int n, float shift_x, float shift_azimuth);
  int size() const { return static_cast<int>(points_->size()); }
  // Direction k in the local frame of the normal (z along it): unit, z >= 0, cosine-distributed over the shifts.
  Eigen::Vector3f Local(int k) const {
    const Point& p = (*points_)[static_cast<size_t>(k)];
    float x = p.x + shift_x_;
    if (x >= 1.0f) x -= 1.0f;
    const float r = std::sqrt(x);
    return {r * (p.cos * cos_shift_ - p.sin * sin_shift_), r * (p.sin * cos_shift_ + p.cos * sin_shift_),
            std::sqrt(std::max(0.0f, 1.0f - x))};
  }

  // The unshifted pattern's points on the unit square (for tests): (x, y), y the azimuth's fraction of a turn.
  static std::vector<Eigen::Vector2d> PatternPoints(int n);

 private:
  struct Point {
    float x, cos, sin;  // x (the squared radius), the cosine and sine of 2 pi y
  };
  const std::vector<Point>* points_;
  float shift_x_, cos_shift_, sin_shift_;
};

}  // namespace sd
