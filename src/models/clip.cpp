#include "models/clip.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"
#include "core/parallel.h"

namespace sd::models {

namespace {

void CheckClipInput(const ImageF& image) {
  const int ch = image.channels();
  if (ch != 1 && ch != 3 && ch != 4)
    throw InputError({}, Msg() << "CLIP: " << ch << "-channel image (1, 3 or 4 supported)");
  if (image.empty()) throw InputError({}, "CLIP: empty image");
}

// sRGB 0..1 with 1, 3 or 4 channels (CheckClipInput) -> 3 channels; alpha composited over white.
ImageF ToRgb(const ImageF& image) {
  const int ch = image.channels();
  if (ch == 3) return image;
  ImageF rgb(image.width(), image.height(), 3);
  for (int y = 0; y < image.height(); ++y)
    for (int x = 0; x < image.width(); ++x)
      for (int c = 0; c < 3; ++c) {
        if (ch == 1) {
          rgb.at(x, y, c) = image.at(x, y, 0);
        } else {
          const float a = image.at(x, y, 3);
          rgb.at(x, y, c) = a * image.at(x, y, c) + (1 - a);
        }
      }
  return rgb;
}

void Normalize(Embedding* e, const std::filesystem::path& file) {
  double n2 = 0;
  for (float v : *e) n2 += double(v) * v;
  if (!(n2 > 0) || !std::isfinite(n2)) throw InputError(file, "produced a zero or non-finite embedding");
  const float inv = static_cast<float>(1.0 / std::sqrt(n2));
  for (float& v : *e) v *= inv;
}

}  // namespace

ImageF ClipPreprocess(const ImageF& rgb, int size) {
  SD_CHECK(rgb.channels() == 3 && size > 0, << rgb.channels() << " " << size);
  const int w = rgb.width(), h = rgb.height();
  // Shorter side to `size`, the longer one scaled alike and truncated (torchvision's Resize(int)).
  const int rw = w <= h ? size : std::max(size, static_cast<int>(static_cast<double>(size) * w / h));
  const int rh = w <= h ? std::max(size, static_cast<int>(static_cast<double>(size) * h / w)) : size;
  const ImageF resized = (rw == w && rh == h) ? rgb : ResizeBicubic(rgb, rw, rh);
  // torchvision's CenterCrop offset: Python's round(), which rounds halves to even (nearbyint's default mode).
  const int x0 = static_cast<int>(std::nearbyint((rw - size) / 2.0));
  const int y0 = static_cast<int>(std::nearbyint((rh - size) / 2.0));
  ImageF out(size, size, 3);
  for (int y = 0; y < size; ++y)
    for (int x = 0; x < size; ++x)
      for (int c = 0; c < 3; ++c) out.at(x, y, c) = std::clamp(resized.at(x0 + x, y0 + y, c), 0.0f, 1.0f);
  return out;
}

ClipEncoder::ClipEncoder(ClipEncoder&&) noexcept = default;
ClipEncoder& ClipEncoder::operator=(ClipEncoder&&) noexcept = default;
ClipEncoder::~ClipEncoder() = default;

ClipEncoder ClipEncoder::Load(const std::filesystem::path& dir, const RuntimeOptions& runtime,
                              const ClipOptions& options) {
  if (options.batch_size < 1) throw InputError({}, Msg() << "CLIP batch size must be >= 1, got " << options.batch_size);
  std::string missing;
  std::error_code ec;
  for (const char* name : {kClipImageFile, kClipTextFile, kClipVocabFile})
    if (!std::filesystem::is_regular_file(dir / name, ec)) missing += std::string(missing.empty() ? "" : ", ") + name;
  if (!missing.empty())
    throw InputError(dir, Msg() << "CLIP model folder lacks " << missing
                                << " (tools/export/export_clip.py writes clip_image.pt, clip_text.pt and "
                                << kClipVocabFile << ")");
  ClipEncoder enc;
  enc.options_ = options;
  enc.image_model_ = std::make_unique<Model>(Model::Load(dir / kClipImageFile, kClipImageStage, runtime));
  enc.text_model_ = std::make_unique<Model>(Model::Load(dir / kClipTextFile, kClipTextStage, runtime));
  const ModelContract& ic = enc.image_model_->contract();
  const ModelContract& tc = enc.text_model_->contract();
  const std::filesystem::path image_file = dir / kClipImageFile, text_file = dir / kClipTextFile;

  const double image_dim = ic.Param("embed_dim", image_file), text_dim = tc.Param("embed_dim", text_file);
  if (image_dim != text_dim || image_dim < 1)
    throw InputError(dir, Msg() << "CLIP image and text models disagree on embed_dim (" << image_dim << " vs "
                                << text_dim << "): they are not one CLIP model");
  enc.embed_dim_ = static_cast<int>(image_dim);
  enc.image_size_ = static_cast<int>(ic.Param("image_size", image_file));
  enc.context_length_ = static_cast<int>(tc.Param("context_length", text_file));
  if (enc.image_size_ < 8) throw InputError(image_file, Msg() << "image_size " << enc.image_size_ << " is too small");
  if (enc.context_length_ < 2)
    throw InputError(text_file, Msg() << "context_length " << enc.context_length_ << " is too small");
  const auto check_spec = [](const TensorSpec& spec, const std::vector<int64_t>& expected,
                             const std::filesystem::path& file, const char* what) {
    bool ok = spec.shape.size() == expected.size();
    for (size_t i = 0; ok && i < expected.size(); ++i) ok = spec.shape[i] == -1 || spec.shape[i] == expected[i];
    if (!ok)
      throw InputError(file, Msg() << what << " is " << ModelContract::ShapeString(spec.shape) << ", expected "
                                   << ModelContract::ShapeString(expected));
  };
  if (ic.inputs.size() != 1 || ic.outputs.size() != 1 || tc.inputs.size() != 1 || tc.outputs.size() != 1)
    throw InputError(dir, "CLIP models take one tensor and return one embedding each; a contract says otherwise");
  check_spec(ic.inputs[0], {-1, 3, enc.image_size_, enc.image_size_}, image_file, "the image input");
  check_spec(ic.outputs[0], {-1, enc.embed_dim_}, image_file, "the embedding output");
  check_spec(tc.inputs[0], {-1, enc.context_length_}, text_file, "the token input");
  check_spec(tc.outputs[0], {-1, enc.embed_dim_}, text_file, "the embedding output");

  int max_merges = -1;
  if (const auto it = tc.params.find("vocab_size"); it != tc.params.end()) {
    // float32 carries every integer below 2^24 exactly: beyond it, ids would be rounded on the way in.
    if (it->second > (1 << 24) || it->second < 514)
      throw InputError(text_file, Msg() << "vocab_size " << it->second << " outside 514..2^24");
    max_merges = static_cast<int>(it->second) - 514;
  }
  enc.tokenizer_ = std::make_unique<ClipTokenizer>(ClipTokenizer::Load(dir / kClipVocabFile, max_merges));
  return enc;
}

std::string ClipEncoder::Describe() const {
  const ModelContract& ic = image_model_->contract();
  const ModelContract& tc = text_model_->contract();
  Msg m;
  m << "CLIP " << ic.name << " / " << tc.name << " (" << (ic.source.empty() ? image_model_->file().string() : ic.source);
  if (!ic.license.empty()) m << ", " << ic.license;
  m << "; D " << embed_dim_ << "; TorchScript on " << RuntimeDescription() << ", device " << image_model_->device()
    << ")";
  return m;
}

std::vector<Embedding> ClipEncoder::RunBatches(const Model& model, int per_item, const std::vector<float>& items) const {
  const size_t n = items.size() / static_cast<size_t>(per_item);
  const std::vector<int64_t> item_shape = model.contract().inputs[0].shape;
  std::vector<Embedding> out;
  out.reserve(n);
  for (size_t first = 0; first < n; first += static_cast<size_t>(options_.batch_size)) {
    const size_t count = std::min(n - first, static_cast<size_t>(options_.batch_size));
    std::vector<int64_t> shape = item_shape;
    shape[0] = static_cast<int64_t>(count);
    // The fixed sizes come from our own checks in Load; -1 ones here are the image side / context length.
    if (shape.size() == 4) {
      shape[1] = 3;
      shape[2] = shape[3] = image_size_;
    } else {
      shape[1] = context_length_;
    }
    Tensor input(shape);
    std::copy(items.begin() + static_cast<std::ptrdiff_t>(first * per_item),
              items.begin() + static_cast<std::ptrdiff_t>((first + count) * per_item), input.values.begin());
    const Tensor result = model.Run({input})[0];
    if (result.shape[0] != static_cast<int64_t>(count) || result.shape[1] != embed_dim_)
      throw InputError(model.file(), Msg() << "returned " << ModelContract::ShapeString(result.shape) << " for "
                                           << count << " inputs, expected [" << count << ", " << embed_dim_ << "]");
    for (size_t i = 0; i < count; ++i) {
      Embedding e(result.values.begin() + static_cast<std::ptrdiff_t>(i * embed_dim_),
                  result.values.begin() + static_cast<std::ptrdiff_t>((i + 1) * embed_dim_));
      Normalize(&e, model.file());
      out.push_back(std::move(e));
    }
  }
  return out;
}

std::vector<Embedding> ClipEncoder::EmbedImages(const std::vector<ImageF>& images) const {
  const int s = image_size_;
  const size_t per = static_cast<size_t>(3) * s * s;
  for (const ImageF& image : images) CheckClipInput(image);  // before the parallel loop, which must not throw
  std::vector<float> items(images.size() * per);
  // Resizing is most of an image's host-side cost; on a GPU it would otherwise bound the throughput.
  ParallelFor(0, images.size(), [&](size_t n) {
    const ImageF crop = ClipPreprocess(ToRgb(images[n]), s);
    float* dst = items.data() + n * per;
    for (int c = 0; c < 3; ++c)
      for (int y = 0; y < s; ++y)
        for (int x = 0; x < s; ++x) dst[(static_cast<size_t>(c) * s + y) * s + x] = crop.at(x, y, c);
  });
  return RunBatches(*image_model_, static_cast<int>(per), items);
}

std::vector<Embedding> ClipEncoder::EmbedImages(const std::vector<ImageU8>& images) const {
  std::vector<ImageF> f;
  f.reserve(images.size());
  for (const ImageU8& im : images) {
    ImageF g(im.width(), im.height(), im.channels());
    for (size_t i = 0; i < im.size(); ++i) g.vector()[i] = im.vector()[i] / 255.0f;
    f.push_back(std::move(g));
  }
  return EmbedImages(f);
}

std::vector<Embedding> ClipEncoder::EmbedTexts(const std::vector<std::string>& texts) const {
  std::vector<float> items;
  items.reserve(texts.size() * static_cast<size_t>(context_length_));
  for (const std::string& text : texts)
    for (int id : tokenizer_->Tokenize(text, context_length_)) items.push_back(static_cast<float>(id));
  return RunBatches(*text_model_, context_length_, items);
}

float ClipEncoder::Similarity(const Embedding& a, const Embedding& b) {
  if (a.size() != b.size())
    throw InputError({}, Msg() << "CLIP similarity of embeddings of different sizes (" << a.size() << " vs "
                               << b.size() << ")");
  double dot = 0;
  for (size_t i = 0; i < a.size(); ++i) dot += double(a[i]) * b[i];
  return static_cast<float>(dot);
}

}  // namespace sd::models
