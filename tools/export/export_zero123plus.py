#!/usr/bin/env python3
"""Exports Zero123++ v1.2 to the SynthDrive multi-view diffusion contracts (src/models/multiview_diffusion.h).

NOT RUN IN THIS REPOSITORY: it needs the real weights (Hugging Face "sudo-ai/zero123plus-v1.2", CC-BY-NC 4.0,
plus the custom pipeline "sudo-ai/zero123plus-pipeline", Apache-2.0) and diffusers + transformers, none of which
the build machine can reach. It was written against diffusers 0.20-0.27 (the authors recommend 0.20.2) and the
pipeline source in SUDO-AI-3D/zero123plus diffusers-support/pipeline.py. The C++ side (loop, scheduler, latent
scaling) was tested on tiny modules with the same contracts (tools/testing/make_diffusion_test_models.py); this
script checks what it writes against the eager modules and refuses to write a module that disagrees.

Writes, into OUT_DIR:
  zero123plus_image_encoder.pt   "mv_image_encoder": image [1,3,S,S] sRGB 0..1 on grey ->
                                 cond_embeds [2,77,1024] (row 0 uncond, row 1 cond), ref_latents [2,4,40,40]
  zero123plus_unet.pt            "mv_unet": latents [N,4,120,80], timestep [N], encoder_hidden_states [N,77,1024],
                                 ref_latents [N,4,40,40] (already noised + scaled by the caller) -> v [N,4,120,80]
  zero123plus_vae_decoder.pt     "mv_vae_decoder": latents [N,4,h,w] -> raw VAE image [N,3,8h,8w] (about -1..1)

Usage:
  export_zero123plus.py OUT_DIR [--model sudo-ai/zero123plus-v1.2] [--pipeline sudo-ai/zero123plus-pipeline]
                                [--timestep-spacing trailing]
Needs: torch >= 1.13, diffusers, transformers, accelerate; about 8 GB of RAM; a GPU is not needed.
"""
import argparse
import json
import os
import sys

import torch
import torch.nn.functional as F

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.realpath(__file__))))  # tools/
from synthdrive_contract import contract, save_scripted, tensor_spec  # noqa: E402

EXPORTER = "tools/export/export_zero123plus.py"
LICENSE = "CC-BY-NC-4.0 (weights), Apache-2.0 (pipeline code)"
GRID_W, GRID_H = 640, 960  # the pipeline's default width/height: 2 columns x 3 rows of 320
SPACING_CODES = {"trailing": 0, "leading": 1, "linspace": 2}
SCHEDULE_CODES = {"linear": 0, "scaled_linear": 1}


def processor_geometry(processor):
    """(resize shortest edge, crop height, crop width, mean, std, rescale) of a transformers CLIPImageProcessor;
    `size` is a dict {"shortest_edge": n} in transformers >= 4.26 and an int before."""
    size = processor.size
    short = size["shortest_edge"] if isinstance(size, dict) else int(size)
    crop = processor.crop_size
    if isinstance(crop, dict):
        ch, cw = crop["height"], crop["width"]
    else:
        ch = cw = int(crop)
    if not processor.do_center_crop:
        ch = cw = short
    rescale = processor.rescale_factor if getattr(processor, "do_rescale", True) else 1.0
    return short, ch, cw, list(processor.image_mean), list(processor.image_std), rescale


class Preprocess(torch.nn.Module):
    """CLIPImageProcessor in torch for a square input: bicubic resize (antialiased, as PIL's downscale is),
    centre crop, then (x * 255 * rescale - mean) / std. The input is 0..1, i.e. PIL's uint8 / 255."""

    def __init__(self, processor):
        super().__init__()
        short, ch, cw, mean, std, rescale = processor_geometry(processor)
        self.short, self.ch, self.cw = short, ch, cw
        self.scale = 255.0 * rescale
        self.register_buffer("mean", torch.tensor(mean, dtype=torch.float32).view(1, 3, 1, 1))
        self.register_buffer("std", torch.tensor(std, dtype=torch.float32).view(1, 3, 1, 1))

    def forward(self, image):
        x = F.interpolate(image, size=(self.short, self.short), mode="bicubic", align_corners=False, antialias=True)
        top = (self.short - self.ch) // 2
        left = (self.short - self.cw) // 2
        x = x[:, :, top:top + self.ch, left:left + self.cw]
        return (x.clamp(0.0, 1.0) * self.scale - self.mean) / self.std


class ImageEncoder(torch.nn.Module):
    """Everything of Zero123PlusPipeline.__call__ that depends only on the condition image:
      cond_lat      = vae.encode(feature_extractor_vae(image)).latent_dist  (mean here; the pipeline samples)
      negative_lat  = the same for torch.zeros_like(normalised image)       (only used when guidance > 1)
      global_embeds = vision_encoder(feature_extractor_clip(image)).image_embeds.unsqueeze(-2)
      cond hidden   = encode_prompt("") + global_embeds * ramping_coefficients[:, None]
      uncond hidden = encode_prompt("")  (StableDiffusionPipeline's negative prompt embedding of "")
    """

    def __init__(self, pipe, text_embeds):
        super().__init__()
        self.pre_vae = Preprocess(pipe.feature_extractor_vae)
        self.pre_clip = Preprocess(pipe.feature_extractor_clip)
        self.vae_encoder = pipe.vae.encoder
        self.quant_conv = pipe.vae.quant_conv
        self.vision = pipe.vision_encoder
        self.register_buffer("text", text_embeds.float())  # [1, 77, 1024]
        ramp = torch.tensor(pipe.config.ramping_coefficients, dtype=torch.float32).unsqueeze(-1)
        self.register_buffer("ramp", ramp)  # [77, 1]

    def vae_mean(self, x):
        # AutoencoderKL.encode: moments = quant_conv(encoder(x)); DiagonalGaussianDistribution.mean = first half.
        moments = self.quant_conv(self.vae_encoder(x))
        return torch.chunk(moments, 2, dim=1)[0]

    def forward(self, image):
        x_vae = self.pre_vae(image)
        ref = torch.cat([self.vae_mean(torch.zeros_like(x_vae)), self.vae_mean(x_vae)], 0)
        global_embeds = self.vision(self.pre_clip(image)).image_embeds.unsqueeze(-2)  # [1, 1, 1024]
        cond = self.text + global_embeds * self.ramp
        return torch.cat([self.text, cond], 0), ref


class UNet(torch.nn.Module):
    """RefOnlyNoisedUNet.forward without its randomness: the caller passes the reference latents already
    noised (add_noise with σ) and scaled (scale_model_input), so the module is a pure function. The first pass
    writes every attn1's keys/values into ref_dict (mode "w"), the second reads them (mode "r")."""

    def __init__(self, unet):
        super().__init__()
        self.unet = unet  # the diffusers UNet2DConditionModel with ReferenceOnlyAttnProc processors installed

    def forward(self, latents, timestep, encoder_hidden_states, ref_latents):
        ref_dict = {}
        self.unet(ref_latents, timestep, encoder_hidden_states=encoder_hidden_states,
                  cross_attention_kwargs=dict(mode="w", ref_dict=ref_dict), return_dict=False)
        return self.unet(latents, timestep, encoder_hidden_states=encoder_hidden_states,
                         cross_attention_kwargs=dict(mode="r", ref_dict=ref_dict), return_dict=False)[0]


class Decoder(torch.nn.Module):
    def __init__(self, vae):
        super().__init__()
        self.vae = vae

    def forward(self, latents):
        return self.vae.decode(latents, return_dict=False)[0]


def encode_empty_prompt(pipe):
    """The text embedding of "" exactly as StableDiffusionPipeline computes prompt and negative embeddings."""
    device = torch.device("cpu")
    if hasattr(pipe, "encode_prompt"):  # diffusers >= 0.22
        return pipe.encode_prompt("", device, 1, False)[0]
    return pipe._encode_prompt("", device, 1, False)


def max_diff(a, b):
    return float((a.float() - b.float()).abs().max())


def save(module, path, doc):
    save_scripted(module, path, doc)
    print(f"wrote {path}")


def main():
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("out_dir")
    ap.add_argument("--model", default="sudo-ai/zero123plus-v1.2")
    ap.add_argument("--pipeline", default="sudo-ai/zero123plus-pipeline")
    ap.add_argument("--timestep-spacing", default="trailing", choices=sorted(SPACING_CODES),
                    help="the README's recommendation is trailing (it overrides the scheduler config's value)")
    args = ap.parse_args()

    from diffusers import DiffusionPipeline  # imported late so --help works without diffusers

    torch.manual_seed(0)
    pipe = DiffusionPipeline.from_pretrained(args.model, custom_pipeline=args.pipeline, torch_dtype=torch.float32)
    pipe.to("cpu")
    # prepare() wraps the UNet in RefOnlyNoisedUNet and installs the reference-attention processors; we keep
    # the processors and drop the wrapper (its forward draws noise and uses the scheduler's step state).
    pipe.prepare()
    inner_unet = pipe.unet.unet if hasattr(pipe.unet, "unet") else pipe.unet
    inner_unet.eval()
    pipe.vae.eval()
    pipe.vision_encoder.eval()

    sched = dict(pipe.scheduler.config)
    if sched.get("prediction_type") != "v_prediction":
        sys.exit(f"expected a v_prediction scheduler, the pipeline says {sched.get('prediction_type')!r}")
    if sched.get("beta_schedule") not in SCHEDULE_CODES:
        sys.exit(f"unsupported beta_schedule {sched.get('beta_schedule')!r} (linear and scaled_linear are)")
    if sched.get("trained_betas") is not None:
        sys.exit("the scheduler has trained_betas; the C++ scheduler only computes linear/scaled_linear")
    print("scheduler config:", json.dumps({k: sched[k] for k in sorted(sched) if not k.startswith('_')}))
    unet_params = {"num_train_timesteps": int(sched["num_train_timesteps"]),
                   "beta_start": float(sched["beta_start"]), "beta_end": float(sched["beta_end"]),
                   "beta_schedule": SCHEDULE_CODES[sched["beta_schedule"]],
                   "timestep_spacing": SPACING_CODES[args.timestep_spacing],
                   "steps_offset": int(sched.get("steps_offset", 0)), "v_prediction": 1}
    vae_factor = 2 ** (len(pipe.vae.config.block_out_channels) - 1)
    scaling_factor = float(pipe.vae.config.scaling_factor)
    source = f"{args.model} with {args.pipeline} (diffusers)"
    os.makedirs(args.out_dir, exist_ok=True)

    with torch.no_grad():
        # --- encoder ---
        text = encode_empty_prompt(pipe)
        encoder = ImageEncoder(pipe, text).eval()
        probe = torch.rand(1, 3, 320, 320)
        embeds, ref = encoder(probe)
        traced_enc = torch.jit.trace(encoder, (probe,), check_trace=False)
        e2, r2 = traced_enc(torch.rand(1, 3, 512, 512))  # another size must work too (resize is inside)
        e1, r1 = traced_enc(probe)
        enc_diff = max(max_diff(e1, embeds), max_diff(r1, ref))
        if enc_diff > 1e-3 or e2.shape != embeds.shape or r2.shape != ref.shape:
            sys.exit(f"traced encoder disagrees with eager (max diff {enc_diff}, shapes {e2.shape} {r2.shape})")
        L, D = embeds.shape[1], embeds.shape[2]
        hr, wr = ref.shape[2], ref.shape[3]
        save(traced_enc, os.path.join(args.out_dir, "zero123plus_image_encoder.pt"), contract(
            "mv_image_encoder", "zero123plus-v1.2-encoder",
            [tensor_spec("image", [1, 3, -1, -1], (0, 1), "NCHW", "srgb")],
            [tensor_spec("cond_embeds", [2, L, D], (-1e4, 1e4)),
             tensor_spec("ref_latents", [2, 4, hr, wr], (-1e3, 1e3), "NCHW")],
            {"vae_image_size": processor_geometry(pipe.feature_extractor_vae)[1],
             "clip_image_size": processor_geometry(pipe.feature_extractor_clip)[1]},
            source, LICENSE, exporter=EXPORTER, verification={"trace_max_abs_diff": enc_diff}))

        # --- UNet (traced at batch 2, checked at batch 1 and 2) ---
        unet = UNet(inner_unet).eval()
        h, w = GRID_H // vae_factor, GRID_W // vae_factor
        lat = torch.randn(2, 4, h, w)
        t = torch.tensor([999.0, 999.0])
        ref_in = torch.randn(2, 4, hr, wr)
        v_eager = unet(lat, t, embeds, ref_in)
        traced_unet = torch.jit.trace(unet, (lat, t, embeds, ref_in), check_trace=False)
        unet_diff = max_diff(traced_unet(lat, t, embeds, ref_in), v_eager)
        t1 = torch.tensor([500.0])
        one_diff = max_diff(traced_unet(lat[1:], t1, embeds[1:], ref_in[1:]), unet(lat[1:], t1, embeds[1:], ref_in[1:]))
        if max(unet_diff, one_diff) > 1e-3:
            sys.exit(f"traced UNet disagrees with eager (batch 2: {unet_diff}, batch 1: {one_diff})")
        save(traced_unet, os.path.join(args.out_dir, "zero123plus_unet.pt"), contract(
            "mv_unet", "zero123plus-v1.2-unet",
            [tensor_spec("latents", [-1, 4, h, w], (-1e3, 1e3), "NCHW"), tensor_spec("timestep", [-1], (0, 1000)),
             tensor_spec("encoder_hidden_states", [-1, L, D], (-1e4, 1e4)),
             tensor_spec("ref_latents", [-1, 4, hr, wr], (-1e3, 1e3), "NCHW")],
            [tensor_spec("v", [-1, 4, h, w], (-1e3, 1e3), "NCHW")],
            unet_params, source, LICENSE, exporter=EXPORTER,
            verification={"trace_max_abs_diff_batch2": unet_diff, "trace_max_abs_diff_batch1": one_diff}))

        # --- VAE decoder ---
        dec = Decoder(pipe.vae).eval()
        z = torch.randn(1, 4, h, w)
        traced_dec = torch.jit.trace(dec, (z,), check_trace=False)
        dec_diff = max_diff(traced_dec(z), dec(z))
        if dec_diff > 1e-3:
            sys.exit(f"traced VAE decoder disagrees with eager ({dec_diff})")
        save(traced_dec, os.path.join(args.out_dir, "zero123plus_vae_decoder.pt"), contract(
            "mv_vae_decoder", "zero123plus-v1.2-vae-decoder",
            [tensor_spec("latents", [-1, 4, -1, -1], (-1e3, 1e3), "NCHW")],
            [tensor_spec("image", [-1, 3, -1, -1], (-1, 1), "NCHW", "srgb")],
            {"scale_factor": vae_factor, "scaling_factor": scaling_factor},
            source, LICENSE, exporter=EXPORTER, verification={"trace_max_abs_diff": dec_diff}))
    print("done; install the three files together (see docs/models.md)")


if __name__ == "__main__":
    main()
