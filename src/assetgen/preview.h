#pragma once
// A small picture of an asset: three-quarter view from the front-left, sun and sky light, soft shadow on a
// grey floor. Used for asset.json's preview.png and the reports.
#include "core/image.h"
#include "core/mesh.h"

namespace sd {

// `mesh` in the canonical frame (metres, z up, x forward). Returns an sRGB RGB image.
ImageU8 RenderPreview(const TriangleMesh& mesh, int width, int height);

}  // namespace sd
