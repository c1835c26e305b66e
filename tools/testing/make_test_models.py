#!/usr/bin/python3
"""Builds the tiny TorchScript models the C++ tests of src/models run (python3-torch; no weights needed).

Each model honours (or, for the error cases, deliberately breaks) a SynthDrive stage contract, so the C++ side
is checked end to end -- loading, contract checks, tensor layout and ranges, tiling -- without real weights.
Usage: make_test_models.py OUT_DIR
"""
import os
import sys

import torch

from raw_tensors import write_raw  # noqa: E402  (beside this script)
import torch.nn.functional as F

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.realpath(__file__))))  # tools/
from synthdrive_contract import contract, save_scripted, tensor_spec  # noqa: E402

SOURCE = "tools/testing/make_test_models.py"


def sr_contract(stage, name, scale, radius, in_range=(0, 255)):
    image = tensor_spec("image", [-1, 3, -1, -1], in_range, "NCHW", "srgb")
    return contract(stage, name, [image], [dict(image)], {"scale": scale, "receptive_radius": radius}, SOURCE,
                    "Apache-2.0")


class TinyUpscaler(torch.nn.Module):
    """conv3 -> relu -> conv3 -> nearest x2 -> conv3: receptive radius 1 + 1 + 1/2 = 2.5 input pixels."""

    def __init__(self):
        super().__init__()
        self.a = torch.nn.Conv2d(3, 8, 3, padding=1)
        self.b = torch.nn.Conv2d(8, 8, 3, padding=1)
        self.c = torch.nn.Conv2d(8, 3, 3, padding=1)

    def forward(self, x):
        y = self.b(F.relu(self.a(x / 255.0)))
        y = F.interpolate(y, scale_factor=2.0, mode="nearest")
        # Residual on the nearest-upsampled input keeps outputs near the input's range, like a real upscaler.
        return 255.0 * (self.c(y) * 0.1) + F.interpolate(x, scale_factor=2.0, mode="nearest")


class Identity(torch.nn.Module):
    def forward(self, x):
        return x


def main():
    out = sys.argv[1]
    os.makedirs(out, exist_ok=True)
    torch.manual_seed(7)
    model = TinyUpscaler().eval()
    save_scripted(model, os.path.join(out, "sr_tiny_x2.pt"), sr_contract("super_resolution", "sr-tiny-x2", 2, 2.5))
    save_scripted(Identity(), os.path.join(out, "no_contract.pt"), None)
    save_scripted(model, os.path.join(out, "wrong_stage.pt"), sr_contract("clip_image", "clip-tiny", 2, 2.5))
    save_scripted(Identity(), os.path.join(out, "not_upscaling.pt"),
                  sr_contract("super_resolution", "sr-identity", 2, 0))
    # A reference pair from the eager module on one whole image: the C++ side must reproduce it tile by tile.
    x = torch.rand(1, 3, 45, 70) * 255.0
    with torch.no_grad():
        y = model(x)
    write_raw(os.path.join(out, "sr_tiny_x2_input.f32"), x)
    write_raw(os.path.join(out, "sr_tiny_x2_output.f32"), y)
    print(f"make_test_models: wrote 4 models and a reference pair to {out}")


if __name__ == "__main__":
    main()
