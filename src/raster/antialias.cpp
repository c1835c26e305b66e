// BuildEdgeTopology / Antialias / AntialiasBackward: analytic anti-aliasing of silhouette edges after
// Laine et al. 2020, "Modular primitives for high-performance differentiable rendering", section 4.3.
//
// The choices made here (the paper leaves the details open):
//  - Pairs. Every horizontally or vertically adjacent pixel pair (a left of / above b) whose triangle ids
//    differ is examined. The "owner" is the pixel whose surface is in front: the covered one when the other
//    is background, else the smaller depth (ties to the lower triangle index, as in Rasterize).
//  - Silhouette edge: a mesh boundary edge, or one whose two triangles face opposite ways on screen (signs of
//    the projected 2D signed areas differ; a neighbour that is not drawn, w <= 0, counts as facing away).
//  - Search (FindSilhouette, in shared.h with the rest of the per-pair code, which CUDA runs too): walk the
//    segment between the two pixel centres from the owner's centre, through
//    the owner's triangle and on across non-silhouette edges into the neighbours (same facing: the same
//    visible surface), until it leaves by a silhouette edge; t in [0, 1] is that crossing's distance from the
//    owner's centre, in pixels. Looking at the owner's triangle alone is not enough: near an outline triangles
//    are seen edge-on, and the pixel next to the background is usually covered by a triangle several slivers
//    away from the silhouette edge (on a 10k-triangle sphere the owner's own triangle held the edge for ~1% of
//    outline pixels). The record keeps the triangle and edge found.
//  - Axis: a horizontal pair only blends across edges at least as vertical as horizontal (|dv| >= |du|), a
//    vertical pair only across the others, so an edge's coverage is counted along one axis, not twice.
//  - Blend: a 1D box filter across the pixel pair. The owner's surface covers [0, t] of the unit segment from
//    the owner's centre towards the other; each pixel's footprint extends half a pixel either side of its
//    centre. So
//      t >= 1/2: the surface spills (t - 1/2) into the other pixel:  out_other += (t - 1/2) (c_owner - c_other);
//      t <  1/2: it misses (1/2 - t) of the owner's pixel:           out_owner += (1/2 - t) (c_other - c_owner).
//    alpha = |t - 1/2| is continuous at t = 1/2 and d(coverage)/dt = +1 on both sides, so moving an edge
//    outwards always raises the owner colour's share: a mask loss pulls the outline the right way, with a
//    gradient of 1 per pixel row crossed (the derivative of a box-filtered edge). A vertical edge at u = e
//    gives a row whose mask sums to exactly e (tested).
//  - Deltas are computed from the input colours (not chained when a pixel is in several pairs) and summed
//    serially in pair order, so the result is deterministic.
// Known limits: a walk longer than kMaxWalk triangles gives up; a silhouette edge that crosses a pair but
// blends along the other axis is not seen by that pair, so where a triangulated outline zigzags a few outline
// pixels (2-4% on a finely tessellated sphere) stay unblended. Such pairs give no gradient; forward and
// backward always agree.
#include <algorithm>
#include <array>
#include <cmath>
#include <cstddef>
#include <cstring>
#include <vector>

#include "core/parallel.h"
#include "geometry/edge_adjacency.h"
#include "raster/internal.h"
#include "raster/raster.h"

namespace sd::raster {
namespace {

using shared::PairGeometry;

// Per-call geometry shared by all pairs on the CPU: each vertex projected once, each triangle's facing once.
struct Scene {
  std::vector<shared::ScreenVertex> screen;  // per vertex
  std::vector<int8_t> facing;                // per triangle: ScreenFacing
  shared::AntialiasScene view;

  explicit Scene(const AntialiasInputs& in) : screen(internal::NumVertices(in.clip_pos)), facing(in.tris.size() / 3) {
    const RasterBuffer& r = in.rast;
    const float* clip_pos = in.clip_pos.data();
    const int32_t* t = in.tris.data();
    ParallelForRange(0, screen.size(), 1024, [&](size_t begin, size_t end) {
      for (size_t v = begin; v < end; ++v)
        screen[v] = shared::Project(clip_pos, static_cast<int32_t>(v), r.width, r.height);
    });
    ParallelForRange(0, facing.size(), 1024, [&](size_t begin, size_t end) {
      for (size_t f = begin; f < end; ++f) facing[f] = static_cast<int8_t>(shared::ScreenFacing(clip_pos, t, f));
    });
    view = {r.width, r.height, r.triangle.data(), r.depth.data(), t, in.topology.neighbour.data(), screen.data(),
            facing.data()};
  }
};

// Where the op runs (raster.h), after checking the inputs.
Memory CheckInputs(const AntialiasInputs& in, const char* op) {
  internal::CheckRaster(in.rast);
  internal::CheckTriangles(in.clip_pos, in.tris);
  const Memory where = internal::CommonMemory(op, in.color, in.rast, in.clip_pos, in.tris,
                                              Span<const int32_t>(in.topology.neighbour));
  internal::CheckVertexIndices(in.tris, internal::NumVertices(in.clip_pos));
  internal::CheckRasterTriangles(in.rast, in.tris);
  SD_CHECK(in.channels > 0 && in.color.size() == static_cast<size_t>(in.channels) * in.rast.NumPixels(),
           << "color: " << in.color.size() << " floats for " << in.channels << " channels");
  SD_CHECK(in.topology.neighbour.size() == in.tris.size(), << "topology built for another mesh");
  return where;
}

#if SYNTHDRIVE_WITH_CUDA
static_assert(sizeof(AntialiasRecord::PixelPair) == sizeof(cuda::PairRecord) &&
              offsetof(AntialiasRecord::PixelPair, alpha) == offsetof(cuda::PairRecord, alpha));
#endif

// The silhouette pairs of the image, in row order, and the geometry of each.
void FindPairs(const AntialiasInputs& in, bool color_gradient, std::vector<AntialiasRecord::PixelPair>* pairs,
               std::vector<PairGeometry>* geometry) {
  if (UseCuda()) {
#if SYNTHDRIVE_WITH_CUDA
    std::vector<cuda::PairRecord> found;
    cuda::FindAntialiasPairs(internal::ToCuda(in), !color_gradient, &found, geometry);
    pairs->resize(found.size());
    if (!found.empty()) std::memcpy(pairs->data(), found.data(), found.size() * sizeof(cuda::PairRecord));
    return;
#endif
  }
  const Scene sc(in);
  const RasterBuffer& rast = in.rast;
  const std::span<const float> color = in.color.host();
  const int width = rast.width, height = rast.height;
  const size_t C = static_cast<size_t>(in.channels);
  auto same_color = [&](int32_t a, int32_t b) {
    for (size_t c = 0; c < C; ++c)
      if (color[C * a + c] != color[C * b + c]) return false;
    return true;
  };
  // Pairs whose first pixel is in row j, found per row in parallel and concatenated in row order.
  std::vector<std::vector<std::pair<AntialiasRecord::PixelPair, PairGeometry>>> rows(height);
  ParallelFor(0, static_cast<size_t>(height), [&](size_t j) {
    for (int i = 0; i < width; ++i) {
      const int32_t a = static_cast<int32_t>(j * width + i);
      for (const int32_t b : {i + 1 < width ? a + 1 : -1, static_cast<int>(j) + 1 < height ? a + width : -1}) {
        PairGeometry g;
        if (b < 0 || rast.triangle[a] == rast.triangle[b]) continue;
        if (!color_gradient && same_color(a, b)) continue;
        if (!shared::ExaminePair(sc.view, a, b, &g)) continue;
        rows[j].push_back({{a, b, g.triangle, g.edge, shared::BlendOf(g).alpha}, g});
      }
    }
  });
  pairs->clear();
  geometry->clear();
  for (const auto& row : rows)
    for (const auto& [pair, g] : row) pairs->push_back(pair), geometry->push_back(g);
}

// The geometry of recorded pairs, recomputed from the same inputs (for the backward pass).
std::vector<PairGeometry> RecordedGeometry(const AntialiasInputs& in, const AntialiasRecord& record) {
  std::vector<PairGeometry> geometry(record.pairs.size());
  if (UseCuda()) {
#if SYNTHDRIVE_WITH_CUDA
    const bool match = cuda::RecordedPairGeometry(internal::ToCuda(in),
                                                  reinterpret_cast<const cuda::PairRecord*>(record.pairs.data()),
                                                  record.pairs.size(), &geometry);
    SD_CHECK(match, << "AntialiasRecord does not match the geometry it is used with");
    return geometry;
#endif
  }
  const Scene sc(in);
  for (size_t n = 0; n < record.pairs.size(); ++n) {
    const AntialiasRecord::PixelPair& p = record.pairs[n];
    SD_CHECK(shared::RecordedPair(sc.view, p.pixel_a, p.pixel_b, p.triangle, p.edge, &geometry[n]),
             << "AntialiasRecord does not match the geometry it is used with");
  }
  return geometry;
}

}  // namespace

EdgeTopology BuildEdgeTopology(std::span<const int32_t> tris, int num_vertices) {
  SD_CHECK(tris.size() % 3 == 0 && num_vertices >= 0);
  std::vector<Eigen::Vector3i> faces(tris.size() / 3);
  std::memcpy(faces.data(), tris.data(), tris.size() * sizeof(int32_t));
  // A degenerate triangle's proper edges count ((a, a, b) puts two half-edges on a-b); runs of exactly two
  // half-edges are manifold edges, whatever their windings.
  const geometry::EdgeAdjacency adjacency =
      geometry::BuildEdgeAdjacency(num_vertices, faces, geometry::DegenerateFaces::kKeepProperEdges);
  EdgeTopology topology;
  topology.neighbour.assign(tris.size(), -1);
  for (int e = 0; e < adjacency.NumEdges(); ++e) {
    if (adjacency.NumFacesOn(e) != 2) continue;
    const std::span<const int> h = adjacency.HalfEdgesOf(e);
    topology.neighbour[h[0]] = h[1] / 3;
    topology.neighbour[h[1]] = h[0] / 3;
  }
  return topology;
}

void Antialias(const AntialiasInputs& in, Span<float> out_in, AntialiasRecord* record, bool color_gradient) {
  const Memory where = CheckInputs(in, "Antialias");
  SD_CHECK(out_in.size() == in.color.size(), << "out: " << out_in.size());
  SD_CHECK(out_in.data() != in.color.data() || in.color.empty(), << "Antialias cannot work in place");
  SD_CHECK(record != nullptr);
  internal::CommonMemory("Antialias", in.color, out_in);
  if (where == Memory::kDevice) {
    internal::CheckDeviceBuild("Antialias");
    record->pairs.clear();
    const size_t slots = 2 * in.rast.NumPixels();
    // Reused from the record's last device pass: allocating per call would wait for the device each time.
    if (record->device_found.where() != Memory::kDevice) record->device_found = Buffer<int32_t>(Memory::kDevice);
    if (record->device_geometry.where() != Memory::kDevice)
      record->device_geometry = Buffer<PairGeometry>(Memory::kDevice);
    record->device_found.resize(slots);
    record->device_geometry.resize(slots);
#if SYNTHDRIVE_WITH_CUDA
    cuda::DeviceAntialias(internal::ToCuda(in), !color_gradient, out_in.data(), record->device_found.data(),
                          record->device_geometry.data());
#endif
    return;
  }
  record->device_found.resize(0);
  record->device_geometry.resize(0);
  const std::span<const float> color = in.color.host();
  const std::span<float> out = out_in.host();
  std::vector<PairGeometry> geometry;
  FindPairs(in, color_gradient, &record->pairs, &geometry);

  const size_t C = static_cast<size_t>(in.channels);
  std::copy(color.begin(), color.end(), out.begin());
  for (const PairGeometry& g : geometry) {
    const shared::Blend blend = shared::BlendOf(g);
    for (size_t c = 0; c < C; ++c)
      out[C * blend.receiver + c] += blend.alpha * (color[C * blend.source + c] - color[C * blend.receiver + c]);
  }
}

void AntialiasBackward(const AntialiasInputs& in, const AntialiasRecord& record, Span<const float> grad_out_in,
                       Span<float> grad_color_in, Span<float> grad_clip_in) {
  const Memory where = CheckInputs(in, "AntialiasBackward");
  SD_CHECK(grad_out_in.size() == in.color.size(), << "grad_out: " << grad_out_in.size());
  SD_CHECK(grad_color_in.empty() || grad_color_in.size() == in.color.size(), << "grad_color: " << grad_color_in.size());
  SD_CHECK(grad_clip_in.size() == in.clip_pos.size(), << "grad_clip: " << grad_clip_in.size());
  internal::CommonMemory("AntialiasBackward", in.color, grad_out_in, grad_color_in, grad_clip_in);
  if (where == Memory::kDevice) {
    internal::CheckDeviceBuild("AntialiasBackward");
    SD_CHECK(record.device_found.size() == 2 * in.rast.NumPixels() &&
                 record.device_geometry.size() == record.device_found.size(),
             << "AntialiasRecord is not a device forward pass's of this resolution");
#if SYNTHDRIVE_WITH_CUDA
    cuda::DeviceAntialiasBackward(internal::ToCuda(in), record.device_found.data(), record.device_geometry.data(),
                                  grad_out_in.data(), grad_color_in.empty() ? nullptr : grad_color_in.data(),
                                  grad_clip_in.data());
#endif
    return;
  }
  const std::span<const float> color = in.color.host(), grad_out = grad_out_in.host();
  const std::span<float> grad_color = grad_color_in.host(), grad_clip = grad_clip_in.host();
  const bool color_gradient = !grad_color.empty();
  const std::vector<PairGeometry> geometry = RecordedGeometry(in, record);
  const size_t C = static_cast<size_t>(in.channels);

  if (color_gradient)
    for (size_t n = 0; n < grad_out.size(); ++n) grad_color[n] += grad_out[n];  // out = color + deltas
  std::vector<double> dL_dclip(grad_clip.size(), 0.0);
  for (const PairGeometry& g : geometry) {
    const shared::Blend blend = shared::BlendOf(g);
    // out_r = c_r + alpha (c_s - c_r).
    double dL_dalpha = 0;
    for (size_t c = 0; c < C; ++c) {
      const float g_r = grad_out[C * blend.receiver + c];
      dL_dalpha += static_cast<double>(g_r) * (color[C * blend.source + c] - color[C * blend.receiver + c]);
      if (!color_gradient) continue;
      grad_color[C * blend.source + c] += blend.alpha * g_r;
      grad_color[C * blend.receiver + c] -= blend.alpha * g_r;
    }
    const double dL_dt = dL_dalpha * blend.dalpha_dt;
    if (dL_dt == 0) continue;
    double d[2][3];
    shared::CrossingClipGradient(g, in.rast.width, dL_dt, d);
    for (int e = 0; e < 2; ++e) {
      double* out = &dL_dclip[4 * static_cast<size_t>(g.end_vertices[e])];
      out[0] += d[e][0];
      out[1] += d[e][1];
      out[3] += d[e][2];
    }
  }
  for (size_t n = 0; n < dL_dclip.size(); ++n) grad_clip[n] += static_cast<float>(dL_dclip[n]);
}

}  // namespace sd::raster
