#pragma once
// Area-weighted vertex normals as an op, so that a loss on interpolated normals (refinement) keeps its whole
// chain on the device: positions in, normals out, and the backward pass to the positions, without a trip to
// the host per evaluation. The arithmetic is geometry::VertexNormals' (the sum over a vertex's faces of
// (b - a) x (c - a) in double, normalised), gathered per vertex in ascending face order instead of scattered
// per face, so that the host op, the device op and geometry::VertexNormals agree bit for bit, and each vertex
// is one thread's work on the GPU (no atomics, no order to lose).
#include <cstdint>
#include <span>

#include "raster/buffer.h"

namespace sd::raster {

// Which faces touch each vertex: built once per mesh topology on the host, copied to the device as needed.
struct VertexFaces {
  Buffer<int32_t> offset;  // num_vertices + 1: vertex v's corners are corner[offset[v] .. offset[v + 1])
  Buffer<int32_t> corner;  // 3 per triangle: 3 * face + k for each corner k of each face, ascending per vertex
};
// SD_CHECKs that every index names one of the num_vertices vertices.
VertexFaces BuildVertexFaces(std::span<const int32_t> tris, int num_vertices);

// normals: 3 floats per vertex, overwritten (0 where a vertex has no face of non-zero area). sums: 3 doubles
// per vertex, overwritten with the unnormalised sums, which the backward pass reads. All buffers on one side.
void VertexNormals(Span<const float> positions, Span<const int32_t> tris, const VertexFaces& incidence,
                   Span<float> normals, Span<double> sums);
// grad_positions (3 per vertex) += dL/dpositions, from dL/dnormals and the forward pass's sums.
void VertexNormalsBackward(Span<const float> positions, Span<const int32_t> tris, const VertexFaces& incidence,
                           Span<const double> sums, Span<const float> grad_normals, Span<float> grad_positions);

}  // namespace sd::raster
