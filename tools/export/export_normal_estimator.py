#!/usr/bin/env python3
"""Exports a monocular surface-normal estimator to the SynthDrive "normal_estimation" contract
(src/models/normal_estimation.h).

NOT RUN IN THIS REPOSITORY'S CI: it needs the network's code and weights from torch.hub (network access),
which the build machine does not have. Written against the published torch.hub entry point of the model below;
treat the frame flags as the part to verify by eye on the first run (see "Checking the frame").

Model: Omnidata v2 surface normals, DPT-Hybrid 384 (Eftekhar et al., ICCV 2021; Kar et al., CVPR 2022),
  torch.hub.load("alexsax/omnidata_models", "surface_normal_dpt_hybrid_384"), weights on Hugging Face
  (sashasax/omnidata_normal_dpt_hybrid_384). Licence: the Omnidata code and weights are released for
  non-commercial research use (check the repository before shipping them).
  Its inputs are RGB 0..1 without mean/std normalisation at 384 x 384 (patch 16: any multiple of 32 works for
  the DPT-Hybrid backbone, which we declare as params.multiple), its output is (n + 1) / 2 in 0..1.

Contract written (normal_estimation): image [N, 3, H, W] sRGB 0..1 -> normals [N, 3, H, W] in OpenCV's camera
frame (x right, y down, z forward; surfaces facing the camera have z < 0). The wrapper maps the network's
output to -1..1 and applies the axis signs of --frame:
  --frame opencv   the network already predicts x right, y down, z forward        -> signs (+1, +1, +1)
  --frame opengl   x right, y up, z towards the viewer (most normal-map renderers) -> signs (+1, -1, -1)
Omnidata's released models predict in the OpenGL-style frame (a wall facing the camera comes out bluish,
rgb ~ (0.5, 0.5, 1)), hence the default --frame opengl.

Checking the frame: run the exported model (synthdrive views ... or the C++ NormalEstimator) on a photo with
a floor and a frontal wall: the floor must come out near (0, -1, 0) (up is -y in OpenCV) and the wall near
(0, 0, -1). A wrong sign shows at once.
Usage: export_normal_estimator.py OUT.pt [--frame opengl|opencv] [--size 384]
"""
import argparse
import os
import sys

import torch
import torch.nn.functional as F

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.realpath(__file__))))  # tools/
from synthdrive_contract import contract, save_scripted, tensor_spec  # noqa: E402


class NormalWrapper(torch.nn.Module):
    def __init__(self, net, signs):
        super().__init__()
        self.net = net
        self.register_buffer("signs", torch.tensor(signs, dtype=torch.float32).view(1, 3, 1, 1))

    def forward(self, image):
        out = self.net(image)                 # [N, 3, H, W], (n + 1) / 2
        n = (out.clamp(0.0, 1.0) * 2.0 - 1.0) * self.signs
        return F.normalize(n, dim=1)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("out")
    ap.add_argument("--frame", choices=["opengl", "opencv"], default="opengl")
    ap.add_argument("--size", type=int, default=384, help="trace size (a multiple of 32)")
    args = ap.parse_args()
    if args.size % 32:
        sys.exit("export_normal_estimator: --size must be a multiple of 32")

    net = torch.hub.load("alexsax/omnidata_models", "surface_normal_dpt_hybrid_384").float().eval()
    signs = (1.0, 1.0, 1.0) if args.frame == "opencv" else (1.0, -1.0, -1.0)
    wrapper = NormalWrapper(net, signs).eval()
    # Traced at one size; DPT interpolates its position embeddings, so other multiples of 32 run too — the
    # self-check below runs a second size to make sure the trace did not freeze the shape.
    with torch.no_grad():
        traced = torch.jit.trace(wrapper, torch.rand(1, 3, args.size, args.size), check_trace=False)
        errs = []
        for h, w in [(args.size, args.size), (256, 320)]:
            x = torch.rand(1, 3, h, w)
            errs.append(float((traced(x) - wrapper(x)).abs().max()))
    if max(errs) > 1e-4:
        sys.exit(f"export_normal_estimator: traced module differs from eager ({errs}); export at a fixed size")

    doc = contract(
        "normal_estimation", "omnidata-normal-dpt-hybrid-384",
        [tensor_spec("image", [-1, 3, -1, -1], (0, 1), "NCHW", "srgb")],
        [tensor_spec("normals", [-1, 3, -1, -1], (-1, 1), "NCHW", "camera_opencv")], {"multiple": 32},
        "torch.hub alexsax/omnidata_models surface_normal_dpt_hybrid_384",
        "Omnidata (non-commercial research; see the repository)",
        exporter="tools/export/export_normal_estimator.py",
        verification={"max_abs_diff_vs_eager": max(errs), "frame_signs_y": signs[1], "frame_signs_z": signs[2]})
    save_scripted(traced, args.out, doc)
    print(f"export_normal_estimator: wrote {args.out} (frame {args.frame}, max |diff| vs eager {max(errs):.2e})")


if __name__ == "__main__":
    main()
