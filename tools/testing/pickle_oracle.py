#!/usr/bin/env python3
"""The Python side of the pickle tests (src/io/pickle_test.cpp, src/io/pandas_frame_test.cpp).

CPython's pickle, numpy and pandas are the oracle: this script writes the reference pickles the C++ reader must
decode, and loads the pickles the C++ writer made, with plain pickle.load / pandas.read_pickle. It needs numpy
and pandas (Debian's /usr/bin/python3 has both); it never unpickles anything it did not write itself except the
C++ writer's output, which is what is under test.

  pickle_oracle.py cases DIR          CASE.pN.pkl for protocols 0-5 + CASE.json (the expected value, tagged);
                                      REFUSED.pN.pkl + REFUSED.refuse.json (what the C++ error must name)
  pickle_oracle.py check DIR          loads every *.wN.pkl the C++ writer left in DIR and compares it with the
                                      value it was made from (CASE.*: the case again; others: NAME.tag.json);
                                      exit status 1 and one line per mismatch when any differs
  pickle_oracle.py tag PKL OUT        pickle.load(PKL) (gunzipped when it is gzip), tagged, to OUT (JSON)
  pickle_oracle.py frames DIR         synthetic DataFrames FRAME.pN.pkl, each with FRAME.pN.frame/ (as `frame`)
  pickle_oracle.py frame PKL OUTDIR   pandas.read_pickle(PKL) as plain columns: OUTDIR/frame.json (names, dtypes,
                                      index, object columns tagged) + OUTDIR/<i>.bin (numeric columns, little-endian)
  pickle_oracle.py frame_equals A B [A2 B2 ...]
                                      exit 0 when pandas reads each A and B to equal frames (df.equals, same
                                      column names, dtypes, index type, index values and names)

The tagged form keeps what JSON alone would lose, so that equal tags mean equal Python values of the same types:
  None -> null, bool -> true/false, int -> ["int", n], float -> ["float", <IEEE bits as int64>] or ["float", "nan"],
  str -> ["str", s], bytes/bytearray -> ["bytes", hex], list/tuple -> ["list"/"tuple", [...]],
  dict/OrderedDict -> ["dict", [[k, v], ...]] (insertion order), set/frozenset -> ["set"/"frozenset", [...]],
  slice -> ["slice", start, stop, step], numpy scalar -> ["scalar", dtype, value],
  ndarray -> ["array", dtype, shape, fortran, [elements in C order]]
where dtype is numpy's name without byte order ("float32", "bool", "object", "U5").
"""
import collections
import gzip
import json
import math
import os
import pickle
import pickletools
import struct
import subprocess
import sys

import numpy as np
import pandas as pd


def dtype_name(dt):
    return f"U{dt.itemsize // 4}" if dt.kind == "U" else dt.name


def tag_float(x):
    x = float(x)
    if math.isnan(x):
        return ["float", "nan"]
    return ["float", struct.unpack("<q", struct.pack("<d", x))[0]]


def tag_element(dt, x):
    if dt.kind == "f":
        return tag_float(x)
    if dt.kind in "iu":
        return ["int", int(x)]
    if dt.kind == "b":
        return bool(x)
    if dt.kind == "U":
        return ["str", str(x)]
    return tag(x)


def tag(o):
    if o is None:
        return None
    if isinstance(o, np.ndarray):
        fortran = bool(o.flags.f_contiguous and not o.flags.c_contiguous)
        flat = o.reshape(-1, order="C") if o.size else []
        return ["array", dtype_name(o.dtype), list(o.shape), fortran, [tag_element(o.dtype, x) for x in flat]]
    if isinstance(o, np.generic):
        return ["scalar", dtype_name(o.dtype), tag_element(o.dtype, o.item() if o.dtype.kind != "U" else str(o))]
    if isinstance(o, bool):
        return o
    if isinstance(o, int):
        return ["int", o]
    if isinstance(o, float):
        return tag_float(o)
    if isinstance(o, str):
        return ["str", o]
    if isinstance(o, (bytes, bytearray)):
        return ["bytes", bytes(o).hex()]
    if isinstance(o, list):
        return ["list", [tag(x) for x in o]]
    if isinstance(o, tuple):
        return ["tuple", [tag(x) for x in o]]
    if isinstance(o, dict):
        return ["dict", [[tag(k), tag(v)] for k, v in o.items()]]
    if isinstance(o, frozenset):
        return ["frozenset", [tag(x) for x in o]]
    if isinstance(o, set):
        return ["set", [tag(x) for x in o]]
    if isinstance(o, slice):
        return ["slice", tag(o.start), tag(o.stop), tag(o.step)]
    raise TypeError(f"no tag for {type(o)}")


# --- Reference values. Each case is rebuilt from scratch by `check`, so it must be deterministic (sets hold
# small ints only: their iteration order does not depend on hash randomisation).

def case_scalars():
    return [None, True, False, 0, 1, -1, 255, 256, 65535, 65536, -129, -32769, 2**31 - 1, -2**31, 2**31, -2**31 - 1,
            2**40, -2**40, 2**62, 2**63 - 1, -2**63, 1.5, -0.0, 0.0, float("nan"), float("inf"), float("-inf"),
            1e300, 5e-324, 0.1, -2.5e-10]


def case_strings():
    return ["", "ascii", "na\u00efve caf\u00e9", "\u65e5\u672c\u8a9e", "emoji \U0001F697", "line\nbreak\\back\r\x00nul\x1a",
            "a" * 300, "quote'\"", "\x7f\x80\xff", ["nested", ("tuple", "\u00e9")]]


def case_bytes():
    return [b"", b"\x00\xff\x80abc", bytes(range(256)), b"x" * 300, bytearray(b"ba\x00\xff"), bytearray()]


def case_containers():
    return {
        "list": [1, [2, [3, []]]], "t0": (), "t1": (1,), "t2": (1, 2), "t3": (1, 2, 3), "t4": (1, 2, 3, 4),
        "keys": {"a": 1, 2: "int key", -7: "negative", (1, "x"): "tuple key", None: 0, 1.5: "float key", True: "bool"},
        "nested": {"x": {"y": {"z": [(), {}, [[]]]}}},
        "big_list": list(range(2500)), "big_dict": {f"k{i}": i for i in range(1500)},
        "sets": [{3, 1, 2}, frozenset({5, 4}), set()], "slice": slice(1, 10, 2), "slice_none": slice(None, 5, None),
    }


def case_shared():
    a = [1, 2]
    s = "shared string"
    return {"a": a, "b": a, "t": (a, a), "s1": s, "s2": s}


def case_ordered():
    return collections.OrderedDict([("z", 1), ("a", [collections.OrderedDict([("q", None)])])])


def case_numpy_dtypes():
    return {
        "float16": np.array([1.5, -0.0, np.inf, 65504.0, 6e-8], dtype=np.float16),
        "float32": np.array([0.1, -1e30, np.nan, 3.4028235e38], dtype=np.float32),
        "float64": np.array([0.1, -2.5, np.nan, -np.inf, 5e-324], dtype=np.float64),
        "int8": np.array([-128, 0, 127], dtype=np.int8),
        "int16": np.array([-32768, 1, 32767], dtype=np.int16),
        "int32": np.array([-2**31, 2, 2**31 - 1], dtype=np.int32),
        "int64": np.array([-2**63, 3, 2**63 - 1], dtype=np.int64),
        "uint8": np.array([0, 200, 255], dtype=np.uint8),
        "uint16": np.array([0, 65535], dtype=np.uint16),
        "uint32": np.array([0, 2**32 - 1], dtype=np.uint32),
        "uint64": np.array([0, 2**64 - 1], dtype=np.uint64),
        "bool": np.array([True, False, True]),
        "object": np.array(["s", None, 1.5, ["x"], ("t",)], dtype=object),
        "unicode": np.array(["", "ab", "\u00e9\u65e5\U0001F697x"]),
    }


def case_numpy_layouts():
    c = np.arange(6, dtype=np.float64).reshape(2, 3)
    return {
        "c2d": c, "f2d": np.asfortranarray(c), "f3d": np.asfortranarray(np.arange(24, dtype=np.int32).reshape(2, 3, 4)),
        "strided": np.arange(12, dtype=np.int16).reshape(3, 4)[:, ::2],
        "be_f8": np.array([1.5, -2.25, np.inf], dtype=">f8"), "be_i4": np.array([-1, 2, 2**31 - 1], dtype=">i4"),
        "be_u2": np.array([1, 65534], dtype=">u2"), "be_f2": np.array([0.5, -3.0], dtype=">f2"),
        "be_U3": np.array(["ab\u00e9", "x"], dtype=">U3"),
        "be_f4_fortran": np.asfortranarray(np.arange(6, dtype=">f4").reshape(2, 3)),
        "d0_float": np.array(3.5), "d0_int": np.array(-7, dtype=np.int8), "d0_str": np.array("z\u00e9"),
        "empty": np.zeros((0,), dtype=np.float64), "empty2": np.zeros((2, 0), dtype=np.int64),
        "object_fortran": np.asfortranarray(np.array([[1, "x"], [None, 2.5]], dtype=object)),
        "bool2d": np.array([[True, False], [False, True]]),
    }


def case_numpy_scalars():
    return [np.float16(1.5), np.float32(0.1), np.float64(-2.5), np.float64(np.nan), np.int8(-5), np.int16(-300),
            np.int32(70000), np.int64(-2**63), np.uint8(255), np.uint16(65535), np.uint32(2**32 - 1),
            np.uint64(2**64 - 1), np.bool_(True), np.bool_(False), np.str_("h\u00e9llo")]


def case_mmdet_like():
    return {"metainfo": {"version": "1.0"}, "infos": [{
        "token": "abc", "gt_boxes": np.arange(21, dtype=np.float32).reshape(3, 7),
        "gt_names": np.array(["car", "pedestrian"]), "valid_flag": np.array([True, False]),
        "num_lidar_pts": np.array([1, 2], dtype=np.int64), "timestamp": 1533201470448696,
        "velocity": np.array([[np.nan, np.nan]]), "ego2global": [[1.0, 0.0], [0.0, 1.0]]}]}


CASES = {
    "scalars": case_scalars, "strings": case_strings, "bytes": case_bytes, "containers": case_containers,
    "shared": case_shared, "ordered": case_ordered, "numpy_dtypes": case_numpy_dtypes,
    "numpy_layouts": case_numpy_layouts, "numpy_scalars": case_numpy_scalars, "mmdet_like": case_mmdet_like,
}


class CallOnLoad:
    """What an attacker pickles: loading it with CPython's pickle would call `func(*args)`."""

    def __init__(self, func, args):
        self.func, self.args = func, args

    def __reduce__(self):
        return (self.func, self.args)


class PlainClass:
    pass


def refused_cases(marker):
    import subprocess as sp
    return {
        "os_system": (CallOnLoad(os.system, (f"touch {marker}",)), "refusing to load global"),
        "builtins_eval": (CallOnLoad(eval, (f"__import__('os').system('touch {marker}')",)), "refusing to load global"),
        "subprocess_popen": (CallOnLoad(sp.Popen, (["touch", marker],)), "refusing to load global"),
        "user_class": (PlainClass(), "refusing to load global"),
        "complex": (1 + 2j, "refusing to load global"),
        "big_int": (2**64, "int64"),
        "negative_big_int": (-2**63 - 1, "int64"),
        "datetime_array": (np.array(["2020-01-01"], dtype="datetime64[D]"), "unsupported numpy dtype"),
        "structured_array": (np.zeros(2, dtype=[("a", "<f4"), ("b", "<i4")]), "numpy dtype"),
    }


# Allowed globals that come before the refused one in the refused cases (protocol 0/1 instances of classes).
ALLOWED_BEFORE = {"copy_reg._reconstructor", "copyreg._reconstructor", "__builtin__.object", "builtins.object"}


def first_global(data):
    """(offset, 'module.name') of the first refused GLOBAL / STACK_GLOBAL / INST in a pickle."""
    strings = []
    for op, arg, pos in pickletools.genops(data):
        name = None
        if op.name in ("GLOBAL", "INST"):
            name = arg.replace(" ", ".")
        elif op.name == "STACK_GLOBAL":
            name = f"{strings[-2]}.{strings[-1]}"
        elif isinstance(arg, str):
            strings.append(arg)
        if name and name not in ALLOWED_BEFORE:
            return pos, name
    return None


def write_cases(out):
    os.makedirs(out, exist_ok=True)
    for name, make in CASES.items():
        value = make()
        for protocol in range(6):
            with open(os.path.join(out, f"{name}.p{protocol}.pkl"), "wb") as f:
                pickle.dump(value, f, protocol=protocol)
        with open(os.path.join(out, f"{name}.json"), "w") as f:
            json.dump(tag(value), f)
    marker = os.path.join(out, "pwned")
    for name, (value, error) in refused_cases(marker).items():
        for protocol in range(6):
            data = pickle.dumps(value, protocol=protocol)
            with open(os.path.join(out, f"{name}.p{protocol}.pkl"), "wb") as f:
                f.write(data)
            expect = {"error": error, "marker": marker}
            if error == "refusing to load global":
                expect["offset"], expect["global"] = first_global(data)
            with open(os.path.join(out, f"{name}.p{protocol}.refuse.json"), "w") as f:
                json.dump(expect, f)


def check(out):
    bad = 0
    checked = 0
    for file in sorted(os.listdir(out)):
        if not (file.endswith(".pkl") and ".w" in file):
            continue
        stem = file.split(".")[0]
        with open(os.path.join(out, file), "rb") as f:
            try:
                got = tag(pickle.load(f))
            except Exception as e:  # noqa: BLE001 - any failure to load is the finding
                print(f"{file}: pickle.load failed: {type(e).__name__}: {e}")
                bad += 1
                continue
        if stem in CASES:
            want = tag(CASES[stem]())
        else:
            with open(os.path.join(out, stem + ".tag.json")) as f:
                want = json.load(f)
        want = json.loads(json.dumps(want))  # the same JSON round trip as `got` takes below
        got = json.loads(json.dumps(got))
        checked += 1
        if got != want:
            bad += 1
            print(f"{file}: differs from what it was made from\n  got  {json.dumps(got)[:600]}\n  want {json.dumps(want)[:600]}")
    print(f"checked {checked} pickles, {bad} bad")
    return 1 if bad or checked == 0 else 0


# --- DataFrames

def synthetic_frames():
    n = 7
    rng = np.random.default_rng(5)
    mixed = pd.DataFrame({
        "f64": rng.normal(size=n), "i64": np.arange(n, dtype=np.int64) - 3, "flag": np.arange(n) % 2 == 0,
        "label": [f"obj{i}" if i % 3 else None for i in range(n)], "f32": np.linspace(0, 1, n, dtype=np.float32),
        "f64b": np.full(n, np.nan), "u8": np.arange(n, dtype=np.uint8), "i32": np.arange(n, dtype=np.int32) * -1000,
        "mixed_obj": [1, "a", 2.5, None, True, "\u00e9", float("nan")],
    })
    mixed.index.name = "index"
    # A frame made from a C-order 2-D array keeps its transpose as the block: column-major (3 x 4) values.
    fortran = pd.DataFrame(np.arange(12, dtype=np.float64).reshape(4, 3), columns=["a", "b", "c"])
    assert fortran._mgr.blocks[0].values.flags.f_contiguous and not fortran._mgr.blocks[0].values.flags.c_contiguous
    return {
        "mixed": mixed,
        "fortran_block": fortran,
        "explicit_index": pd.DataFrame({"v": [1.0, 2.0, 3.0]}, index=pd.Index([10, 20, 5], dtype=np.int64)),
        "string_index": pd.DataFrame({"v": [1, 2]}, index=pd.Index(["r1", "r2"])),
        "stepped_range": pd.DataFrame({"v": [1, 2, 3]}, index=pd.RangeIndex(4, 13, 3)),
        "empty_rows": pd.DataFrame({"a": np.zeros(0), "s": np.array([], dtype=object)}),
        "no_columns": pd.DataFrame(index=pd.RangeIndex(0, 3)),
    }


def write_frame(df, out):
    os.makedirs(out, exist_ok=True)
    columns = []
    for i, name in enumerate(df.columns):
        col = df.iloc[:, i]
        entry = {"name": name, "dtype": dtype_name(col.dtype)}
        if col.dtype == object:
            entry["objects"] = [tag(x) for x in col.tolist()]
        else:
            values = col.to_numpy()
            entry["file"] = f"{i}.bin"
            with open(os.path.join(out, entry["file"]), "wb") as f:
                f.write(values.astype(values.dtype.newbyteorder("<")).tobytes())
        columns.append(entry)
    index = df.index
    if isinstance(index, pd.RangeIndex):
        idx = {"kind": "range", "start": index.start, "stop": index.stop, "step": index.step}
    else:
        idx = {"kind": "labels", "values": tag(index.to_numpy())}
    idx["name"] = tag(index.name)
    with open(os.path.join(out, "frame.json"), "w") as f:
        json.dump({"rows": len(df), "columns": columns, "index": idx, "columns_name": tag(df.columns.name)}, f)


def write_frames(out):
    os.makedirs(out, exist_ok=True)
    for name, df in synthetic_frames().items():
        for protocol in range(6):
            path = os.path.join(out, f"{name}.p{protocol}.pkl")
            df.to_pickle(path, protocol=protocol)
            write_frame(pd.read_pickle(path), path[:-4] + ".frame")


def frame_equals(a_path, b_path):
    try:
        a, b = pd.read_pickle(a_path), pd.read_pickle(b_path)
    except Exception as e:  # noqa: BLE001 - a pickle pandas cannot read is the finding
        print(f"{b_path}: pandas.read_pickle failed: {type(e).__name__}: {e}")
        return 1
    problems = []
    if not isinstance(b, pd.DataFrame):
        problems.append(f"{b_path} holds a {type(b).__name__}, not a DataFrame")
    else:
        if list(a.columns) != list(b.columns):
            problems.append(f"columns {list(a.columns)} != {list(b.columns)}")
        elif not a.dtypes.equals(b.dtypes):
            problems.append(f"dtypes {list(a.dtypes)} != {list(b.dtypes)}")
        if not a.equals(b):
            problems.append("df.equals is False")
        if type(a.index) is not type(b.index) or not a.index.equals(b.index):
            problems.append(f"index {a.index!r} != {b.index!r}")
        if a.index.name != b.index.name or a.columns.name != b.columns.name:
            problems.append(f"axis names ({a.index.name}, {a.columns.name}) != ({b.index.name}, {b.columns.name})")
    for p in problems:
        print(f"{b_path}: {p}")
    return 1 if problems else 0


def main(argv):
    if len(argv) == 3 and argv[1] == "cases":
        write_cases(argv[2])
        return 0
    if len(argv) == 3 and argv[1] == "check":
        return check(argv[2])
    if len(argv) == 4 and argv[1] == "tag":
        with open(argv[2], "rb") as f:
            data = f.read()
        if data[:2] == b"\x1f\x8b":
            data = gzip.decompress(data)
        with open(argv[3], "w") as f:
            json.dump(tag(pickle.loads(data)), f)
        return 0
    if len(argv) == 3 and argv[1] == "frames":
        write_frames(argv[2])
        return 0
    if len(argv) == 4 and argv[1] == "frame":
        write_frame(pd.read_pickle(argv[2]), argv[3])
        return 0
    if len(argv) >= 4 and len(argv) % 2 == 0 and argv[1] == "frame_equals":
        bad = [frame_equals(argv[i], argv[i + 1]) for i in range(2, len(argv), 2)]
        print(f"compared {len(bad)} frames, {sum(bad)} differ")
        return 1 if any(bad) else 0
    print(__doc__, file=sys.stderr)
    return 2


if __name__ == "__main__":
    sys.exit(main(sys.argv))
