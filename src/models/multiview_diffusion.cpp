#include "models/multiview_diffusion.h"

#include <algorithm>
#include <cmath>

#include "core/error.h"
#include "core/log.h"

namespace sd::models {

namespace fs = std::filesystem;

struct MultiViewGenerator::Models {
  Model encoder, unet, decoder;
  double vae_scaling_factor = 0;
  int vae_scale_factor = 8;
};

namespace {

struct ExpectedFile {
  const char* name;
  const char* stage;
  const char* what;
};

constexpr ExpectedFile kFiles[] = {
    {kMvImageEncoderFile, kMvImageEncoderStage,
     "the condition-image encoder: CLIP image embedding + ramping into the text embedding, and the VAE-encoded "
     "reference latents"},
    {kMvUnetFile, kMvUnetStage, "the Zero123++ UNet with reference attention, returning the v-prediction"},
    {kMvVaeDecoderFile, kMvVaeDecoderStage, "the Stable Diffusion 2 VAE decoder (latents to RGB)"},
};

SchedulerConfig ScheduleFromContract(const Model& unet) {
  const ModelContract& c = unet.contract();
  const fs::path& file = unet.file();
  if (c.Param("v_prediction", file) != 1)
    throw InputError(file, "the mv_unet contract must declare \"v_prediction\": 1 (Zero123++ predicts v); "
                           "other parameterisations are not supported");
  SchedulerConfig s;
  s.num_train_timesteps = static_cast<int>(c.Param("num_train_timesteps", file));
  s.beta_start = c.Param("beta_start", file);
  s.beta_end = c.Param("beta_end", file);
  const double schedule = c.Param("beta_schedule", file);
  if (schedule != 0 && schedule != 1)
    throw InputError(file, Msg() << "beta_schedule must be 0 (linear) or 1 (scaled_linear), the contract says "
                                 << schedule);
  s.beta_schedule = schedule == 0 ? BetaSchedule::kLinear : BetaSchedule::kScaledLinear;
  const double spacing = c.Param("timestep_spacing", file);
  if (spacing != 0 && spacing != 1 && spacing != 2)
    throw InputError(file, Msg() << "timestep_spacing must be 0 (trailing), 1 (leading) or 2 (linspace), the "
                                 << "contract says " << spacing);
  s.spacing = spacing == 0 ? TimestepSpacing::kTrailing
                           : (spacing == 1 ? TimestepSpacing::kLeading : TimestepSpacing::kLinspace);
  s.steps_offset = static_cast<int>(c.Param("steps_offset", file));
  try {
    EulerAncestralScheduler check(s, 1);
  } catch (const InputError& e) {
    throw InputError(file, Msg() << "unusable schedule in the contract: " << e.what());
  }
  return s;
}

// Row `row` of a [B, ...] tensor, as a [1, ...] tensor.
Tensor Row(const Tensor& t, int64_t row) {
  std::vector<int64_t> shape = t.shape;
  shape[0] = 1;
  Tensor out(shape);
  const size_t n = out.values.size();
  std::copy_n(t.values.begin() + static_cast<std::ptrdiff_t>(n * row), n, out.values.begin());
  return out;
}

// Stacks [1, ...] tensors into [B, ...].
Tensor Stack(const std::vector<Tensor>& rows) {
  std::vector<int64_t> shape = rows.front().shape;
  shape[0] = static_cast<int64_t>(rows.size());
  Tensor out;
  out.shape = shape;
  for (const Tensor& r : rows) out.values.insert(out.values.end(), r.values.begin(), r.values.end());
  return out;
}

}  // namespace

MultiViewGenerator::MultiViewGenerator(std::unique_ptr<Models> models, SchedulerConfig scheduler,
                                       MultiViewOptions options)
    : models_(std::move(models)), scheduler_config_(scheduler), options_(options) {}
MultiViewGenerator::MultiViewGenerator(MultiViewGenerator&&) noexcept = default;
MultiViewGenerator& MultiViewGenerator::operator=(MultiViewGenerator&&) noexcept = default;
MultiViewGenerator::~MultiViewGenerator() = default;

MultiViewGenerator MultiViewGenerator::Load(const fs::path& dir, const RuntimeOptions& runtime,
                                            const MultiViewOptions& options) {
  Msg missing;
  int missing_count = 0;
  for (const ExpectedFile& f : kFiles) {
    std::error_code ec;
    if (!fs::is_regular_file(dir / f.name, ec)) {
      missing << (missing_count++ ? "; " : "") << f.name << " (stage \"" << f.stage << "\": " << f.what << ")";
    }
  }
  if (missing_count > 0)
    throw InputError(dir, Msg() << "multi-view diffusion model directory lacks " << missing_count << " of 3 files: "
                                << std::string(missing)
                                << ". tools/export/export_zero123plus.py writes them from the Zero123++ v1.2 "
                                   "weights");
  auto models = std::make_unique<Models>(Models{Model::Load(dir / kMvImageEncoderFile, kMvImageEncoderStage, runtime),
                                                Model::Load(dir / kMvUnetFile, kMvUnetStage, runtime),
                                                Model::Load(dir / kMvVaeDecoderFile, kMvVaeDecoderStage, runtime)});
  const SchedulerConfig schedule = ScheduleFromContract(models->unet);
  const fs::path& dec = models->decoder.file();
  models->vae_scaling_factor = models->decoder.contract().Param("scaling_factor", dec);
  const double f = models->decoder.contract().Param("scale_factor", dec);
  if (!(models->vae_scaling_factor > 0))
    throw InputError(dec, Msg() << "scaling_factor must be positive, the contract says " << models->vae_scaling_factor);
  if (f < 1 || f != std::floor(f) || (kMultiViewSize * kMultiViewGridCols) % static_cast<int>(f) != 0 ||
      (kMultiViewSize * kMultiViewGridRows) % static_cast<int>(f) != 0)
    throw InputError(dec, Msg() << "scale_factor must be an integer dividing 640 and 960, the contract says " << f);
  models->vae_scale_factor = static_cast<int>(f);
  return MultiViewGenerator(std::move(models), schedule, options);
}

std::string MultiViewGenerator::Describe() const {
  Msg m;
  m << "multi-view diffusion: " << models_->unet.contract().name << " (" << models_->unet.contract().source;
  if (!models_->unet.contract().license.empty()) m << ", " << models_->unet.contract().license;
  m << "), Euler ancestral, v-prediction; TorchScript on " << RuntimeDescription() << ", device "
    << models_->unet.device();
  return m;
}

ImageF Zero123ConditionImage(const ImageU8& object_image) {
  if (object_image.empty()) throw InputError({}, "multi-view diffusion: empty object image");
  const int ch = object_image.channels();
  if (ch != 1 && ch != 3 && ch != 4)
    throw InputError({}, Msg() << "multi-view diffusion: " << ch << "-channel object image (1, 3 or 4 supported)");
  const int w = object_image.width(), h = object_image.height(), side = std::max(w, h);
  const float grey = kZero123Background / 255.0f;
  ImageF out(side, side, 3, grey);
  const int x0 = (side - w) / 2, y0 = (side - h) / 2;
  for (int y = 0; y < h; ++y)
    for (int x = 0; x < w; ++x) {
      const float alpha = ch == 4 ? object_image.at(x, y, 3) / 255.0f : 1.0f;
      for (int c = 0; c < 3; ++c) {
        const float v = object_image.at(x, y, ch == 1 ? 0 : c) / 255.0f;
        out.at(x0 + x, y0 + y, c) = alpha * v + (1.0f - alpha) * grey;
      }
    }
  return out;
}

std::vector<ImageF> SplitMultiViewGrid(const ImageF& grid) {
  const int s = kMultiViewSize;
  if (grid.width() != s * kMultiViewGridCols || grid.height() != s * kMultiViewGridRows)
    throw InputError({}, Msg() << "multi-view grid must be " << s * kMultiViewGridCols << "x" << s * kMultiViewGridRows
                               << ", got " << grid.width() << "x" << grid.height());
  std::vector<ImageF> views;
  for (int r = 0; r < kMultiViewGridRows; ++r)
    for (int c = 0; c < kMultiViewGridCols; ++c) {
      ImageF view(s, s, grid.channels());
      for (int y = 0; y < s; ++y)
        std::copy_n(grid.pixel(c * s, r * s + y), static_cast<size_t>(s) * grid.channels(), view.pixel(0, y));
      views.push_back(std::move(view));
    }
  return views;
}

ImageF MultiViewGenerator::GenerateGrid(const ImageU8& object_image, int steps, float guidance, uint64_t seed) const {
  if (steps < 1) throw InputError({}, Msg() << "multi-view diffusion: steps must be at least 1, got " << steps);
  if (!(guidance >= 0))
    throw InputError({}, Msg() << "multi-view diffusion: guidance must be >= 0, got " << guidance);
  const EulerAncestralScheduler scheduler(scheduler_config_, steps);
  const ImageF condition = Zero123ConditionImage(object_image);

  // Condition: once per image.
  const int side = condition.width();
  Tensor image({1, 3, side, side});
  for (int c = 0; c < 3; ++c)
    for (int y = 0; y < side; ++y)
      for (int x = 0; x < side; ++x)
        image.values[(static_cast<size_t>(c) * side + y) * side + x] = condition.at(x, y, c);
  const std::vector<Tensor> encoded = models_->encoder.Run({image});
  const fs::path& enc_file = models_->encoder.file();
  if (encoded.size() != 2 || encoded[0].shape.size() != 3 || encoded[0].shape[0] != 2 ||
      encoded[1].shape.size() != 4 || encoded[1].shape[0] != 2 || encoded[1].shape[1] != 4)
    throw InputError(enc_file, "mv_image_encoder must return cond_embeds [2, L, D] and ref_latents [2, 4, h, w]");
  const bool guided = guidance > 1.0f;
  std::vector<int64_t> rows = guided ? std::vector<int64_t>{0, 1} : std::vector<int64_t>{1};
  std::vector<Tensor> embeds, refs;
  for (int64_t r : rows) {
    embeds.push_back(Row(encoded[0], r));
    refs.push_back(Row(encoded[1], r));
  }

  const int f = models_->vae_scale_factor;
  const int64_t lh = kMultiViewSize * kMultiViewGridRows / f, lw = kMultiViewSize * kMultiViewGridCols / f;
  const size_t n = static_cast<size_t>(4 * lh * lw);
  GaussianNoise noise(seed);
  std::vector<float> x = noise.Draw(n);
  const double init_sigma = scheduler.init_noise_sigma();
  for (float& v : x) v = static_cast<float>(v * init_sigma);

  std::vector<float> v_guided(n), step_noise(n);
  for (int i = 0; i < steps; ++i) {
    const double sigma = scheduler.sigmas()[i], scale = scheduler.input_scale(i);
    const auto t = static_cast<float>(scheduler.timesteps()[i]);
    Tensor latent_in({1, 4, lh, lw});
    for (size_t k = 0; k < n; ++k) latent_in.values[k] = static_cast<float>(x[k] * scale);
    // The reference latents, noised to this step's level (RefOnlyNoisedUNet: add_noise then scale_model_input).
    std::vector<Tensor> ref_in;
    for (const Tensor& ref : refs) {
      Tensor noised = ref;
      const std::vector<float> eps = noise.Draw(noised.values.size());
      for (size_t k = 0; k < eps.size(); ++k)
        noised.values[k] = static_cast<float>((ref.values[k] + sigma * eps[k]) * scale);
      ref_in.push_back(std::move(noised));
    }
    std::vector<Tensor> v_rows;
    if (options_.batched_guidance && rows.size() > 1) {
      Tensor timestep({static_cast<int64_t>(rows.size())}, t);
      const Tensor out = models_->unet.Run({Stack(std::vector<Tensor>(rows.size(), latent_in)), timestep,
                                            Stack(embeds), Stack(ref_in)})[0];
      for (size_t r = 0; r < rows.size(); ++r) v_rows.push_back(Row(out, static_cast<int64_t>(r)));
    } else {
      for (size_t r = 0; r < rows.size(); ++r)
        v_rows.push_back(models_->unet.Run({latent_in, Tensor({1}, t), embeds[r], ref_in[r]})[0]);
    }
    for (const Tensor& v : v_rows)
      if (v.shape != std::vector<int64_t>{1, 4, lh, lw})
        throw InputError(models_->unet.file(), Msg() << "mv_unet returned " << ModelContract::ShapeString(v.shape)
                                                     << " for latents " << ModelContract::ShapeString(latent_in.shape));
    if (guided)
      ApplyGuidance(v_rows[0].values, v_rows[1].values, guidance, v_guided);
    else
      v_guided = v_rows[0].values;
    noise.Fill(step_noise);
    scheduler.Step(i, v_guided, x, step_noise);
  }

  // pipeline.py: unscale_latents, / vae scaling_factor, decode, unscale_image, then VaeImageProcessor's
  // denormalisation (x / 2 + 0.5, clamped).
  Tensor z({1, 4, lh, lw});
  for (size_t k = 0; k < n; ++k)
    z.values[k] = static_cast<float>((x[k] / kZero123LatentScale + kZero123LatentShift) / models_->vae_scaling_factor);
  const Tensor decoded = models_->decoder.Run({z})[0];
  const int gw = kMultiViewSize * kMultiViewGridCols, gh = kMultiViewSize * kMultiViewGridRows;
  if (decoded.shape != std::vector<int64_t>{1, 3, gh, gw})
    throw InputError(models_->decoder.file(), Msg() << "mv_vae_decoder returned " << ModelContract::ShapeString(decoded.shape)
                                                    << ", expected [1, 3, " << gh << ", " << gw << "]");
  ImageF grid(gw, gh, 3);
  for (int c = 0; c < 3; ++c)
    for (int y = 0; y < gh; ++y)
      for (int xx = 0; xx < gw; ++xx) {
        const double raw = decoded.values[(static_cast<size_t>(c) * gh + y) * gw + xx];
        const double img = raw / kZero123ImageScale;
        grid.at(xx, y, c) = static_cast<float>(std::clamp(img / 2.0 + 0.5, 0.0, 1.0));
      }
  return grid;
}

std::vector<ImageU8> MultiViewGenerator::Generate(const ImageU8& object_image, int steps, float guidance,
                                                  uint64_t seed) const {
  const ImageF grid = GenerateGrid(object_image, steps, guidance, seed);
  std::vector<ImageU8> views;
  for (const ImageF& view : SplitMultiViewGrid(grid)) {
    ImageU8 out(view.width(), view.height(), 3);
    for (size_t k = 0; k < view.size(); ++k)
      out.vector()[k] = static_cast<uint8_t>(std::lround(view.vector()[k] * 255.0f));
    views.push_back(std::move(out));
  }
  SD_LOG(Info, "multi-view diffusion: " << steps << " steps, guidance " << guidance << ", seed " << seed);
  return views;
}

}  // namespace sd::models
