#pragma once
// Image harmonisation: make an object pasted into a photograph look shot by the same camera — exposure, white
// balance and contrast matched to its surroundings (DESIGN.md synth: "compositing, colour harmonisation").
// The synth pipeline's lighting calibration (synth/lighting.h) already matches the light falling on the object;
// this stage corrects what remains after compositing (tone curve, colour cast, sensor contrast).
//
// Contract "harmonization" (runtime.h; docs/models.md):
//   inputs "composite": [N, 3, H, W] float32, RGB, sRGB-encoded, 0..1, NCHW — the photograph with the object in
//                       it; "mask": [N, 1, H, W] float32 0..1, the object's coverage (soft edges allowed).
//   output "image":     [N, 3, H, W] float32, sRGB 0..1, the harmonised composite.
//   params: "image_size" (optional): the square resolution the network runs at (e.g. 256 for iS2AM-style
//           models). The composite and mask are resized to it, and the model's CHANGE (output - input) is
//           resized back and added at full resolution, so the photograph's detail is never resampled.
// Either path changes only the object: the result is composite + mask · (harmonised − composite), so pixels
// outside the mask are returned bit for bit.
//
// Classical path (Reinhard et al. 2001, "Color transfer between images", here in CIELAB): the object's
// per-channel Lab mean and standard deviation are moved towards those of a ring of background around it
// (pixels within `ring_px` of the mask, not the whole image: the light where the object stands). Full transfer
// would also give a red car the grey of the road, so lightness (which carries the exposure mismatch) and
// chroma have separate strengths, and the contrast ratio is bounded. Chroma is split further: each region's
// mean a*b* = its colour cast (the mean a*b* of its near-grey pixels, chroma < `grey_chroma`: road, tyres,
// windows; 0 when under 10% of the region is grey) + its own colour (the rest). The cast difference is
// transferred with `cast_strength` (a warm evening light reaches the object fully; bounded by `max_cast`, in
// case the ring's grey pixels are not neutral), the own-colour difference with `chroma_strength` (kept low, so
// a red cone stays red). With cast_strength == chroma_strength this is the plain Reinhard transfer.
//
// HarmonizeInsert composites an object (straight, not premultiplied, colour + alpha) into a photograph and
// harmonises it: the one call the synth pipeline needs.
#include <array>
#include <filesystem>
#include <memory>
#include <string>

#include "core/image.h"
#include "models/runtime.h"

namespace sd::models {

constexpr const char* kHarmonizationStage = "harmonization";
constexpr const char* kHarmonizerFile = "harmonizer.pt";  // the installed default in DefaultModelDir()

struct HarmonizeOptions {
  int ring_px = 0;                 // background ring width; 0: max(4, 0.25 * sqrt(object pixel count))
  float lightness_strength = 0.8f; // 0: keep the object's L* statistics, 1: take the ring's
  float chroma_strength = 0.1f;    // the same for the object's own colour (a*, b* beyond the cast) and the a*b* std
  float cast_strength = 1.0f;      // the same for the colour cast (a*b* of the grey pixels)
  float max_cast = 15.0f;          // bound (a*b* units) of the cast change applied
  float grey_chroma = 25.0f;       // pixels under this Lab chroma count as grey for the cast estimate (casts reach ~15)
  float min_ratio = 0.5f, max_ratio = 2.0f;  // bounds of the std ratio (contrast change)
};

// CIELAB (D65 white) of sRGB-encoded 0..1 values and back; L* in 0..100.
std::array<float, 3> SrgbToLab(const std::array<float, 3>& srgb);
std::array<float, 3> LabToSrgb(const std::array<float, 3>& lab);  // clamped to 0..1 (out-of-gamut Lab)

class Harmonizer {
 public:
  static Harmonizer Classical(const HarmonizeOptions& options = {});
  // InputError naming the file when it is unusable or its contract does not have the shapes above.
  static Harmonizer FromModel(const std::filesystem::path& file, const RuntimeOptions& runtime = {});
  // "classical"; "auto" (DefaultModelDir()/harmonizer.pt when installed, else classical, logged); a .pt path.
  static Harmonizer Resolve(const std::string& choice, const RuntimeOptions& runtime = {},
                            const HarmonizeOptions& options = {});

  Harmonizer(Harmonizer&&) noexcept;
  Harmonizer& operator=(Harmonizer&&) noexcept;
  ~Harmonizer();

  bool learned() const { return model_ != nullptr; }
  std::string Describe() const;

  // `composite`: sRGB 0..1, 3 channels; `mask`: 1 channel 0..1, same size. Returns the harmonised composite,
  // clamped to 0..1, identical to `composite` wherever mask is 0.
  ImageF Harmonize(const ImageF& composite, const ImageF& mask) const;

 private:
  Harmonizer(std::unique_ptr<Model> model, HarmonizeOptions options);
  ImageF HarmonizeClassical(const ImageF& composite, const ImageF& mask) const;
  ImageF HarmonizeLearned(const ImageF& composite, const ImageF& mask) const;

  std::unique_ptr<Model> model_;
  HarmonizeOptions options_;
  int image_size_ = 0;  // learned: 0 = full resolution
};

struct InsertOptions {
  const Harmonizer* harmonizer = nullptr;  // learned or classical; nullptr: Harmonizer::Classical(classical)
  HarmonizeOptions classical;
};

// `image`: the photograph, sRGB 0..1, 3 channels; `object_rgb`: the object's colour, sRGB 0..1, 3 channels, same
// size, straight (not premultiplied); `object_alpha`: its coverage 0..1 (antialiased, occlusion applied), 1
// channel. Returns the composite image * (1 - alpha) + object * alpha, harmonised: equal to `image` wherever
// alpha is 0. InputError on mismatched sizes or channel counts.
ImageF HarmonizeInsert(const ImageF& image, const ImageF& object_rgb, const ImageF& object_alpha,
                       const InsertOptions& options = {});

}  // namespace sd::models
