#pragma once
// Small robust statistics and sampling helpers the modules share.
#include <algorithm>
#include <vector>

namespace sd {

// The upper median (element n/2 in order); 0 for no values. Takes a copy: the order is its own.
inline double Median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
  return v[v.size() / 2];
}

// The columns of a stratified grid of exactly n cells (n / columns rows): the least divisor of n not below its
// square root. A square n gives its square grid; any other n a grid that still covers the whole square (a
// ceil(sqrt(n))-wide grid would leave part of its last row empty, and the directions it maps to never drawn).
inline int StratifiedColumns(int n) {
  if (n <= 1) return 1;
  int cols = 1;
  while (cols * cols < n) ++cols;
  while (n % cols != 0) ++cols;
  return cols;
}

}  // namespace sd
