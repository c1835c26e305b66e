#!/usr/bin/python3
"""Builds the tiny TorchScript models the segmentation tests run (python3-torch; no weights needed).

seg_tiny.pt honours the "segmentation" contract with input_size 64: a per-pixel colour rule (object = red more
than blue, with green near its 0..1 value) plus a small fixed random 3x3 convolution, so channel order, the 0..1
input range, NCHW layout and flips all change its answer. The C++ test checks the stage against the rule on
images of other sizes (resizing) and against this module's own output on a 64x64 reference (no resizing).
The other files break one thing each. Usage: make_segmentation_test_models.py OUT_DIR
"""
import os
import sys

import torch

from raw_tensors import write_raw  # noqa: E402  (beside this script)

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.realpath(__file__))))  # tools/
from synthdrive_contract import contract, save_scripted, tensor_spec  # noqa: E402

SIZE = 64
SOURCE = "tools/testing/make_segmentation_test_models.py"


def seg_contract(name, stage="segmentation", size=SIZE, out_range=(0, 1), in_shape=None):
    return contract(stage, name, [tensor_spec("image", in_shape or [1, 3, size, size], (0, 1), "NCHW", "srgb")],
                    [tensor_spec("mask", [1, 1, size, size], out_range, "NCHW", "linear")], {"input_size": size},
                    SOURCE, "Apache-2.0")


class ColourRule(torch.nn.Module):
    def __init__(self, scale=1.0):
        super().__init__()
        self.conv = torch.nn.Conv2d(3, 1, 3, padding=1, bias=False)
        with torch.no_grad():
            self.conv.weight.mul_(0.5)
        self.scale = scale

    def forward(self, x):
        r, g, b = x[:, 0:1], x[:, 1:2], x[:, 2:3]
        return self.scale * torch.sigmoid(20.0 * (r - b) + 10.0 * (0.5 - g) + self.conv(x))


class Empty(torch.nn.Module):
    def forward(self, x):
        return torch.zeros_like(x[:, 0:1])


def main():
    out = sys.argv[1]
    os.makedirs(out, exist_ok=True)
    torch.manual_seed(3)
    rule = ColourRule().eval()
    save_scripted(rule, os.path.join(out, "seg_tiny.pt"), seg_contract("seg-tiny"))
    scaled = ColourRule(255.0).eval()
    scaled.load_state_dict(rule.state_dict())
    save_scripted(scaled, os.path.join(out, "seg_tiny_255.pt"), seg_contract("seg-tiny-255", out_range=(0, 255)))
    save_scripted(Empty(), os.path.join(out, "seg_empty.pt"), seg_contract("seg-empty"))
    save_scripted(rule, os.path.join(out, "seg_wrong_stage.pt"), seg_contract("seg-tiny", stage="super_resolution"))
    save_scripted(rule, os.path.join(out, "seg_any_size.pt"), seg_contract("seg-any", in_shape=[1, 3, -1, -1]))
    # Reference: an 8-bit 64x64 image (object block + noise), HWC, and the module's mask on it.
    g = torch.Generator().manual_seed(11)
    img = torch.empty(SIZE, SIZE, 3)
    img[..., 0], img[..., 1], img[..., 2] = 0.3, 0.3, 0.8
    img[12:40, 20:52] = torch.tensor([0.9, 0.3, 0.1])
    img = (img + 0.15 * torch.rand(SIZE, SIZE, 3, generator=g)).clamp(0, 1)
    u8 = (img * 255).round().to(torch.uint8)
    x = (u8.to(torch.float32) / 255.0).permute(2, 0, 1).unsqueeze(0)
    with torch.no_grad():
        y = rule(x)
    write_raw(os.path.join(out, "seg_ref_input.u8"), u8.numpy(), "u1")
    write_raw(os.path.join(out, "seg_ref_mask.f32"), y[0, 0].numpy(), "<f4")
    print(f"make_segmentation_test_models: wrote 5 models and a reference pair to {out}")


if __name__ == "__main__":
    main()
