#include "models/scheduler.h"

#include <algorithm>
#include <cmath>
#include <numbers>

#include "core/error.h"

namespace sd::models {

double GaussianNoise::Next() {
  if (has_spare_) {
    has_spare_ = false;
    return spare_;
  }
  constexpr double kTwoToMinus53 = 1.0 / 9007199254740992.0;
  const uint64_t a = engine_() >> 11, b = engine_() >> 11;
  const double u1 = static_cast<double>(a + 1) * kTwoToMinus53;  // (0, 1]: log never sees 0
  const double u2 = static_cast<double>(b) * kTwoToMinus53;
  const double r = std::sqrt(-2.0 * std::log(u1));
  const double angle = 2.0 * std::numbers::pi * u2;
  spare_ = r * std::sin(angle);
  has_spare_ = true;
  return r * std::cos(angle);
}

void GaussianNoise::Fill(std::span<float> out) {
  for (float& v : out) v = static_cast<float>(Next());
}

std::vector<float> GaussianNoise::Draw(size_t count) {
  std::vector<float> out(count);
  Fill(out);
  return out;
}

EulerAncestralScheduler::EulerAncestralScheduler(const SchedulerConfig& config, int steps) : config_(config) {
  const int T = config.num_train_timesteps;
  if (T < 2) throw InputError({}, Msg() << "diffusion schedule: num_train_timesteps must be >= 2, got " << T);
  if (steps < 1 || steps > T)
    throw InputError({}, Msg() << "diffusion sampling: steps must be 1.." << T << ", got " << steps);
  if (!(config.beta_start > 0 && config.beta_end >= config.beta_start && config.beta_end < 1))
    throw InputError({}, Msg() << "diffusion schedule: betas must satisfy 0 < start <= end < 1, got "
                               << config.beta_start << ".." << config.beta_end);

  // β over the T training steps, then ᾱ as a running product.
  alphas_cumprod_.resize(T);
  double cumulative = 1.0;
  for (int i = 0; i < T; ++i) {
    const double f = static_cast<double>(i) / (T - 1);
    double beta = 0;
    if (config.beta_schedule == BetaSchedule::kLinear) {
      beta = config.beta_start + f * (config.beta_end - config.beta_start);
    } else {
      const double s = std::sqrt(config.beta_start) + f * (std::sqrt(config.beta_end) - std::sqrt(config.beta_start));
      beta = s * s;
    }
    cumulative *= 1.0 - beta;
    alphas_cumprod_[i] = cumulative;
  }

  timesteps_.resize(steps);
  switch (config.spacing) {
    case TimestepSpacing::kTrailing: {
      // np.arange(T, 0, -T/N).round() - 1: N values since T/N·N = T exactly in the arange's own arithmetic.
      const double ratio = static_cast<double>(T) / steps;
      for (int i = 0; i < steps; ++i) timesteps_[i] = std::nearbyint(T - i * ratio) - 1.0;
      break;
    }
    case TimestepSpacing::kLeading: {
      const int ratio = T / steps;
      for (int i = 0; i < steps; ++i)
        timesteps_[i] = static_cast<double>((steps - 1 - i) * ratio + config.steps_offset);
      break;
    }
    case TimestepSpacing::kLinspace:
      for (int i = 0; i < steps; ++i)
        timesteps_[i] = steps == 1 ? T - 1.0 : (T - 1.0) * (steps - 1 - i) / (steps - 1);
      break;
  }

  // σ at each timestep, linearly interpolated between integer training steps (np.interp semantics: clamped).
  sigmas_.resize(steps + 1);
  for (int i = 0; i < steps; ++i) {
    const double t = std::clamp(timesteps_[i], 0.0, T - 1.0);
    const int lo = static_cast<int>(std::floor(t));
    const int hi = std::min(lo + 1, T - 1);
    const double w = t - lo;
    const auto sigma = [&](int k) { return std::sqrt((1.0 - alphas_cumprod_[k]) / alphas_cumprod_[k]); };
    sigmas_[i] = (1.0 - w) * sigma(lo) + w * sigma(hi);
  }
  sigmas_[steps] = 0.0;
}

double EulerAncestralScheduler::init_noise_sigma() const {
  const double max_sigma = *std::max_element(sigmas_.begin(), sigmas_.end());
  if (config_.spacing == TimestepSpacing::kLeading) return std::sqrt(max_sigma * max_sigma + 1.0);
  return max_sigma;
}

double EulerAncestralScheduler::input_scale(int step) const {
  SD_CHECK(step >= 0 && step < steps(), << step);
  return 1.0 / std::sqrt(sigmas_[step] * sigmas_[step] + 1.0);
}

void EulerAncestralScheduler::Denoised(int step, std::span<const float> sample, std::span<const float> v,
                                       std::span<float> x0) const {
  SD_CHECK(step >= 0 && step < steps(), << step);
  SD_CHECK(sample.size() == v.size() && x0.size() == v.size(), << sample.size() << " " << v.size() << " " << x0.size());
  const double s = sigmas_[step];
  const double c_v = -s / std::sqrt(s * s + 1.0), c_x = 1.0 / (s * s + 1.0);
  for (size_t k = 0; k < v.size(); ++k) x0[k] = static_cast<float>(c_v * v[k] + c_x * sample[k]);
}

void EulerAncestralScheduler::Step(int step, std::span<const float> v, std::span<float> sample,
                                   std::span<const float> noise) const {
  SD_CHECK(step >= 0 && step < steps(), << step);
  SD_CHECK(sample.size() == v.size() && noise.size() == v.size(), << sample.size() << " " << v.size() << " "
                                                                   << noise.size());
  const double s = sigmas_[step], s_next = sigmas_[step + 1];
  const double sigma_up = std::sqrt(std::max(0.0, s_next * s_next * (s * s - s_next * s_next) / (s * s)));
  const double sigma_down = std::sqrt(std::max(0.0, s_next * s_next - sigma_up * sigma_up));
  const double dt = sigma_down - s;
  const double c_v = -s / std::sqrt(s * s + 1.0), c_x = 1.0 / (s * s + 1.0);
  for (size_t k = 0; k < v.size(); ++k) {
    const double x = sample[k];
    const double x0 = c_v * v[k] + c_x * x;
    const double derivative = (x - x0) / s;
    sample[k] = static_cast<float>(x + derivative * dt + sigma_up * noise[k]);
  }
}

void ApplyGuidance(std::span<const float> uncond, std::span<const float> cond, float scale, std::span<float> out) {
  SD_CHECK(uncond.size() == cond.size() && out.size() == cond.size(), << uncond.size() << " " << cond.size() << " "
                                                                       << out.size());
  for (size_t k = 0; k < out.size(); ++k) out[k] = uncond[k] + scale * (cond[k] - uncond[k]);
}

}  // namespace sd::models
