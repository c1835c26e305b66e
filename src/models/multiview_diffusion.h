#pragma once
// The multi-view diffusion stage (DESIGN.md generate): one object image → 6 views at the Zero123++ v1.2 rig,
// 320×320 each. The denoising loop, the sampler (models/scheduler.h) and Zero123++'s latent/image scaling run
// here in C++; the networks are three TorchScript modules, each carrying its contract (runtime.h), exported
// from the diffusers pipeline by tools/export/export_zero123plus.py. docs/models.md has the details.
//
// Files, in one directory (MultiViewGenerator::Load):
//   zero123plus_image_encoder.pt   stage "mv_image_encoder"
//   zero123plus_unet.pt            stage "mv_unet"
//   zero123plus_vae_decoder.pt     stage "mv_vae_decoder"
//
// Contract "mv_image_encoder": everything that depends only on the condition image, run once.
//   input  "image":        [1, 3, S, S] float32, RGB, sRGB-encoded 0..1, the object on Zero123++'s grey
//                          (127/255) background; the module resizes/normalises it itself (both CLIP and VAE
//                          preprocessors live inside, so the C++ side never has to match PIL's resampling)
//   output "cond_embeds":  [2, L, D] the UNet's encoder_hidden_states; row 0 unconditional (the empty-prompt
//                          text embedding, what diffusers' CFG uses), row 1 conditional (the same + the
//                          pipeline's ramping_coefficients × the CLIP image embedding)
//   output "ref_latents":  [2, 4, h_r, w_r] VAE latents for reference attention, not scaled (the pipeline
//                          feeds vae.encode(...).latent_dist straight through); row 0 of an all-zero (normalised)
//                          image — the pipeline's negative_lat —, row 1 of the condition image. The exporter
//                          uses the posterior mean (the pipeline samples it; its std is negligible) so the
//                          module is deterministic.
// Contract "mv_unet": one denoiser evaluation; no randomness inside (the pipeline's RefOnlyNoisedUNet draws
//   the reference-latent noise itself; here C++ draws it from the seeded generator and passes it noised).
//   input  "latents":      [N, 4, h, w] x · 1/sqrt(σ² + 1) (the scheduler's scaled model input)
//   input  "timestep":     [N] float32, the training timestep t (0..T−1)
//   input  "encoder_hidden_states": [N, L, D] rows of cond_embeds
//   input  "ref_latents":  [N, 4, h_r, w_r] (ref + σ·ε) / sqrt(σ² + 1), ε fresh standard normal per step
//   output "v":            [N, 4, h, w] v-prediction
//   params: "num_train_timesteps", "beta_start", "beta_end", "beta_schedule" (0 linear, 1 scaled_linear),
//           "timestep_spacing" (0 trailing, 1 leading, 2 linspace), "steps_offset", "v_prediction" (must be 1)
//           — copied from the pipeline's scheduler config by the exporter, so the schedule is never guessed.
// Contract "mv_vae_decoder": the plain diffusers vae.decode.
//   input  "latents":      [N, 4, h, w] VAE latents (already unscaled, see below)
//   output "image":        [N, 3, f·h, f·w] the VAE's raw output, nominally −1..1
//   params: "scale_factor" (f = 8), "scaling_factor" (vae.config.scaling_factor, 0.18215 for SD 2's VAE)
//
// Zero123++'s scaling (pipeline.py: unscale_latents / unscale_image), applied here exactly:
//   z = (x / 0.75 + 0.22) / scaling_factor;  img = vae.decode(z) / 0.5 · 0.8;  rgb = clamp(img / 2 + 0.5, 0, 1)
// The grid is 640 wide × 960 high (3 rows × 2 columns of 320²), latents 80 × 120. Views are cut row-major:
//   (row 0, col 0) azimuth  30° elevation +20°   (row 0, col 1)  90° −10°
//   (row 1, col 0)        150°           +20°   (row 1, col 1) 210° −10°
//   (row 2, col 0)        270°           +20°   (row 2, col 1) 330° −10°
// which is the order of assetgen's Zero123PlusPlusRig().
//
// Noise, from one GaussianNoise(seed) stream in this order: the initial latents (×init_noise_sigma); then per
// step: ε for ref_latents (the rows in batch order: uncond first when guidance is on), then the ancestral ε.
// Guidance > 1 runs classifier-free guidance (uncond + g·(cond − uncond)), as diffusers does; 0 ≤ g ≤ 1 runs
// the conditional branch alone.
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <vector>

#include "core/image.h"
#include "models/runtime.h"
#include "models/scheduler.h"

namespace sd::models {

constexpr const char* kMvImageEncoderStage = "mv_image_encoder";
constexpr const char* kMvUnetStage = "mv_unet";
constexpr const char* kMvVaeDecoderStage = "mv_vae_decoder";
constexpr const char* kMvImageEncoderFile = "zero123plus_image_encoder.pt";
constexpr const char* kMvUnetFile = "zero123plus_unet.pt";
constexpr const char* kMvVaeDecoderFile = "zero123plus_vae_decoder.pt";

constexpr int kMultiViewCount = 6;
constexpr int kMultiViewSize = 320;
constexpr int kMultiViewGridRows = 3, kMultiViewGridCols = 2;
// pipeline.py's scale_latents / unscale_latents and scale_image / unscale_image constants.
constexpr double kZero123LatentShift = 0.22, kZero123LatentScale = 0.75;
constexpr double kZero123ImageScale = 0.5 / 0.8;  // scale_image multiplies by this, unscale_image divides
// The grey the pipeline composites RGBA inputs onto (to_rgb_image: 127).
constexpr uint8_t kZero123Background = 127;

struct MultiViewOptions {
  // Run the unconditional and conditional branches of guidance as one batch of 2 (faster on a GPU); false runs
  // them one at a time (less memory). Both give the same result.
  bool batched_guidance = true;
};

class MultiViewGenerator {
 public:
  // Loads the three files from `dir`. InputError naming every missing file and what it must contain, or
  // naming a file with the wrong stage, or a UNet contract without a usable schedule.
  static MultiViewGenerator Load(const std::filesystem::path& dir, const RuntimeOptions& runtime = {},
                                 const MultiViewOptions& options = {});

  MultiViewGenerator(MultiViewGenerator&&) noexcept;
  MultiViewGenerator& operator=(MultiViewGenerator&&) noexcept;
  ~MultiViewGenerator();

  const SchedulerConfig& scheduler_config() const { return scheduler_config_; }
  std::string Describe() const;

  // The 6 views (320×320 RGB, rig order above) of the object in `object_image` (RGB or RGBA, any size; it is
  // padded to a square on the grey background). InputError for an empty image, steps < 1 (or more than the
  // schedule has), guidance < 0.
  std::vector<ImageU8> Generate(const ImageU8& object_image, int steps = kZero123PlusDefaultSteps,
                                float guidance = kZero123PlusDefaultGuidance, uint64_t seed = 0) const;
  // The same, as the 640×960 grid Zero123++ produces (3 rows × 2 columns), values 0..1.
  ImageF GenerateGrid(const ImageU8& object_image, int steps, float guidance, uint64_t seed) const;

 private:
  struct Models;
  MultiViewGenerator(std::unique_ptr<Models> models, SchedulerConfig scheduler, MultiViewOptions options);

  std::unique_ptr<Models> models_;
  SchedulerConfig scheduler_config_;
  MultiViewOptions options_;
};

// Cuts a 640×960 grid into the 6 views in rig order (row-major), each 320×320.
std::vector<ImageF> SplitMultiViewGrid(const ImageF& grid);
// The object as the encoder takes it: alpha composited onto grey 127, padded to a square with the same grey.
ImageF Zero123ConditionImage(const ImageU8& object_image);

}  // namespace sd::models
