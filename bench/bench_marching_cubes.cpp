// geometry::MarchingCubes on a sphere SDF (radius 0.8 of the half-extent, so the surface spans most of the grid):
// seconds per call (median of --runs) and peak resident memory beyond the input volume.
//
// Peak memory is the process's ru_maxrss after the calls minus its resident size just before the first one, when
// the volume is already filled; the mesh is freed between calls, so every call peaks alike. Run one size per
// process: ru_maxrss never goes down.
//
// Usage: bench_marching_cubes [n=256] [--runs 3]   (an n^3 grid of floats)
#include <sys/resource.h>

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <string>
#include <vector>

#include "core/parallel.h"
#include "geometry/marching_cubes.h"

namespace {

// Current resident set, from /proc (ru_maxrss only keeps the high-water mark).
double ResidentMiB() {
  std::ifstream status("/proc/self/status");
  std::string line;
  while (std::getline(status, line))
    if (line.rfind("VmRSS:", 0) == 0) return std::atof(line.c_str() + 6) / 1024.0;
  return 0;
}

double PeakMiB() {
  rusage usage{};
  getrusage(RUSAGE_SELF, &usage);
  return usage.ru_maxrss / 1024.0;  // kilobytes on Linux
}

}  // namespace

int main(int argc, char** argv) {
  int n = 256, runs = 3;
  for (int a = 1; a < argc; ++a) {
    if (!std::strcmp(argv[a], "--runs") && a + 1 < argc) {
      runs = std::atoi(argv[++a]);
    } else {
      n = std::atoi(argv[a]);
    }
  }
  if (n < 2 || runs < 1) {
    std::fprintf(stderr, "usage: bench_marching_cubes [n>=2] [--runs k>=1]\n");
    return 2;
  }

  sd::geometry::ScalarGrid grid;
  grid.dims = Eigen::Vector3i::Constant(n);
  grid.origin = Eigen::Vector3f::Constant(-1.0f);
  grid.voxel_size = 2.0f / float(n - 1);
  grid.values.resize(size_t(n) * n * n);
  sd::ParallelFor(0, size_t(n), [&](size_t k) {
    for (int j = 0; j < n; ++j)
      for (int i = 0; i < n; ++i) grid.at(i, j, int(k)) = 0.8f - grid.NodePosition(i, j, int(k)).norm();
  });
  const double volume_mib = double(grid.values.size() * sizeof(float)) / (1 << 20);
  const double before_mib = ResidentMiB();

  std::vector<double> seconds;
  size_t vertices = 0, faces = 0;
  for (int r = 0; r < runs; ++r) {
    const auto t0 = std::chrono::steady_clock::now();
    const sd::TriangleMesh mesh = sd::geometry::MarchingCubes(grid, 0.0f);
    seconds.push_back(std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());
    vertices = mesh.NumVertices();
    faces = mesh.NumFaces();
  }
  const double peak_mib = PeakMiB();
  std::vector<double> sorted = seconds;
  std::sort(sorted.begin(), sorted.end());
  const double mesh_mib = double(vertices * sizeof(Eigen::Vector3f) + faces * sizeof(Eigen::Vector3i)) / (1 << 20);

  std::printf("grid %d^3, %d threads: %zu vertices, %zu faces\n", n, sd::MaxThreads(), vertices, faces);
  std::printf("seconds per call: median %.3f (", sorted[sorted.size() / 2]);
  for (size_t r = 0; r < seconds.size(); ++r) std::printf("%s%.3f", r ? ", " : "", seconds[r]);
  std::printf(")\n");
  std::printf("input volume %.1f MiB, output mesh %.1f MiB; resident before %.1f MiB, peak %.1f MiB, "
              "peak beyond resident-before %.1f MiB\n",
              volume_mib, mesh_mib, before_mib, peak_mib, peak_mib - before_mib);
  return 0;
}
