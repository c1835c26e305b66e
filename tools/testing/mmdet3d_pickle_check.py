#!/usr/bin/env python3
"""The Python side of src/datasets/mmdet3d_pickle_test.cpp: CPython's pickle and numpy judge the mmdet3d info
pickles our writer makes (datasets/mmdet3d.cpp WriteInfoEdit). It needs numpy (Debian's /usr/bin/python3 has it);
it unpickles only the repo's and ../shared's info files, the writer's output under test, and what it wrote itself.

  mmdet3d_pickle_check.py check SPEC.json     exit 0 when the output info agrees with the input and the spec;
                                              else exit 1 with one line per mismatch
  mmdet3d_pickle_check.py redump IN OUT PROTO [gzip]
                                              pickle.load(IN) written again in protocol PROTO (gzipped)
  mmdet3d_pickle_check.py evil OUT MARKER     a v1 info whose record holds os.system('touch MARKER') as a REDUCE:
                                              what a hostile .pkl looks like (CPython would run it on load)

SPEC (written by the C++ test):
  {"input": IN.pkl, "output": OUT.pkl, "list_key": "data_list" | "infos" | "" (the root is the record list),
   "classes": [names by label index after the edit] (optional: v1 layouts),
   "json_output": OUT.json (optional: the text writer's output for the same edits; its added elements must
                  equal the pickle's, value for value),
   "records": [{"input_index": i, "insert_at": k or null,
                "lists": {"instances": [{field: value}, ...], "cam_instances/CAM_FRONT": [...],
                          "gt_boxes": [[row], ...], "annos/name": [...], ...}}]}
Checks: every top-level key but the record list and metainfo's class list is equal (type, dtype, shape, value);
the class list is the input's followed by the new names; the output holds exactly the listed records, in order;
every field of an edited record that the spec does not list is equal; listed lists keep their input elements
(before and after the insertion point) and hold the expected added ones (numbers to 1e-6) typed like their
neighbours (numpy scalars stay numpy scalars of the same dtype, list elements keep their element types, numpy
columns keep their dtype; unicode may widen).
"""
import gzip
import json
import math
import os
import pickle
import sys

import numpy as np


def load(path):
    with open(path, "rb") as f:
        data = f.read()
    if data[:2] == b"\x1f\x8b":
        data = gzip.decompress(data)
    return pickle.loads(data)


def same(a, b):
    """Equal values of equal types (numpy: dtype, shape, elements; NaN equals NaN)."""
    if type(a) is not type(b):
        return False
    if isinstance(a, np.ndarray):
        return (a.dtype == b.dtype and a.shape == b.shape
                and np.array_equal(a, b, equal_nan=a.dtype.kind in "fc"))
    if isinstance(a, np.generic):
        return a.dtype == b.dtype and (a == b or (a != a and b != b))
    if isinstance(a, dict):
        return list(a.keys()) == list(b.keys()) and all(same(a[k], b[k]) for k in a)
    if isinstance(a, (list, tuple)):
        return len(a) == len(b) and all(same(x, y) for x, y in zip(a, b))
    if isinstance(a, float):
        return a == b or (math.isnan(a) and math.isnan(b))
    return a == b


def sig(v):
    """What a value is, type-wise: the neighbours' signature is what an added value must have."""
    if isinstance(v, np.ndarray):
        return ("ndarray", v.dtype.kind if v.dtype.kind == "U" else v.dtype.str, v.ndim)
    if isinstance(v, np.generic):
        return ("scalar", v.dtype.str)
    if isinstance(v, (list, tuple)):
        return (type(v).__name__, tuple(sorted({sig(x) for x in v}, key=repr)))
    if isinstance(v, dict):
        return ("dict",)
    return (type(v).__name__,)


def close(expected, actual):
    if isinstance(actual, np.ndarray):
        actual = actual.tolist()
    elif isinstance(actual, np.generic):
        actual = actual.item()
    if isinstance(expected, list):
        return (isinstance(actual, (list, tuple)) and len(actual) == len(expected)
                and all(close(e, a) for e, a in zip(expected, actual)))
    if isinstance(expected, (bool, str)) or expected is None:
        return expected == actual
    if isinstance(actual, bool) or not isinstance(actual, (int, float)):
        return False
    return abs(expected - actual) <= 1e-6


def plain(v):
    """A pickle value as json.load would give its JSON twin."""
    if isinstance(v, np.ndarray):
        return v.tolist()
    if isinstance(v, np.generic):
        return v.item()
    if isinstance(v, dict):
        return {k: plain(x) for k, x in v.items()}
    if isinstance(v, (list, tuple)):
        return [plain(x) for x in v]
    return v


def get(d, path):
    for key in path:
        if not isinstance(d, dict) or key not in d:
            return None
        d = d[key]
    return d


def class_list(root):
    meta = root.get("metainfo") if isinstance(root, dict) else None
    if not isinstance(meta, dict):
        return None, []
    if isinstance(meta.get("categories"), dict):
        cats = {k: int(v) for k, v in meta["categories"].items() if int(v) >= 0}
        return "categories", [k for k, _ in sorted(cats.items(), key=lambda kv: kv[1])]
    for key in ("classes", "CLASSES"):
        if key in meta:
            return key, list(meta[key])
    return None, []


def check(spec_path):
    with open(spec_path) as f:
        spec = json.load(f)
    errors = []
    src, out = load(spec["input"]), load(spec["output"])
    key = spec["list_key"]
    in_list = src[key] if key else src
    out_list = out[key] if key else out
    if type(src) is not type(out) or type(in_list) is not type(out_list):
        errors.append(f"root or record list changed type: {type(src).__name__} -> {type(out).__name__}")
        return errors
    # Around the record list.
    if key:
        if list(out.keys()) != list(src.keys()) + [k for k in out if k not in src]:
            errors.append(f"top-level keys {list(src)} -> {list(out)}")
        for k in src:
            if k in (key, "metainfo"):
                continue
            if not same(src[k], out.get(k)):
                errors.append(f"top-level {k!r} changed")
        in_key, in_classes = class_list(src)
        out_key, out_classes = class_list(out)
        if "classes" in spec and out_classes != spec["classes"]:
            errors.append(f"class list {out_classes}, expected {spec['classes']}")
        if in_classes and out_classes[: len(in_classes)] != in_classes:
            errors.append(f"class list {in_classes} not kept as the prefix of {out_classes}")
        meta_in, meta_out = src.get("metainfo"), out.get("metainfo")
        if isinstance(meta_in, dict):
            for k in meta_in:
                if k != in_key and not same(meta_in[k], meta_out.get(k)):
                    errors.append(f"metainfo {k!r} changed")
            if in_key == "categories":
                for name, index in meta_in["categories"].items():  # negative indices (DontCare) too
                    if not same(index, meta_out["categories"].get(name)):
                        errors.append(f"metainfo.categories[{name!r}] changed")
    records = spec["records"]
    if len(out_list) != len(records):
        errors.append(f"{len(out_list)} records written, expected {len(records)}")
        return errors
    twin = None
    if spec.get("json_output"):
        with open(spec["json_output"]) as f:
            twin = json.load(f)
        twin = twin[key] if key else twin
    for r, (want, got) in enumerate(zip(records, out_list)):
        where = f"record {r} (input {want['input_index']})"
        rec = in_list[want["input_index"]]
        lists = {tuple(p.split("/")): items for p, items in want["lists"].items()}
        parents = {p[0] for p in lists}
        if list(got.keys())[: len(rec)] != list(rec.keys()):
            errors.append(f"{where}: keys {list(rec)} -> {list(got)}")
        for k in rec:
            if k in parents:
                continue
            if not same(rec[k], got.get(k)):
                errors.append(f"{where}: field {k!r} changed")
        for parent in parents:  # other children of an edited parent (cam_instances.CAM_BACK, ...) unchanged
            children = {p[1] for p in lists if len(p) == 2 and p[0] == parent}
            if children and isinstance(rec.get(parent), dict):
                for k, v in rec[parent].items():
                    if k not in children and not same(v, got[parent].get(k)):
                        errors.append(f"{where}: {parent}.{k} changed")
        for path, items in lists.items():
            name = f"{where}: {'.'.join(path)}"
            before, after = get(rec, path), get(got, path)
            if after is None:
                errors.append(f"{name} missing")
                continue
            n_in = 0 if before is None else len(before)
            at = want.get("insert_at")
            at = n_in if at is None else min(at, n_in)
            if len(after) != n_in + len(items):
                errors.append(f"{name}: {len(after)} elements, expected {n_in} + {len(items)}")
                continue
            if isinstance(after, np.ndarray):
                if before is not None and not isinstance(before, np.ndarray):
                    errors.append(f"{name}: a {type(before).__name__} became an ndarray")
                elif before is not None:
                    if before.dtype.kind == "U":
                        if after.dtype.kind != "U" or after.dtype.itemsize < before.dtype.itemsize:
                            errors.append(f"{name}: dtype {before.dtype} -> {after.dtype}")
                    elif before.dtype != after.dtype:
                        errors.append(f"{name}: dtype {before.dtype} -> {after.dtype}")
                    if before.shape[1:] != after.shape[1:] and n_in > 0:
                        errors.append(f"{name}: row shape {before.shape[1:]} -> {after.shape[1:]}")
                    nan = before.dtype.kind in "fc"
                    if not (np.array_equal(after[:at], before[:at], equal_nan=nan)
                            and np.array_equal(after[at + len(items):], before[at:], equal_nan=nan)):
                        errors.append(f"{name}: existing rows changed")
            else:
                kept = list(after[:at]) + list(after[at + len(items):])
                if before is not None and (type(before) is not type(after) or not same(list(before), kept)):
                    errors.append(f"{name}: existing elements changed")
                neighbour = before[0] if before else None
                if neighbour is None:  # typed like the same list of another record
                    for other in in_list:
                        o = get(other, path)
                        if o:
                            neighbour = o[0]
                            break
                for k, element in enumerate(after[at: at + len(items)]):
                    if neighbour is None:
                        continue
                    if isinstance(neighbour, dict):
                        missing = [f for f in neighbour if f not in element]
                        if missing:
                            errors.append(f"{name}[+{k}]: lacks the neighbours' fields {missing}")
                        for f in neighbour:
                            if f in element and sig(element[f]) != sig(neighbour[f]):
                                errors.append(f"{name}[+{k}].{f}: {sig(element[f])}, neighbours {sig(neighbour[f])}")
                    elif sig(element) != sig(neighbour):
                        errors.append(f"{name}[+{k}]: {sig(element)}, neighbours {sig(neighbour)}")
            added = after[at: at + len(items)]
            for k, (e, a) in enumerate(zip(items, added)):
                if isinstance(e, dict):
                    for f, v in e.items():
                        if f not in a or not close(v, a[f]):
                            errors.append(f"{name}[+{k}].{f} = {plain(a.get(f))}, expected {v}")
                elif not close(e, a):
                    errors.append(f"{name}[+{k}] = {plain(a)}, expected {e}")
            if twin is not None:
                t = get(twin[r], path)
                t_added = None if t is None else t[at: at + len(items)]
                if t_added != plain(list(added)):
                    errors.append(f"{name}: added elements differ from the JSON writer's: {plain(list(added))} vs {t_added}")
    return errors


class Hostile:
    """Pickles to a REDUCE of os.system: loading it with CPython would run the command."""

    def __init__(self, command):
        self.command = command

    def __reduce__(self):
        return (os.system, (self.command,))


def main():
    mode = sys.argv[1]
    if mode == "check":
        errors = check(sys.argv[2])
        for e in errors:
            print(e)
        return 1 if errors else 0
    if mode == "redump":
        value = load(sys.argv[2])
        data = pickle.dumps(value, protocol=int(sys.argv[4]))
        if len(sys.argv) > 5 and sys.argv[5] == "gzip":
            data = gzip.compress(data)
        with open(sys.argv[3], "wb") as f:
            f.write(data)
        return 0
    if mode == "evil":
        info = {"metainfo": {"categories": {"car": 0}},
                "data_list": [{"token": "a", "instances": [], "note": Hostile("touch " + sys.argv[3])}]}
        with open(sys.argv[2], "wb") as f:
            pickle.dump(info, f, protocol=2)
        return 0
    print("unknown mode " + mode)
    return 2


if __name__ == "__main__":
    sys.exit(main())
