#pragma once
// CLIP image and text encoders (Radford et al. 2021): one embedding space for pictures and captions, so asset
// mining can rank images by a text query and the bank can find near-duplicates.
//
// A CLIP model is a folder of three files, written by tools/export/export_clip.py:
//   clip_image.pt               contract "clip_image"
//   clip_text.pt                contract "clip_text"
//   bpe_simple_vocab_16e6.txt   the BPE merges (clip_tokenizer.h), uncompressed
//
// Contract "clip_image" (runtime.h; docs/models.md):
//   input  "image":     [N, 3, S, S] float32, RGB, sRGB-encoded, 0..1, NCHW. S = params.image_size (224 for
//                       ViT-B/32 and ViT-L/14). The model's own mean / std normalisation is INSIDE the exported
//                       module, so the C++ side never needs to know the training statistics of a checkpoint.
//   output "embedding": [N, D] float32, D = params.embed_dim; not normalised (the C++ side L2-normalises).
// Contract "clip_text":
//   input  "tokens":    [N, L] float32 holding exact integer token ids (L = params.context_length, 77). The
//                       runtime moves float32 tensors only (one dtype across the boundary keeps Model::Run and
//                       its checks simple); ids stay below params.vocab_size (49408) < 2^24, where float32
//                       represents every integer exactly, and the exported module casts them back to int64
//                       before its embedding lookup.
//   output "embedding": [N, D] float32, not normalised.
//   params: "embed_dim", "context_length", "vocab_size" (optional: when present, only the first
//           vocab_size - 514 merges of the vocabulary file are read, as the reference tokenizer does).
//
// Image preprocessing is the reference one: resize so the shorter side is S (bicubic, antialiased when
// shrinking), centre crop S × S. There is no classical path: without the three files, Load says which are
// missing.
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "core/image.h"
#include "models/clip_tokenizer.h"
#include "models/resample.h"
#include "models/runtime.h"

namespace sd::models {

constexpr const char* kClipImageStage = "clip_image";
constexpr const char* kClipTextStage = "clip_text";
constexpr const char* kClipImageFile = "clip_image.pt";
constexpr const char* kClipTextFile = "clip_text.pt";
constexpr const char* kClipVocabFile = "bpe_simple_vocab_16e6.txt";

struct ClipOptions {
  int batch_size = 16;  // images or texts per forward pass
};

// One embedding: D floats, unit L2 norm.
using Embedding = std::vector<float>;

class ClipEncoder {
 public:
  // Loads the folder's three files. InputError naming every missing file at once, or the file whose contract
  // is for another stage, or image and text models whose embed_dim differ.
  static ClipEncoder Load(const std::filesystem::path& dir, const RuntimeOptions& runtime = {},
                          const ClipOptions& options = {});

  ClipEncoder(ClipEncoder&&) noexcept;
  ClipEncoder& operator=(ClipEncoder&&) noexcept;
  ~ClipEncoder();

  int embed_dim() const { return embed_dim_; }
  int image_size() const { return image_size_; }
  int context_length() const { return context_length_; }
  const ClipTokenizer& tokenizer() const { return *tokenizer_; }
  // One line for logs and provenance: both models' names and sources, the runtime.
  std::string Describe() const;

  // Images: sRGB-encoded 0..1 (ImageF) or 8-bit (ImageU8), 1 (grey), 3 or 4 channels (RGBA is composited
  // over white, the usual product-photo background). Any size. Unit-norm embeddings, one per image, in order.
  std::vector<Embedding> EmbedImages(const std::vector<ImageF>& images) const;
  std::vector<Embedding> EmbedImages(const std::vector<ImageU8>& images) const;
  // Texts: UTF-8, tokenised by the folder's vocabulary; longer than the context are truncated.
  std::vector<Embedding> EmbedTexts(const std::vector<std::string>& texts) const;

  // Cosine similarity of two unit embeddings (their dot product); both must have the same size.
  static float Similarity(const Embedding& a, const Embedding& b);

 private:
  ClipEncoder() = default;
  std::vector<Embedding> RunBatches(const Model& model, int per_item, const std::vector<float>& items) const;

  std::unique_ptr<Model> image_model_, text_model_;
  std::unique_ptr<ClipTokenizer> tokenizer_;
  ClipOptions options_;
  int embed_dim_ = 0, image_size_ = 0, context_length_ = 0;
};

// The reference preprocessing: shorter side to `size` (ResizeBicubic), then the centre `size` × `size` crop.
// 3 channels in and out.
ImageF ClipPreprocess(const ImageF& rgb, int size);

}  // namespace sd::models
