#include "models/harmonization.h"

#include <algorithm>
#include <cmath>
#include <mutex>

#include "core/error.h"
#include "core/log.h"
#include "core/parallel.h"
#include "models/resample.h"

namespace sd::models {

namespace {

constexpr double kDelta = 6.0 / 29.0;
constexpr double kWhite[3] = {0.95047, 1.0, 1.08883};  // D65

double LabF(double t) { return t > kDelta * kDelta * kDelta ? std::cbrt(t) : t / (3 * kDelta * kDelta) + 4.0 / 29.0; }
double LabFInv(double f) { return f > kDelta ? f * f * f : 3 * kDelta * kDelta * (f - 4.0 / 29.0); }

bool Foreground(float m) { return m >= 0.5f; }

struct Stats {
  std::array<double, 3> mean{}, std{};
  size_t count = 0;
};

Stats StatsOf(const std::vector<std::array<float, 3>>& lab) {
  Stats s;
  s.count = lab.size();
  if (lab.empty()) return s;
  for (const auto& v : lab)
    for (int c = 0; c < 3; ++c) s.mean[c] += v[c];
  for (double& m : s.mean) m /= static_cast<double>(lab.size());
  for (const auto& v : lab)
    for (int c = 0; c < 3; ++c) s.std[c] += (v[c] - s.mean[c]) * (v[c] - s.mean[c]);
  for (double& d : s.std) d = std::sqrt(d / static_cast<double>(lab.size()));
  return s;
}

void CheckInputs(const ImageF& composite, const ImageF& mask) {
  if (composite.empty() || composite.channels() != 3)
    throw InputError({}, Msg() << "harmonisation: the composite must be a non-empty RGB image, got "
                               << composite.channels() << " channels");
  if (mask.channels() != 1 || mask.width() != composite.width() || mask.height() != composite.height())
    throw InputError({}, Msg() << "harmonisation: the mask must be one channel of the composite's size ("
                               << composite.width() << "x" << composite.height() << "), got " << mask.width() << "x"
                               << mask.height() << "x" << mask.channels());
}

// composite + mask · (harmonised − composite), clamped: the background is returned exactly.
ImageF BlendByMask(const ImageF& composite, const ImageF& mask, const ImageF& harmonised) {
  ImageF out = composite;
  for (int y = 0; y < composite.height(); ++y)
    for (int x = 0; x < composite.width(); ++x) {
      const float m = std::clamp(mask.at(x, y), 0.0f, 1.0f);
      if (m <= 0) continue;
      for (int c = 0; c < 3; ++c)
        out.at(x, y, c) = std::clamp(composite.at(x, y, c) + m * (harmonised.at(x, y, c) - composite.at(x, y, c)),
                                     0.0f, 1.0f);
    }
  return out;
}

}  // namespace

std::array<float, 3> SrgbToLab(const std::array<float, 3>& srgb) {
  const double r = SrgbToLinear(srgb[0]), g = SrgbToLinear(srgb[1]), b = SrgbToLinear(srgb[2]);
  const double x = 0.4124564 * r + 0.3575761 * g + 0.1804375 * b;
  const double y = 0.2126729 * r + 0.7151522 * g + 0.0721750 * b;
  const double z = 0.0193339 * r + 0.1191920 * g + 0.9503041 * b;
  const double fx = LabF(x / kWhite[0]), fy = LabF(y / kWhite[1]), fz = LabF(z / kWhite[2]);
  return {static_cast<float>(116 * fy - 16), static_cast<float>(500 * (fx - fy)), static_cast<float>(200 * (fy - fz))};
}

std::array<float, 3> LabToSrgb(const std::array<float, 3>& lab) {
  const double fy = (lab[0] + 16.0) / 116.0, fx = fy + lab[1] / 500.0, fz = fy - lab[2] / 200.0;
  const double x = kWhite[0] * LabFInv(fx), y = kWhite[1] * LabFInv(fy), z = kWhite[2] * LabFInv(fz);
  const double r = 3.2404542 * x - 1.5371385 * y - 0.4985314 * z;
  const double g = -0.9692660 * x + 1.8760108 * y + 0.0415560 * z;
  const double b = 0.0556434 * x - 0.2040259 * y + 1.0572252 * z;
  return {LinearToSrgb(static_cast<float>(r)), LinearToSrgb(static_cast<float>(g)), LinearToSrgb(static_cast<float>(b))};
}

Harmonizer::Harmonizer(std::unique_ptr<Model> model, HarmonizeOptions options)
    : model_(std::move(model)), options_(options) {}
Harmonizer::Harmonizer(Harmonizer&&) noexcept = default;
Harmonizer& Harmonizer::operator=(Harmonizer&&) noexcept = default;
Harmonizer::~Harmonizer() = default;

Harmonizer Harmonizer::Classical(const HarmonizeOptions& options) {
  if (options.ring_px < 0) throw InputError({}, Msg() << "harmonisation ring must be >= 0 pixels, got " << options.ring_px);
  if (!(options.min_ratio > 0 && options.min_ratio <= 1 && options.max_ratio >= 1))
    throw InputError({}, "harmonisation std ratio bounds must satisfy 0 < min <= 1 <= max");
  for (float s : {options.lightness_strength, options.chroma_strength, options.cast_strength})
    if (!(s >= 0 && s <= 1)) throw InputError({}, Msg() << "harmonisation strengths are 0..1, got " << s);
  if (!(options.max_cast >= 0) || !(options.grey_chroma >= 0))
    throw InputError({}, "harmonisation max_cast and grey_chroma must be >= 0");
  return Harmonizer(nullptr, options);
}

Harmonizer Harmonizer::FromModel(const std::filesystem::path& file, const RuntimeOptions& runtime) {
  auto model = std::make_unique<Model>(Model::Load(file, kHarmonizationStage, runtime));
  const ModelContract& c = model->contract();
  const auto rank4 = [](const TensorSpec& s, int64_t channels) {
    return s.shape.size() == 4 && (s.shape[1] == channels || s.shape[1] == -1);
  };
  if (c.inputs.size() != 2 || c.outputs.size() != 1 || !rank4(c.inputs[0], 3) || !rank4(c.inputs[1], 1) ||
      !rank4(c.outputs[0], 3))
    throw InputError(file, "a harmonization model maps (composite [N, 3, H, W], mask [N, 1, H, W]) to an image "
                           "[N, 3, H, W]; its contract says otherwise");
  Harmonizer h(std::move(model), {});
  if (const auto it = c.params.find("image_size"); it != c.params.end()) {
    if (it->second < 8 || it->second != std::floor(it->second))
      throw InputError(file, Msg() << "harmonization image_size must be an integer >= 8, the contract says " << it->second);
    h.image_size_ = static_cast<int>(it->second);
  }
  return h;
}

Harmonizer Harmonizer::Resolve(const std::string& choice, const RuntimeOptions& runtime,
                               const HarmonizeOptions& options) {
  if (choice == "classical") return Classical(options);
  if (choice == "auto") {
    const std::filesystem::path file = DefaultModelDir() / kHarmonizerFile;
    std::error_code ec;
    // The file first: asking for the runtime loads LibTorch, which a run without models should not pay for.
    const bool installed = std::filesystem::is_regular_file(file, ec);
    if (installed && RuntimeAvailable()) return FromModel(file, runtime);
    const std::string why = !installed ? file.string() + " not installed" : RuntimeDescription();
    SD_LOG(Info, "harmonisation: no learned model (" << why << "); using the classical Lab statistics transfer");
    return Classical(options);
  }
  return FromModel(choice, runtime);
}

std::string Harmonizer::Describe() const {
  if (!model_) {
    return Msg() << "Lab statistics transfer (classical; lightness " << options_.lightness_strength << ", chroma "
                 << options_.chroma_strength << ", cast " << options_.cast_strength << ")";
  }
  const ModelContract& c = model_->contract();
  Msg m;
  m << c.name << " (" << (c.source.empty() ? model_->file().string() : c.source);
  if (!c.license.empty()) m << ", " << c.license;
  if (image_size_ > 0) m << "; runs at " << image_size_ << "x" << image_size_;
  m << "; TorchScript on " << RuntimeDescription() << ", device " << model_->device() << ")";
  return m;
}

ImageF Harmonizer::Harmonize(const ImageF& composite, const ImageF& mask) const {
  CheckInputs(composite, mask);
  return model_ ? HarmonizeLearned(composite, mask) : HarmonizeClassical(composite, mask);
}

ImageF Harmonizer::HarmonizeClassical(const ImageF& composite, const ImageF& mask) const {
  const int w = composite.width(), h = composite.height();
  size_t fg_count = 0;
  int x0 = w, y0 = h, x1 = -1, y1 = -1;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x)
      if (Foreground(mask.at(x, y))) {
        ++fg_count;
        x0 = std::min(x0, x), x1 = std::max(x1, x), y0 = std::min(y0, y), y1 = std::max(y1, y);
      }
  if (fg_count == 0) return composite;
  const int ring = options_.ring_px > 0
                       ? options_.ring_px
                       : std::max(4, static_cast<int>(std::lround(0.25 * std::sqrt(static_cast<double>(fg_count)))));
  // The ring: background pixels within `ring` (Chebyshev) of a foreground pixel — a square dilation as two
  // separable passes over the object's box grown by the ring, each a window sum of a running count (constant
  // work per pixel whatever the ring's width; the ring grows with the object, to ~125 px for a close car).
  const int bx0 = std::max(0, x0 - ring), by0 = std::max(0, y0 - ring);
  const int bx1 = std::min(w - 1, x1 + ring), by1 = std::min(h - 1, y1 + ring);
  const int bw = bx1 - bx0 + 1, bh = by1 - by0 + 1;
  std::vector<uint8_t> fg(static_cast<size_t>(bw) * bh), row_dilated(fg.size()), dilated(fg.size());
  for (int y = 0; y < bh; ++y)
    for (int x = 0; x < bw; ++x) fg[static_cast<size_t>(y) * bw + x] = Foreground(mask.at(bx0 + x, by0 + y));
  // count[i + 1] = set entries among the first i + 1 of a line; the window [a, b] holds one iff
  // count[b + 1] > count[a].
  std::vector<int> count(static_cast<size_t>(std::max(bw, bh)) + 1);
  const auto dilate_line = [&](const uint8_t* in, uint8_t* out, int n, size_t stride) {
    count[0] = 0;
    for (int i = 0; i < n; ++i) count[static_cast<size_t>(i) + 1] = count[static_cast<size_t>(i)] + in[i * stride];
    for (int i = 0; i < n; ++i)
      out[i * stride] = count[static_cast<size_t>(std::min(n - 1, i + ring)) + 1] > count[static_cast<size_t>(std::max(0, i - ring))];
  };
  for (int y = 0; y < bh; ++y) dilate_line(&fg[static_cast<size_t>(y) * bw], &row_dilated[static_cast<size_t>(y) * bw], bw, 1);
  for (int x = 0; x < bw; ++x) dilate_line(&row_dilated[static_cast<size_t>(x)], &dilated[static_cast<size_t>(x)], bh, bw);
  const auto rgb_at = [&](int x, int y) {
    return std::array<float, 3>{composite.at(x, y, 0), composite.at(x, y, 1), composite.at(x, y, 2)};
  };
  // The object's and the ring's pixels in scan order, then their Lab values in parallel (a cube root and three
  // powers each), each into its own slot: the statistics below sum them in that order.
  std::vector<size_t> fg_at, ring_at;
  for (size_t i = 0; i < fg.size(); ++i) {
    if (fg[i]) fg_at.push_back(i);
    else if (dilated[i]) ring_at.push_back(i);
  }
  const auto lab_of = [&](const std::vector<size_t>& at) {
    std::vector<std::array<float, 3>> lab(at.size());
    ParallelForRange(0, at.size(), 4096, [&](size_t begin, size_t end) {
      for (size_t j = begin; j < end; ++j)
        lab[j] = SrgbToLab(rgb_at(bx0 + static_cast<int>(at[j] % bw), by0 + static_cast<int>(at[j] / bw)));
    });
    return lab;
  };
  const std::vector<std::array<float, 3>> fg_lab = lab_of(fg_at), ring_lab = lab_of(ring_at);
  if (ring_lab.size() < 16) {
    SD_LOG(Warn, "harmonisation: only " << ring_lab.size() << " background pixels around the object; left as is");
    return composite;
  }
  const Stats f = StatsOf(fg_lab), b = StatsOf(ring_lab);
  std::array<double, 3> ratio{}, strength{options_.lightness_strength, options_.chroma_strength,
                                          options_.chroma_strength};
  for (int c = 0; c < 3; ++c)
    ratio[c] = f.std[c] < 1e-6 ? 1.0 : std::clamp(b.std[c] / f.std[c], double(options_.min_ratio), double(options_.max_ratio));
  // Mean shift per channel: lightness as Reinhard; a*b* as cast difference (cast_strength, bounded) + own-colour
  // difference (chroma_strength). See the header.
  const auto cast_of = [&](const std::vector<std::array<float, 3>>& lab) {
    std::array<double, 2> sum{};
    size_t n = 0;
    for (const auto& v : lab)
      if (std::hypot(v[1], v[2]) < options_.grey_chroma) sum[0] += v[1], sum[1] += v[2], ++n;
    if (n < std::max<size_t>(8, lab.size() / 10)) return std::array<double, 2>{0, 0};
    return std::array<double, 2>{sum[0] / n, sum[1] / n};
  };
  const std::array<double, 2> cast_fg = cast_of(fg_lab), cast_ring = cast_of(ring_lab);
  std::array<double, 3> shift{};
  shift[0] = options_.lightness_strength * (b.mean[0] - f.mean[0]);
  double cast_shift[2];
  for (int c = 0; c < 2; ++c) cast_shift[c] = options_.cast_strength * (cast_ring[c] - cast_fg[c]);
  const double cast_len = std::hypot(cast_shift[0], cast_shift[1]);
  if (cast_len > options_.max_cast) cast_shift[0] *= options_.max_cast / cast_len, cast_shift[1] *= options_.max_cast / cast_len;
  for (int c = 1; c < 3; ++c)
    shift[c] = cast_shift[c - 1] +
               options_.chroma_strength * ((b.mean[c] - cast_ring[c - 1]) - (f.mean[c] - cast_fg[c - 1]));
  // Every pixel the mask touches (soft edges included) gets the transfer; BlendByMask weighs it by coverage.
  ImageF harmonised = composite;
  ParallelRows(by0, by1 + 1, [&](int y) {  // pixel by pixel
    for (int x = bx0; x <= bx1; ++x) {
      if (mask.at(x, y) <= 0) continue;
      std::array<float, 3> lab = SrgbToLab(rgb_at(x, y));
      for (int c = 0; c < 3; ++c)
        lab[c] = static_cast<float>(lab[c] + shift[c] + strength[c] * (ratio[c] - 1) * (lab[c] - f.mean[c]));
      const std::array<float, 3> rgb = LabToSrgb(lab);
      for (int c = 0; c < 3; ++c) harmonised.at(x, y, c) = rgb[c];
    }
  });
  return BlendByMask(composite, mask, harmonised);
}

ImageF Harmonizer::HarmonizeLearned(const ImageF& composite, const ImageF& mask) const {
  const int w = composite.width(), h = composite.height();
  const bool resize = image_size_ > 0 && (w != image_size_ || h != image_size_);
  const ImageF comp_in = resize ? ResizeBicubic(composite, image_size_, image_size_) : composite;
  const ImageF mask_in = resize ? ResizeBicubic(mask, image_size_, image_size_) : mask;
  const int iw = comp_in.width(), ih = comp_in.height();
  Tensor c_t({1, 3, ih, iw}), m_t({1, 1, ih, iw});
  for (int y = 0; y < ih; ++y)
    for (int x = 0; x < iw; ++x) {
      for (int c = 0; c < 3; ++c)
        c_t.values[(static_cast<size_t>(c) * ih + y) * iw + x] = std::clamp(comp_in.at(x, y, c), 0.0f, 1.0f);
      m_t.values[static_cast<size_t>(y) * iw + x] = std::clamp(mask_in.at(x, y), 0.0f, 1.0f);
    }
  // A frame's cameras harmonise at once (synth/frame.cpp); the model's forward passes take turns, each with the
  // runtime's whole thread pool, rather than splitting it.
  static std::mutex one_forward_at_a_time;
  std::unique_lock<std::mutex> turn(one_forward_at_a_time);
  const Tensor out = model_->Run({c_t, m_t})[0];
  turn.unlock();
  if (out.shape[0] != 1 || out.shape[2] != ih || out.shape[3] != iw)
    throw InputError(model_->file(), Msg() << "returned " << ModelContract::ShapeString(out.shape) << " for a "
                                           << iw << "x" << ih << " composite");
  // The change the model made, at its resolution; resized back and added, so the photograph is not resampled.
  ImageF delta(iw, ih, 3);
  for (int c = 0; c < 3; ++c)
    for (int y = 0; y < ih; ++y)
      for (int x = 0; x < iw; ++x)
        delta.at(x, y, c) = out.values[(static_cast<size_t>(c) * ih + y) * iw + x] -
                            c_t.values[(static_cast<size_t>(c) * ih + y) * iw + x];
  if (resize) delta = ResizeBicubic(delta, w, h);
  ImageF harmonised = composite;
  for (size_t i = 0; i < harmonised.size(); ++i) harmonised.vector()[i] += delta.vector()[i];
  return BlendByMask(composite, mask, harmonised);
}

ImageF HarmonizeInsert(const ImageF& image, const ImageF& object_rgb, const ImageF& object_alpha,
                       const InsertOptions& options) {
  if (image.empty() || image.channels() != 3 || object_rgb.channels() != 3 || object_rgb.width() != image.width() ||
      object_rgb.height() != image.height())
    throw InputError({}, Msg() << "harmonised insert: the photograph and the object colour must be RGB images of one size, got "
                               << image.width() << "x" << image.height() << "x" << image.channels() << " and "
                               << object_rgb.width() << "x" << object_rgb.height() << "x" << object_rgb.channels());
  CheckInputs(image, object_alpha);
  ImageF composite = image;
  for (int y = 0; y < image.height(); ++y)
    for (int x = 0; x < image.width(); ++x) {
      const float a = std::clamp(object_alpha.at(x, y), 0.0f, 1.0f);
      if (a <= 0) continue;
      for (int c = 0; c < 3; ++c) composite.at(x, y, c) = image.at(x, y, c) * (1 - a) + object_rgb.at(x, y, c) * a;
    }
  if (options.harmonizer) return options.harmonizer->Harmonize(composite, object_alpha);
  return Harmonizer::Classical(options.classical).Harmonize(composite, object_alpha);
}

}  // namespace sd::models
