#pragma once
// Small robust statistics the modules share.
#include <algorithm>
#include <vector>

namespace sd {

// The upper median (element n/2 in order); 0 for no values. Takes a copy: the order is its own.
inline double Median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::nth_element(v.begin(), v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2), v.end());
  return v[v.size() / 2];
}

}  // namespace sd
