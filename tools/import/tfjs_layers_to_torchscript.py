#!/usr/bin/python3
"""Import a TensorFlow.js "layers-model" (Keras graph + binary weight shards) into TorchScript.

The result is a shape-generic traced module, NCHW float32 in and out, in the model's native value range,
with a `synthdrive_contract.json` extra file that the C++ side reads (stage, range, scale, receptive radius,
provenance, verification PSNR).

Only the layer classes and configurations listed in SUPPORTED are accepted; anything else is refused with one
line naming the file, the layer and the problem (exit code 2), so an import never silently computes something
different from the original model. The output is written to a temporary name beside --out and renamed only
once complete.
"""
import argparse
import json
import math
import os
import re
import struct
import sys
import tempfile
import time
import zlib

import numpy as np
import torch
import torch.nn.functional as F

sys.path.insert(0, os.path.dirname(os.path.dirname(os.path.realpath(__file__))))  # tools/
from synthdrive_contract import contract, save_scripted, tensor_spec  # noqa: E402

IMPORTER = "tools/import/tfjs_layers_to_torchscript.py"
FUSED_ACTIVATIONS = ("linear", "relu", "sigmoid", "tanh", "softmax")
SUPPORTED = ("InputLayer", "Conv2D", "Activation", "ReLU", "LeakyReLU", "Add", "Multiply", "Concatenate",
             "UpSampling2D", "MultiplyBeta", "PixelShuffle<N>x")
PIXEL_SHUFFLE = re.compile(r"^PixelShuffle(\d+)x$")
# UpscalerJS's custom MultiplyBeta layer scales residuals by this constant (BETA in its esrgan setup()).
UPSCALERJS_BETA = 0.2
# The trace uses one size and the self-check another, so that a size baked into the graph is caught.
TRACE_SHAPE = (40, 40)
CHECK_SHAPE = (37, 53)
SELF_CHECK_TOLERANCE = 1e-3


class ImportFailure(Exception):
    """Bad input or unsupported model: reported as one line and exit code 2."""

    def __init__(self, path, problem):
        super().__init__(f"{path}: {problem}")


# ---------------------------------------------------------------------------------------------------------------
# model.json and weights


def load_model_json(path):
    try:
        with open(path, "rb") as f:
            model = json.loads(f.read().decode("utf-8"))
    except FileNotFoundError:
        raise ImportFailure(path, "no such file")
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise ImportFailure(path, f"not valid JSON ({e})")
    if not isinstance(model, dict):
        raise ImportFailure(path, "not a TF.js model (top level is not a JSON object)")
    if model.get("format") != "layers-model":
        raise ImportFailure(path, f"format is {model.get('format')!r}, only \"layers-model\" is supported "
                                  "(graph models carry no Keras layer graph)")
    for key in ("modelTopology", "weightsManifest"):
        if key not in model:
            raise ImportFailure(path, f"missing \"{key}\"")
    return model


# Bytes per stored element; the dtype after dequantisation is always float32.
STORED_BYTES = {"float32": 4, "int32": 4, "uint8": 1, "uint16": 2, "float16": 2}


def stored_dtype(entry):
    quant = entry.get("quantization")
    return quant["dtype"] if quant else entry.get("dtype", "float32")


def decode_weight(raw, entry, where):
    quant = entry.get("quantization")
    kind = stored_dtype(entry)
    if kind == "float32":
        return np.frombuffer(raw, dtype="<f4").astype(np.float32)
    if kind == "float16":
        return np.frombuffer(raw, dtype="<f2").astype(np.float32)
    if kind in ("uint8", "uint16") and quant:
        if "scale" not in quant or "min" not in quant:
            raise ImportFailure(where, f"weight {entry['name']}: {kind} quantisation without scale and min "
                                       "(only affine scale+min quantisation is supported)")
        q = np.frombuffer(raw, dtype="<u1" if kind == "uint8" else "<u2").astype(np.float64)
        return (q * quant["scale"] + quant["min"]).astype(np.float32)
    raise ImportFailure(where, f"weight {entry['name']}: dtype {kind} is not supported "
                               "(float32, float16, uint8/uint16 with scale+min)")


def read_group(model_path, group):
    """Concatenates one manifest group's shards and splits them into named float32 arrays."""
    base = os.path.dirname(os.path.abspath(model_path))
    chunks = []
    for rel in group.get("paths", []):
        shard = os.path.join(base, rel)
        try:
            with open(shard, "rb") as f:
                chunks.append(f.read())
        except FileNotFoundError:
            raise ImportFailure(shard, f"weight shard listed in {os.path.basename(model_path)} is missing")
    data = b"".join(chunks)
    where = os.path.join(base, group["paths"][-1]) if group.get("paths") else model_path
    sizes = []
    for entry in group.get("weights", []):
        kind = stored_dtype(entry)
        if kind not in STORED_BYTES:
            raise ImportFailure(model_path, f"weight {entry.get('name')}: dtype {kind} is not supported")
        sizes.append(int(np.prod(entry["shape"], dtype=np.int64)) * STORED_BYTES[kind])
    if len(data) != sum(sizes):
        names = ", ".join(os.path.basename(p) for p in group.get("paths", []))
        raise ImportFailure(where, f"weight data is {len(data)} bytes but the manifest needs {sum(sizes)} "
                                   f"bytes (shards: {names})")
    weights, offset = {}, 0
    for entry, size in zip(group["weights"], sizes):
        values = decode_weight(data[offset:offset + size], entry, where)
        weights[entry["name"]] = values.reshape(entry["shape"])
        offset += size
    return weights


def read_weights(model_path, manifest):
    weights = {}
    for group in manifest:
        weights.update(read_group(model_path, group))
    return weights


# ---------------------------------------------------------------------------------------------------------------
# Graph: Keras layer list -> nodes in topological order


class Node:
    def __init__(self, name, class_name, config, inputs):
        self.name, self.class_name, self.config, self.inputs = name, class_name, config, inputs


def inbound_names(layer, where):
    nodes = layer.get("inbound_nodes", [])
    if not nodes:
        return []
    if len(nodes) > 1:
        raise ImportFailure(where, f"layer {layer.get('name')!r} is called {len(nodes)} times "
                                   "(shared layers are not supported)")
    names = []
    for ref in nodes[0]:
        if not isinstance(ref, list) or len(ref) < 3:
            raise ImportFailure(where, f"layer {layer.get('name')!r}: inbound node format not understood "
                                       "(expected Keras 2 [name, node, tensor, kwargs] lists)")
        if ref[1] != 0 or ref[2] != 0:
            raise ImportFailure(where, f"layer {layer.get('name')!r}: input {ref[0]!r} refers to node "
                                       f"{ref[1]} tensor {ref[2]}; only single-output layers are supported")
        names.append(ref[0])
    return names


def parse_graph(model, where):
    topology = model["modelTopology"]
    config = topology.get("model_config", topology)
    cls, body = config.get("class_name"), config.get("config")
    if cls == "Sequential":
        layers = body if isinstance(body, list) else body.get("layers", [])
        return sequential_nodes(layers, where)
    if cls not in ("Functional", "Model"):
        raise ImportFailure(where, f"model class {cls!r} is not supported (Functional, Model, Sequential)")
    nodes = [Node(l["name"], l["class_name"], l.get("config", {}), inbound_names(l, where))
             for l in body["layers"]]
    if len(body["input_layers"]) != 1 or len(body["output_layers"]) != 1:
        raise ImportFailure(where, "only models with one input and one output are supported")
    return topological(nodes, where), body["input_layers"][0][0], body["output_layers"][0][0]


def sequential_nodes(layers, where):
    nodes, previous = [], None
    if layers and layers[0]["class_name"] != "InputLayer":
        shape = layers[0]["config"].get("batch_input_shape")
        nodes.append(Node("input", "InputLayer", {"batch_input_shape": shape}, []))
        previous = "input"
    for layer in layers:
        nodes.append(Node(layer["config"]["name"], layer["class_name"], layer["config"],
                          [previous] if previous else []))
        previous = nodes[-1].name
    return nodes, nodes[0].name, previous


def topological(nodes, where):
    by_name = {n.name: n for n in nodes}
    order, state = [], {}

    def visit(name, chain):
        if state.get(name) == "done":
            return
        if state.get(name) == "open":
            raise ImportFailure(where, f"cycle in the layer graph through {name!r}")
        if name not in by_name:
            raise ImportFailure(where, f"layer {chain!r} takes input from unknown layer {name!r}")
        state[name] = "open"
        for src in by_name[name].inputs:
            visit(src, name)
        state[name] = "done"
        order.append(by_name[name])

    for n in nodes:
        visit(n.name, n.name)
    return order


# ---------------------------------------------------------------------------------------------------------------
# Ops: one small nn.Module per supported layer class. Each takes the list of input tensors (NCHW).


def activation_fn(name):
    if name == "linear":
        return lambda x: x
    if name == "relu":
        return torch.relu
    if name == "sigmoid":
        return torch.sigmoid
    if name == "tanh":
        return torch.tanh
    if name == "softmax":
        return lambda x: torch.softmax(x, dim=1)  # Keras applies it over the last (channel) axis.
    return None


class Conv(torch.nn.Module):
    def __init__(self, weight, bias, pad, dilation, activation):
        super().__init__()
        self.weight = torch.nn.Parameter(torch.from_numpy(weight), requires_grad=False)
        self.bias = None if bias is None else torch.nn.Parameter(torch.from_numpy(bias), requires_grad=False)
        self.pad, self.dilation, self.activation = pad, dilation, activation_fn(activation)

    def forward(self, xs):
        x = xs[0]
        left, right, top, bottom = self.pad
        symmetric = left == right and top == bottom
        if not symmetric:
            x = F.pad(x, [left, right, top, bottom])
        padding = (top, left) if symmetric else (0, 0)
        return self.activation(F.conv2d(x, self.weight, self.bias, 1, padding, self.dilation))


class Elementwise(torch.nn.Module):
    def __init__(self, fn):
        super().__init__()
        self.fn = fn

    def forward(self, xs):
        return self.fn(xs[0])


class Sum(torch.nn.Module):
    def forward(self, xs):
        out = xs[0]
        for x in xs[1:]:
            out = out + x
        return out


class Product(torch.nn.Module):
    def forward(self, xs):
        out = xs[0]
        for x in xs[1:]:
            out = out * x
        return out


class Concat(torch.nn.Module):
    def forward(self, xs):
        return torch.cat(xs, dim=1)


class UpsampleNearest(torch.nn.Module):
    def __init__(self, sy, sx):
        super().__init__()
        self.sy, self.sx = sy, sx

    def forward(self, xs):
        # repeat_interleave is exactly Keras's nearest UpSampling2D (each pixel copied s times) and, unlike a
        # computed output size, carries no input size into the trace.
        return xs[0].repeat_interleave(self.sy, dim=2).repeat_interleave(self.sx, dim=3)


class UpsampleBilinear(torch.nn.Module):
    # Keras UpSampling2D(interpolation="bilinear") calls tf.image.resize (v2), which samples at half-pixel
    # centres without corner alignment: the same as torch's align_corners=False. Note TF.js's own
    # UpSampling2D calls tf.image.resizeBilinear with halfPixelCenters=false (legacy asymmetric sampling),
    # so a TF.js runtime can differ from the Keras model it was converted from by up to half a pixel; we
    # follow Keras, the framework the weights were trained in.
    def __init__(self, sy, sx):
        super().__init__()
        self.sy, self.sx = float(sy), float(sx)

    def forward(self, xs):
        return F.interpolate(xs[0], scale_factor=(self.sy, self.sx), mode="bilinear", align_corners=False)


class DepthToSpace(torch.nn.Module):
    # TF depth_to_space (NHWC): out[y*b+i, x*b+j, c] = in[y, x, (i*b+j)*C + c]. torch.pixel_shuffle instead
    # reads channel c*b*b + i*b + j, so the channel axis is split as (i, j, c) here, not (c, i, j).
    def __init__(self, block):
        super().__init__()
        self.block = block

    def forward(self, xs):
        b = self.block
        x = xs[0].unflatten(1, (b, b, -1))            # N, i, j, C, H, W
        x = x.permute(0, 3, 4, 1, 5, 2)                # N, C, H, i, W, j
        return x.flatten(4, 5).flatten(2, 3)


# ---------------------------------------------------------------------------------------------------------------
# Layer builders: validate the config and weights, return (op, out_channels, scale factor, radius added)


class Built:
    def __init__(self, op, channels, upscale=1, radius=0.0, params=0):
        self.op, self.channels, self.upscale, self.radius, self.params = op, channels, upscale, radius, params


def pair(value, what, node, where):
    if isinstance(value, int):
        return value, value
    if isinstance(value, (list, tuple)) and len(value) == 2 and all(isinstance(v, int) for v in value):
        return tuple(value)
    raise ImportFailure(where, f"layer {node.name!r} ({node.class_name}): {what} {value!r} not understood")


def require(cond, node, where, problem):
    if not cond:
        raise ImportFailure(where, f"layer {node.name!r} ({node.class_name}): {problem}")


def check_channels_last(node, where):
    fmt = node.config.get("data_format", "channels_last")
    require(fmt in (None, "channels_last"), node, where, f"data_format {fmt} is not supported (channels_last)")


def layer_weight(weights, node, kind, where):
    for key in (f"{node.name}/{kind}", f"{node.name}/{kind}:0"):
        if key in weights:
            return weights[key]
    suffix = f"/{node.name}/{kind}"
    hits = [k for k in weights if k.endswith(suffix) or k.endswith(suffix + ":0")]
    if len(hits) == 1:
        return weights[hits[0]]
    raise ImportFailure(where, f"layer {node.name!r} ({node.class_name}): weight {node.name}/{kind} not found "
                               "in weightsManifest")


def same_padding(k, dilation):
    # TF "same" with stride 1 pads dilation*(k-1) in total, the smaller half before (matters for even k).
    total = dilation * (k - 1)
    return total // 2, total - total // 2


def build_conv(node, in_channels, weights, where):
    c = node.config
    check_channels_last(node, where)
    kh, kw = pair(c.get("kernel_size"), "kernel_size", node, where)
    require(pair(c.get("strides", 1), "strides", node, where) == (1, 1), node, where,
            f"strides {c.get('strides')} are not supported (only 1)")
    dy, dx = pair(c.get("dilation_rate", 1), "dilation_rate", node, where)
    require(c.get("groups", 1) == 1, node, where, f"groups={c.get('groups')} is not supported (only 1)")
    activation = c.get("activation", "linear")
    require(activation in FUSED_ACTIVATIONS, node, where,
            f"activation {activation!r} is not supported ({', '.join(FUSED_ACTIVATIONS)})")
    padding = c.get("padding", "valid")
    require(padding in ("same", "valid"), node, where, f"padding {padding!r} is not supported (same, valid)")
    filters = c["filters"]
    kernel = layer_weight(weights, node, "kernel", where)
    require(kernel.shape == (kh, kw, in_channels, filters), node, where,
            f"kernel shape {list(kernel.shape)} does not match the config [{kh}, {kw}, {in_channels}, {filters}]"
            " (kernel_size, input channels, filters)")
    bias = None
    if c.get("use_bias", True):
        bias = layer_weight(weights, node, "bias", where)
        require(bias.shape == (filters,), node, where,
                f"bias shape {list(bias.shape)} does not match filters={filters}")
    if padding == "same":
        top, bottom = same_padding(kh, dy)
        left, right = same_padding(kw, dx)
    else:
        top = bottom = left = right = 0
    oihw = np.ascontiguousarray(kernel.transpose(3, 2, 0, 1), dtype=np.float32)
    op = Conv(oihw, None if bias is None else bias.astype(np.float32), (left, right, top, bottom), (dy, dx),
              activation)
    radius = max(dy * (kh - 1), dx * (kw - 1)) / 2.0
    return Built(op, filters, radius=radius, params=kernel.size + (0 if bias is None else bias.size))


def build_activation(node, in_channels, where):
    name = node.config.get("activation")
    fn = activation_fn(name)
    require(fn is not None, node, where,
            f"activation {name!r} is not supported ({', '.join(FUSED_ACTIVATIONS)})")
    return Built(Elementwise(fn), in_channels)


def build_relu(node, in_channels, where):
    c = node.config
    max_value, slope = c.get("max_value"), float(c.get("negative_slope", 0.0) or 0.0)
    require(float(c.get("threshold", 0.0) or 0.0) == 0.0, node, where, "threshold != 0 is not supported")
    cap = None if max_value is None else float(max_value)

    def relu(x):
        y = F.leaky_relu(x, slope) if slope else torch.relu(x)
        return y if cap is None else torch.clamp(y, max=cap)

    return Built(Elementwise(relu), in_channels)


def build_leaky_relu(node, in_channels, where):
    alpha = float(node.config.get("alpha", 0.3))  # Keras's default slope.
    return Built(Elementwise(lambda x: F.leaky_relu(x, alpha)), in_channels)


def build_upsampling(node, in_channels, where):
    check_channels_last(node, where)
    sy, sx = pair(node.config.get("size", 2), "size", node, where)
    mode = node.config.get("interpolation", "nearest")
    require(mode in ("nearest", "bilinear"), node, where, f"interpolation {mode!r} is not supported")
    require(sy == sx, node, where, f"anisotropic size {[sy, sx]} is not supported")
    op = UpsampleNearest(sy, sx) if mode == "nearest" else UpsampleBilinear(sy, sx)
    return Built(op, in_channels, upscale=sy)


def build_merge(node, in_channels, where):
    require(len(in_channels) >= 2, node, where, "needs at least two inputs")
    if node.class_name == "Concatenate":
        axis = node.config.get("axis", -1)
        require(axis in (3, -1), node, where, f"axis {axis} is not supported (only the channel axis, 3 or -1)")
        return Built(Concat(), sum(in_channels))
    require(len(set(in_channels)) == 1, node, where, f"inputs have different channel counts {in_channels}")
    return Built(Sum() if node.class_name == "Add" else Product(), in_channels[0])


def build_pixel_shuffle(node, in_channels, block, where):
    require(in_channels % (block * block) == 0, node, where,
            f"{in_channels} input channels are not divisible by block {block}x{block}")
    return Built(DepthToSpace(block), in_channels // (block * block), upscale=block)


def build_node(node, in_channels, weights, where):
    cls = node.class_name
    single = cls not in ("Add", "Multiply", "Concatenate")
    if single:
        require(len(in_channels) == 1, node, where, f"expects one input, got {len(in_channels)}")
    if cls == "Conv2D":
        return build_conv(node, in_channels[0], weights, where)
    if cls == "Activation":
        return build_activation(node, in_channels[0], where)
    if cls == "ReLU":
        return build_relu(node, in_channels[0], where)
    if cls == "LeakyReLU":
        return build_leaky_relu(node, in_channels[0], where)
    if cls == "UpSampling2D":
        return build_upsampling(node, in_channels[0], where)
    if cls == "MultiplyBeta":
        return Built(Elementwise(lambda x: x * UPSCALERJS_BETA), in_channels[0])
    match = PIXEL_SHUFFLE.match(cls)
    if match:
        return build_pixel_shuffle(node, in_channels[0], int(match.group(1)), where)
    if not single:
        return build_merge(node, in_channels, where)
    raise ImportFailure(where, f"layer {node.name!r} has unknown class {cls!r} (supported: {', '.join(SUPPORTED)})")


# ---------------------------------------------------------------------------------------------------------------
# The torch module


class LayerGraph(torch.nn.Module):
    """Runs the imported layers in topological order; slot i holds the output of step i."""

    def __init__(self, ops, sources, output_slot):
        super().__init__()
        self.ops = torch.nn.ModuleList(ops)
        self.sources = sources
        self.output_slot = output_slot

    def forward(self, image):
        slots = [image]
        for op, src in zip(self.ops, self.sources):
            slots.append(op([slots[i] for i in src]))
        return slots[self.output_slot]


class Imported:
    def __init__(self, module, in_channels, out_channels, scale, radius, layers, params):
        self.module, self.in_channels, self.out_channels = module, in_channels, out_channels
        self.scale, self.radius, self.layers, self.params = scale, radius, layers, params


def input_channels(node, where):
    shape = node.config.get("batch_input_shape") or node.config.get("batch_shape")
    if not shape or len(shape) != 4 or not isinstance(shape[3], int):
        raise ImportFailure(where, f"input layer {node.name!r}: batch_input_shape {shape} is not "
                                   "[batch, height, width, channels] with known channels")
    return shape[3]


def build_graph(model_path):
    model = load_model_json(model_path)
    nodes, input_name, output_name = parse_graph(model, model_path)
    weights = read_weights(model_path, model["weightsManifest"])
    slot = {input_name: 0}
    info = {}  # name -> (channels, cumulative upscale, receptive radius in input pixels)
    ops, sources, params = [], [], 0
    for node in nodes:
        if node.class_name == "InputLayer" or node.name == input_name:
            require(node.name == input_name, node, model_path, "second input layer; only one is supported")
            info[node.name] = (input_channels(node, model_path), 1, 0.0)
            continue
        ins = [info[n] for n in node.inputs]
        built = build_node(node, [c for c, _, _ in ins], weights, model_path)
        upscale = max(s for _, s, _ in ins)
        # A kernel applied after an s-fold upsampling reaches radius/s input pixels.
        radius = max(r for _, _, r in ins) + built.radius / upscale
        info[node.name] = (built.channels, upscale * built.upscale, radius)
        slot[node.name] = len(ops) + 1
        ops.append(built.op)
        sources.append([slot[n] for n in node.inputs])
        params += built.params
    channels_in = info[input_name][0]
    channels_out, scale, radius = info[output_name]
    module = LayerGraph(ops, sources, slot[output_name]).eval()
    return Imported(module, channels_in, channels_out, scale, int(math.ceil(radius - 1e-9)), len(nodes), params)


def trace(imported, model_path):
    gen = torch.Generator().manual_seed(0)
    example = torch.rand(1, imported.in_channels, *TRACE_SHAPE, generator=gen) * 255.0
    probe = torch.rand(1, imported.in_channels, *CHECK_SHAPE, generator=gen) * 255.0
    with torch.no_grad():
        traced = torch.jit.trace(imported.module, example, check_trace=False)
        eager, scripted = imported.module(probe), traced(probe)
    if eager.shape != scripted.shape:
        raise ImportFailure(model_path, f"traced module is not shape-generic: {tuple(scripted.shape)} vs eager "
                                        f"{tuple(eager.shape)} for input {tuple(probe.shape)}")
    diff = (eager - scripted).abs().max().item()
    if not diff < SELF_CHECK_TOLERANCE:
        raise ImportFailure(model_path, f"traced module differs from eager by {diff:g} on a "
                                        f"{CHECK_SHAPE[0]}x{CHECK_SHAPE[1]} input (limit {SELF_CHECK_TOLERANCE})")
    return traced


# ---------------------------------------------------------------------------------------------------------------
# Verification against a reference output (PNG, read without PIL, which Debian's torch does not pull in)


def png_unfilter(raw, width, height, bpp):
    stride = width * bpp
    out = bytearray(height * stride)
    prev = bytearray(stride)
    pos = 0
    for y in range(height):
        ftype, line = raw[pos], bytearray(raw[pos + 1:pos + 1 + stride])
        pos += 1 + stride
        if ftype == 1:
            for i in range(bpp, stride):
                line[i] = (line[i] + line[i - bpp]) & 255
        elif ftype == 2:
            line = bytearray((a + b) & 255 for a, b in zip(line, prev))
        elif ftype == 3:
            for i in range(stride):
                left = line[i - bpp] if i >= bpp else 0
                line[i] = (line[i] + ((left + prev[i]) >> 1)) & 255
        elif ftype == 4:
            for i in range(stride):
                a = line[i - bpp] if i >= bpp else 0
                b, c = prev[i], (prev[i - bpp] if i >= bpp else 0)
                p = a + b - c
                pa, pb, pc = abs(p - a), abs(p - b), abs(p - c)
                pred = a if pa <= pb and pa <= pc else (b if pb <= pc else c)
                line[i] = (line[i] + pred) & 255
        elif ftype != 0:
            raise ValueError(f"bad PNG filter type {ftype}")
        out[y * stride:(y + 1) * stride] = line
        prev = line
    return out


def read_png_rgb(path):
    """8-bit grey/RGB/RGBA, non-interlaced PNG -> HxWx3 uint8 (alpha dropped)."""
    try:
        with open(path, "rb") as f:
            data = f.read()
    except OSError as e:
        raise ImportFailure(path, f"cannot read ({e.strerror})")
    if data[:8] != b"\x89PNG\r\n\x1a\n":
        raise ImportFailure(path, "not a PNG file")
    pos, header, idat = 8, None, []
    while pos + 8 <= len(data):
        length, kind = struct.unpack(">I4s", data[pos:pos + 8])
        body = data[pos + 8:pos + 8 + length]
        if kind == b"IHDR":
            header = struct.unpack(">IIBBBBB", body)
        elif kind == b"IDAT":
            idat.append(body)
        elif kind == b"IEND":
            break
        pos += 12 + length
    if header is None:
        raise ImportFailure(path, "PNG without IHDR")
    width, height, depth, color, _, _, interlace = header
    channels = {0: 1, 2: 3, 4: 2, 6: 4}.get(color)
    if depth != 8 or channels is None or interlace:
        raise ImportFailure(path, f"PNG bit depth {depth}, colour type {color}, interlace {interlace} not "
                                  "supported (8-bit grey/RGB/RGBA, non-interlaced)")
    try:
        pixels = png_unfilter(zlib.decompress(b"".join(idat)), width, height, channels)
    except (zlib.error, ValueError, IndexError) as e:
        raise ImportFailure(path, f"corrupt PNG data ({e})")
    image = np.frombuffer(bytes(pixels), dtype=np.uint8).reshape(height, width, channels)
    if channels <= 2:
        return np.repeat(image[:, :, :1], 3, axis=2)
    return image[:, :, :3]


def psnr_against(traced, input_png, expected_png):
    lr = read_png_rgb(input_png)
    expected = read_png_rgb(expected_png)
    x = torch.from_numpy(lr.astype(np.float32)).permute(2, 0, 1)[None]
    with torch.no_grad():
        y = traced(x)[0].clamp(0, 255).round().permute(1, 2, 0).numpy()
    if y.shape != expected.shape:
        raise ImportFailure(expected_png, f"model output is {y.shape[1]}x{y.shape[0]} but the expected image is "
                                          f"{expected.shape[1]}x{expected.shape[0]}")
    mse = float(np.mean((y.astype(np.float64) - expected.astype(np.float64)) ** 2))
    return float("inf") if mse == 0 else 10.0 * math.log10(255.0 ** 2 / mse)


def package_relative(path):
    """Path relative to the enclosing npm package (the folder holding package.json), for provenance."""
    path = os.path.abspath(path)
    folder = os.path.dirname(path)
    while folder != os.path.dirname(folder):
        if os.path.isfile(os.path.join(folder, "package.json")):
            return os.path.relpath(path, folder)
        folder = os.path.dirname(folder)
    return os.path.basename(path)


# ---------------------------------------------------------------------------------------------------------------
# Contract and output


def build_contract(args, imported, verification):
    def port(channels, value_range):
        return tensor_spec("image", [-1, channels, -1, -1], number_list(value_range), "NCHW", args.encoding)

    extra = {"importer": IMPORTER}
    if verification:
        extra["verification"] = verification
    try:
        return contract(args.stage, args.name, [port(imported.in_channels, args.input_range)],
                        [port(imported.out_channels, args.output_range or args.input_range)],
                        {"scale": imported.scale, "receptive_radius": imported.radius}, args.source, args.license,
                        **extra)
    except ValueError as e:  # e.g. an --input-range whose low is not below its high
        raise ImportFailure(args.out, str(e))


def number_list(values):
    return [int(v) if float(v).is_integer() else float(v) for v in values]


def current_umask():
    mask = os.umask(0)
    os.umask(mask)
    return mask


def save_atomically(traced, out_path, doc):
    folder = os.path.dirname(os.path.abspath(out_path))
    os.makedirs(folder, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix="." + os.path.basename(out_path) + ".", suffix=".tmp", dir=folder)
    os.close(fd)
    try:
        os.chmod(tmp, 0o666 & ~current_umask())  # mkstemp's 0600 would hide the model from other users.
        save_scripted(traced, tmp, doc, indent=1)
        os.replace(tmp, out_path)
    finally:
        if os.path.exists(tmp):
            os.remove(tmp)


def run(args):
    started = time.time()
    imported = build_graph(args.model)
    if args.scale is not None and args.scale != imported.scale:
        raise ImportFailure(args.model, f"--scale {args.scale} but the graph upsamples by {imported.scale}")
    traced = trace(imported, args.model)
    verification = None
    if args.verify_input or args.verify_expected:
        if not (args.verify_input and args.verify_expected):
            raise ImportFailure(args.model, "--verify-input and --verify-expected go together")
        psnr = psnr_against(traced, args.verify_input, args.verify_expected)
        print(f"verify: PSNR {psnr:.2f} dB against {os.path.basename(args.verify_expected)}")
        if args.min_psnr is not None and not psnr >= args.min_psnr:
            raise ImportFailure(args.verify_expected, f"PSNR {psnr:.2f} dB is below --min-psnr {args.min_psnr}")
        verification = {"input": package_relative(args.verify_input),
                        "expected": package_relative(args.verify_expected),
                        "psnr_db": round(psnr, 2) if math.isfinite(psnr) else 999.0}
    save_atomically(traced, args.out, build_contract(args, imported, verification))
    print(f"imported {args.name}: {imported.layers} layers, {imported.params:,} parameters, x{imported.scale}, "
          f"receptive radius {imported.radius} px, {time.time() - started:.1f} s -> {args.out}")


def parse_args(argv):
    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--model", required=True, help="model.json of a TF.js layers model")
    p.add_argument("--out", required=True, help="TorchScript file to write")
    p.add_argument("--name", required=True)
    p.add_argument("--source", required=True, help="where the weights came from (package@version path)")
    p.add_argument("--license", required=True)
    p.add_argument("--stage", required=True, help="SynthDrive learned stage, e.g. super_resolution")
    p.add_argument("--scale", type=int, help="expected upscale factor; checked against the graph")
    p.add_argument("--input-range", nargs=2, type=float, default=[0.0, 1.0], metavar=("LO", "HI"))
    p.add_argument("--output-range", nargs=2, type=float, metavar=("LO", "HI"), help="default: input range")
    p.add_argument("--encoding", default="srgb", help="colour encoding of the image values")
    p.add_argument("--verify-input", help="PNG fed to the model (alpha dropped)")
    p.add_argument("--verify-expected", help="PNG the original runtime produced for --verify-input")
    p.add_argument("--min-psnr", type=float, help="fail when verification PSNR (dB) is below this")
    return p.parse_args(argv)


def main(argv=None):
    args = parse_args(argv)
    try:
        run(args)
    except ImportFailure as e:
        print(f"tfjs_layers_to_torchscript: error: {e}", file=sys.stderr)
        return 2
    except OSError as e:
        print(f"tfjs_layers_to_torchscript: error: {e.filename or args.out}: {e.strerror}", file=sys.stderr)
        return 2
    return 0


if __name__ == "__main__":
    sys.exit(main())
