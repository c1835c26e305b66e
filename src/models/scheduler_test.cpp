#include "models/scheduler.h"

#include <cmath>
#include <cstdlib>
#include <fstream>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "core/error.h"

namespace sd::models {
namespace {

TEST(Scheduler, LinearBetasGiveAMonotoneCumulativeProductWithKnownEnds) {
  const EulerAncestralScheduler s(SchedulerConfig::Zero123PlusDefaults(), 28);
  const auto& ac = s.alphas_cumprod();
  ASSERT_EQ(ac.size(), 1000u);
  EXPECT_DOUBLE_EQ(ac[0], 1.0 - 0.00085);
  for (size_t i = 1; i < ac.size(); ++i) ASSERT_LT(ac[i], ac[i - 1]) << i;
  EXPECT_GT(ac.back(), 0.0);
  // ln ᾱ_{T-1} = Σ ln(1 − β_i) ≈ −Σ β_i − Σ β_i²/2 with Σ β_i = 1000·(0.00085 + 0.012)/2 = 6.425.
  EXPECT_NEAR(std::log(ac.back()), -6.425, 0.06);
  // σ at t = 0 is sqrt(β_0 / (1 − β_0)); the first σ of a trailing schedule is σ(999).
  const EulerAncestralScheduler one(SchedulerConfig::Zero123PlusDefaults(), 1000);
  EXPECT_NEAR(one.sigmas()[999], std::sqrt(0.00085 / (1 - 0.00085)), 1e-12);
  EXPECT_NEAR(s.sigmas()[0], std::sqrt((1 - ac.back()) / ac.back()), 1e-12);
  EXPECT_NEAR(s.sigmas()[0], 25.1461, 1e-4);
  EXPECT_DOUBLE_EQ(s.init_noise_sigma(), s.sigmas()[0]);  // trailing: σ_max, not sqrt(σ_max² + 1)
  EXPECT_EQ(s.sigmas().back(), 0.0);
}

TEST(Scheduler, ScaledLinearReachesStableDiffusionsSigmaMax) {
  SchedulerConfig c;
  c.beta_schedule = BetaSchedule::kScaledLinear;
  c.spacing = TimestepSpacing::kLeading;
  const EulerAncestralScheduler s(c, 50);
  // Stable Diffusion's well-known σ_max for scaled_linear 0.00085..0.012 over 1000 steps.
  const double last = s.alphas_cumprod().back();
  EXPECT_NEAR(std::sqrt((1 - last) / last), 14.6146, 1e-4);
  // leading: 0, 20, ..., 980 reversed, + steps_offset 1.
  EXPECT_EQ(s.timesteps().front(), 981.0);
  EXPECT_EQ(s.timesteps().back(), 1.0);
  EXPECT_NEAR(s.init_noise_sigma(), std::sqrt(s.sigmas()[0] * s.sigmas()[0] + 1), 1e-12);
}

TEST(Scheduler, TrailingTimestepsForThePipelineDefaultAndTheReadmeCounts) {
  // 28 = pipeline.py's num_inference_steps default: round(1000 − i·1000/28) − 1.
  const std::vector<double> expected28{999, 963, 928, 892, 856, 820, 785, 749, 713, 678, 642, 606, 570, 535,
                                       499, 463, 428, 392, 356, 320, 285, 249, 213, 178, 142, 106, 70,  35};
  EXPECT_EQ(EulerAncestralScheduler(SchedulerConfig{}, 28).timesteps(), expected28);
  const auto t36 = EulerAncestralScheduler(SchedulerConfig{}, 36).timesteps();
  ASSERT_EQ(t36.size(), 36u);
  EXPECT_EQ(t36[1], 971.0);
  EXPECT_EQ(t36[18], 499.0);
  EXPECT_EQ(t36.back(), 27.0);
  for (int n : {1, 2, 61, 75, 100, 103, 1000}) {
    const auto t = EulerAncestralScheduler(SchedulerConfig{}, n).timesteps();
    ASSERT_EQ(static_cast<int>(t.size()), n);
    EXPECT_EQ(t.front(), 999.0) << n;  // trailing always starts from pure noise
    EXPECT_GE(t.back(), 0.0) << n;
    for (size_t i = 1; i < t.size(); ++i) ASSERT_LT(t[i], t[i - 1]) << n;
  }
}

TEST(Scheduler, VPredictionOfTheTrueVelocityRecoversTheCleanSample) {
  const EulerAncestralScheduler s(SchedulerConfig{}, 10);
  const int i = 3;
  const double sigma = s.sigmas()[i];
  // x = x0 + σ ε in k-diffusion form; v (on the scaled input) = α ε − σ' x0 with α = 1/sqrt(σ²+1), σ' = σ α.
  const std::vector<float> x0{0.5f, -1.25f, 2.0f}, eps{0.3f, 1.1f, -0.7f};
  std::vector<float> x(3), v(3), got(3);
  const double a = 1 / std::sqrt(sigma * sigma + 1);
  for (int k = 0; k < 3; ++k) {
    x[k] = static_cast<float>(x0[k] + sigma * eps[k]);
    v[k] = static_cast<float>(a * eps[k] - sigma * a * x0[k]);
  }
  s.Denoised(i, x, v, got);
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(got[k], x0[k], 2e-4 * sigma);
  EXPECT_NEAR(s.input_scale(i), a, 1e-15);
}

TEST(Scheduler, TheLastStepLandsExactlyOnTheDenoisedSample) {
  const EulerAncestralScheduler s(SchedulerConfig{}, 4);
  std::vector<float> x{1.0f, -2.0f, 0.5f}, v{0.2f, 0.1f, -0.3f}, x0(3);
  s.Denoised(3, x, v, x0);
  const std::vector<float> huge_noise{100.0f, -100.0f, 55.0f};  // σ_up is 0 on the last step
  s.Step(3, v, x, huge_noise);
  for (int k = 0; k < 3; ++k) EXPECT_NEAR(x[k], x0[k], 1e-6);
}

TEST(Scheduler, RejectsBadStepCounts) {
  EXPECT_THROW(EulerAncestralScheduler(SchedulerConfig{}, 0), InputError);
  EXPECT_THROW(EulerAncestralScheduler(SchedulerConfig{}, 1001), InputError);
  SchedulerConfig bad;
  bad.beta_end = 0.0001;
  EXPECT_THROW(EulerAncestralScheduler(bad, 10), InputError);
}

TEST(Scheduler, GuidanceInterpolatesAndExtrapolates) {
  const std::vector<float> u{1, 2, 3}, c{2, 2, 0};
  std::vector<float> out(3);
  ApplyGuidance(u, c, 1.0f, out);
  EXPECT_EQ(out, c);
  ApplyGuidance(u, c, 0.0f, out);
  EXPECT_EQ(out, u);
  ApplyGuidance(u, c, 4.0f, out);
  EXPECT_EQ(out, (std::vector<float>{5, 2, -9}));
}

TEST(GaussianNoise, IsStandardNormalAndIndependentOfChunking) {
  GaussianNoise a(123), b(123), c(124);
  std::vector<float> whole = a.Draw(100001);
  std::vector<float> parts;
  for (size_t n : {1u, 2u, 7u, 99991u}) {
    const auto p = b.Draw(n);
    parts.insert(parts.end(), p.begin(), p.end());
  }
  ASSERT_EQ(parts.size(), whole.size());
  EXPECT_EQ(parts, whole);
  EXPECT_NE(c.Draw(4), std::vector<float>(whole.begin(), whole.begin() + 4));
  double mean = 0, var = 0;
  for (float v : whole) mean += v;
  mean /= whole.size();
  for (float v : whole) var += (v - mean) * (v - mean);
  var /= whole.size();
  EXPECT_NEAR(mean, 0.0, 0.01);  // 3.2 standard errors
  EXPECT_NEAR(var, 1.0, 0.015);
}

// The synthetic model of scheduler_reference.py.
float ModelV(float x_in, double t, size_t k, bool cond) {
  if (cond) return static_cast<float>(0.3 * x_in + 0.1 * std::cos(0.004 * t + 0.05 * static_cast<double>(k)));
  return static_cast<float>(0.25 * x_in - 0.05 * std::sin(0.003 * t));
}

TEST(Scheduler, MatchesTheIndependentNumpyReference) {
  const char* path = std::getenv("SYNTHDRIVE_SCHEDULER_REFERENCE");
  if (!path || !std::ifstream(path)) GTEST_SKIP() << "scheduler reference not built (needs python3 with numpy)";
  std::ifstream in(path);
  const nlohmann::json ref = nlohmann::json::parse(in);
  {
    GaussianNoise g(42);
    for (double expected : ref["noise_seed_42"]) EXPECT_EQ(static_cast<float>(g.Next()), expected);  // bit-exact
  }
  ASSERT_EQ(ref["cases"].size(), 5u);
  for (const auto& c : ref["cases"]) {
    SCOPED_TRACE(c["name"].get<std::string>());
    const auto& jc = c["config"];
    SchedulerConfig cfg;
    cfg.num_train_timesteps = jc["num_train_timesteps"];
    cfg.beta_start = jc["beta_start"];
    cfg.beta_end = jc["beta_end"];
    cfg.beta_schedule = jc["beta_schedule"] == "linear" ? BetaSchedule::kLinear : BetaSchedule::kScaledLinear;
    const std::string spacing = jc["spacing"];
    cfg.spacing = spacing == "trailing" ? TimestepSpacing::kTrailing
                                        : (spacing == "leading" ? TimestepSpacing::kLeading : TimestepSpacing::kLinspace);
    cfg.steps_offset = jc["steps_offset"];
    const int steps = c["steps"];
    const EulerAncestralScheduler s(cfg, steps);
    EXPECT_NEAR(s.alphas_cumprod().front(), c["alphas_cumprod_first"].get<double>(), 1e-15);
    EXPECT_NEAR(s.alphas_cumprod().back() / c["alphas_cumprod_last"].get<double>(), 1.0, 1e-12);
    ASSERT_EQ(s.timesteps().size(), c["timesteps"].size());
    for (int i = 0; i < steps; ++i) EXPECT_EQ(s.timesteps()[i], c["timesteps"][i].get<double>()) << i;
    for (int i = 0; i <= steps; ++i) EXPECT_NEAR(s.sigmas()[i], c["sigmas"][i].get<double>(), 1e-9 * (1 + s.sigmas()[i]));
    EXPECT_NEAR(s.init_noise_sigma(), c["init_noise_sigma"].get<double>(), 1e-9);

    const size_t n = c["size"];
    const float guidance = c["guidance"];
    GaussianNoise noise(c["seed"]);
    std::vector<float> x = noise.Draw(n);
    for (float& v : x) v = static_cast<float>(v * s.init_noise_sigma());
    std::vector<float> vc(n), vu(n), eps(n);
    for (int i = 0; i < steps; ++i) {
      const double t = s.timesteps()[i];
      for (size_t k = 0; k < n; ++k) {
        const auto x_in = static_cast<float>(x[k] * s.input_scale(i));
        vc[k] = ModelV(x_in, t, k, true);
        vu[k] = ModelV(x_in, t, k, false);
      }
      if (guidance > 1) ApplyGuidance(vu, vc, guidance, vc);
      noise.Fill(eps);
      s.Step(i, vc, x, eps);
    }
    double max_rel = 0;
    for (size_t k = 0; k < n; ++k) {
      const double expected = c["final"][k];
      max_rel = std::max(max_rel, std::abs(x[k] - expected) / std::max(1.0, std::abs(expected)));
    }
    EXPECT_LT(max_rel, 1e-4);
    RecordProperty(c["name"].get<std::string>() + "_max_rel_error", std::to_string(max_rel));
    std::printf("%s: max relative error vs numpy %.3g\n", c["name"].get<std::string>().c_str(), max_rel);
  }
}

}  // namespace
}  // namespace sd::models
