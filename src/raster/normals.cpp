// Vertex normals on the host (below) and the device (cuda/raster_cuda.cu), both from shared.h's per-vertex code.
#include "raster/normals.h"

#include "core/error.h"
#include "core/parallel.h"
#include "raster/internal.h"

namespace sd::raster {
namespace {

void CheckShapes(const char* op, Span<const float> positions, Span<const int32_t> tris, const VertexFaces& incidence) {
  SD_CHECK(positions.size() % 3 == 0, << op << ": positions hold 3 floats per vertex, got " << positions.size());
  SD_CHECK(tris.size() % 3 == 0, << op << ": tris holds 3 indices per triangle, got " << tris.size());
  SD_CHECK(incidence.offset.size() == positions.size() / 3 + 1 && incidence.corner.size() == tris.size(),
           << op << ": the vertex-face incidence is of another mesh (" << incidence.offset.size() << " offsets, "
           << incidence.corner.size() << " corners for " << positions.size() / 3 << " vertices, " << tris.size() / 3
           << " triangles)");
}

// On the host the gathers index without checks: every index is checked here first (on the device the kernels
// check as they read, buffer.h).
void CheckHostIndices(Span<const int32_t> tris, const VertexFaces& incidence, size_t num_vertices) {
  internal::CheckVertexIndices(tris, num_vertices);
  const std::vector<int32_t>& offset = incidence.offset.host();
  const std::vector<int32_t>& corner = incidence.corner.host();
  SD_CHECK(offset.front() == 0 && static_cast<size_t>(offset.back()) == corner.size(),
           << "vertex-face incidence: offsets span " << offset.front() << ".." << offset.back() << " of "
           << corner.size() << " corners");
  for (size_t v = 0; v + 1 < offset.size(); ++v)
    SD_CHECK(offset[v] <= offset[v + 1], << "vertex-face incidence: offsets decrease at vertex " << v);
  SD_CHECK(internal::AllWithin(corner, 0, corner.size()),
           << "vertex-face incidence: a corner lies past the " << corner.size() << " corners of the triangles");
}

constexpr size_t kVertexGrain = 1024;

}  // namespace

VertexFaces BuildVertexFaces(std::span<const int32_t> tris, int num_vertices) {
  SD_CHECK(num_vertices >= 0 && tris.size() % 3 == 0);
  const size_t nv = static_cast<size_t>(num_vertices);
  internal::CheckVertexIndices(tris, nv);
  std::vector<int32_t> offset(nv + 1, 0), corner(tris.size());
  for (const int32_t v : tris) ++offset[static_cast<size_t>(v) + 1];
  for (size_t v = 0; v < nv; ++v) offset[v + 1] += offset[v];
  std::vector<int32_t> next(offset.begin(), offset.end() - 1);
  // Corners in ascending order, so each vertex's list is ascending: the order of geometry's face loops.
  for (size_t c = 0; c < tris.size(); ++c) corner[static_cast<size_t>(next[static_cast<size_t>(tris[c])]++)] = static_cast<int32_t>(c);
  return {std::move(offset), std::move(corner)};
}

void VertexNormals(Span<const float> positions, Span<const int32_t> tris, const VertexFaces& incidence,
                   Span<float> normals, Span<double> sums) {
  CheckShapes("VertexNormals", positions, tris, incidence);
  const size_t nv = positions.size() / 3;
  SD_CHECK(normals.size() == 3 * nv && sums.size() == 3 * nv,
           << "VertexNormals: " << normals.size() << " normal and " << sums.size() << " sum values for " << nv
           << " vertices (3 each)");
  if (internal::CommonMemory("VertexNormals", positions, tris, Span<const int32_t>(incidence.offset),
                             Span<const int32_t>(incidence.corner), normals, sums) == Memory::kDevice) {
    internal::CheckDeviceBuild("VertexNormals");
#if SYNTHDRIVE_WITH_CUDA
    cuda::DeviceVertexNormals({positions.data(), nv, tris.data(), tris.size() / 3, incidence.offset.data(),
                               incidence.corner.data()},
                              normals.data(), sums.data());
#endif
    return;
  }
  CheckHostIndices(tris, incidence, nv);
  const float* p = positions.data();
  const int32_t* t = tris.data();
  const int32_t* offset = incidence.offset.data();
  const int32_t* corner = incidence.corner.data();
  float* n = normals.data();
  double* s = sums.data();
  ParallelFor(0, nv, [&](size_t v) {
    const shared::Vec3d sum = shared::VertexNormalSum(p, t, corner, offset[v], offset[v + 1]);
    s[3 * v] = sum.x, s[3 * v + 1] = sum.y, s[3 * v + 2] = sum.z;
    shared::NormalFromSum(sum, &n[3 * v]);
  }, kVertexGrain);
}

void VertexNormalsBackward(Span<const float> positions, Span<const int32_t> tris, const VertexFaces& incidence,
                           Span<const double> sums, Span<const float> grad_normals, Span<float> grad_positions) {
  CheckShapes("VertexNormalsBackward", positions, tris, incidence);
  const size_t nv = positions.size() / 3;
  SD_CHECK(sums.size() == 3 * nv && grad_normals.size() == 3 * nv && grad_positions.size() == 3 * nv,
           << "VertexNormalsBackward: " << sums.size() << " sums, " << grad_normals.size() << " normal gradients, "
           << grad_positions.size() << " position gradients for " << nv << " vertices (3 each)");
  if (internal::CommonMemory("VertexNormalsBackward", positions, tris, Span<const int32_t>(incidence.offset),
                             Span<const int32_t>(incidence.corner), sums, grad_normals,
                             grad_positions) == Memory::kDevice) {
    internal::CheckDeviceBuild("VertexNormalsBackward");
#if SYNTHDRIVE_WITH_CUDA
    cuda::DeviceVertexNormalsBackward({positions.data(), nv, tris.data(), tris.size() / 3, incidence.offset.data(),
                                       incidence.corner.data()},
                                      sums.data(), grad_normals.data(), grad_positions.data());
#endif
    return;
  }
  CheckHostIndices(tris, incidence, nv);
  std::vector<double> ds(3 * nv);
  const double* s = sums.data();
  const float* gn = grad_normals.data();
  ParallelFor(0, nv, [&](size_t v) {
    const shared::Vec3d d = shared::NormalSumGradient({s[3 * v], s[3 * v + 1], s[3 * v + 2]}, &gn[3 * v]);
    ds[3 * v] = d.x, ds[3 * v + 1] = d.y, ds[3 * v + 2] = d.z;
  }, kVertexGrain);
  const float* p = positions.data();
  const int32_t* t = tris.data();
  const int32_t* offset = incidence.offset.data();
  const int32_t* corner = incidence.corner.data();
  float* g = grad_positions.data();
  ParallelFor(0, nv, [&](size_t v) {
    const shared::Vec3d d = shared::VertexPositionGradient(p, t, ds.data(), corner, offset[v], offset[v + 1]);
    g[3 * v] += static_cast<float>(d.x), g[3 * v + 1] += static_cast<float>(d.y);
    g[3 * v + 2] += static_cast<float>(d.z);
  }, kVertexGrain);
}

}  // namespace sd::raster
