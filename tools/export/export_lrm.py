#!/usr/bin/env python3
"""Exports OpenLRM (He & Wang, 3DTopia/OpenLRM, an open re-implementation of LRM, Hong et al. 2023) to the
SynthDrive "lrm_encoder" / "lrm_decoder" contracts (src/models/lrm.h).

NOT RUN IN THIS REPOSITORY'S CI: it needs the openlrm package (a checkout of github.com/3DTopia/OpenLRM on
PYTHONPATH, Apache-2.0 code) and its weights from the Hugging Face hub (network access), neither of which the
build machine has. It was written against OpenLRM v1.1's inference runner (openlrm/runners/infer/lrm.py):
  - the model: model_dict["lrm"] wrapped by openlrm.utils.hf_hub.wrap_model_hub, .from_pretrained(name);
  - triplanes: model.forward_planes(image [N, 3, S, S] 0..1, source_camera) -> [N, 3, C, R, R], with the
    runner's canonical source camera (extrinsics looking along +y from distance 2, intrinsics f = 0.75,
    c = 0.5, build_camera_principle);
  - fields: model.synthesizer.forward_points(planes, points [N, P, 3] in [-1, 1]^3) -> {"sigma", "rgb"};
    the runner meshes sigma at mesh_thres = 3.0.
Weights: zxhezexin/openlrm-mix-base-1.1 (source size 336) or openlrm-mix-large-1.1 (448); the weights are
licensed CC-BY-NC 4.0 (Objaverse + MVImgNet training data) — research use only.

What the wrappers do, so the C++ side stays model-agnostic:
  encoder: the runner's white-background image in, the canonical camera as a constant buffer;
  decoder: points in our unit cube [-0.5, 0.5]^3 are scaled by 2 into OpenLRM's [-1, 1]^3; the SDF-like field
           is (mesh_thres - sigma) / mesh_thres: negative inside, zero on the runner's iso-surface (a density
           model has no metric distance; marching cubes only needs the sign and the zero level).
If tracing the decoder freezes the number of points (the self-check tries two sizes), the contract declares
that fixed P and the C++ side pads its last chunk (src/models/lrm.cpp).
Usage: export_lrm.py OUT_DIR [--model zxhezexin/openlrm-mix-base-1.1] [--source-size 336] [--mesh-thres 3.0]
"""
import argparse
import os
import sys

import torch

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.realpath(__file__))))  # tools/
from synthdrive_contract import contract, save_scripted, tensor_spec  # noqa: E402

EXPORTER = "tools/export/export_lrm.py"


def canonical_source_camera(dist_to_center=2.0):
    from openlrm.datasets.cam_utils import build_camera_principle, create_intrinsics
    extrinsics = torch.tensor([[[1, 0, 0, 0], [0, 0, -1, -dist_to_center], [0, 1, 0, 0]]], dtype=torch.float32)
    intrinsics = create_intrinsics(f=0.75, c=0.5, device=torch.device("cpu")).unsqueeze(0)
    return build_camera_principle(extrinsics, intrinsics)


class Encoder(torch.nn.Module):
    def __init__(self, model, camera):
        super().__init__()
        self.model = model
        self.register_buffer("camera", camera)

    def forward(self, image):
        return self.model.forward_planes(image, self.camera.repeat(image.shape[0], 1)).float()


class Decoder(torch.nn.Module):
    def __init__(self, model, thres):
        super().__init__()
        self.synthesizer = model.synthesizer
        self.thres = float(thres)

    def forward(self, planes, points):
        out = self.synthesizer.forward_points(planes, points * 2.0)
        sdf = (self.thres - out["sigma"].float()) / self.thres
        return sdf, out["rgb"].float().clamp(0.0, 1.0)


def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("out_dir")
    ap.add_argument("--model", default="zxhezexin/openlrm-mix-base-1.1")
    ap.add_argument("--source-size", type=int, default=336)
    ap.add_argument("--mesh-thres", type=float, default=3.0)
    ap.add_argument("--trace-points", type=int, default=65536)
    args = ap.parse_args()
    os.makedirs(args.out_dir, exist_ok=True)

    from openlrm.models import model_dict
    from openlrm.utils.hf_hub import wrap_model_hub
    model = wrap_model_hub(model_dict["lrm"]).from_pretrained(args.model).float().eval()
    s = args.source_size
    enc = Encoder(model, canonical_source_camera()).eval()
    dec = Decoder(model, args.mesh_thres).eval()
    with torch.no_grad():
        image = torch.rand(1, 3, s, s)
        planes = enc(image)
        traced_enc = torch.jit.trace(enc, image, check_trace=False)
        err_enc = float((traced_enc(image) - planes).abs().max())
        pts = torch.rand(1, args.trace_points, 3) - 0.5
        traced_dec = torch.jit.trace(dec, (planes, pts), check_trace=False)
        # A second point count: does the trace generalise over P?
        pts2 = torch.rand(1, 1000, 3) - 0.5
        try:
            a, b = traced_dec(planes, pts2)
            ra, rb = dec(planes, pts2)
            err_dec = max(float((a - ra).abs().max()), float((b - rb).abs().max()))
            fixed_p = -1 if err_dec < 1e-4 else args.trace_points
        except RuntimeError:
            err_dec, fixed_p = float("nan"), args.trace_points
        a, b = traced_dec(planes, pts)
        ra, rb = dec(planes, pts)
        err_dec_traced = max(float((a - ra).abs().max()), float((b - rb).abs().max()))
    if err_enc > 1e-3 or err_dec_traced > 1e-4:
        sys.exit(f"export_lrm: traced modules differ from eager (encoder {err_enc:g}, decoder {err_dec_traced:g})")

    _, _, c, r, r2 = planes.shape
    source, license_ = f"3DTopia/OpenLRM {args.model}", "CC-BY-NC-4.0"
    params = {"image_size": s, "triplane_channels": int(c), "triplane_resolution": int(r), "background": 1.0,
              "mesh_thres": args.mesh_thres}
    tri = tensor_spec("triplane", [1, 3, int(c), int(r), int(r2)], (-1e4, 1e4), "NPCHW")
    enc_contract = contract("lrm_encoder", args.model.split("/")[-1] + "-encoder",
                            [tensor_spec("image", [1, 3, s, s], (0, 1), "NCHW", "srgb")], [tri], params,
                            source, license_, exporter=EXPORTER, verification={"max_abs_diff_vs_eager": err_enc})
    dec_contract = contract("lrm_decoder", args.model.split("/")[-1] + "-decoder",
                            [dict(tri), tensor_spec("points", [1, fixed_p, 3], (-0.5, 0.5), "NPC", "unit_cube")],
                            [tensor_spec("sdf", [1, fixed_p, 1], (-1e4, 1e4), "NPC"),
                             tensor_spec("colour", [1, fixed_p, 3], (0, 1), "NPC", "srgb")],
                            params, source, license_, exporter=EXPORTER,
                            verification={"max_abs_diff_vs_eager": err_dec_traced})
    save_scripted(traced_enc, os.path.join(args.out_dir, "lrm_encoder.pt"), enc_contract)
    save_scripted(traced_dec, os.path.join(args.out_dir, "lrm_decoder.pt"), dec_contract)
    print(f"export_lrm: {args.model}: S={s}, triplane 3x{c}x{r}x{r2}, points per call "
          f"{'any' if fixed_p < 0 else fixed_p}; max |diff| vs eager: encoder {err_enc:.2e}, "
          f"decoder {err_dec_traced:.2e} -> {args.out_dir}")


if __name__ == "__main__":
    main()
