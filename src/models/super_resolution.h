#pragma once
// The super-resolution stage (DESIGN.md generate: "×2 super-resolution of the views"), learned or classical.
//
// Contract "super_resolution" (runtime.h; docs/models.md):
//   input  "image": [N, 3, H, W] float32, RGB, sRGB-encoded, in the contract's input range (0..255 for the
//                   UpscalerJS ESRGAN/RDN models), NCHW
//   output "image": [N, 3, s·H, s·W] float32, same encoding, in the output range
//   params: "scale" (s, an integer ≥ 2), "receptive_radius" (input pixels a output pixel depends on, each side;
//           tiles overlap by this much, so tiled results equal whole-image results)
// Learned models are applied tile by tile (bounded memory on any image size); the alpha channel of RGBA
// images and grey images go through the classical upscaler, since the models are trained on colour only.
//
// Classical path: separable bicubic convolution (Keys, a = −0.5) on the sRGB-encoded values — what the
// learned path is compared against, and what runs when no weights are installed (and says so).
#include <filesystem>
#include <memory>
#include <string>

#include "core/image.h"
#include "models/resample.h"
#include "models/runtime.h"

namespace sd::models {

constexpr const char* kSuperResolutionStage = "super_resolution";

struct UpscaleOptions {
  int tile = 128;  // tile interior, input pixels (the UpscalerJS models were trained on 128-pixel patches)
};

class Upscaler {
 public:
  // Bicubic ×`scale`.
  static Upscaler Classical(int scale);
  // A super_resolution model file; InputError naming the file when it is unusable (runtime.h), or its scale
  // is not an integer ≥ 2.
  static Upscaler FromModel(const std::filesystem::path& file, const RuntimeOptions& runtime = {},
                            const UpscaleOptions& options = {});
  // What `synthdrive upscale --model` and the texture stage accept:
  //   "auto"      the installed default for `scale` (esrgan-slim-x<scale>.pt in DefaultModelDir()), else bicubic
  //               with a warning that says why;
  //   "bicubic"   the classical path;
  //   a name      "<name>-x<scale>.pt" in DefaultModelDir() (e.g. "esrgan-medium"), InputError when absent;
  //   a path      any file ending in .pt.
  static Upscaler Resolve(const std::string& choice, int scale, const RuntimeOptions& runtime = {},
                          const UpscaleOptions& options = {});

  Upscaler(Upscaler&&) noexcept;
  Upscaler& operator=(Upscaler&&) noexcept;
  ~Upscaler();

  int scale() const { return scale_; }
  bool learned() const { return model_ != nullptr; }
  // One line for logs and provenance: the model, its source and licence, the runtime; or "bicubic ×2 (classical)".
  std::string Describe() const;

  // `image` holds sRGB-encoded values in 0..1, 1 to 4 channels; the result is scale() times larger, same
  // channels, clamped to 0..1.
  ImageF Upscale(const ImageF& image) const;
  ImageU8 Upscale(const ImageU8& image) const;

 private:
  Upscaler(int scale, std::unique_ptr<Model> model, UpscaleOptions options);
  ImageF UpscaleColorLearned(const ImageF& rgb) const;

  int scale_ = 2;
  std::unique_ptr<Model> model_;
  UpscaleOptions options_;
  int margin_ = 0;  // tile overlap, input pixels
};

}  // namespace sd::models
