#pragma once
// Our own UV parametrisation and texture baking, so texture detail is not limited by vertex density.
//
// BuildUvAtlas cuts the mesh into charts of near-coplanar neighbouring triangles (region growing on face
// normals), flattens each chart by projecting it onto its best-fit plane (charts grow only while that
// projection stays injective and undistorted within bounds), and packs the charts into one square atlas with
// a gutter of `padding_px` texels around every chart. BakeTexture fills each chart's texels from the colour
// views (the same most-head-on, depth-tested rule as vertex fusion, per texel) and dilates the result into
// the gutters, so bilinear filtering and mip-mapping at normal viewing distances never fetch background
// across a chart border (no visible seams).
#include <vector>

#include "assetgen/texture.h"
#include "core/image.h"
#include "core/mesh.h"

namespace sd {

struct UvAtlasOptions {
  int texture_size = 1024;      // atlas side in texels
  int padding_px = 4;           // gutter around each chart, texels
  float max_normal_angle_deg = 60.0f;  // a chart grows while its faces stay within this of the chart's normal
};

struct UvAtlasStats {
  int charts = 0;
  float utilisation = 0;  // fraction of the atlas covered by triangles
};

// Returns a copy of the mesh with per-vertex UVs (glTF convention, core/mesh.h); vertices on chart borders are
// split. Positions, faces' geometry and normals are kept. InputError for a mesh without faces or a texture
// size outside [64, 16384].
TriangleMesh BuildUvAtlas(const TriangleMesh& mesh, const UvAtlasOptions& options, UvAtlasStats* stats = nullptr);

struct BakeOptions {
  VertexFusionOptions fusion;  // visibility tolerance and grazing-angle cut-off
  int padding_px = 4;          // dilation into the gutters
};

// Bakes the views onto a mesh with UVs: returns an sRGB texture (3 channels) of `texture_size` square.
// Texels no view sees take the colour propagated from the vertex fusion. InputError when the mesh has no UVs.
// `provenance` (optional) receives where the surface texels' colour came from.
ImageU8 BakeTexture(const TriangleMesh& mesh_with_uvs, const ColorViewSet& views, int texture_size,
                    const BakeOptions& options = {}, TextureProvenance* provenance = nullptr);

}  // namespace sd
