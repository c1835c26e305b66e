#include "geometry/edge_adjacency.h"

#include <algorithm>
#include <cstdint>
#include <numeric>

#include "core/error.h"

namespace sd::geometry {

EdgeAdjacency BuildEdgeAdjacency(int num_vertices, const std::vector<Eigen::Vector3i>& faces,
                                 DegenerateFaces degenerate) {
  SD_CHECK(num_vertices >= 0, << "negative vertex count " << num_vertices);
  const int num_faces = static_cast<int>(faces.size());
  auto for_each_kept = [&](auto&& fn) {
    for (int f = 0; f < num_faces; ++f) {
      const Eigen::Vector3i& t = faces[f];
      if (degenerate == DegenerateFaces::kSkip && (t[0] == t[1] || t[1] == t[2] || t[2] == t[0])) continue;
      for (int k = 0; k < 3; ++k) {
        const int a = t[k], b = t[(k + 1) % 3];
        if (a != b) fn(3 * f + k, std::min(a, b), std::max(a, b));
      }
    }
  };
  for (int f = 0; f < num_faces; ++f) {
    SD_CHECK((faces[f].array() >= 0).all() && (faces[f].array() < num_vertices).all(),
             << "face " << f << " indexes a vertex outside [0, " << num_vertices << ")");
  }

  // A counting sort on the lower endpoint (stable: ascending h within a vertex), then each vertex's few
  // half-edges sorted on (higher endpoint, h), gives (lo, hi, h) order in linear time. Remesh() rebuilds this
  // every pass, where one comparison sort of all 3F keys would cost a log factor more.
  std::vector<int> start(static_cast<size_t>(num_vertices) + 1, 0);
  for_each_kept([&](int, int lo, int) { ++start[lo + 1]; });
  std::partial_sum(start.begin(), start.end(), start.begin());
  std::vector<uint64_t> hi_h(start.back());
  std::vector<int> fill(start.begin(), start.end() - 1);
  for_each_kept([&](int h, int lo, int hi) {
    hi_h[fill[lo]++] = (uint64_t{static_cast<uint32_t>(hi)} << 32) | static_cast<uint32_t>(h);
  });

  EdgeAdjacency adjacency;
  adjacency.half_edges.reserve(hi_h.size());
  for (int v = 0; v < num_vertices; ++v) {
    std::sort(hi_h.begin() + start[v], hi_h.begin() + start[v + 1]);
    for (int i = start[v]; i < start[v + 1]; ++i) {
      const int hi = static_cast<int>(hi_h[i] >> 32);
      if (i == start[v] || hi != static_cast<int>(hi_h[i - 1] >> 32)) {
        adjacency.edges.emplace_back(v, hi);
        adjacency.offset.push_back(static_cast<int>(adjacency.half_edges.size()));
      }
      adjacency.half_edges.push_back(static_cast<int>(hi_h[i] & 0xffffffffu));
    }
  }
  adjacency.offset.push_back(static_cast<int>(adjacency.half_edges.size()));

  adjacency.twin.assign(3 * faces.size(), -1);
  auto from = [&](int h) { return faces[h / 3][h % 3]; };
  for (int e = 0; e < adjacency.NumEdges(); ++e) {
    if (adjacency.NumFacesOn(e) != 2) continue;
    const int h = adjacency.half_edges[adjacency.offset[e]], g = adjacency.half_edges[adjacency.offset[e] + 1];
    if (from(h) == from(g)) continue;
    adjacency.twin[h] = g;
    adjacency.twin[g] = h;
  }
  return adjacency;
}

}  // namespace sd::geometry
