#include "core/sampling.h"

#include <cmath>
#include <random>
#include <set>

#include <gtest/gtest.h>

#include "core/stats.h"

namespace sd {
namespace {

// Every cell of the cols x rows grid, every one of the n columns and every one of the n rows holds one point.
TEST(ShiftedCosinePattern, PatternIsStratifiedInCellsColumnsAndRows) {
  for (int n : {1, 2, 3, 4, 6, 8, 12, 16, 64, 256}) {
    const std::vector<Eigen::Vector2d> p = ShiftedCosinePattern::PatternPoints(n);
    ASSERT_EQ(static_cast<int>(p.size()), n);
    const int cols = StratifiedColumns(n), rows = n / cols;
    std::set<int> cells, columns, sub_rows;
    for (const Eigen::Vector2d& q : p) {
      ASSERT_GE(q.x(), 0.0);
      ASSERT_LT(q.x(), 1.0);
      ASSERT_GE(q.y(), 0.0);
      ASSERT_LT(q.y(), 1.0);
      cells.insert(static_cast<int>(q.y() * rows) * cols + static_cast<int>(q.x() * cols));
      columns.insert(static_cast<int>(q.x() * n));
      sub_rows.insert(static_cast<int>(q.y() * n));
    }
    EXPECT_EQ(static_cast<int>(cells.size()), n) << n << " points";
    EXPECT_EQ(static_cast<int>(columns.size()), n) << n << " points";
    EXPECT_EQ(static_cast<int>(sub_rows.size()), n) << n << " points";
  }
}

// The canonical arrangement puts the points on a diagonal in each cell; the shuffle must break it.
TEST(ShiftedCosinePattern, PatternIsNotTheCanonicalDiagonal) {
  const std::vector<Eigen::Vector2d> p = ShiftedCosinePattern::PatternPoints(16);
  int on_diagonal = 0;
  for (int k = 0; k < 16; ++k) {
    const int i = k % 4, j = k / 4;
    // Canonical: x's sub-column within the cell is j, y's sub-row is i.
    if (static_cast<int>(p[static_cast<size_t>(k)].x() * 16) == 4 * i + j &&
        static_cast<int>(p[static_cast<size_t>(k)].y() * 16) == 4 * j + i)
      ++on_diagonal;
  }
  EXPECT_LT(on_diagonal, 8);
}

TEST(ShiftedCosinePattern, DirectionsAreUnitAndInTheUpperHemisphere) {
  std::mt19937 rng(3);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  for (int n : {1, 4, 16, 33}) {
    const ShiftedCosinePattern p(n, u(rng), u(rng));
    ASSERT_EQ(p.size(), n);
    for (int k = 0; k < n; ++k) {
      const Eigen::Vector3f d = p.Local(k);
      EXPECT_NEAR(d.norm(), 1.0f, 1e-5f);
      EXPECT_GE(d.z(), 0.0f);
    }
  }
  // Shifts at the ends of [0, 1).
  const ShiftedCosinePattern edge(16, 0.99999994f, 0.99999994f);
  for (int k = 0; k < 16; ++k) EXPECT_NEAR(edge.Local(k).norm(), 1.0f, 1e-5f);
}

// A wedge of the sky: under cosine weighting, the share of directions with azimuth in [0, 0.3)
// of a turn and elevation above 30 degrees is 0.3 x P(z > 0.5) = 0.3 x 0.75.
double InWedge(const Eigen::Vector3f& d) {
  double az = std::atan2(d.y(), d.x()) / (2 * M_PI);
  if (az < 0) az += 1;
  return az < 0.3 && d.z() > 0.5 ? 1.0 : 0.0;
}

// Over random shifts, the estimate is unbiased, and its variance far below that of as many independent directions.
TEST(ShiftedCosinePattern, UnbiasedAndBetterThanIndependentDirections) {
  const double truth = 0.3 * 0.75;
  std::mt19937 rng(11);
  std::uniform_real_distribution<float> u(0.0f, 1.0f);
  for (int n : {4, 16}) {
    const int trials = 40000;
    double sum = 0, sum2 = 0;
    for (int t = 0; t < trials; ++t) {
      const ShiftedCosinePattern p(n, u(rng), u(rng));
      double e = 0;
      for (int k = 0; k < n; ++k) e += InWedge(p.Local(k));
      e /= n;
      sum += e, sum2 += e * e;
    }
    const double mean = sum / trials, var = sum2 / trials - mean * mean;
    EXPECT_NEAR(mean, truth, 4 * std::sqrt(var / trials) + 1e-4) << n << " directions";
    const double independent = truth * (1 - truth) / n;
    EXPECT_LT(var, 0.6 * independent) << n << " directions: variance " << var << " against " << independent;
  }
}

}  // namespace
}  // namespace sd
