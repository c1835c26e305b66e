#pragma once
// Large reconstruction model (LRM, Hong et al. 2023; OpenLRM, InstantMesh): one object image -> a triplane ->
// an implicit surface with colour, turned into a vertex-coloured mesh by marching cubes. The fast, coarse
// alternative to multi-view generation + refinement (DESIGN.md generate).
//
// A model is two TorchScript files (tools/export/export_lrm.py), so the encoder runs once per object and the
// decoder many times on bounded chunks of points:
// Contract "lrm_encoder" (runtime.h; docs/models.md):
//   input  "image":    [1, 3, S, S] float32, RGB, sRGB-encoded, 0..1, NCHW; S = params.image_size. The object
//                      centred on a plain background (params.background, grey level 0..1, default 1 = white).
//                      Camera conditioning the network needs is a constant inside the exported module.
//   output "triplane": [1, 3, C, R, R] float32 (3 planes, C channels, R × R each), opaque to the C++ side.
// Contract "lrm_decoder":
//   inputs "triplane": as above; "points": [1, P, 3] float32 in the unit cube [-0.5, 0.5]^3 centred on the
//                      object (the exporter scales to the network's own bounds). P is -1 (any) or, for a
//                      decoder traced at one size, fixed: the last chunk is then padded by repeating a point.
//   outputs "sdf":     [1, P, 1] NEGATIVE INSIDE, zero on the surface: a signed distance in unit-cube units,
//                      or, for density models, (iso - density) / iso as the exporter wraps them — marching
//                      cubes needs only the sign and the zero level;
//           "colour":  [1, P, 3] RGB, sRGB-encoded, 0..1.
// Reconstruct() samples -sdf on a G^3 node grid over the cube, P points per decoder call (memory is bounded
// and the result does not depend on P), closes the field on the cube's border (a surface touching it is
// capped, so the mesh is always watertight), extracts the zero level with geometry::MarchingCubes and colours
// each vertex with the decoder's colour there (converted to linear, as TriangleMesh stores it). The mesh stays
// in the unit-cube frame: the canonicalisation step gives it axes and metric scale.
// No classical path: single-image 3D needs the learned prior.
#include <filesystem>
#include <memory>
#include <string>

#include "core/image.h"
#include "core/mesh.h"
#include "geometry/marching_cubes.h"
#include "models/runtime.h"

namespace sd::models {

constexpr const char* kLrmEncoderStage = "lrm_encoder";
constexpr const char* kLrmDecoderStage = "lrm_decoder";
constexpr const char* kLrmEncoderFile = "lrm_encoder.pt";
constexpr const char* kLrmDecoderFile = "lrm_decoder.pt";

struct LrmOptions {
  int grid = 128;      // G: nodes per axis of the sampled cube (cell = 1 / (G - 1) of the cube)
  int chunk = 65536;   // P: points per decoder call
};

class LrmReconstructor {
 public:
  // A folder with lrm_encoder.pt and lrm_decoder.pt; InputError naming every missing file, or the file whose
  // contract is for another stage or does not have the shapes above.
  static LrmReconstructor Load(const std::filesystem::path& dir, const RuntimeOptions& runtime = {},
                               const LrmOptions& options = {});

  LrmReconstructor(LrmReconstructor&&) noexcept;
  LrmReconstructor& operator=(LrmReconstructor&&) noexcept;
  ~LrmReconstructor();

  int image_size() const { return image_size_; }
  std::string Describe() const;

  // The encoder input for `image` (sRGB 0..1, 3 or 4 channels; alpha composites over the background): the
  // image letterboxed to a square with the background, then resized to S × S.
  ImageF PrepareImage(const ImageF& image) const;
  // Runs the encoder on PrepareImage(image).
  Tensor EncodeTriplane(const ImageF& image) const;
  // -sdf (inside positive) at the G^3 nodes of the unit cube, border nodes forced outside.
  geometry::ScalarGrid SampleField(const Tensor& triplane) const;
  // The vertex-coloured mesh of the image's object, unit-cube frame, vertex normals computed.
  TriangleMesh Reconstruct(const ImageF& image) const;

 private:
  LrmReconstructor() = default;
  // Runs the decoder on `points` (xyz triples) chunk by chunk; sdf and / or colour (sRGB) per point.
  void Decode(const Tensor& triplane, const std::vector<float>& points, std::vector<float>* sdf,
              std::vector<float>* colour) const;

  std::unique_ptr<Model> encoder_, decoder_;
  LrmOptions options_;
  int image_size_ = 0;
  int fixed_points_ = 0;  // > 0: the decoder's contract fixes P (a trace that froze it)
  float background_ = 1.0f;
};

}  // namespace sd::models
