#pragma once
// Disjoint sets over the integers [0, n), with path halving. A union keeps the smaller root, so every set's
// root is its lowest member whatever order the unions come in: callers that number their sets by root get the
// same numbering from any scan order (geometry's manifold check, perception's grid clustering).
#include <algorithm>
#include <cstddef>
#include <numeric>
#include <vector>

namespace sd {

class UnionFind {
 public:
  explicit UnionFind(size_t n) : parent_(n) { std::iota(parent_.begin(), parent_.end(), 0); }
  int Find(int x) {
    while (parent_[x] != x) x = parent_[x] = parent_[parent_[x]];
    return x;
  }
  void Unite(int a, int b) {
    a = Find(a);
    b = Find(b);
    if (a != b) parent_[std::max(a, b)] = std::min(a, b);
  }

 private:
  std::vector<int> parent_;
};

}  // namespace sd
