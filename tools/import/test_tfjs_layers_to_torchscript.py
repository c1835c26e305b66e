#!/usr/bin/python3
"""Tests for tfjs_layers_to_torchscript.py against an independent NHWC numpy reference.

The tiny model written here uses every layer kind the real UpscalerJS models need plus the ESRGAN custom
layers, one uint8-quantised and one float16 weight; the reference below re-implements each layer directly
from the Keras/TF definitions (tap-by-tap convolution, TF depth_to_space indexing), sharing no code with the
importer. Run: /usr/bin/python3 tools/import/test_tfjs_layers_to_torchscript.py
"""
import json
import os
import subprocess
import sys
import tempfile
import unittest

import numpy as np
import torch

IMPORTER = os.path.join(os.path.dirname(os.path.abspath(__file__)), "tfjs_layers_to_torchscript.py")
TOLERANCE = 1e-3


# ---------------------------------------------------------------------------------------------------------------
# Writing a TF.js layers model


def layer(class_name, name, inputs, **config):
    config["name"] = name
    return {"class_name": class_name, "name": name, "config": config,
            "inbound_nodes": [[[src, 0, 0, {}] for src in inputs]] if inputs else []}


def conv(name, src, k, filters, padding="same", dilation=1, activation="linear"):
    return layer("Conv2D", name, [src], filters=filters, kernel_size=[k, k], strides=[1, 1], padding=padding,
                 data_format="channels_last", dilation_rate=[dilation, dilation], groups=1,
                 activation=activation, use_bias=True)


def quantise_uint8(values):
    """TF.js affine uint8 quantisation: stored q, value = q * scale + min."""
    lo, hi = float(values.min()), float(values.max())
    scale = (hi - lo) / 255.0
    q = np.round((values - lo) / scale).astype(np.uint8)
    return q, {"dtype": "uint8", "scale": scale, "min": lo}, (q.astype(np.float64) * scale + lo).astype(np.float32)


def write_model(folder, layers, weights, output):
    """weights: list of (name, stored array, quantization dict or None). One group, split over two shards."""
    entries, blobs = [], []
    for name, stored, quant in weights:
        entry = {"name": name, "shape": list(stored.shape), "dtype": "float32"}
        if quant:
            entry["quantization"] = quant
        entries.append(entry)
        blobs.append(stored.astype(stored.dtype.newbyteorder("<")).tobytes())
    data = b"".join(blobs)
    half = len(data) // 2
    shards = ["group1-shard1of2.bin", "group1-shard2of2.bin"]
    for shard, chunk in zip(shards, (data[:half], data[half:])):
        with open(os.path.join(folder, shard), "wb") as f:
            f.write(chunk)
    model = {"format": "layers-model", "generatedBy": "test", "convertedBy": "test",
             "modelTopology": {"keras_version": "2.10.0", "backend": "tensorflow",
                               "model_config": {"class_name": "Functional", "config": {
                                   "name": "tiny", "layers": layers, "input_layers": [["in", 0, 0]],
                                   "output_layers": [[output, 0, 0]]}}},
             "weightsManifest": [{"paths": shards, "weights": entries}]}
    path = os.path.join(folder, "model.json")
    with open(path, "w") as f:
        json.dump(model, f)
    return path


def tiny_model(folder, seed=1):
    """Returns (model.json path, the float weights the reference uses). Upscales by 4, valid conv last."""
    rng = np.random.default_rng(seed)
    layers = [
        layer("InputLayer", "in", [], batch_input_shape=[None, None, None, 3], dtype="float32"),
        conv("c1", "in", 3, 8),
        layer("Activation", "a1", ["c1"], activation="relu"),
        conv("c2", "a1", 1, 4, padding="valid"),
        layer("Concatenate", "cat", ["a1", "c2"], axis=3),
        conv("c3", "cat", 3, 8, dilation=2),
        layer("MultiplyBeta", "beta", ["c3"]),
        layer("Add", "add", ["beta", "a1"]),
        layer("UpSampling2D", "up", ["add"], size=[2, 2], data_format="channels_last", interpolation="nearest"),
        conv("c4", "up", 3, 12, activation="relu"),
        layer("PixelShuffle2x", "ps", ["c4"]),
        conv("out", "ps", 3, 3, padding="valid"),
    ]
    shapes = {"c1": (3, 3, 3, 8), "c2": (1, 1, 8, 4), "c3": (3, 3, 12, 8), "c4": (3, 3, 8, 12), "out": (3, 3, 3, 3)}
    ref, stored = {}, []
    for name, shape in shapes.items():
        kernel = rng.normal(0, 0.3, shape).astype(np.float32)
        bias = rng.normal(0, 0.5, shape[3]).astype(np.float32)
        if name == "c3":
            q, quant, kernel = quantise_uint8(kernel)
            stored.append((f"{name}/kernel", q, quant))
        else:
            stored.append((f"{name}/kernel", kernel, None))
        if name == "c4":
            half = bias.astype(np.float16)
            stored.append((f"{name}/bias", half, {"dtype": "float16"}))
            bias = half.astype(np.float32)
        else:
            stored.append((f"{name}/bias", bias, None))
        ref[name] = (kernel, bias)
    return write_model(folder, layers, stored, "out"), ref


# ---------------------------------------------------------------------------------------------------------------
# Independent NHWC reference


def ref_conv(x, kernel, bias, padding, dilation=1):
    kh, kw = kernel.shape[:2]
    if padding == "same":
        ty, tx = dilation * (kh - 1), dilation * (kw - 1)
        x = np.pad(x, ((ty // 2, ty - ty // 2), (tx // 2, tx - tx // 2), (0, 0)))
    h = x.shape[0] - dilation * (kh - 1)
    w = x.shape[1] - dilation * (kw - 1)
    out = np.zeros((h, w, kernel.shape[3]), np.float64) + bias
    for dy in range(kh):
        for dx in range(kw):
            window = x[dy * dilation:dy * dilation + h, dx * dilation:dx * dilation + w, :]
            out += np.einsum("yxi,io->yxo", window, kernel[dy, dx])
    return out


def ref_depth_to_space(x, b):
    h, w, c = x.shape
    cout = c // (b * b)
    out = np.zeros((h * b, w * b, cout))
    for i in range(b):
        for j in range(b):
            out[i::b, j::b, :] = x[:, :, (i * b + j) * cout:(i * b + j + 1) * cout]
    return out


def ref_tiny(x, w):
    a1 = np.maximum(ref_conv(x, *w["c1"], "same"), 0)
    c2 = ref_conv(a1, *w["c2"], "valid")
    c3 = ref_conv(np.concatenate([a1, c2], axis=2), *w["c3"], "same", dilation=2)
    up = np.repeat(np.repeat(c3 * 0.2 + a1, 2, axis=0), 2, axis=1)
    c4 = np.maximum(ref_conv(up, *w["c4"], "same"), 0)
    return ref_conv(ref_depth_to_space(c4, 2), *w["out"], "valid")


# ---------------------------------------------------------------------------------------------------------------


def run_importer(model, out, *extra):
    cmd = [sys.executable, IMPORTER, "--model", model, "--out", out, "--name", "tiny", "--source", "test",
           "--license", "MIT", "--stage", "super_resolution", "--input-range", "0", "255", *extra]
    return subprocess.run(cmd, capture_output=True, text=True)


class ImporterTest(unittest.TestCase):
    def setUp(self):
        self.tmp = tempfile.TemporaryDirectory()
        self.dir = self.tmp.name
        self.model, self.weights = tiny_model(self.dir)
        self.out = os.path.join(self.dir, "out", "tiny.pt")

    def tearDown(self):
        self.tmp.cleanup()

    def assert_clean_failure(self, result, *needles):
        self.assertEqual(result.returncode, 2, result.stderr)
        message = result.stderr.strip()
        self.assertEqual(message.count("\n"), 0, f"error must be one line: {message}")
        for needle in needles:
            self.assertIn(needle, message)
        leftovers = os.listdir(os.path.dirname(self.out)) if os.path.isdir(os.path.dirname(self.out)) else []
        self.assertEqual(leftovers, [], "nothing may be left in the output folder")

    def edit_model(self, change):
        with open(self.model) as f:
            doc = json.load(f)
        change(doc["modelTopology"]["model_config"]["config"]["layers"], doc)
        with open(self.model, "w") as f:
            json.dump(doc, f)

    def test_matches_numpy_reference_on_two_sizes(self):
        result = run_importer(self.model, self.out, "--scale", "4")
        self.assertEqual(result.returncode, 0, result.stderr)
        extra = {"synthdrive_contract.json": ""}
        module = torch.jit.load(self.out, _extra_files=extra)
        doc = json.loads(extra["synthdrive_contract.json"])
        self.assertEqual(doc["params"]["scale"], 4)
        # c1 (1) + dilated c3 (2) + c4 after 2x (1/2) + out after 4x (1/4) = 3.75 input pixels.
        self.assertEqual(doc["params"]["receptive_radius"], 4)
        self.assertEqual(doc["inputs"][0]["range"], [0, 255])
        rng = np.random.default_rng(7)
        for h, w in ((9, 11), (6, 5)):
            # Unit-range input keeps outputs O(10), where float32 vs float64 differ far below TOLERANCE.
            x = rng.uniform(0, 1, (h, w, 3)).astype(np.float32)
            expected = ref_tiny(x.astype(np.float64), self.weights)
            with torch.no_grad():
                got = module(torch.from_numpy(x).permute(2, 0, 1)[None])[0].permute(1, 2, 0).numpy()
            self.assertEqual(got.shape, expected.shape)
            err = np.abs(got - expected).max()
            self.assertLess(err, TOLERANCE, f"{h}x{w}: max abs error {err} (output max {np.abs(expected).max()})")

    def test_scale_mismatch_is_refused(self):
        self.assert_clean_failure(run_importer(self.model, self.out, "--scale", "2"), "--scale 2", "4")

    def test_truncated_shard(self):
        shard = os.path.join(self.dir, "group1-shard2of2.bin")
        size = os.path.getsize(shard)
        with open(shard, "r+b") as f:
            f.truncate(size - 6)
        total = size + os.path.getsize(os.path.join(self.dir, "group1-shard1of2.bin"))
        self.assert_clean_failure(run_importer(self.model, self.out), "group1-shard2of2.bin",
                                  str(total - 6), str(total))

    def test_missing_shard(self):
        os.remove(os.path.join(self.dir, "group1-shard1of2.bin"))
        self.assert_clean_failure(run_importer(self.model, self.out), "group1-shard1of2.bin", "missing")

    def test_unknown_layer_class(self):
        self.edit_model(lambda layers, _: layers[2].update(class_name="Lambda"))
        self.assert_clean_failure(run_importer(self.model, self.out), "'a1'", "'Lambda'", "Conv2D")

    def test_unsupported_stride(self):
        self.edit_model(lambda layers, _: layers[1]["config"].update(strides=[2, 2]))
        self.assert_clean_failure(run_importer(self.model, self.out), "'c1'", "strides")

    def test_kernel_shape_mismatch(self):
        self.edit_model(lambda layers, _: layers[1]["config"].update(kernel_size=[5, 5]))
        self.assert_clean_failure(run_importer(self.model, self.out), "'c1'", "[3, 3, 3, 8]", "[5, 5, 3, 8]")

    def test_model_json_not_json(self):
        with open(self.model, "w") as f:
            f.write("<html>not a model</html>")
        self.assert_clean_failure(run_importer(self.model, self.out), "model.json", "JSON")

    def test_graph_model_format_refused(self):
        self.edit_model(lambda _, doc: doc.update(format="graph-model"))
        self.assert_clean_failure(run_importer(self.model, self.out), "model.json", "graph-model")


if __name__ == "__main__":
    unittest.main()
