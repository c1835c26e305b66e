#pragma once
// The sampler of the multi-view diffusion stage: Euler ancestral over a discrete DDPM noise schedule, with
// v-prediction and classifier-free guidance — what Zero123++ v1.2 samples with. Pure C++ over float vectors, so
// it is tested on its own against an independent numpy implementation (tools/testing/scheduler_reference.py).
//
// Facts, as found in public sources (docs/models.md has the full list):
//  - The Zero123++ custom pipeline (SUDO-AI-3D/zero123plus, diffusers-support/pipeline.py) runs diffusers'
//    StableDiffusionPipeline loop; its README and every published usage replace the scheduler with
//    `EulerAncestralDiscreteScheduler.from_config(pipeline.scheduler.config, timestep_spacing='trailing')`.
//  - Its defaults: num_inference_steps = 28, guidance_scale = 4.0 (pipeline.py __call__); the README suggests
//    28 steps for ordinary objects and 75–100 for fine detail (36 in the depth-ControlNet example).
//  - v-prediction: the authors chose "a v-prediction base model" (maintainer, zero123plus issue #86); the
//    report (arXiv 2310.15110, "noise schedule") swaps Stable Diffusion's scaled-linear betas for a *linear*
//    schedule. The exact scheduler_config.json of the v1.2 weights could not be read here, so the schedule is
//    never assumed at run time: the exporter copies it from the pipeline into the UNet's contract, and
//    SchedulerConfig::Zero123PlusDefaults() (linear, 0.00085..0.012, 1000 steps) only documents our reading.
//
// The sampler, in the k-diffusion σ parameterisation diffusers uses (t = training timestep, ᾱ_t = ∏(1 − β)):
//   σ(t) = sqrt((1 − ᾱ_t) / ᾱ_t), σ at fractional t by linear interpolation over t = 0..T−1;
//   x_T = ε · init_noise_sigma (σ_max for "trailing"/"linspace", sqrt(σ_max² + 1) for "leading");
//   model input = x / sqrt(σ² + 1); v-prediction → x̂0 = x/(σ²+1) − v·σ/sqrt(σ²+1);
//   σ_up = sqrt(σ_next² (σ² − σ_next²) / σ²), σ_down = sqrt(σ_next² − σ_up²);
//   x ← x + (x − x̂0)/σ · (σ_down − σ) + σ_up · ε.
// Noise comes from GaussianNoise, a generator we own so runs are reproducible bit for bit across platforms
// and a Python reference can replay it (its exact definition is below).
#include <cstdint>
#include <random>
#include <span>
#include <vector>

namespace sd::models {

enum class BetaSchedule {
  kLinear,        // β_i = linspace(β_start, β_end, T)
  kScaledLinear,  // β_i = linspace(sqrt β_start, sqrt β_end, T)²  (Stable Diffusion's)
};

enum class TimestepSpacing {
  kTrailing,  // round(arange(T, 0, −T/N)) − 1: always starts at T−1, the fully noised step (Lin et al. 2023)
  kLeading,   // arange(0, N)·(T div N), reversed, + steps_offset
  kLinspace,  // linspace(0, T−1, N), reversed (fractional timesteps, σ interpolated)
};

struct SchedulerConfig {
  int num_train_timesteps = 1000;
  double beta_start = 0.00085;
  double beta_end = 0.012;
  BetaSchedule beta_schedule = BetaSchedule::kLinear;
  TimestepSpacing spacing = TimestepSpacing::kTrailing;
  int steps_offset = 1;  // only "leading" uses it

  static SchedulerConfig Zero123PlusDefaults() { return {}; }
};

// Zero123++'s pipeline defaults (pipeline.py __call__).
constexpr int kZero123PlusDefaultSteps = 28;
constexpr float kZero123PlusDefaultGuidance = 4.0f;

// Standard normal samples from std::mt19937_64(seed), two per Box–Muller pair, in this exact order:
//   a = engine() >> 11, b = engine() >> 11           (53-bit integers)
//   u1 = (a + 1) · 2⁻⁵³  ∈ (0, 1],  u2 = b · 2⁻⁵³  ∈ [0, 1)
//   r = sqrt(−2 ln u1);  first = r cos(2π u2), second = r sin(2π u2)
// computed in double and rounded to float. Fill() continues the same stream (a pending second value is used
// first), so one generator drawn in any chunking gives the same sequence.
class GaussianNoise {
 public:
  explicit GaussianNoise(uint64_t seed) : engine_(seed) {}
  double Next();
  void Fill(std::span<float> out);
  std::vector<float> Draw(size_t count);

 private:
  std::mt19937_64 engine_;
  bool has_spare_ = false;
  double spare_ = 0;
};

class EulerAncestralScheduler {
 public:
  // InputError for steps < 1, steps > num_train_timesteps, or a degenerate schedule.
  EulerAncestralScheduler(const SchedulerConfig& config, int steps);

  const SchedulerConfig& config() const { return config_; }
  int steps() const { return static_cast<int>(timesteps_.size()); }
  const std::vector<double>& alphas_cumprod() const { return alphas_cumprod_; }  // T values, ᾱ_0 .. ᾱ_{T−1}
  const std::vector<double>& timesteps() const { return timesteps_; }  // N values, descending: what the model gets
  const std::vector<double>& sigmas() const { return sigmas_; }        // N + 1 values, the last one 0
  double init_noise_sigma() const;
  // 1 / sqrt(σ_i² + 1): what the sample is multiplied by before it goes to the model at step i.
  double input_scale(int step) const;

  // x̂0 from a v-prediction `v` of `sample` at step i (out may alias neither).
  void Denoised(int step, std::span<const float> sample, std::span<const float> v, std::span<float> x0) const;
  // One ancestral Euler step from step i to i + 1, in place on `sample`; `noise` (standard normal, same size)
  // is scaled by σ_up (zero on the last step, where the result is exactly x̂0).
  void Step(int step, std::span<const float> v, std::span<float> sample, std::span<const float> noise) const;

 private:
  SchedulerConfig config_;
  std::vector<double> alphas_cumprod_, timesteps_, sigmas_;
};

// Classifier-free guidance: out = uncond + scale · (cond − uncond). out may alias either input.
void ApplyGuidance(std::span<const float> uncond, std::span<const float> cond, float scale, std::span<float> out);

}  // namespace sd::models
