#pragma once
// The segmentation stage (DESIGN.md generate: "segment the object out of the crop"), learned or classical.
//
// Contract "segmentation" (runtime.h; docs/models.md):
//   input  "image": [1, 3, S, S] float32, RGB, sRGB-encoded, range [0, 1], NCHW. S = params "input_size",
//                   fixed (1024 for ISNet). Any normalisation the network needs (mean/std) is inside the module.
//   output "mask":  [1, 1, S, S] float32, object probability, in the contract's output range (normally [0, 1])
//   params: "input_size" (S)
// The learned path resizes the whole image to S×S without keeping the aspect ratio (a plain, antialiased
// linear resize — how ISNet was trained and how its reference pipelines feed it; a letterbox would waste input
// pixels on padding the network never saw in training), runs the model, resizes the mask back, and zeroes it
// outside the box grown by a margin (kBoxMarginFraction of the box's longer side, at least kBoxMarginPixels):
// the box says which object is meant, the network only where its edges are. The prior is not used there.
//
// Classical path (the default, and what "auto" falls back to): GrabCut from the box (models/grabcut.h), seeded
// by the prior where given.
//
// Both paths: InputError for an empty image, a box with no pixel in the image, a prior of another size, and
// "no object found in the box" when fewer than kMinObjectFraction of the box's pixels come out ≥ 0.5.
#include <filesystem>
#include <memory>
#include <string>

#include "core/box3.h"
#include "core/image.h"
#include "models/grabcut.h"
#include "models/resample.h"
#include "models/runtime.h"

namespace sd::models {

constexpr const char* kSegmentationStage = "segmentation";
constexpr double kMinObjectFraction = 0.01;
constexpr double kBoxMarginFraction = 0.05;
constexpr int kBoxMarginPixels = 4;

struct SegmentationResult {
  ImageF mask;         // 1 channel, image size, 0..1 (classical: 0 or 1)
  std::string method;  // "grabcut" or the model's contract name
};

class Segmenter {
 public:
  static Segmenter Classical(const GrabCutOptions& options = {});
  // A segmentation model file; InputError naming the file when it is unusable (runtime.h) or its contract's
  // shapes are not [1, 3, S, S] → [1, 1, S, S] with S = params "input_size".
  static Segmenter FromModel(const std::filesystem::path& file, const RuntimeOptions& runtime = {});
  // What `synthdrive generate --segmenter` accepts:
  //   "classical"  GrabCut (the default: no weights needed);
  //   "auto"       isnet.pt in DefaultModelDir() (scripts/fetch_isnet.sh installs it, opt-in: AGPL-3.0) when
  //                present and LibTorch is available, else GrabCut with a warning saying why;
  //   a path       any file ending in .pt.
  static Segmenter Resolve(const std::string& choice, const RuntimeOptions& runtime = {});

  Segmenter(Segmenter&&) noexcept;
  Segmenter& operator=(Segmenter&&) noexcept;
  ~Segmenter();

  bool learned() const { return model_ != nullptr; }
  int input_size() const { return input_size_; }
  // One line for logs and provenance.
  std::string Describe() const;

  // `image`: sRGB, 1, 3 or 4 channels (alpha ignored). `box`: the object's pixel box ([x1, x2) × [y1, y2)).
  // `prior`: optional 1-channel image-size mask, ≥ 0.5 = surely object (classical path only).
  SegmentationResult Segment(const ImageU8& image, const Box2& box, const ImageF* prior = nullptr) const;

 private:
  Segmenter(GrabCutOptions options, std::unique_ptr<Model> model, int input_size);
  ImageF SegmentLearned(const ImageU8& image) const;

  GrabCutOptions grabcut_;
  std::unique_ptr<Model> model_;
  int input_size_ = 0;
};

}  // namespace sd::models
