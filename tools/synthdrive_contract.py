"""The SynthDrive model contract ("synthdrive-model/1", docs/models.md) as every Python tool writes it.

A model file is a TorchScript archive with the contract as the extra file `synthdrive_contract.json`;
src/models/runtime.cpp (ModelContract::Parse) reads it. This is the one place the tools build that JSON, so
the exporters, importers and test-model generators cannot drift apart from each other or from the C++ reader.
The checks below repeat the ones the C++ side makes when it loads the file (dimensions positive or -1, range
low below high, at least one input and output, float32 only) at export time, where a mistake is cheapest;
params must be numbers because the C++ side silently drops any other member.

Use (a script adds this folder, tools/, to sys.path from its own location first):
    doc = contract("segmentation", "isnet", [tensor_spec("image", [1, 3, S, S], (0, 1), "NCHW", "srgb")],
                   [tensor_spec("mask", [1, 1, S, S], (0, 1), "NCHW", "linear")], {"input_size": S},
                   source="...", license="...", importer="tools/import/onnx_to_torchscript.py")
    save_scripted(module_or_traced, "isnet.pt", doc)
"""
import json
import numbers

import torch

FORMAT = "synthdrive-model/1"
CONTRACT_FILE = "synthdrive_contract.json"
DTYPE = "float32"  # the only dtype that crosses the runtime boundary
PROVENANCE = ("exporter", "importer")  # the script that wrote the file


def tensor_spec(name, shape, value_range, layout="", encoding=""):
    """One input or output: shape with -1 for "any", value_range (low, high), layout ("NCHW", ...) and
    encoding ("srgb", "linear", ...); an empty layout or encoding means "not stated"."""
    shape = [int(d) for d in shape]
    if any(d == 0 or d < -1 for d in shape):
        raise ValueError(f"tensor {name!r}: a dimension is a positive size or -1 (any), found {shape}")
    value_range = list(value_range)
    if len(value_range) != 2 or not value_range[0] < value_range[1]:
        raise ValueError(f"tensor {name!r}: range must be [low, high] with low below high, found {value_range}")
    return {"name": name, "shape": shape, "dtype": DTYPE, "layout": layout, "range": value_range,
            "encoding": encoding}


def contract(stage, name, inputs, outputs, params, source, license, **extra):
    """The contract document. `params` are the stage's numeric settings (docs/models.md, per stage); `extra`
    holds the provenance members the C++ side stores but does not interpret, e.g. exporter= / importer= (the
    script), verification= (numbers measured against the original model), onnx_ops=."""
    for key, value in params.items():
        if isinstance(value, bool) or not isinstance(value, numbers.Real):
            raise ValueError(f"{stage} contract {name!r}: params.{key} must be a number, found {value!r}")
    if not inputs or not outputs:
        raise ValueError(f"{stage} contract {name!r}: needs at least one input and one output")
    doc = {"format": FORMAT, "stage": stage, "name": name, "source": source, "license": license}
    # The tool that wrote the file goes with the provenance, everything else after params (the order the
    # tools have always written and docs/models.md shows; the C++ side does not depend on it).
    doc.update((key, value) for key, value in extra.items() if key in PROVENANCE)
    doc.update(inputs=list(inputs), outputs=list(outputs), params=dict(params))
    for key, value in extra.items():
        if key in PROVENANCE:
            continue
        if key in doc:
            raise ValueError(f"{stage} contract {name!r}: {key} is a contract member, not an extra one")
        doc[key] = value
    return doc


def save_scripted(module, path, contract_dict, indent=None):
    """Saves a TorchScript file with its contract. An eager nn.Module is scripted first; a traced or scripted
    module is saved as it is. contract_dict None writes no contract (only the runtime's error-case tests want
    that). Returns the saved ScriptModule."""
    if not isinstance(module, torch.jit.ScriptModule):
        module = torch.jit.script(module)
    files = {}
    if contract_dict is not None:
        if contract_dict.get("format") != FORMAT:
            raise ValueError(f"{path}: contract format {contract_dict.get('format')!r}, expected {FORMAT!r}")
        files[CONTRACT_FILE] = json.dumps(contract_dict, indent=indent)
    torch.jit.save(module, path, _extra_files=files)
    return module
