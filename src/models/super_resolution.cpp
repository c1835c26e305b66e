#include "models/super_resolution.h"

#include <algorithm>
#include <array>
#include <cmath>

#include "core/error.h"
#include "core/log.h"
#include "core/parallel.h"

namespace sd::models {

namespace {

ImageF Channels(const ImageF& image, int first, int count) {
  ImageF out(image.width(), image.height(), count);
  for (int y = 0; y < image.height(); ++y)
    for (int x = 0; x < image.width(); ++x)
      for (int c = 0; c < count; ++c) out.at(x, y, c) = image.at(x, y, first + c);
  return out;
}

void Clamp01(ImageF* image) {
  for (float& v : image->vector()) v = std::clamp(v, 0.0f, 1.0f);
}

std::filesystem::path InstalledModel(const std::string& name, int scale) {
  return DefaultModelDir() / (name + "-x" + std::to_string(scale) + ".pt");
}

}  // namespace

Upscaler::Upscaler(int scale, std::unique_ptr<Model> model, UpscaleOptions options)
    : scale_(scale), model_(std::move(model)), options_(options) {}
Upscaler::Upscaler(Upscaler&&) noexcept = default;
Upscaler& Upscaler::operator=(Upscaler&&) noexcept = default;
Upscaler::~Upscaler() = default;

Upscaler Upscaler::Classical(int scale) {
  if (scale < 2 || scale > 8) throw InputError({}, Msg() << "upscale factor must be 2..8, got " << scale);
  return Upscaler(scale, nullptr, {});
}

Upscaler Upscaler::FromModel(const std::filesystem::path& file, const RuntimeOptions& runtime,
                             const UpscaleOptions& options) {
  if (options.tile < 16) throw InputError({}, Msg() << "upscale tile must be at least 16 pixels, got " << options.tile);
  auto model = std::make_unique<Model>(Model::Load(file, kSuperResolutionStage, runtime));
  const ModelContract& c = model->contract();
  const double scale = c.Param("scale", file);
  if (scale < 2 || scale != std::floor(scale))
    throw InputError(file, Msg() << "super_resolution scale must be an integer >= 2, the contract says " << scale);
  const double radius = c.Param("receptive_radius", file);
  if (radius < 0) throw InputError(file, Msg() << "negative receptive_radius " << radius);
  const std::vector<int64_t> rgb{-1, 3, -1, -1};
  for (const auto* specs : {&c.inputs, &c.outputs})
    if (specs->size() != 1 || specs->front().shape.size() != 4 || (specs->front().shape[1] != 3))
      throw InputError(file, Msg() << "a super_resolution model maps one image " << ModelContract::ShapeString(rgb)
                                   << " to one image; its contract says otherwise");
  Upscaler up(static_cast<int>(scale), std::move(model), options);
  up.margin_ = static_cast<int>(std::ceil(radius));
  return up;
}

Upscaler Upscaler::Resolve(const std::string& choice, int scale, const RuntimeOptions& runtime,
                           const UpscaleOptions& options) {
  if (choice == "bicubic") return Classical(scale);
  if (choice == "auto") {
    const std::filesystem::path file = InstalledModel("esrgan-slim", scale);
    std::error_code ec;
    // The file first: asking for the runtime loads LibTorch, which a run without models should not pay for.
    if (!std::filesystem::is_regular_file(file, ec)) {
      SD_LOG(Warn, "super-resolution: no learned ×" << scale << " model installed (" << file.string()
                                                   << "; scripts/fetch_models.sh installs it); "
                                                   << "using the classical bicubic upscaler");
      return Classical(scale);
    }
    if (!RuntimeAvailable()) {
      SD_LOG(Warn, "super-resolution: " << RuntimeDescription() << "; using the classical bicubic upscaler");
      return Classical(scale);
    }
    return FromModel(file, runtime, options);
  }
  const bool is_path = choice.size() > 3 && choice.substr(choice.size() - 3) == ".pt";
  const std::filesystem::path file = is_path ? std::filesystem::path(choice) : InstalledModel(choice, scale);
  Upscaler up = FromModel(file, runtime, options);
  if (up.scale() != scale)
    throw InputError(file, Msg() << "is a ×" << up.scale() << " model, ×" << scale << " was asked for");
  return up;
}

std::string Upscaler::Describe() const {
  if (!model_) return Msg() << "bicubic ×" << scale_ << " (classical)";
  const ModelContract& c = model_->contract();
  Msg m;
  m << c.name << " ×" << scale_ << " (" << (c.source.empty() ? model_->file().string() : c.source);
  if (!c.license.empty()) m << ", " << c.license;
  m << "; TorchScript on " << RuntimeDescription() << ", device " << model_->device() << ")";
  return m;
}

ImageF Upscaler::Upscale(const ImageF& image) const {
  if (image.empty()) throw InputError({}, "upscale: empty image");
  const int ch = image.channels();
  if (ch < 1 || ch > 4) throw InputError({}, Msg() << "upscale: " << ch << "-channel image (1 to 4 supported)");
  ImageF out;
  if (!model_ || ch < 3) {
    out = UpscaleBicubic(image, scale_);
  } else {
    const ImageF rgb = ch == 3 ? image : Channels(image, 0, 3);
    out = UpscaleColorLearned(rgb);
    if (ch == 4) {
      const ImageF alpha = UpscaleBicubic(Channels(image, 3, 1), scale_);
      ImageF rgba(out.width(), out.height(), 4);
      for (int y = 0; y < out.height(); ++y)
        for (int x = 0; x < out.width(); ++x) {
          for (int c = 0; c < 3; ++c) rgba.at(x, y, c) = out.at(x, y, c);
          rgba.at(x, y, 3) = alpha.at(x, y);
        }
      out = std::move(rgba);
    }
  }
  Clamp01(&out);
  return out;
}

ImageU8 Upscaler::Upscale(const ImageU8& image) const {
  ImageF in(image.width(), image.height(), image.channels());
  for (size_t i = 0; i < image.size(); ++i) in.vector()[i] = image.vector()[i] / 255.0f;
  const ImageF out = Upscale(in);
  ImageU8 result(out.width(), out.height(), out.channels());
  for (size_t i = 0; i < out.size(); ++i)
    result.vector()[i] = static_cast<uint8_t>(std::lround(out.vector()[i] * 255.0f));
  return result;
}

// Tiles of options_.tile² input pixels, each run with margin_ pixels of real context on every side that has
// any (the model's own zero padding then happens only at the image border, as in a whole-image pass).
ImageF Upscaler::UpscaleColorLearned(const ImageF& rgb) const {
  const ModelContract& c = model_->contract();
  const double in_lo = c.inputs[0].range[0], in_span = c.inputs[0].range[1] - c.inputs[0].range[0];
  const double out_lo = c.outputs[0].range[0], out_span = c.outputs[0].range[1] - c.outputs[0].range[0];
  const int w = rgb.width(), h = rgb.height(), s = scale_, tile = options_.tile;
  ImageF out(w * s, h * s, 3);
  for (int ty = 0; ty < h; ty += tile) {
    for (int tx = 0; tx < w; tx += tile) {
      const int x1 = std::min(w, tx + tile), y1 = std::min(h, ty + tile);
      const int cx0 = std::max(0, tx - margin_), cy0 = std::max(0, ty - margin_);
      const int cx1 = std::min(w, x1 + margin_), cy1 = std::min(h, y1 + margin_);
      const int cw = cx1 - cx0, chh = cy1 - cy0;
      Tensor input({1, 3, chh, cw});
      for (int c3 = 0; c3 < 3; ++c3)
        for (int y = 0; y < chh; ++y)
          for (int x = 0; x < cw; ++x)
            input.values[(static_cast<size_t>(c3) * chh + y) * cw + x] =
                static_cast<float>(in_lo + in_span * rgb.at(cx0 + x, cy0 + y, c3));
      const Tensor result = model_->Run({input})[0];
      if (result.shape[2] != static_cast<int64_t>(chh) * s || result.shape[3] != static_cast<int64_t>(cw) * s)
        throw InputError(model_->file(), Msg() << "'" << c.name << "' turned a " << cw << "x" << chh << " tile into "
                                               << result.shape[3] << "x" << result.shape[2] << ", not ×" << s);
      const int ow = cw * s, oh = chh * s;
      for (int c3 = 0; c3 < 3; ++c3)
        for (int y = (ty - cy0) * s; y < (y1 - cy0) * s; ++y)
          for (int x = (tx - cx0) * s; x < (x1 - cx0) * s; ++x) {
            const float v = result.values[(static_cast<size_t>(c3) * oh + y) * ow + x];
            out.at(cx0 * s + x, cy0 * s + y, c3) = static_cast<float>((v - out_lo) / out_span);
          }
    }
  }
  return out;
}

}  // namespace sd::models
