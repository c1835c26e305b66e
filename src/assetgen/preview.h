#pragma once
// A small picture of an asset: three-quarter view from the front-left, sun and sky light, soft shadow on a
// grey floor. Used for asset.json's preview.png and the reports.
#include "core/image.h"
#include "core/mesh.h"

namespace sd {

// `mesh` in the canonical frame (metres, z up, x forward). Returns an sRGB RGB image.
ImageU8 RenderPreview(const TriangleMesh& mesh, int width, int height);

}  // namespace sd

namespace sd {

// A turntable strip: `views` unlit base-colour renders (texture × material × vertex colour, no light) side by
// side, `size` px square each, azimuth 0°, 360°/views, … from the front towards the left, elevation 15°, on
// light grey. Shows what the texture holds on every side (where a shape prior filled it, say), which a lit
// preview from one side does not.
ImageU8 RenderTurntable(const TriangleMesh& mesh, int views = 8, int size = 160);

}  // namespace sd
