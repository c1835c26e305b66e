#!/usr/bin/python3
"""Tests tools/import/onnx_to_torchscript.py on tiny ONNX graphs built with onnx.helper, against an independent
numpy implementation of the ops (written from the ONNX operator specifications). Exit status 0 = pass."""
import json
import os
import sys
import tempfile

import numpy as np
import onnx
from onnx import TensorProto, helper, numpy_helper
import torch

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import onnx_to_torchscript as importer  # noqa: E402

RNG = np.random.default_rng(5)


# --- numpy reference --------------------------------------------------------------------------------------------

def np_conv(x, w, b, stride=1, pad=0, dil=1, group=1):
    n, c, h, wd = x.shape
    m, cg, kh, kw = w.shape
    xp = np.pad(x, ((0, 0), (0, 0), (pad, pad), (pad, pad)))
    oh = (h + 2 * pad - dil * (kh - 1) - 1) // stride + 1
    ow = (wd + 2 * pad - dil * (kw - 1) - 1) // stride + 1
    y = np.zeros((n, m, oh, ow), np.float64)
    per = m // group
    for o in range(m):
        g = o // per
        for i in range(oh):
            for j in range(ow):
                patch = xp[0, g * cg:(g + 1) * cg, i * stride:i * stride + dil * (kh - 1) + 1:dil,
                           j * stride:j * stride + dil * (kw - 1) + 1:dil]
                y[0, o, i, j] = np.sum(patch * w[o]) + (b[o] if b is not None else 0)
    return y


def np_maxpool_ceil(x, k=2, s=2):
    n, c, h, w = x.shape
    oh, ow = -(-(h - k) // s) + 1, -(-(w - k) // s) + 1
    y = np.zeros((n, c, oh, ow))
    for i in range(oh):
        for j in range(ow):
            y[:, :, i, j] = x[:, :, i * s:min(h, i * s + k), j * s:min(w, j * s + k)].max(axis=(2, 3))
    return y


def np_resize_linear_half_pixel(x, oh, ow):
    def axis(n_in, n_out):
        src = np.clip((np.arange(n_out) + 0.5) * n_in / n_out - 0.5, 0, n_in - 1)
        i0 = np.floor(src).astype(int)
        i1 = np.minimum(i0 + 1, n_in - 1)
        return i0, i1, src - i0
    y0, y1, fy = axis(x.shape[2], oh)
    x0, x1, fx = axis(x.shape[3], ow)
    top = x[:, :, y0][:, :, :, x0] * (1 - fx) + x[:, :, y0][:, :, :, x1] * fx
    bot = x[:, :, y1][:, :, :, x0] * (1 - fx) + x[:, :, y1][:, :, :, x1] * fx
    return top * (1 - fy)[:, None] + bot * fy[:, None]


def np_resize_nearest_asymmetric(x, sh, sw):
    oh, ow = int(x.shape[2] * sh), int(x.shape[3] * sw)
    iy = np.minimum(np.floor(np.arange(oh) / sh).astype(int), x.shape[2] - 1)
    ix = np.minimum(np.floor(np.arange(ow) / sw).astype(int), x.shape[3] - 1)
    return x[:, :, iy][:, :, :, ix]


def sigmoid(v):
    return 1 / (1 + np.exp(-v))


# --- graphs -----------------------------------------------------------------------------------------------------

def tensor(name, a):
    return numpy_helper.from_array(a, name)


def isnet_like():
    """Conv (float16 weights) → ReLU → MaxPool(ceil) → dilated Conv → ReLU → Resize(linear, half_pixel) to the
    input's size computed by Shape/Slice/Concat → Concat → 1×1 Conv → Cast round trip → Sigmoid, plus Add/Mul."""
    w1 = RNG.normal(0, 0.5, (4, 3, 3, 3)).astype(np.float16)
    b1 = RNG.normal(0, 0.1, 4).astype(np.float16)
    w2 = RNG.normal(0, 0.3, (4, 4, 3, 3)).astype(np.float32)
    b2 = RNG.normal(0, 0.1, 4).astype(np.float32)
    w3 = RNG.normal(0, 0.3, (1, 8, 1, 1)).astype(np.float32)
    b3 = np.array([0.05], np.float32)
    nodes = [
        helper.make_node("Conv", ["x", "w1", "b1"], ["c1"], pads=[1, 1, 1, 1], strides=[1, 1], dilations=[1, 1]),
        helper.make_node("Relu", ["c1"], ["r1"]),
        helper.make_node("MaxPool", ["r1"], ["p1"], kernel_shape=[2, 2], strides=[2, 2], ceil_mode=1),
        helper.make_node("Conv", ["p1", "w2", "b2"], ["c2"], pads=[2, 2, 2, 2], dilations=[2, 2]),
        helper.make_node("Relu", ["c2"], ["r2"]),
        helper.make_node("Shape", ["r1"], ["shape"]),
        helper.make_node("Constant", [], ["start"], value=tensor("start", np.array([2], np.int64))),
        helper.make_node("Constant", [], ["end"], value=tensor("end", np.array([4], np.int64))),
        helper.make_node("Constant", [], ["axes"], value=tensor("axes", np.array([0], np.int64))),
        helper.make_node("Slice", ["shape", "start", "end", "axes"], ["hw"]),
        helper.make_node("Constant", [], ["nc"], value=tensor("nc", np.array([1, 4], np.int64))),
        helper.make_node("Concat", ["nc", "hw"], ["sizes"], axis=0),
        helper.make_node("Resize", ["r2", "", "", "sizes"], ["up"], mode="linear",
                         coordinate_transformation_mode="half_pixel", nearest_mode="floor"),
        helper.make_node("Concat", ["up", "r1"], ["cat"], axis=1),
        helper.make_node("Conv", ["cat", "w3", "b3"], ["c3"]),
        helper.make_node("Cast", ["c3"], ["c3h"], to=TensorProto.FLOAT16),
        helper.make_node("Cast", ["c3h"], ["c3f"], to=TensorProto.FLOAT),
        helper.make_node("Constant", [], ["two"], value=tensor("two", np.array([2.0], np.float32))),
        helper.make_node("Mul", ["c3f", "two"], ["m"]),
        helper.make_node("Add", ["m", "b3"], ["a"]),
        helper.make_node("Sigmoid", ["a"], ["output"]),
        helper.make_node("Sigmoid", ["c3f"], ["side"]),
    ]
    h, w = 10, 10
    g = helper.make_graph(nodes, "isnet_like",
                          [helper.make_tensor_value_info("x", TensorProto.FLOAT, [1, 3, h, w])],
                          [helper.make_tensor_value_info("output", TensorProto.FLOAT, [1, 1, h, w]),
                           helper.make_tensor_value_info("side", TensorProto.FLOAT, [1, 1, h, w])],
                          [tensor("w1", w1), tensor("b1", b1), tensor("w2", w2), tensor("b2", b2), tensor("w3", w3),
                           tensor("b3", b3)])
    model = helper.make_model(g, opset_imports=[helper.make_opsetid("", 15)])
    onnx.checker.check_model(model)

    def reference(x):
        r1 = np.maximum(np_conv(x, w1.astype(np.float64), b1.astype(np.float64), pad=1), 0)
        p1 = np_maxpool_ceil(r1)
        r2 = np.maximum(np_conv(p1, w2, b2, pad=2, dil=2), 0)
        up = np_resize_linear_half_pixel(r2, h, w)
        c3 = np_conv(np.concatenate([up, r1], axis=1), w3, b3)
        return sigmoid(2 * c3 + b3[0])
    return model, h, reference


def nearest_grouped():
    """1×1 Conv → strided grouped Conv → Resize(nearest, asymmetric, ×2 scales) → Sigmoid, on a 12×12 input."""
    w0 = RNG.normal(0, 0.5, (4, 3, 1, 1)).astype(np.float32)
    w = RNG.normal(0, 0.5, (4, 2, 3, 3)).astype(np.float32)
    b = RNG.normal(0, 0.1, 4).astype(np.float32)
    w2 = RNG.normal(0, 0.5, (1, 4, 1, 1)).astype(np.float32)
    nodes = [
        helper.make_node("Conv", ["x", "w0"], ["x4"]),
        helper.make_node("Conv", ["x4", "w", "b"], ["c"], pads=[1, 1, 1, 1], strides=[2, 2], group=2),
        helper.make_node("Resize", ["c", "", "scales"], ["u"], mode="nearest",
                         coordinate_transformation_mode="asymmetric", nearest_mode="floor"),
        helper.make_node("Conv", ["u", "w2"], ["c2"]),
        helper.make_node("Sigmoid", ["c2"], ["output"]),
    ]
    g = helper.make_graph(nodes, "nearest_grouped",
                          [helper.make_tensor_value_info("x", TensorProto.FLOAT, [1, 3, 12, 12])],
                          [helper.make_tensor_value_info("output", TensorProto.FLOAT, [1, 1, 12, 12])],
                          [tensor("w0", w0), tensor("w", w), tensor("b", b), tensor("w2", w2),
                           tensor("scales", np.array([1, 1, 2, 2], np.float32))])
    model = helper.make_model(g, opset_imports=[helper.make_opsetid("", 15)])
    onnx.checker.check_model(model)

    def reference(x):
        c = np_conv(np_conv(x, w0, None), w, b, stride=2, pad=1, group=2)
        return sigmoid(np_conv(np_resize_nearest_asymmetric(c, 2, 2), w2, None))
    return model, 12, reference


def check(model, size, reference, mean=128.0, std=256.0):
    with tempfile.TemporaryDirectory() as d:
        path, out = os.path.join(d, "m.onnx"), os.path.join(d, "m.pt")
        onnx.save(model, path)
        importer.convert(path, out, size, mean=mean, std=std, name="tiny", source="test", license_="Apache-2.0")
        files = {"synthdrive_contract.json": ""}
        loaded = torch.jit.load(out, _extra_files=files)
        contract = json.loads(files["synthdrive_contract.json"])
        assert contract["stage"] == "segmentation" and contract["params"]["input_size"] == size, contract
        assert contract["inputs"][0]["shape"] == [1, 3, size, size], contract
        x = RNG.random((1, 3, size, size)).astype(np.float32)
        with torch.no_grad():
            got = loaded(torch.from_numpy(x)).numpy()
        want = reference((x.astype(np.float64) * 255.0 - mean) / std)
        err = np.abs(got - want).max()
        assert err < 1e-4, f"max error {err}"
        return err


def main():
    model, size, ref = isnet_like()
    err1 = check(model, size, ref)
    model, size, ref = nearest_grouped()
    err2 = check(model, size, ref, mean=127.5, std=127.5)
    # Unsupported ops and asymmetric pads are refused, naming the node.
    bad = helper.make_model(helper.make_graph(
        [helper.make_node("Softmax", ["x"], ["output"], name="the_softmax")], "bad",
        [helper.make_tensor_value_info("x", TensorProto.FLOAT, [1, 3, 4, 4])],
        [helper.make_tensor_value_info("output", TensorProto.FLOAT, [1, 3, 4, 4])]))
    try:
        importer.OnnxModule(bad, "output")
        raise AssertionError("Softmax was accepted")
    except importer.UnsupportedGraph as e:
        assert "the_softmax" in str(e) and "Softmax" in str(e), e
    asym = helper.make_model(helper.make_graph(
        [helper.make_node("MaxPool", ["x"], ["output"], name="pool", kernel_shape=[2, 2], pads=[0, 0, 1, 1])],
        "asym", [helper.make_tensor_value_info("x", TensorProto.FLOAT, [1, 1, 4, 4])],
        [helper.make_tensor_value_info("output", TensorProto.FLOAT, [1, 1, 4, 4])]))
    try:
        importer.OnnxModule(asym, "output")(torch.zeros(1, 1, 4, 4))
        raise AssertionError("asymmetric pads were accepted")
    except importer.UnsupportedGraph as e:
        assert "asymmetric" in str(e), e
    print(f"test_onnx_to_torchscript: ok (max errors {err1:.2e}, {err2:.2e})")


if __name__ == "__main__":
    main()
