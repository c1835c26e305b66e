#!/usr/bin/python3
"""Builds the tiny TorchScript models the segmentation tests run (python3-torch; no weights needed).

seg_tiny.pt honours the "segmentation" contract with input_size 64: a per-pixel colour rule (object = red more
than blue, with green near its 0..1 value) plus a small fixed random 3x3 convolution, so channel order, the 0..1
input range, NCHW layout and flips all change its answer. The C++ test checks the stage against the rule on
images of other sizes (resizing) and against this module's own output on a 64x64 reference (no resizing).
The other files break one thing each. Usage: make_segmentation_test_models.py OUT_DIR
"""
import json
import os
import sys

import torch

from raw_tensors import write_raw  # noqa: E402  (beside this script)

SIZE = 64


def contract(name, stage="segmentation", size=SIZE, out_range=(0, 1), in_shape=None):
    return {"format": "synthdrive-model/1", "stage": stage, "name": name,
            "source": "tools/testing/make_segmentation_test_models.py", "license": "Apache-2.0",
            "inputs": [{"name": "image", "shape": in_shape or [1, 3, size, size], "dtype": "float32",
                        "layout": "NCHW", "range": [0, 1], "encoding": "srgb"}],
            "outputs": [{"name": "mask", "shape": [1, 1, size, size], "dtype": "float32", "layout": "NCHW",
                         "range": list(out_range), "encoding": "linear"}],
            "params": {"input_size": size}}


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


def save(module, path, extra):
    torch.jit.save(torch.jit.script(module), path, _extra_files={"synthdrive_contract.json": json.dumps(extra)})


def main():
    out = sys.argv[1]
    os.makedirs(out, exist_ok=True)
    torch.manual_seed(3)
    rule = ColourRule().eval()
    save(rule, os.path.join(out, "seg_tiny.pt"), contract("seg-tiny"))
    scaled = ColourRule(255.0).eval()
    scaled.load_state_dict(rule.state_dict())
    save(scaled, os.path.join(out, "seg_tiny_255.pt"), contract("seg-tiny-255", out_range=(0, 255)))
    save(Empty(), os.path.join(out, "seg_empty.pt"), contract("seg-empty"))
    save(rule, os.path.join(out, "seg_wrong_stage.pt"), contract("seg-tiny", stage="super_resolution"))
    save(rule, os.path.join(out, "seg_any_size.pt"), contract("seg-any", in_shape=[1, 3, -1, -1]))
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
