#!/usr/bin/python3
"""Builds tiny TorchScript modules with the multi-view diffusion contracts (src/models/multiview_diffusion.h)
for the C++ tests (python3-torch; no weights needed).

  diffusion/            a tiny encoder, UNet and decoder: every output depends on every input, per sample, so the
                        C++ loop is checked for wiring, batching, determinism and ranges
  oracle/               the same encoder and decoder with an "oracle" UNet whose v-prediction always denoises
                        to a known constant latent C, so the final image is known in closed form (it checks
                        Zero123++'s latent/image scaling); oracle.json holds C, the decoder weights and scaling
  missing_two/          only the encoder
  wrong_stage/          the UNet file saved under the encoder's name
  reference_grid.f32    the whole Generate loop for diffusion/ replayed in Python from the documented contracts
                        (noise order, reference-latent noising, input scaling, CFG row order, Zero123++ scaling;
                        the sampler from scheduler_reference.py), for one object image both sides synthesise
Usage: make_diffusion_test_models.py OUT_DIR
"""
import json
import os
import shutil
import sys

import numpy as np
import torch

from raw_tensors import write_raw  # noqa: E402  (beside this script)
import torch.nn.functional as F

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import scheduler_reference as sr  # noqa: E402  (the independent sampler + noise replay)
sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.realpath(__file__))))  # tools/
from synthdrive_contract import contract, save_scripted, tensor_spec  # noqa: E402

T = 1000
BETA_START, BETA_END = 0.00085, 0.012
SCALING_FACTOR = 0.18215
EMBED_LEN, EMBED_DIM = 4, 8
SOURCE, LICENSE = "tools/testing/make_diffusion_test_models.py", "Apache-2.0"
ANY = (-1e9, 1e9)  # the range of tensors the contracts leave unbounded (no layout stated either)

ENCODER_CONTRACT = contract(
    "mv_image_encoder", "tiny-mv-encoder",
    [tensor_spec("image", [1, 3, -1, -1], (0, 1), encoding="srgb")],
    [tensor_spec("cond_embeds", [2, -1, -1], ANY), tensor_spec("ref_latents", [2, 4, -1, -1], ANY)], {},
    SOURCE, LICENSE)
UNET_PARAMS = {"num_train_timesteps": T, "beta_start": BETA_START, "beta_end": BETA_END, "beta_schedule": 0,
               "timestep_spacing": 0, "steps_offset": 1, "v_prediction": 1}
UNET_INPUTS = [tensor_spec("latents", [-1, 4, -1, -1], ANY), tensor_spec("timestep", [-1], ANY),
               tensor_spec("encoder_hidden_states", [-1, -1, -1], ANY),
               tensor_spec("ref_latents", [-1, 4, -1, -1], ANY)]
DECODER_CONTRACT = contract(
    "mv_vae_decoder", "tiny-mv-decoder", [tensor_spec("latents", [-1, 4, -1, -1], ANY)],
    [tensor_spec("image", [-1, 3, -1, -1], (-1, 1))], {"scale_factor": 8, "scaling_factor": SCALING_FACTOR},
    SOURCE, LICENSE)


class TinyEncoder(torch.nn.Module):
    """Resizes to 320 like the real preprocessors, 'VAE-encodes' by 8x8 pooling + 1x1 conv, embeds the mean colour."""

    def __init__(self):
        super().__init__()
        self.to_latent = torch.nn.Conv2d(3, 4, 1)
        self.embed = torch.nn.Linear(3, EMBED_DIM)
        self.uncond = torch.nn.Parameter(torch.randn(1, EMBED_LEN, EMBED_DIM) * 0.5)
        self.ramp = torch.nn.Parameter(torch.linspace(0.0, 1.0, EMBED_LEN).reshape(1, EMBED_LEN, 1))

    def latent(self, x):
        return self.to_latent(F.avg_pool2d(x, 8))

    def forward(self, image):
        x = F.interpolate(image, size=(320, 320), mode="bilinear", align_corners=False)
        x = (x - 0.5) / 0.5
        ref = torch.cat([self.latent(torch.zeros_like(x)), self.latent(x)], 0)
        glob = self.embed(x.mean(dim=(2, 3))).unsqueeze(1)  # [1, 1, D]
        embeds = torch.cat([self.uncond, self.uncond + self.ramp * glob], 0)
        return embeds, ref


class TinyUNet(torch.nn.Module):
    """Per-sample: a conv of the latents plus terms from the timestep, the embeddings and the reference latents."""

    def __init__(self):
        super().__init__()
        self.conv = torch.nn.Conv2d(4, 4, 3, padding=1)
        self.from_embed = torch.nn.Linear(EMBED_DIM, 4)
        self.from_ref = torch.nn.Conv2d(4, 4, 1)

    def forward(self, latents, timestep, encoder_hidden_states, ref_latents):
        h, w = latents.shape[2], latents.shape[3]
        e = self.from_embed(encoder_hidden_states.mean(dim=1))[:, :, None, None]
        r = F.interpolate(self.from_ref(ref_latents), size=(h, w), mode="nearest")
        t = torch.cos(timestep * 0.003)[:, None, None, None]
        return 0.2 * self.conv(latents) + 0.3 * e + 0.2 * r + 0.1 * t


class OracleUNet(torch.nn.Module):
    """The exact v of a sample whose clean latent is C: x_in = a·C + s·ε with a = sqrt(ᾱ_t), s = sqrt(1 − ᾱ_t),
    so ε = (x_in − a·C)/s and v = a·ε − s·C. The sampler's x̂0 is then C at every step, whatever the noise."""

    def __init__(self, target):
        super().__init__()
        betas = torch.linspace(BETA_START, BETA_END, T, dtype=torch.float64)
        self.register_buffer("alphas_cumprod", torch.cumprod(1.0 - betas, 0))
        self.register_buffer("target", torch.tensor(target, dtype=torch.float64).reshape(1, 4, 1, 1))

    def forward(self, latents, timestep, encoder_hidden_states, ref_latents):
        ac = self.alphas_cumprod[timestep.round().long()][:, None, None, None]
        a, s = ac.sqrt(), (1.0 - ac).sqrt()
        x = latents.double()
        eps = (x - a * self.target) / s
        return (a * eps - s * self.target).float()


class TinyDecoder(torch.nn.Module):
    """A 1x1 conv (known weights) then nearest x8: the raw 'VAE' output is W·z + b per pixel."""

    def __init__(self):
        super().__init__()
        self.conv = torch.nn.Conv2d(4, 3, 1)

    def forward(self, latents):
        return F.interpolate(self.conv(latents), scale_factor=8.0, mode="nearest")


def reference_object():
    """The 96x80 RGB object image the C++ test synthesises the same way."""
    y, x, c = np.meshgrid(np.arange(80), np.arange(96), np.arange(3), indexing="ij")
    return ((x * 7 + y * 3 + c * 50) % 256).astype(np.uint8)  # [H, W, 3]


def reference_generate(encoder, unet, decoder, obj, steps, guidance, seed):
    """MultiViewGenerator::GenerateGrid, from multiview_diffusion.h's contract text (not from the C++ code)."""
    h, w = obj.shape[:2]
    side = max(h, w)
    cond = np.full((side, side, 3), np.float32(127) / np.float32(255), dtype=np.float32)
    cond[(side - h) // 2:(side - h) // 2 + h, (side - w) // 2:(side - w) // 2 + w] = obj.astype(np.float32) / np.float32(255)
    with torch.no_grad():
        embeds, ref = encoder(torch.from_numpy(cond.transpose(2, 0, 1)[None].copy()))
    cfg = {"num_train_timesteps": T, "beta_start": BETA_START, "beta_end": BETA_END, "beta_schedule": "linear",
           "spacing": "trailing", "steps_offset": 1}
    ac = sr.alphas_cumprod(cfg)
    ts = sr.timesteps_for(cfg, steps)
    sigmas = np.concatenate([np.interp(ts, np.arange(T), np.sqrt((1 - ac) / ac)), [0.0]])
    noise = sr.Gaussian(seed)
    shape = (1, 4, 120, 80)
    n = int(np.prod(shape))
    x = noise.draw(n).reshape(shape) * sigmas.max()
    rows = [0, 1] if guidance > 1 else [1]
    for i in range(steps):
        s, s_next = sigmas[i], sigmas[i + 1]
        scale = 1.0 / np.sqrt(s * s + 1.0)
        refs_in = []
        for r in rows:
            eps = noise.draw(ref[r].numel()).reshape(tuple(ref[r:r + 1].shape))
            refs_in.append(torch.from_numpy(((ref[r:r + 1].double().numpy() + s * eps) * scale).astype(np.float32)))
        lat_in = torch.from_numpy((x * scale).astype(np.float32))
        with torch.no_grad():
            vs = [unet(lat_in, torch.tensor([float(ts[i])]), embeds[r:r + 1], refs_in[k]).double().numpy()
                  for k, r in enumerate(rows)]
        v = vs[0] + guidance * (vs[1] - vs[0]) if guidance > 1 else vs[0]
        x0 = x / (s * s + 1.0) - v * s / np.sqrt(s * s + 1.0)
        up = np.sqrt(s_next ** 2 * (s ** 2 - s_next ** 2) / s ** 2)
        down = np.sqrt(s_next ** 2 - up ** 2)
        x = x + (x - x0) / s * (down - s) + up * noise.draw(n).reshape(shape)
    z = torch.from_numpy(((x / 0.75 + 0.22) / SCALING_FACTOR).astype(np.float32))
    with torch.no_grad():
        raw = decoder(z).double()
    return (raw / 0.5 * 0.8 / 2 + 0.5).clamp(0, 1).float()


def main():
    out = sys.argv[1]
    torch.manual_seed(11)
    encoder, unet, decoder = TinyEncoder().eval(), TinyUNet().eval(), TinyDecoder().eval()
    with torch.no_grad():
        # Small enough that the oracle's image stays inside 0..1 after Zero123++'s unscaling (no clamping).
        decoder.conv.weight.copy_(0.2 * torch.tensor([[0.5, -0.25, 0.1, 0.0], [0.0, 0.3, -0.2, 0.1],
                                                      [-0.1, 0.0, 0.2, 0.4]]).reshape(3, 4, 1, 1))
        decoder.conv.bias.copy_(torch.tensor([0.05, -0.1, 0.0]))
    target = [0.1, -0.3, 0.25, 0.05]
    unet_contract = contract("mv_unet", "tiny-mv-unet", UNET_INPUTS, [tensor_spec("v", [-1, 4, -1, -1], ANY)],
                             UNET_PARAMS, SOURCE, LICENSE)
    for sub in ("diffusion", "oracle", "missing_two", "wrong_stage"):
        shutil.rmtree(os.path.join(out, sub), ignore_errors=True)
        os.makedirs(os.path.join(out, sub))
    d = os.path.join(out, "diffusion")
    save_scripted(encoder, os.path.join(d, "zero123plus_image_encoder.pt"), ENCODER_CONTRACT)
    save_scripted(unet, os.path.join(d, "zero123plus_unet.pt"), unet_contract)
    save_scripted(decoder, os.path.join(d, "zero123plus_vae_decoder.pt"), DECODER_CONTRACT)
    o = os.path.join(out, "oracle")
    save_scripted(encoder, os.path.join(o, "zero123plus_image_encoder.pt"), ENCODER_CONTRACT)
    save_scripted(OracleUNet(target), os.path.join(o, "zero123plus_unet.pt"),
                  dict(unet_contract, name="oracle-mv-unet"))
    save_scripted(decoder, os.path.join(o, "zero123plus_vae_decoder.pt"), DECODER_CONTRACT)
    with open(os.path.join(out, "oracle.json"), "w") as f:
        json.dump({"target": target, "weight": decoder.conv.weight.reshape(3, 4).tolist(),
                   "bias": decoder.conv.bias.tolist(), "scaling_factor": SCALING_FACTOR}, f)
    save_scripted(encoder, os.path.join(out, "missing_two", "zero123plus_image_encoder.pt"), ENCODER_CONTRACT)
    w = os.path.join(out, "wrong_stage")
    save_scripted(unet, os.path.join(w, "zero123plus_image_encoder.pt"), unet_contract)
    save_scripted(unet, os.path.join(w, "zero123plus_unet.pt"), unet_contract)
    save_scripted(decoder, os.path.join(w, "zero123plus_vae_decoder.pt"), DECODER_CONTRACT)
    grid = reference_generate(encoder, unet, decoder, reference_object(), steps=3, guidance=3.0, seed=21)
    write_raw(os.path.join(out, "reference_grid.f32"), grid)
    print(f"make_diffusion_test_models: wrote the tiny multi-view diffusion models to {out}")


if __name__ == "__main__":
    main()
