#include "models/segmentation.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"
#include "core/log.h"
#include "core/parallel.h"

namespace sd::models {

namespace {

// The box grown by the margin, as pixel bounds.
PixelRect GrownBox(const Box2& box, int w, int h) {
  const double margin = std::max<double>(kBoxMarginPixels,
                                         kBoxMarginFraction * std::max(box.x2 - box.x1, box.y2 - box.y1));
  return PixelsOf(Box2{box.x1 - margin, box.y1 - margin, box.x2 + margin, box.y2 + margin}, w, h);
}

}  // namespace

Segmenter::Segmenter(GrabCutOptions options, std::unique_ptr<Model> model, int input_size)
    : grabcut_(options), model_(std::move(model)), input_size_(input_size) {}
Segmenter::Segmenter(Segmenter&&) noexcept = default;
Segmenter& Segmenter::operator=(Segmenter&&) noexcept = default;
Segmenter::~Segmenter() = default;

Segmenter Segmenter::Classical(const GrabCutOptions& options) {
  if (options.components < 1 || options.components > 16 || options.iterations < 1 || !(options.gamma >= 0))
    throw InputError({}, Msg() << "grabcut: components must be 1..16, iterations >= 1 and gamma >= 0 (got "
                               << options.components << ", " << options.iterations << ", " << options.gamma << ")");
  return Segmenter(options, nullptr, 0);
}

Segmenter Segmenter::FromModel(const std::filesystem::path& file, const RuntimeOptions& runtime) {
  auto model = std::make_unique<Model>(Model::Load(file, kSegmentationStage, runtime));
  const ModelContract& c = model->contract();
  const double size = c.Param("input_size", file);
  if (size < 8 || size > 8192 || size != std::floor(size))
    throw InputError(file, Msg() << "segmentation input_size must be an integer 8..8192, the contract says " << size);
  const auto s = static_cast<int64_t>(size);
  const std::vector<int64_t> in{1, 3, s, s}, out{1, 1, s, s};
  if (c.inputs.size() != 1 || c.outputs.size() != 1 || c.inputs[0].shape != in || c.outputs[0].shape != out)
    throw InputError(file, Msg() << "a segmentation model maps one image " << ModelContract::ShapeString(in)
                                 << " to one mask " << ModelContract::ShapeString(out) << "; its contract says "
                                 << (c.inputs.empty() ? "no input" : ModelContract::ShapeString(c.inputs[0].shape))
                                 << " -> "
                                 << (c.outputs.empty() ? "no output" : ModelContract::ShapeString(c.outputs[0].shape)));
  const auto& r = c.outputs[0].range;
  if (!(r[1] > r[0])) throw InputError(file, Msg() << "segmentation output range [" << r[0] << ", " << r[1] << "] is empty");
  return Segmenter({}, std::move(model), static_cast<int>(s));
}

Segmenter Segmenter::Resolve(const std::string& choice, const RuntimeOptions& runtime) {
  if (choice == "classical" || choice == "grabcut") return Classical();
  if (choice == "auto") {
    const std::filesystem::path file = DefaultModelDir() / "isnet.pt";
    std::error_code ec;
    // The file first: asking for the runtime loads LibTorch, which a run without models should not pay for.
    if (!std::filesystem::is_regular_file(file, ec)) {
      SD_LOG(Warn, "segmentation: no learned model installed (" << file.string()
                                                               << "; scripts/fetch_isnet.sh installs ISNet, "
                                                                  "AGPL-3.0, opt-in); using the classical GrabCut");
      return Classical();
    }
    if (!RuntimeAvailable()) {
      SD_LOG(Warn, "segmentation: " << RuntimeDescription() << "; using the classical GrabCut");
      return Classical();
    }
    return FromModel(file, runtime);
  }
  if (choice.size() > 3 && choice.substr(choice.size() - 3) == ".pt") return FromModel(choice, runtime);
  throw InputError({}, Msg() << "segmenter '" << choice << "': expected classical, auto or a .pt model file");
}

std::string Segmenter::Describe() const {
  if (!model_)
    return Msg() << "GrabCut (classical; " << grabcut_.components << "-component colour models, "
                 << grabcut_.iterations << " iterations)";
  const ModelContract& c = model_->contract();
  Msg m;
  m << c.name << " " << input_size_ << "x" << input_size_ << " ("
    << (c.source.empty() ? model_->file().string() : c.source);
  if (!c.license.empty()) m << ", " << c.license;
  m << "; TorchScript on " << RuntimeDescription() << ", device " << model_->device() << ")";
  return m;
}

ImageF Segmenter::SegmentLearned(const ImageU8& image) const {
  const int w = image.width(), h = image.height(), ch = image.channels();
  ImageF rgb(w, h, 3);
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      for (int c = 0; c < 3; ++c) rgb.at(x, y, c) = image.at(x, y, ch >= 3 ? c : 0) / 255.0f;
  const int s = input_size_;
  const ImageF small = ResizeLinear(rgb, s, s);
  const ModelContract& c = model_->contract();
  const double in_lo = c.inputs[0].range[0], in_span = c.inputs[0].range[1] - c.inputs[0].range[0];
  Tensor input({1, 3, s, s});
  for (int k = 0; k < 3; ++k)
    for (int y = 0; y < s; ++y)
      for (int x = 0; x < s; ++x)
        input.values[(static_cast<size_t>(k) * s + static_cast<size_t>(y)) * s + static_cast<size_t>(x)] =
            static_cast<float>(in_lo + in_span * small.at(x, y, k));
  const Tensor result = model_->Run({input})[0];
  const double out_lo = c.outputs[0].range[0], out_span = c.outputs[0].range[1] - c.outputs[0].range[0];
  ImageF mask(s, s, 1);
  for (size_t i = 0; i < mask.size(); ++i) {
    const double v = (result.values[i] - out_lo) / out_span;
    mask.vector()[i] = std::isfinite(v) ? static_cast<float>(std::clamp(v, 0.0, 1.0)) : 0.0f;
  }
  ImageF full = ResizeLinear(mask, w, h);
  for (float& v : full.vector()) v = std::clamp(v, 0.0f, 1.0f);
  return full;
}

SegmentationResult Segmenter::Segment(const ImageU8& image, const Box2& box, const ImageF* prior) const {
  CheckSegmentationInput(image, box, prior);
  const int w = image.width(), h = image.height();
  const PixelRect r = PixelsOf(box, w, h);
  SegmentationResult result;
  if (model_) {
    result.mask = SegmentLearned(image);
    result.method = model_->contract().name;
    const PixelRect keep = GrownBox(box, w, h);
    for (int y = 0; y < h; ++y)
      for (int x = 0; x < w; ++x)
        if (x < keep.x0 || x >= keep.x1 || y < keep.y0 || y >= keep.y1) result.mask.at(x, y) = 0.0f;
  } else {
    result.mask = GrabCut(image, box, prior, grabcut_);
    result.method = "grabcut";
  }
  int64_t area = 0;
  for (int y = r.y0; y < r.y1; ++y)
    for (int x = r.x0; x < r.x1; ++x) area += result.mask.at(x, y) >= 0.5f;
  if (static_cast<double>(area) < kMinObjectFraction * static_cast<double>(r.Area()))
    throw InputError({}, Msg() << "segmentation (" << result.method << "): no object found in the box (" << box.x1
                               << ", " << box.y1 << ") - (" << box.x2 << ", " << box.y2 << "): " << area << " of "
                               << r.Area() << " pixels");
  SD_LOG(Debug, "segmentation: " << result.method << ", " << area << " of " << r.Area() << " box pixels");
  return result;
}

}  // namespace sd::models
