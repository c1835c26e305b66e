#!/usr/bin/env python3
"""The corruption battery: corrupted copies of the repo's real inputs, each run through `synthdrive`.

usage: corruption_battery.py <synthdrive binary> <repo data dir> [--jobs N] [--timeout S] [--only SUBSTRING] [--keep]

Item 5 of the issue "Hostile and careless input" (docs/robustness.md, "The corruption battery"). Every case copies
a real input into a temporary folder, breaks one thing, runs the command that reads it (mostly
`synthdrive -q synth --log ... --asset ... --scenario ... --out OUT`; also `asset import`, `eval geometry` and
`mine index`) and asserts:

  * the process ends by itself (no signal: returncode >= 0) within the time limit (a hang is a failure);
  * then, by what the case expects (`expect`):
      REFUSE  it was refused: exit status 2 (README, "Exit status": 2 is a refused input; 1 would be an internal
              error, i.e. an exception the readers did not turn into a located message), stderr is exactly one
              non-empty line, that line names the corrupted file (its basename) or the field (one of the case's
              `names`), the output path does not exist afterwards (or, where it existed before the run, it is
              byte-identical) and nothing `*.tmp-*` or `OUT.parts` is left beside it;
      EITHER  refused as above, or succeeded with exit 0 and a complete output (the same files the unbroken
              input's control run writes) -- only for corruptions that may legitimately be harmless: a byte flip
              that stays a valid value (a digit of a token, a JPEG entropy byte, a float mantissa bit of a point),
              a truncation of a sweep at a whole record (a shorter sweep is a valid sweep), a UTF-8 BOM, an empty
              KITTI label file (a frame with no objects);
      WARN    refused as above, or succeeded with a complete output *and* a warning naming the field (checked by a
              second, `--dry-run` pass without -q): for the fields docs/datasets.md lists as optional with a stated
              default (ego2global, images, a camera's lidar2cam, lidar_points, instances). A silent default fails.
  * Families that make the data wrong (non-rigid or singular matrices, resized images, missing required fields,
    duplicated samples, paths escaping the data root, non-finite or absurd numbers) are REFUSE: a "successful"
    dataset built on them is a failure, never accepted.

Deterministic: every random choice comes from random.Random(SEED + crc32(case name)). Python 3 standard library only.
Prints one line per case (PASS/FAIL, name, exit code, stderr's line) and a summary; exits 1 if any case fails.

KNOWN_GAPS lists case names whose failure is reported as GAP but does not fail the run. It is empty: every case
that fails today fails the run until the product refuses what it should.
"""

import argparse
import hashlib
import json
import os
import random
import shutil
import signal
import stat
import struct
import subprocess
import sys
import tempfile
import time
import zlib
from concurrent.futures import ThreadPoolExecutor

SEED = 20240521
KNOWN_GAPS = []  # case names reported as GAP instead of FAIL; empty by default (see the docstring)

REFUSE, EITHER, WARN, SUCCEED = "refuse", "either", "warn", "succeed"

NUS = "driving/nuscenes-scene0061-kf0"
NUS_INFO = "mmdet3d_info/n015-2018-07-24-11-22-45+0800.json"
NUS_V0 = "bevfusion_demo_info/nuscenes_infos_test.json"
NUS_SWEEP = "samples/LIDAR_TOP/n015-2018-07-24-11-22-45+0800__LIDAR_TOP__1532402927647951.pcd.bin"
NUS_FRONT = "samples/CAM_FRONT/n015-2018-07-24-11-22-45+0800__CAM_FRONT__1532402927612460.jpg"
KPKL = "driving/kitti-mmdet3d-pkl-000008"
KPKL_INFO = "v1x_format/000008.pkl"
KPKL_BIN = "v1x_format/000008.bin"
LYFT = "driving/lyft-tables"
LYFT_TABLES = "v1.01-train/v1.01-train"
KITTI = "driving/kitti-object"


# ----------------------------------------------------------------------------------------------------------------
# Small file tools (standard library only)

class Raw:
    """A JSON value written as this exact text (1e999, NaN, a deep list) where json.dumps cannot."""

    def __init__(self, text):
        self.text = text


def dump_json(obj, indent=1):
    raws = []

    def walk(x):
        if isinstance(x, Raw):
            raws.append(x.text)
            return "@@RAW%d@@" % (len(raws) - 1)
        if isinstance(x, dict):
            return {k: walk(v) for k, v in x.items()}
        if isinstance(x, list):
            return [walk(v) for v in x]
        return x

    text = json.dumps(walk(obj), indent=indent, allow_nan=True)
    for i, r in enumerate(raws):
        text = text.replace('"@@RAW%d@@"' % i, r)
    return text


def edit_json(path, fn):
    """fn edits the parsed file in place (its return value is ignored: list.pop and comprehensions return things)."""
    with open(path, encoding="utf-8") as f:
        obj = json.load(f)
    fn(obj)
    with open(path, "w", encoding="utf-8") as f:
        f.write(dump_json(obj))


def replace_json(path, fn):
    """The file becomes fn(parsed file)."""
    with open(path, encoding="utf-8") as f:
        obj = json.load(f)
    with open(path, "w", encoding="utf-8") as f:
        f.write(dump_json(fn(obj)))


def read(path):
    with open(path, "rb") as f:
        return f.read()


def write(path, data):
    if isinstance(data, str):
        data = data.encode()
    if os.path.lexists(path) and not os.path.isdir(path):
        os.remove(path)
    with open(path, "wb") as f:
        f.write(data)


def replace_with(path, kind):
    """Replaces a file by a FIFO, a directory, an empty file, a symlink loop or a symlink to a device."""
    if os.path.isdir(path) and not os.path.islink(path):
        shutil.rmtree(path)
    elif os.path.lexists(path):
        os.remove(path)
    if kind == "fifo":
        os.mkfifo(path)
    elif kind == "dir":
        os.mkdir(path)
        write(os.path.join(path, "inside.txt"), "a directory, not a file\n")
    elif kind == "empty":
        write(path, b"")
    elif kind == "symlink loop":  # path -> path.loop -> path
        os.symlink(os.path.basename(path) + ".loop", path)
        os.symlink(os.path.basename(path), path + ".loop")
    elif kind.startswith("/dev/"):
        os.symlink(kind, path)
    else:
        raise ValueError(kind)


def truncate(path, at):
    data = read(path)
    write(path, data[:at])


def content_len(path):
    """Length without trailing whitespace: a cut beyond it is no corruption of a text file."""
    return len(read(path).rstrip())


def flip_bytes(path, count, rng, lo=0, hi=None, avoid=b""):
    data = bytearray(read(path))
    hi = len(data) if hi is None else hi
    for _ in range(count):
        while True:
            i = rng.randrange(lo, hi)
            if data[i] not in avoid:
                break
        data[i] ^= rng.randrange(1, 256)
    write(path, bytes(data))


def flip_sweep_mantissas(path, count, rng, record=20):
    """XOR the lowest mantissa byte of `count` random float32 values: they stay finite (a harmless corruption)."""
    data = bytearray(read(path))
    for _ in range(count):
        i = rng.randrange(0, len(data) // 4) * 4
        data[i] ^= rng.randrange(1, 256)
    write(path, bytes(data))


def set_sweep_value(path, point, feature, value, record=20):
    data = bytearray(read(path))
    struct.pack_into("<f", data, point * record + feature * 4, value)
    write(path, bytes(data))


def png(width, height):
    """A PNG of a plausible road scene (sky above, grey road below), any size, quickly."""
    rows = []
    for y in range(height):
        c = (120, 160, 210) if y < height // 2 else (90, 90, 95)
        rows.append(b"\x00" + bytes(c) * width)
    raw = zlib.compress(b"".join(rows), 6)

    def chunk(tag, body):
        return struct.pack(">I", len(body)) + tag + body + struct.pack(">I", zlib.crc32(tag + body) & 0xFFFFFFFF)

    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)) +
            chunk(b"IDAT", raw) + chunk(b"IEND", b""))


def forged_png(width, height):
    """A PNG header declaring width x height over a few bytes of data (a decompression bomb's header)."""
    def chunk(tag, body):
        return struct.pack(">I", len(body)) + tag + body + struct.pack(">I", zlib.crc32(tag + body) & 0xFFFFFFFF)
    return (b"\x89PNG\r\n\x1a\n" + chunk(b"IHDR", struct.pack(">IIBBBBB", width, height, 8, 2, 0, 0, 0)) +
            chunk(b"IDAT", zlib.compress(b"\x00" * 64)) + chunk(b"IEND", b""))


def jpeg_sof(data):
    i = 2
    while i + 9 < len(data):
        if data[i] != 0xFF:
            raise ValueError("not a JPEG marker")
        m = data[i + 1]
        if 0xC0 <= m <= 0xCF and m not in (0xC4, 0xC8, 0xCC):
            return i
        i += 2 + struct.unpack(">H", data[i + 2:i + 4])[0]
    raise ValueError("no SOF")


def jpeg_set_size(path, width, height):
    data = bytearray(read(path))
    i = jpeg_sof(data)
    struct.pack_into(">HH", data, i + 5, height, width)
    write(path, bytes(data))


def jpeg_scan_start(data):
    i = data.find(b"\xff\xda")
    return i + 2 + struct.unpack(">H", data[i + 2:i + 4])[0]


def glb_split(data):
    magic, version, length = struct.unpack("<4sII", data[:12])
    assert magic == b"glTF"
    n0, t0 = struct.unpack("<I4s", data[12:20])
    j = json.loads(data[20:20 + n0])
    rest = data[20 + n0:]
    return j, rest


def glb_join(j, rest):
    body = json.dumps(j).encode()
    body += b" " * (-len(body) % 4)
    out = struct.pack("<I4s", len(body), b"JSON") + body + rest
    return struct.pack("<4sII", b"glTF", 2, 12 + len(out)) + out


def edit_glb_json(path, fn):
    j, rest = glb_split(read(path))
    fn(j)
    write(path, glb_join(j, rest))


def tree_digest(path):
    """sha256 over every file (relative path, type, bytes) under `path`, or of `path` itself."""
    h = hashlib.sha256()
    if not os.path.lexists(path):
        return None
    if os.path.isfile(path):
        h.update(read(path))
        return h.hexdigest()
    for root, dirs, files in os.walk(path):
        dirs.sort()
        for name in sorted(files + dirs):
            p = os.path.join(root, name)
            rel = os.path.relpath(p, path)
            h.update(rel.encode() + b"\0")
            if os.path.isfile(p) and not os.path.islink(p):
                h.update(read(p))
    return h.hexdigest()


def rel_files(path):
    out = set()
    for root, _, files in os.walk(path):
        for name in files:
            out.add(os.path.relpath(os.path.join(root, name), path))
    return out


def mat(m, fn):
    """Applies fn(row, col, value) -> value to a nested-list matrix in place."""
    for r, row in enumerate(m):
        for c, v in enumerate(row):
            m[r][c] = fn(r, c, v)


# ----------------------------------------------------------------------------------------------------------------
# The battery

class Run:
    """What a case runs: argv (without the binary and -q), its output path, and what the error may name."""

    def __init__(self, argv, out, names, kind, warn_argv=None):
        self.argv = argv
        self.out = out
        self.names = names
        self.kind = kind          # which control's output file set a success must hold ("nus", "kitti", ...)
        self.warn_argv = warn_argv
        self.warn_names = names   # what a WARN case's warning must name (the field)


class Case:
    def __init__(self, family, name, expect, prepare, preexisting=False):
        self.family = family
        self.name = name
        self.expect = expect
        self.prepare = prepare    # prepare(ctx, d, rng) -> Run
        self.preexisting = preexisting


class Battery:
    def __init__(self, binary, data, work, timeout):
        self.bin = os.path.abspath(binary)
        self.data = os.path.abspath(data)
        self.work = work
        self.timeout = timeout
        self.cases = []
        self.control_files = {}

    # --- inputs -------------------------------------------------------------------------------------------------
    def src(self, rel):
        return os.path.join(self.data, rel)

    def copy(self, rel, d, name):
        dst = os.path.join(d, name)
        shutil.copytree(self.src(rel), dst, symlinks=True)
        for root, dirs, files in os.walk(dst):
            for n in dirs + files:
                p = os.path.join(root, n)
                if not os.path.islink(p):
                    os.chmod(p, os.stat(p).st_mode | stat.S_IWUSR)
        return dst

    def run_bin(self, argv, quiet=True, timeout=None):
        cmd = [self.bin] + (["-q"] if quiet else []) + argv
        start = time.time()
        p = subprocess.Popen(cmd, stdin=subprocess.DEVNULL, stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                             start_new_session=True)
        try:
            out, err = p.communicate(timeout=timeout or self.timeout)
            hung = False
        except subprocess.TimeoutExpired:
            os.killpg(p.pid, signal.SIGKILL)
            out, err = p.communicate()
            hung = True
        return p.returncode, out.decode(errors="replace"), err.decode(errors="replace"), hung, time.time() - start

    def setup(self):
        """Assets and scenarios shared by every case (made once, never corrupted in place)."""
        self.assets = os.path.join(self.work, "assets")
        os.makedirs(self.assets)
        imports = [
            ("cone", "assets/metadrive_traffic_cone/scene.gltf", ["--up", "+y", "--height", "0.7", "--category",
                                                                   "traffic_cone"]),
            ("barrier", "assets/procedural_jersey_barrier/jersey_barrier.obj", ["--category", "barrier"]),
        ]
        for name, mesh, flags in imports:
            rc, _, err, hung, _ = self.run_bin(["asset", "import", "--mesh", self.src(mesh)] + flags +
                                               ["--out", os.path.join(self.assets, name)], timeout=300)
            if rc != 0 or hung:
                raise SystemExit("setup: asset import of %s failed (rc %s): %s" % (mesh, rc, err.strip()))
        self.cone = os.path.join(self.assets, "cone")
        self.barrier = os.path.join(self.assets, "barrier")
        self.one_cone = os.path.join(self.work, "one_cone.json")
        write(self.one_cone, json.dumps({"seed": 3, "objects": [
            {"category": "traffic_cone", "count": 1, "distance_m": [6, 15], "lateral_m": [-3, 3]}]}))
        self.kitti_cone = os.path.join(self.work, "kitti_cone.json")
        write(self.kitti_cone, json.dumps({"seed": 5, "objects": [
            {"category": "traffic_cone", "count": 2, "distance_m": [6, 14], "lateral_m": [-3, 3]}]}))
        # The scenario family corrupts data/scenarios/demo.json (cones, a barrier and a car): a car asset too.
        rc, _, err, hung, _ = self.run_bin(["asset", "import", "--mesh", self.src("assets/torcs_p406/obj/torcs_p406.obj"),
                                            "--up", "+y", "--front", "+x", "--category", "car", "--out",
                                            os.path.join(self.assets, "car")], timeout=300)
        if rc != 0 or hung:
            raise SystemExit("setup: asset import of the car failed (rc %s): %s" % (rc, err.strip()))
        self.car = os.path.join(self.assets, "car")
        # The CAM_FRONT image enlarged x2 (3200x1800, the calibration is for 1600x900), by the product's bicubic.
        self.front_x2 = os.path.join(self.work, "front_x2.jpg")
        rc, _, err, hung, _ = self.run_bin(["upscale", "--in", self.src(os.path.join(NUS, NUS_FRONT)), "--out",
                                            self.front_x2, "--model", "bicubic", "--scale", "2"], timeout=300)
        if rc != 0 or hung:
            raise SystemExit("setup: upscale of CAM_FRONT failed (rc %s): %s" % (rc, err.strip()))

    # --- commands -----------------------------------------------------------------------------------------------
    def synth(self, log, d, names, kind, scenario=None, assets=None, extra=(), warn=False):
        out = os.path.join(d, "out")
        assets = assets or [self.cone]
        argv = ["synth", "--log", log]
        for a in assets:
            argv += ["--asset", a]
        argv += ["--scenario", scenario or self.one_cone, "--spp", "1", "--ao-samples", "2"] + list(extra)
        warn_argv = None
        if warn:
            warn_argv = argv + ["--dry-run", "--out", os.path.join(d, "dry")]
        return Run(argv + ["--out", out], out, names, kind, warn_argv)

    def nus(self, d, mutate, names, extra=(), warn=False, info=NUS_INFO, strict=False):
        root = self.copy(NUS, d, "log")
        p = {"root": root, "info": os.path.join(root, info), "sweep": os.path.join(root, NUS_SWEEP),
             "front": os.path.join(root, NUS_FRONT), "d": d}
        mutate(p)
        # The corrupted file is the info file unless the case names the sweep or the image (then the line must name
        # that file); `strict`: the line must say what is wrong (one of `names`), naming the info is not enough.
        fields = list(names)
        if not strict and not any(n in (os.path.basename(NUS_SWEEP), os.path.basename(NUS_FRONT)) for n in names):
            names = [os.path.basename(p["info"])] + list(names)
        run = self.synth(p["info"], d, names, "nus_v0" if info == NUS_V0 else "nus", extra=extra, warn=warn)
        run.warn_names = fields
        return run

    def add(self, family, name, expect, prepare, preexisting=False):
        self.cases.append(Case(family, name, expect, prepare, preexisting))

    # --- one case -----------------------------------------------------------------------------------------------
    def run_case(self, idx, case, control=False):
        d = os.path.join(self.work, "c%03d" % idx)
        os.makedirs(d)
        rng = random.Random(SEED + zlib.crc32(case.name.encode()))
        try:
            run = case.prepare(self, d, rng)
        except Exception as e:  # a broken case set-up is a failure of the battery, reported as such
            return case, False, None, "set-up failed: %r" % e, 0.0, ""
        before = None
        argv = list(run.argv)
        if case.preexisting:  # an earlier result at OUT, and --overwrite: a refused run must leave it as it was
            if run.out.endswith(".json"):
                write(run.out, '{"earlier": "result"}\n')
            else:
                os.makedirs(run.out)
                write(os.path.join(run.out, "keep.txt"), "an earlier result the run must not lose\n")
                os.makedirs(os.path.join(run.out, "sub"))
                write(os.path.join(run.out, "sub", "data.bin"), bytes(range(256)))
            before = tree_digest(run.out)
            argv.append("--overwrite")
        case.command = " ".join([os.path.basename(self.bin), "-q"] + [a if " " not in a else "'%s'" % a for a in argv])
        rc, _, err, hung, secs = self.run_bin(argv)
        lines = [l for l in err.splitlines() if l.strip()]
        line = lines[0] if len(lines) == 1 else " | ".join(lines)[:600]
        ok, why = self.judge(case, run, rc, lines, hung, before, d)
        if control and ok and run.kind not in self.control_files and os.path.isdir(run.out):
            self.control_files[run.kind] = {f for f in rel_files(run.out) if not f.startswith("report" + os.sep)}
        if not self.keep:
            shutil.rmtree(d, ignore_errors=True)
        return case, ok, rc, why, secs, line

    def leftovers(self, out):
        parent, base = os.path.split(out)
        return sorted(n for n in os.listdir(parent) if ".tmp-" in n or n == base + ".parts")

    def judge(self, case, run, rc, lines, hung, before, d):
        if hung:
            return False, "hung: killed after %d s" % self.timeout
        if rc < 0:
            return False, "killed by signal %d" % -rc
        left = self.leftovers(run.out)
        if rc == 0:
            if case.expect == REFUSE:
                return False, "accepted (exit 0): a dataset built on wrong data"
            if left:
                return False, "exit 0 but left %s" % left
            want = self.control_files.get(run.kind)
            if want is not None and case.expect == WARN:  # a defaulted camera or sweep is not written: the rest is
                want = {f for f in want if not f.startswith(("samples" + os.sep, "sweeps" + os.sep))}
            if want is not None:
                have = rel_files(run.out) if os.path.isdir(run.out) else {os.path.basename(run.out)} \
                    if os.path.isfile(run.out) else set()
                missing = sorted(want - have)
                if missing:
                    return False, "exit 0 but the output lacks %s" % missing[:4]
            elif not os.path.exists(run.out):
                return False, "exit 0 but no output"
            if case.expect == WARN:
                rc2, _, err2, hung2, _ = self.run_bin(run.warn_argv, quiet=False)
                warned = [l for l in err2.splitlines() if l.startswith("warning:") and
                          any(n.lower() in l.lower() for n in run.warn_names)]
                if not warned:
                    return False, "exit 0 with the field silently defaulted (no warning naming %s)" % run.warn_names
            return True, "accepted" + (" with a warning" if case.expect == WARN else "")
        # refused
        if case.expect == SUCCEED:
            return False, "refused an intact input"
        if rc != 2:
            return False, "exit %d, not 2 (a refused input); 1 is an internal error" % rc
        if len(lines) != 1:
            return False, "%d lines on stderr, not 1" % len(lines)
        if not any(n.lower() in lines[0].lower() for n in run.names):
            return False, "the line names none of %s" % run.names
        if before is not None:
            if tree_digest(run.out) != before:
                return False, "the existing output was changed"
        elif os.path.lexists(run.out):
            return False, "the output %s was created" % os.path.basename(run.out)
        if left:
            return False, "left %s beside the output" % left
        return True, "refused"


# ----------------------------------------------------------------------------------------------------------------
# The cases

def nus_case(b, family, name, expect, mutate, names=(), extra=(), preexisting=False, info=NUS_INFO, strict=False):
    b.add(family, name, expect,
          lambda ctx, d, rng: ctx.nus(d, lambda p: mutate(p, rng), names, extra=extra, warn=(expect == WARN),
                                      info=info, strict=strict),
          preexisting)


def record(fn):
    """A mutation of the info file's first data_list record."""
    def m(p, rng):
        edit_json(p["info"], lambda j: fn(j["data_list"][0]))
    return m


def info(fn):
    def m(p, rng):
        edit_json(p["info"], fn)
    return m


def scale3(m, s):
    mat(m, lambda r, c, v: v * s if r < 3 and c < 3 else v)


def add_cases(b):
    F = "CAM_FRONT"

    # -- controls: the unbroken inputs succeed (and give the output file set a success must match) ---------------
    nus_case(b, "control", "nuscenes info json intact", SUCCEED, lambda p, rng: None)
    nus_case(b, "control", "nuscenes v0 info json intact", SUCCEED, lambda p, rng: None, info=NUS_V0)
    b.add("control", "nuscenes tables intact", SUCCEED, lambda c, d, r: tables(c, d, lambda p: None, []))
    b.add("control", "kitti pkl intact", SUCCEED, lambda c, d, r: kpkl(c, d, lambda p: None, []))
    b.add("control", "kitti object intact", SUCCEED, lambda c, d, r: kitti(c, d, lambda p: None, []))
    # KITTI object frames each have their own calibration and image size (1224x370, 1242x375, ...).
    b.add("control", "kitti object intact, all 3 frames", SUCCEED,
          lambda c, d, r: kitti(c, d, lambda p: None, [], all_frames=True))
    b.add("control", "lyft tables intact", SUCCEED, lambda c, d, r: lyft(c, d, lambda p: None, []))
    b.add("control", "scenario demo.json intact", SUCCEED, lambda c, d, r: scen(c, d, lambda p: None))
    b.add("control", "asset intact", SUCCEED, lambda c, d, r: asset(c, d, lambda p: None, []))
    b.add("control", "asset import obj intact", SUCCEED, lambda c, d, r: obj_import(c, d, lambda p: None))

    # -- truncation ------------------------------------------------------------------------------------------------
    T = "truncation"
    for at in ("1", "half", "end-2"):
        def cut(p, rng, at=at):
            n = content_len(p["info"])
            truncate(p["info"], {"1": 1, "4096": 4096, "half": n // 2, "end-2": n - 2}[at])
        nus_case(b, T, "info json cut at %s" % at, REFUSE, cut)
    nus_case(b, T, "info json cut at half, existing OUT", REFUSE,
             lambda p, rng: truncate(p["info"], content_len(p["info"]) // 2), preexisting=True)
    sweep = os.path.basename(NUS_SWEEP)
    nus_case(b, T, "sweep cut at 1003 B", REFUSE, lambda p, rng: truncate(p["sweep"], 1003), [sweep])
    nus_case(b, T, "sweep cut at half + 7 B", REFUSE,
             lambda p, rng: truncate(p["sweep"], os.path.getsize(p["sweep"]) // 2 + 7), [sweep])
    # A sweep cut at a whole record is a valid, shorter sweep (here the last 10 % of the turn): nothing can tell.
    nus_case(b, T, "sweep cut at a whole record (90 % of the points)", EITHER,
             lambda p, rng: truncate(p["sweep"], os.path.getsize(p["sweep"]) // 200 * 180), [sweep])
    front = os.path.basename(NUS_FRONT)
    nus_case(b, T, "CAM_FRONT jpeg cut at 300 B (header)", REFUSE, lambda p, rng: truncate(p["front"], 300), [front])
    nus_case(b, T, "CAM_FRONT jpeg cut at half (entropy data)", REFUSE,
             lambda p, rng: truncate(p["front"], os.path.getsize(p["front"]) // 2), [front])
    # Only the end-of-image marker missing: every pixel is there.
    nus_case(b, T, "CAM_FRONT jpeg without its last 2 B (EOI)", EITHER,
             lambda p, rng: truncate(p["front"], os.path.getsize(p["front"]) - 2), [front])
    b.add(T, "scenario demo.json cut at half", REFUSE,
          lambda c, d, r: scen(c, d, lambda s: truncate(s, content_len(s) // 2)))
    b.add(T, "asset.json cut at half", REFUSE,
          lambda c, d, r: asset(c, d, lambda a: truncate(j(a, "asset.json"), content_len(j(a, "asset.json")) // 2),
                                ["asset.json"]))
    b.add(T, "asset mesh.glb cut at 12 B", REFUSE,
          lambda c, d, r: asset(c, d, lambda a: truncate(j(a, "mesh.glb"), 12), ["mesh.glb"]))
    b.add(T, "asset mesh.glb cut at half", REFUSE,
          lambda c, d, r: asset(c, d, lambda a: truncate(j(a, "mesh.glb"), os.path.getsize(j(a, "mesh.glb")) // 2),
                                ["mesh.glb"]))
    for at in ("half", "end-1"):
        def cutp(p, at=at):
            n = os.path.getsize(p["info"])
            truncate(p["info"], {"2": 2, "half": n // 2, "end-1": n - 1}[at])
        b.add(T, "kitti pkl cut at %s" % at, REFUSE, lambda c, d, r, f=cutp: kpkl(c, d, f, []))
    b.add(T, "kitti pkl sweep cut at 1001 B", REFUSE,
          lambda c, d, r: kpkl(c, d, lambda p: truncate(p["bin"], 1001), ["000008.bin"]))
    b.add(T, "lyft sample_data.json cut at half", REFUSE,
          lambda c, d, r: lyft(c, d, lambda p: truncate(p["sample_data"], content_len(p["sample_data"]) // 2),
                               ["sample_data.json"]))
    b.add(T, "nuscenes tables calibrated_sensor.json cut at half", REFUSE,
          lambda c, d, r: tables(c, d, lambda p: truncate(p["calibrated_sensor"],
                                                          content_len(p["calibrated_sensor"]) // 2),
                                 ["calibrated_sensor.json"]))
    b.add(T, "kitti calib cut mid-file", REFUSE,
          lambda c, d, r: kitti(c, d, lambda p: truncate(p["calib"], content_len(p["calib"]) // 2), ["000000.txt"]))
    b.add(T, "kitti label cut mid-line", REFUSE,
          lambda c, d, r: kitti(c, d, lambda p: truncate(p["label"], 30), ["000000.txt"]))
    b.add(T, "kitti velodyne cut at 1001 B", REFUSE,
          lambda c, d, r: kitti(c, d, lambda p: truncate(p["velo"], 1001), ["000000.bin"]))
    b.add(T, "gltf buffer scene.bin cut at half (asset import)", REFUSE,
          lambda c, d, r: gltf_import(c, d, lambda g: truncate(j(g, "scene.bin"), os.path.getsize(j(g, "scene.bin")) // 2),
                                      ["scene.bin", "scene.gltf"]))

    # -- byte flips (fixed seed) -----------------------------------------------------------------------------------
    BF = "byte flips"
    # A flipped byte of a JSON file breaks its syntax, renames a key (a missing field), or changes a digit or a
    # letter of a value (a token, a number that may stay plausible): refusal or success are both right, a crash not.
    for n in (1, 32):
        nus_case(b, BF, "info json, %d random bytes" % n, EITHER,
                 lambda p, rng, n=n: flip_bytes(p["info"], n, rng))
    # Low mantissa bits of sweep floats: the points move by < 1e-5 relative and stay finite: harmless.
    nus_case(b, BF, "sweep, 64 float mantissa bytes", EITHER,
             lambda p, rng: flip_sweep_mantissas(p["sweep"], 64, rng), [sweep])
    # Any byte of the sweep: may make a coordinate NaN/Inf (refused) or move a point (undetectable).
    for n in (16,):
        nus_case(b, BF, "sweep, %d random bytes" % n, EITHER, lambda p, rng, n=n: flip_bytes(p["sweep"], n, rng),
                 [sweep])

    def jpeg_entropy(p, rng, n):
        data = read(p["front"])
        s = jpeg_scan_start(data)
        flip_bytes(p["front"], n, rng, lo=s + (len(data) - s) // 4, hi=len(data) - 16, avoid=b"\xff")
    for n in (8,):
        nus_case(b, BF, "CAM_FRONT jpeg entropy data, %d bytes" % n, EITHER,
                 lambda p, rng, n=n: jpeg_entropy(p, rng, n), [front])
    nus_case(b, BF, "CAM_FRONT jpeg header (tables, SOF), 4 bytes", EITHER,
             lambda p, rng: flip_bytes(p["front"], 4, rng, lo=2, hi=jpeg_scan_start(read(p["front"]))), [front])
    b.add(BF, "scenario demo.json, 4 random bytes", EITHER,
          lambda c, d, r: scen(c, d, lambda s: flip_bytes(s, 4, r)))
    b.add(BF, "asset mesh.glb binary chunk, 16 bytes", EITHER,
          lambda c, d, r: asset(c, d, lambda a: flip_bytes(j(a, "mesh.glb"), 16, r,
                                                           lo=20 + struct.unpack("<I", read(j(a, "mesh.glb"))[12:16])[0] + 8),
                                ["mesh.glb"]))
    b.add(BF, "asset mesh.glb JSON chunk, 4 bytes", EITHER,
          lambda c, d, r: asset(c, d, lambda a: flip_bytes(j(a, "mesh.glb"), 4, r, lo=20,
                                                           hi=20 + struct.unpack("<I", read(j(a, "mesh.glb"))[12:16])[0]),
                                ["mesh.glb"]))
    for n in (1, 8):
        b.add(BF, "kitti pkl, %d random bytes" % n, EITHER,
              lambda c, d, r, n=n: kpkl(c, d, lambda p: flip_bytes(p["info"], n, r), []))
    b.add(BF, "lyft calibrated_sensor.json, 4 random bytes", EITHER,
          lambda c, d, r: lyft(c, d, lambda p: flip_bytes(p["calibrated_sensor"], 4, r), ["calibrated_sensor.json"]))
    b.add(BF, "kitti calib, 4 random bytes", EITHER,
          lambda c, d, r: kitti(c, d, lambda p: flip_bytes(p["calib"], 4, r), ["000000.txt"]))

    # -- wrong JSON types ------------------------------------------------------------------------------------------
    W = "wrong types"
    nus_case(b, W, "data_list an object", REFUSE, info(lambda j: j.update(data_list={"0": j["data_list"][0]})),
             ["data_list"])
    nus_case(b, W, "ego2global a string", REFUSE, record(lambda r: r.update(ego2global="identity")), ["ego2global"])
    nus_case(b, W, "cam2img a number", REFUSE, record(lambda r: r["images"][F].update(cam2img=1266.4)), ["cam2img"])
    nus_case(b, W, "images a list", REFUSE, record(lambda r: r.update(images=list(r["images"].values()))),
             ["images"])
    nus_case(b, W, "lidar_points a string", REFUSE, record(lambda r: r.update(lidar_points="LIDAR_TOP")),
             ["lidar_points"])
    nus_case(b, W, "instances an object", REFUSE, record(lambda r: r.update(instances={"0": r["instances"][0]})),
             ["instances"])
    nus_case(b, W, "bbox_3d entry a string", REFUSE,
             record(lambda r: r["instances"][0]["bbox_3d"].__setitem__(0, "18.4")), ["bbox_3d"])
    nus_case(b, W, "bbox_label_3d a string", REFUSE,
             record(lambda r: r["instances"][0].update(bbox_label_3d="pedestrian")), ["bbox_label_3d"])
    nus_case(b, W, "lidar_path a number", REFUSE, record(lambda r: r["lidar_points"].update(lidar_path=7)),
             ["lidar_path"])
    nus_case(b, W, "timestamp a string", REFUSE, record(lambda r: r.update(timestamp="1532402927.647951")),
             ["timestamp"])
    nus_case(b, W, "lidar2ego row of 3", REFUSE, record(lambda r: r["lidar_points"]["lidar2ego"][0].pop()),
             ["lidar2ego"])
    nus_case(b, W, "num_pts_feats a string", REFUSE, record(lambda r: r["lidar_points"].update(num_pts_feats="5")),
             ["num_pts_feats"])
    nus_case(b, W, "num_pts_feats 5.5", REFUSE, record(lambda r: r["lidar_points"].update(num_pts_feats=5.5)),
             ["num_pts_feats"])
    nus_case(b, W, "num_pts_feats 6 (Waymo-style)", REFUSE,
             record(lambda r: r["lidar_points"].update(num_pts_feats=6)), ["num_pts_feats"])
    nus_case(b, W, "num_pts_feats 2", REFUSE, record(lambda r: r["lidar_points"].update(num_pts_feats=2)),
             ["num_pts_feats"])
    nus_case(b, W, "v0 cams a list", REFUSE,
             info(lambda j: j["infos"][0].update(cams=list(j["infos"][0]["cams"].values()))), ["cams"], info=NUS_V0)
    b.add(W, "scenario count a string", REFUSE,
          lambda c, d, r: scen(c, d, lambda s: edit_json(s, lambda x: x["objects"][0].update(count="3")), ["count"]))
    b.add(W, "scenario objects an object", REFUSE,
          lambda c, d, r: scen(c, d, lambda s: edit_json(s, lambda x: x.update(objects={"a": x["objects"][0]})),
                               ["objects"]))
    b.add(W, "scenario distance_m a string", REFUSE,
          lambda c, d, r: scen(c, d, lambda s: edit_json(s, lambda x: x["objects"][0].update(distance_m="7-20")),
                               ["distance_m"]))
    b.add(W, "scenario seed a string", REFUSE,
          lambda c, d, r: scen(c, d, lambda s: edit_json(s, lambda x: x.update(seed="7")), ["seed"]))
    b.add(W, "asset.json extent_m a string", REFUSE,
          lambda c, d, r: asset(c, d, lambda a: edit_json(j(a, "asset.json"), lambda x: x.update(extent_m="1 1 1")),
                                ["asset.json", "extent_m"]))
    b.add(W, "asset.json id a number", REFUSE,
          lambda c, d, r: asset(c, d, lambda a: edit_json(j(a, "asset.json"), lambda x: x.update(id=5)),
                                ["asset.json", "id"]))
    b.add(W, "asset.json category a list", REFUSE,
          lambda c, d, r: asset(c, d, lambda a: edit_json(j(a, "asset.json"),
                                                          lambda x: x.update(category=["traffic_cone"])),
                                ["asset.json", "category"]))
    b.add(W, "lyft sample.json an object", REFUSE,
          lambda c, d, r: lyft(c, d, lambda p: replace_json(p["sample"], lambda x: {"0": x[0]}), ["sample.json"]))
    b.add(W, "lyft calibrated_sensor rotation a string", REFUSE,
          lambda c, d, r: lyft(c, d, lambda p: edit_json(p["calibrated_sensor"],
                                                         lambda x: x[0].update(rotation="1 0 0 0")),
                               ["calibrated_sensor.json", "rotation"]))
    b.add(W, "gltf accessor count a string (asset import)", REFUSE,
          lambda c, d, r: gltf_import(c, d, lambda g: edit_json(j(g, "scene.gltf"),
                                                                lambda x: x["accessors"][0].update(count="many")),
                                      ["scene.gltf", "count"]))

    # -- NaN / Inf / 1e308 / 1e999 ---------------------------------------------------------------------------------
    N = "non-finite and huge numbers"
    nus_case(b, N, "ego2global x NaN", REFUSE, record(lambda r: r["ego2global"][0].__setitem__(3, float("nan"))),
             ["ego2global"])
    nus_case(b, N, "lidar2ego z Infinity", REFUSE,
             record(lambda r: r["lidar_points"]["lidar2ego"][2].__setitem__(3, float("inf"))), ["lidar2ego"])
    nus_case(b, N, "cam2img fx -Infinity", REFUSE,
             record(lambda r: r["images"][F]["cam2img"][0].__setitem__(0, float("-inf"))), ["cam2img"])
    nus_case(b, N, "lidar2ego z 1e308", REFUSE,
             record(lambda r: r["lidar_points"]["lidar2ego"][2].__setitem__(3, 1e308)), ["lidar2ego"])
    nus_case(b, N, "lidar2ego z -1e308", REFUSE,
             record(lambda r: r["lidar_points"]["lidar2ego"][2].__setitem__(3, -1e308)), ["lidar2ego"])
    nus_case(b, N, "lidar2ego z 1e17", REFUSE,
             record(lambda r: r["lidar_points"]["lidar2ego"][2].__setitem__(3, 1e17)), ["lidar2ego"])
    nus_case(b, N, "cam2img fx 1e999", REFUSE,
             record(lambda r: r["images"][F]["cam2img"][0].__setitem__(0, Raw("1e999"))), ["1e999", "cam2img"])
    nus_case(b, N, "cam2img fx 1e308", REFUSE,
             record(lambda r: r["images"][F]["cam2img"][0].__setitem__(0, 1e308)), ["cam2img"])
    nus_case(b, N, "ego2global x 1e12", REFUSE, record(lambda r: r["ego2global"][0].__setitem__(3, 1e12)),
             ["ego2global"])
    nus_case(b, N, "bbox_3d length 1e308", REFUSE,
             record(lambda r: r["instances"][0]["bbox_3d"].__setitem__(3, 1e308)), ["bbox_3d"])
    nus_case(b, N, "bbox_3d x NaN", REFUSE,
             record(lambda r: r["instances"][0]["bbox_3d"].__setitem__(0, float("nan"))), ["bbox_3d"])
    nus_case(b, N, "bbox_3d x 1e999", REFUSE,
             record(lambda r: r["instances"][0]["bbox_3d"].__setitem__(0, Raw("1e999"))), ["bbox_3d", "1e999"])
    nus_case(b, N, "timestamp NaN", REFUSE, record(lambda r: r.update(timestamp=float("nan"))), ["timestamp"])
    nus_case(b, N, "timestamp 1e308", REFUSE, record(lambda r: r.update(timestamp=1e308)), ["timestamp"])
    nus_case(b, N, "v0 lidar2ego_translation 1e308", REFUSE,
             info(lambda j: j["infos"][0]["lidar2ego_translation"].__setitem__(2, 1e308)), ["lidar2ego"],
             info=NUS_V0)
    nus_case(b, N, "sweep point x NaN", REFUSE, lambda p, rng: set_sweep_value(p["sweep"], 100, 0, float("nan")),
             [sweep])
    nus_case(b, N, "sweep point z Inf", REFUSE, lambda p, rng: set_sweep_value(p["sweep"], 100, 2, float("inf")),
             [sweep])
    # A finite point 1e38 m away: nonsense, but a reader may drop far points; a crash is the failure here.
    nus_case(b, N, "sweep point x 1e38", EITHER, lambda p, rng: set_sweep_value(p["sweep"], 100, 0, 1e38), [sweep])
    b.add(N, "scenario distance_m 1e308", REFUSE,
          lambda c, d, r: scen(c, d, lambda s: edit_json(s, lambda x: x["objects"][0].update(distance_m=[1e308, 1e308])),
                               ["distance_m"]))
    b.add(N, "scenario margin_m 1e999", REFUSE,
          lambda c, d, r: scen(c, d, lambda s: edit_json(s, lambda x: x.update(margin_m=Raw("1e999"))),
                               ["margin_m", "1e999"]))
    b.add(N, "scenario count 1e308", REFUSE,
          lambda c, d, r: scen(c, d, lambda s: edit_json(s, lambda x: x["objects"][0].update(count=1e308)), ["count"]))
    b.add(N, "scenario sun elevation NaN", REFUSE,
          lambda c, d, r: scen(c, d, lambda s: edit_json(s, lambda x: x.update(
              sun={"azimuth_deg": 120, "elevation_deg": Raw("NaN")})), ["elevation_deg", "NaN", "sun"]))
    b.add(N, "asset.json extent_m 1e308", REFUSE,
          lambda c, d, r: asset(c, d, lambda a: edit_json(j(a, "asset.json"),
                                                          lambda x: x["extent_m"].__setitem__(0, 1e308)),
                                ["asset.json", "extent_m"]))
    b.add(N, "asset.json extent_m NaN", REFUSE,
          lambda c, d, r: asset(c, d, lambda a: edit_json(j(a, "asset.json"),
                                                          lambda x: x["extent_m"].__setitem__(0, Raw("NaN"))),
                                ["asset.json", "extent_m"]))
    b.add(N, "lyft ego_pose x 1e12", REFUSE,
          lambda c, d, r: lyft(c, d, lambda p: edit_json(p["ego_pose"], lambda x: x[0]["translation"].__setitem__(0, 1e12)),
                               ["ego_pose"]))
    b.add(N, "lyft calibrated_sensor translation NaN", REFUSE,
          lambda c, d, r: lyft(c, d, lambda p: edit_json(p["calibrated_sensor"],
                                                         lambda x: x[0]["translation"].__setitem__(0, Raw("NaN"))),
                               ["calibrated_sensor", "translation"]))
    b.add(N, "lyft sample_annotation size 1e308", REFUSE,
          lambda c, d, r: lyft(c, d, lambda p: edit_json(p["sample_annotation"],
                                                         lambda x: x[0]["size"].__setitem__(0, 1e308)),
                               ["sample_annotation", "size"]))
    for v in ("nan", "inf", "1e999"):
        b.add(N, "obj vertex %s (asset import)" % v, REFUSE,
              lambda c, d, r, v=v: obj_import(c, d, lambda o: obj_vertex(o, "v %s 0 0" % v)))
    b.add(N, "obj vertex nan (eval geometry --gt)", REFUSE,
          lambda c, d, r: eval_geo(c, d, lambda o: obj_vertex(o, "v nan 0 0")))
    b.add(N, "kitti calib P2 nan", REFUSE,
          lambda c, d, r: kitti(c, d, lambda p: calib_edit(p["calib"], "P2", lambda v: ["nan"] + v[1:]),
                                ["000000.txt", "P2"]))
    b.add(N, "kitti label dimension 1e308", REFUSE,
          lambda c, d, r: kitti(c, d, lambda p: label_edit(p["label"], 8, "1e308"), ["000000.txt"]))
    b.add(N, "kitti label location nan", REFUSE,
          lambda c, d, r: kitti(c, d, lambda p: label_edit(p["label"], 11, "nan"), ["000000.txt"]))

    # -- non-rigid and singular matrices ---------------------------------------------------------------------------
    M = "non-rigid and singular matrices"
    nus_case(b, M, "lidar2cam rotation scaled x2", REFUSE, record(lambda r: scale3(r["images"][F]["lidar2cam"], 2.0)),
             ["lidar2cam"])
    nus_case(b, M, "lidar2cam rotation scaled x2, existing OUT", REFUSE,
             record(lambda r: scale3(r["images"][F]["lidar2cam"], 2.0)), ["lidar2cam"], preexisting=True)
    nus_case(b, M, "lidar2cam sheared", REFUSE,
             record(lambda r: r["images"][F]["lidar2cam"][0].__setitem__(1, r["images"][F]["lidar2cam"][0][1] + 0.5)),
             ["lidar2cam"])
    nus_case(b, M, "lidar2cam reflected (a column negated)", REFUSE,
             record(lambda r: mat(r["images"][F]["lidar2cam"], lambda i, k, v: -v if k == 0 and i < 3 else v)),
             ["lidar2cam"])
    nus_case(b, M, "lidar2cam rotation zero", REFUSE, record(lambda r: scale3(r["images"][F]["lidar2cam"], 0.0)),
             ["lidar2cam"])
    nus_case(b, M, "cam2ego reflected", REFUSE,
             record(lambda r: mat(r["images"][F]["cam2ego"], lambda i, k, v: -v if k == 1 and i < 3 else v)),
             ["cam2ego"])
    nus_case(b, M, "lidar2ego rotation scaled x1.01", REFUSE,
             record(lambda r: scale3(r["lidar_points"]["lidar2ego"], 1.01)), ["lidar2ego"])
    nus_case(b, M, "ego2global rotation scaled x2", REFUSE, record(lambda r: scale3(r["ego2global"], 2.0)),
             ["ego2global"])
    nus_case(b, M, "ego2global sheared", REFUSE,
             record(lambda r: r["ego2global"][1].__setitem__(0, r["ego2global"][1][0] + 0.3)), ["ego2global"])
    nus_case(b, M, "cam2img all zeros", REFUSE, record(lambda r: mat(r["images"][F]["cam2img"], lambda i, k, v: 0.0)),
             ["cam2img"])
    nus_case(b, M, "cam2img fx = 0", REFUSE, record(lambda r: r["images"][F]["cam2img"][0].__setitem__(0, 0.0)),
             ["cam2img"])
    nus_case(b, M, "cam2img fy < 0", REFUSE,
             record(lambda r: r["images"][F]["cam2img"][1].__setitem__(1, -1266.4)), ["cam2img"])
    nus_case(b, M, "cam2img bottom row [0 0 0]", REFUSE,
             record(lambda r: r["images"][F]["cam2img"].__setitem__(2, [0.0, 0.0, 0.0])), ["cam2img"])
    nus_case(b, M, "cam2img principal point at 1e5 px", REFUSE,
             record(lambda r: r["images"][F]["cam2img"][0].__setitem__(2, 1e5)), ["cam2img"])
    for field in ("lidar2ego", "ego2global", "cam2ego", "lidar2cam"):
        def bottom(r, field=field):
            m = {"lidar2ego": lambda: r["lidar_points"]["lidar2ego"], "ego2global": lambda: r["ego2global"],
                 "cam2ego": lambda: r["images"][F]["cam2ego"], "lidar2cam": lambda: r["images"][F]["lidar2cam"]}[field]()
            m[3] = [0.0, 0.0, 0.0, 0.0]
        nus_case(b, M, "%s bottom row [0 0 0 0]" % field, REFUSE, record(bottom), [field])
    nus_case(b, M, "v0 sensor2ego_rotation quaternion zero", REFUSE,
             info(lambda j: j["infos"][0]["cams"][F].update(sensor2ego_rotation=[0.0, 0.0, 0.0, 0.0])),
             ["sensor2ego_rotation", "quaternion"], info=NUS_V0)
    nus_case(b, M, "v0 ego2global_rotation quaternion of norm 2", REFUSE,
             info(lambda j: j["infos"][0].update(ego2global_rotation=[2 * q for q in j["infos"][0]["ego2global_rotation"]])),
             ["ego2global_rotation", "quaternion"], info=NUS_V0)
    b.add(M, "lyft calibrated_sensor quaternion zero", REFUSE,
          lambda c, d, r: lyft(c, d, lambda p: edit_json(p["calibrated_sensor"],
                                                         lambda x: [s.update(rotation=[0.0, 0.0, 0.0, 0.0]) for s in x]),
                               ["calibrated_sensor", "rotation", "quaternion"]))
    b.add(M, "lyft ego_pose quaternion of norm 2", REFUSE,
          lambda c, d, r: lyft(c, d, lambda p: edit_json(p["ego_pose"], lambda x: [
              e.update(rotation=[2 * q for q in e["rotation"]]) for e in x]), ["ego_pose", "rotation", "quaternion"]))
    b.add(M, "lyft camera_intrinsic fx = 0", REFUSE,
          lambda c, d, r: lyft(c, d, lambda p: edit_json(p["calibrated_sensor"], lambda x: [
              s["camera_intrinsic"][0].__setitem__(0, 0.0) for s in x if s["camera_intrinsic"]]),
                               ["calibrated_sensor", "camera_intrinsic", "focal"]))
    b.add(M, "nuscenes tables camera_intrinsic all zeros", REFUSE,
          lambda c, d, r: tables(c, d, lambda p: edit_json(p["calibrated_sensor"], lambda x: [
              s.update(camera_intrinsic=[[0.0] * 3] * 3) for s in x if s["camera_intrinsic"]]),
                                 ["calibrated_sensor", "camera_intrinsic", "focal"]))
    b.add(M, "kitti calib P2 fx = 0", REFUSE,
          lambda c, d, r: kitti(c, d, lambda p: calib_edit(p["calib"], "P2", lambda v: ["0"] + v[1:]),
                                ["000000.txt", "P2"]))
    b.add(M, "kitti calib R0_rect scaled x2", REFUSE,
          lambda c, d, r: kitti(c, d, lambda p: calib_edit(p["calib"], "R0_rect",
                                                           lambda v: [repr(2 * float(x)) for x in v]),
                                ["000000.txt", "R0_rect"]))
    b.add(M, "kitti calib Tr_velo_to_cam reflected", REFUSE,
          lambda c, d, r: kitti(c, d, lambda p: calib_edit(p["calib"], "Tr_velo_to_cam", lambda v: [
              repr(-float(x)) if i % 4 == 0 else x for i, x in enumerate(v)]), ["000000.txt", "Tr_velo_to_cam"]))

    # -- missing fields --------------------------------------------------------------------------------------------
    MF = "missing fields"
    nus_case(b, MF, "ego2global missing", WARN, record(lambda r: r.pop("ego2global")), ["ego2global"])
    nus_case(b, MF, "images missing", WARN, record(lambda r: r.pop("images")), ["images"])
    nus_case(b, MF, "CAM_FRONT lidar2cam missing", WARN, record(lambda r: r["images"][F].pop("lidar2cam")),
             ["lidar2cam"])
    nus_case(b, MF, "lidar_points missing", WARN, record(lambda r: r.pop("lidar_points")), ["lidar_points"])
    nus_case(b, MF, "instances missing", WARN, record(lambda r: r.pop("instances")), ["instances"])
    nus_case(b, MF, "CAM_FRONT img_path missing", REFUSE, record(lambda r: r["images"][F].pop("img_path")),
             ["img_path"])
    nus_case(b, MF, "CAM_FRONT cam2img missing", REFUSE, record(lambda r: r["images"][F].pop("cam2img")),
             ["cam2img"])
    nus_case(b, MF, "lidar_path missing", REFUSE, record(lambda r: r["lidar_points"].pop("lidar_path")),
             ["lidar_path"])
    nus_case(b, MF, "lidar2ego missing", REFUSE, record(lambda r: r["lidar_points"].pop("lidar2ego")), ["lidar2ego"])
    nus_case(b, MF, "data_list missing", REFUSE, info(lambda j: j.pop("data_list")), ["data_list"])
    nus_case(b, MF, "bbox_3d of an instance missing", REFUSE, record(lambda r: r["instances"][0].pop("bbox_3d")),
             ["bbox_3d"])
    nus_case(b, MF, "v0 CAM_FRONT cam_intrinsic missing", REFUSE,
             info(lambda j: j["infos"][0]["cams"][F].pop("cam_intrinsic")), ["cam_intrinsic"], info=NUS_V0)
    nus_case(b, MF, "the CAM_FRONT image file missing", REFUSE, lambda p, rng: os.remove(p["front"]), [front])
    nus_case(b, MF, "the sweep file missing", REFUSE, lambda p, rng: os.remove(p["sweep"]), [sweep])
    b.add(MF, "lyft sample_data calibrated_sensor_token missing", REFUSE,
          lambda c, d, r: lyft(c, d, lambda p: edit_json(p["sample_data"], lambda x: x[0].pop("calibrated_sensor_token")),
                               ["sample_data", "calibrated_sensor_token"]))
    b.add(MF, "lyft ego_pose.json missing", REFUSE,
          lambda c, d, r: lyft(c, d, lambda p: os.remove(p["ego_pose"]), ["ego_pose.json"]))
    b.add(MF, "kitti calib without its P2 line", REFUSE,
          lambda c, d, r: kitti(c, d, lambda p: calib_drop(p["calib"], "P2"), ["000000.txt", "P2"]))
    b.add(MF, "kitti calib without Tr_velo_to_cam", REFUSE,
          lambda c, d, r: kitti(c, d, lambda p: calib_drop(p["calib"], "Tr_velo_to_cam"),
                                ["000000.txt", "Tr_velo_to_cam"]))
    b.add(MF, "kitti image missing", REFUSE,
          lambda c, d, r: kitti(c, d, lambda p: os.remove(p["image"]), ["000000.png"]))
    b.add(MF, "asset.json without id", REFUSE,
          lambda c, d, r: asset(c, d, lambda a: edit_json(j(a, "asset.json"), lambda x: x.pop("id")),
                                ["asset.json", "id"]))
    b.add(MF, "asset.json without extent_m", REFUSE,
          lambda c, d, r: asset(c, d, lambda a: edit_json(j(a, "asset.json"), lambda x: x.pop("extent_m")),
                                ["asset.json", "extent_m"]))
    b.add(MF, "asset mesh.glb missing", REFUSE,
          lambda c, d, r: asset(c, d, lambda a: os.remove(j(a, "mesh.glb")), ["mesh.glb"]))
    b.add(MF, "scenario without objects", REFUSE,
          lambda c, d, r: scen(c, d, lambda s: edit_json(s, lambda x: x.pop("objects")), ["objects"]))

    # -- huge declared sizes ---------------------------------------------------------------------------------------
    H = "huge declared sizes"
    nus_case(b, H, "CAM_FRONT jpeg SOF declares 65500x65500", REFUSE,
             lambda p, rng: jpeg_set_size(p["front"], 65500, 65500), [front, "cam2img"])
    nus_case(b, H, "CAM_FRONT a png declaring 60000x60000", REFUSE, lambda p, rng: write(p["front"], forged_png(60000, 60000)),
             [front, "cam2img"])
    nus_case(b, H, "num_pts_feats 1e9", REFUSE, record(lambda r: r["lidar_points"].update(num_pts_feats=1000000000)),
             ["num_pts_feats"])
    b.add(H, "asset mesh.glb JSON chunk length 0xFFFFFFF0", REFUSE,
          lambda c, d, r: asset(c, d, lambda a: patch(j(a, "mesh.glb"), 12, struct.pack("<I", 0xFFFFFFF0)), ["mesh.glb"]))
    b.add(H, "asset mesh.glb accessor count 2^31", REFUSE,
          lambda c, d, r: asset(c, d, lambda a: edit_glb_json(j(a, "mesh.glb"),
                                                              lambda g: g["accessors"][0].update(count=2 ** 31)),
                                ["mesh.glb"]))
    b.add(H, "gltf buffer byteLength 2^40 (asset import)", REFUSE,
          lambda c, d, r: gltf_import(c, d, lambda g: edit_json(j(g, "scene.gltf"),
                                                                lambda x: x["buffers"][0].update(byteLength=2 ** 40)),
                                      ["scene.gltf", "scene.bin", "byteLength"]))
    b.add(H, "lyft sample_data width 1e9", REFUSE,
          lambda c, d, r: lyft(c, d, lambda p: edit_json(p["sample_data"], lambda x: [
              s.update(width=1000000000) for s in x if s.get("width")]), ["sample_data", "width"]))
    b.add(H, "kitti pkl BINUNICODE of 2^32-1 bytes", REFUSE,
          lambda c, d, r: kpkl(c, d, lambda p: write(p["info"], b"\x80\x04X\xff\xff\xff\xffabc."), []))
    b.add(H, "kitti pkl FRAME of 2^62 bytes", REFUSE,
          lambda c, d, r: kpkl(c, d, lambda p: write(p["info"], b"\x80\x04\x95" + struct.pack("<Q", 2 ** 62) + b"}."),
                               []))

    # -- deep nesting ----------------------------------------------------------------------------------------------
    DN = "deep nesting"
    deep = "[" * 100000 + "]" * 100000
    nus_case(b, DN, "info json record key holding 100000-deep lists", REFUSE,
             record(lambda r: r.update(_comment=Raw(deep))), ["nested", "deep"])
    nus_case(b, DN, "info json of 100000 '['", REFUSE, lambda p, rng: write(p["info"], "[" * 100000), [])
    b.add(DN, "scenario comment holding 100000-deep lists", REFUSE,
          lambda c, d, r: scen(c, d, lambda s: edit_json(s, lambda x: x.update(_comment=Raw(deep)))))
    b.add(DN, "asset.json key holding 100000-deep lists", REFUSE,
          lambda c, d, r: asset(c, d, lambda a: edit_json(j(a, "asset.json"), lambda x: x.update(quality=Raw(deep))),
                                ["asset.json"]))
    b.add(DN, "lyft sample.json of 100000 '['", REFUSE,
          lambda c, d, r: lyft(c, d, lambda p: write(p["sample"], "[" * 100000), ["sample.json"]))
    b.add(DN, "gltf extras holding 100000-deep lists (asset import)", REFUSE,
          lambda c, d, r: gltf_import(c, d, lambda g: edit_json(j(g, "scene.gltf"), lambda x: x.update(extras=Raw(deep))),
                                      ["scene.gltf"]))
    b.add(DN, "kitti pkl of 100000-deep lists", REFUSE,
          lambda c, d, r: kpkl(c, d, lambda p: write(p["info"], b"\x80\x02" + b"]" * 100000 + b"a" * 99999 + b"."), []))

    # -- a UTF-8 BOM: harmless if read through, else a refusal that names the file --------------------------------
    BOM = "utf-8 bom"
    nus_case(b, BOM, "info json with a BOM", EITHER, lambda p, rng: write(p["info"], b"\xef\xbb\xbf" + read(p["info"])))
    b.add(BOM, "scenario with a BOM", EITHER, lambda c, d, r: scen(c, d, lambda s: write(s, b"\xef\xbb\xbf" + read(s))))
    b.add(BOM, "asset.json with a BOM", EITHER,
          lambda c, d, r: asset(c, d, lambda a: write(j(a, "asset.json"), b"\xef\xbb\xbf" + read(j(a, "asset.json"))),
                                ["asset.json"]))
    b.add(BOM, "lyft sample.json with a BOM", EITHER,
          lambda c, d, r: lyft(c, d, lambda p: write(p["sample"], b"\xef\xbb\xbf" + read(p["sample"])), ["sample.json"]))

    # -- paths escaping the data root ------------------------------------------------------------------------------
    P = "paths escaping the data root"
    for field, val in (("img_path", "../../../etc/passwd"), ("img_path", "/etc/passwd"),
                       ("img_path", "samples/../../../../../etc/passwd"),
                       ("lidar_path", "../../../etc/passwd"), ("lidar_path", "/etc/passwd")):
        def esc(r, field=field, val=val):
            (r["images"][F] if field == "img_path" else r["lidar_points"])[field] = val
        nus_case(b, P, "%s %s" % (field, val), REFUSE, record(esc), [field, "passwd", "data root"], strict=True)

    # Escaping to a *valid* file outside the root: refused by the path check, not by a failing decode.
    def esc_valid(p, rng, field):
        outside = os.path.join(p["d"], "elsewhere")
        os.makedirs(outside)
        src = p["front"] if field == "img_path" else p["sweep"]
        shutil.copy(src, os.path.join(outside, os.path.basename(src)))
        rel = "../elsewhere/" + os.path.basename(src)  # data_root / rel: beside the data root, outside it
        edit_json(p["info"], lambda j: (j["data_list"][0]["images"][F] if field == "img_path"
                                        else j["data_list"][0]["lidar_points"]).__setitem__(field, rel))
    for field in ("img_path", "lidar_path"):
        nus_case(b, P, "%s ../elsewhere/<a valid copy>" % field, REFUSE,
                 lambda p, rng, field=field: esc_valid(p, rng, field), ["data root", "outside"], strict=True)
    nus_case(b, P, "v0 data_path /etc/passwd", REFUSE,
             info(lambda j: j["infos"][0]["cams"][F].update(data_path="/etc/passwd")),
             ["data_path", "passwd", "data root"], info=NUS_V0)
    b.add(P, "lyft sample_data filename ../../../etc/passwd", REFUSE,
          lambda c, d, r: lyft(c, d, lambda p: edit_json(p["sample_data"], lambda x: [
              s.update(filename="../../../etc/passwd") for s in x if s.get("fileformat") == "bin"]),
                               ["sample_data", "filename", "passwd", "data root"]))
    b.add(P, "asset.json mesh ../../../../etc/passwd", REFUSE,
          lambda c, d, r: asset(c, d, lambda a: edit_json(j(a, "asset.json"),
                                                          lambda x: x.update(mesh="../../../../etc/passwd")),
                                ["asset.json", "mesh", "passwd"]))
    b.add(P, "asset id ../../evil", REFUSE,
          lambda c, d, r: asset(c, d, lambda a: edit_json(j(a, "asset.json"), lambda x: x.update(id="../../evil")),
                                ["asset.json", "id", "evil"]))
    b.add(P, "asset id /tmp/evil", REFUSE,
          lambda c, d, r: asset(c, d, lambda a: edit_json(j(a, "asset.json"), lambda x: x.update(id="/tmp/evil")),
                                ["asset.json", "id", "evil"]))
    b.add(P, "asset import --id ../evil", REFUSE,
          lambda c, d, r: obj_import(c, d, lambda o: None, extra=["--id", "../evil"], names=["--id", "id", "evil"]))

    # -- FIFOs, devices, directories, empty files ------------------------------------------------------------------
    S = "not a regular file"
    for kind in ("fifo", "/dev/zero", "/dev/urandom", "dir", "empty", "symlink loop"):
        nus_case(b, S, "sweep is %s" % kind, REFUSE, lambda p, rng, kind=kind: replace_with(p["sweep"], kind), [sweep])
    for kind in ("fifo", "/dev/zero", "dir", "empty", "symlink loop"):
        nus_case(b, S, "CAM_FRONT image is %s" % kind, REFUSE,
                 lambda p, rng, kind=kind: replace_with(p["front"], kind), [front])
    nus_case(b, S, "sweep is a fifo, existing OUT", REFUSE, lambda p, rng: replace_with(p["sweep"], "fifo"), [sweep],
             preexisting=True)
    for kind in ("fifo", "empty", "symlink loop"):
        nus_case(b, S, "info json is %s" % kind, REFUSE, lambda p, rng, kind=kind: replace_with(p["info"], kind))
    for kind in ("fifo", "dir", "empty", "/dev/zero"):
        b.add(S, "scenario is %s" % kind, REFUSE, lambda c, d, r, kind=kind: scen(c, d, lambda s: replace_with(s, kind)))
    for kind in ("fifo", "dir", "empty"):
        b.add(S, "asset mesh.glb is %s" % kind, REFUSE,
              lambda c, d, r, kind=kind: asset(c, d, lambda a: replace_with(j(a, "mesh.glb"), kind), ["mesh.glb"]))
    for kind in ("dir", "empty", "/dev/zero"):
        b.add(S, "asset.json is %s" % kind, REFUSE,
              lambda c, d, r, kind=kind: asset(c, d, lambda a: replace_with(j(a, "asset.json"), kind), ["asset.json"]))
    for kind in ("fifo", "empty"):
        b.add(S, "obj mesh is %s (asset import)" % kind, REFUSE,
              lambda c, d, r, kind=kind: obj_import(c, d, lambda o: replace_with(o, kind)))
    b.add(S, "kitti pkl is empty", REFUSE, lambda c, d, r: kpkl(c, d, lambda p: replace_with(p["info"], "empty"), []))
    for kind in ("fifo", "dir", "empty"):
        b.add(S, "kitti calib is %s" % kind, REFUSE,
              lambda c, d, r, kind=kind: kitti(c, d, lambda p: replace_with(p["calib"], kind), ["000000.txt"]))
    # An empty label file is a frame without objects.
    b.add(S, "kitti label is empty", EITHER,
          lambda c, d, r: kitti(c, d, lambda p: replace_with(p["label"], "empty"), ["000000.txt"]))
    b.add(S, "kitti velodyne is /dev/zero", REFUSE,
          lambda c, d, r: kitti(c, d, lambda p: replace_with(p["velo"], "/dev/zero"), ["000000.bin"]))
    b.add(S, "lyft sample_data.json is a directory", REFUSE,
          lambda c, d, r: lyft(c, d, lambda p: replace_with(p["sample_data"], "dir"), ["sample_data.json"]))
    b.add(S, "lyft sample.json is empty", REFUSE,
          lambda c, d, r: lyft(c, d, lambda p: replace_with(p["sample"], "empty"), ["sample.json"]))

    # -- duplicated samples ----------------------------------------------------------------------------------------
    D = "duplicated samples"
    nus_case(b, D, "data_list holds its record twice", REFUSE,
             info(lambda j: j["data_list"].append(json.loads(json.dumps(j["data_list"][0])))),
             ["twice", "duplicate", "ca9a282c9e77460f8360f564131a8af5"])
    nus_case(b, D, "data_list holds its record twice, existing OUT", REFUSE,
             info(lambda j: j["data_list"].append(json.loads(json.dumps(j["data_list"][0])))),
             ["twice", "duplicate", "ca9a282c9e77460f8360f564131a8af5"], preexisting=True)

    def renamed_dup(j):
        r = json.loads(json.dumps(j["data_list"][0]))
        r["token"] = "f" * 32
        r["sample_idx"] = 1
        j["data_list"].append(r)
    nus_case(b, D, "a second record (another token) with the same sensor files", REFUSE, info(renamed_dup),
             ["twice", "duplicate", "one sample", "samples", sweep, front])
    nus_case(b, D, "v0 infos hold the record twice", REFUSE,
             info(lambda j: j["infos"].append(json.loads(json.dumps(j["infos"][0])))),
             ["twice", "duplicate", "ca9a282c9e77460f8360f564131a8af5"], info=NUS_V0)
    b.add(D, "lyft sample.json holds its record twice", REFUSE,
          lambda c, d, r: lyft(c, d, lambda p: replace_json(p["sample"], lambda x: x + [x[0]]),
                               ["sample", "twice", "duplicate"]))
    b.add(D, "nuscenes tables sample.json holds its record twice", REFUSE,
          lambda c, d, r: tables(c, d, lambda p: replace_json(p["sample"], lambda x: x + [x[0]]),
                                 ["sample", "twice", "duplicate"]))

    # -- camera images of another size than their calibration ------------------------------------------------------
    I = "resized images"
    for w, h in ((800, 450), (1, 1), (1600, 800), (1920, 1080)):
        nus_case(b, I, "CAM_FRONT %dx%d" % (w, h), REFUSE, lambda p, rng, w=w, h=h: write(p["front"], png(w, h)),
                 [front, F, "cam2img"])
    nus_case(b, I, "CAM_FRONT enlarged x2 to 3200x1800 (bicubic jpeg)", REFUSE,
             lambda p, rng: shutil.copy(b.front_x2, p["front"]), [front, F, "cam2img"])
    b.add(I, "nuscenes tables: CAM_FRONT 800x450 (sample_data says 1600x900)", REFUSE,
          lambda c, d, r: tables(c, d, lambda p: write(p["front"], png(800, 450)), [front, F, "width"]))
    b.add(I, "nuscenes tables: CAM_FRONT enlarged x2", REFUSE,
          lambda c, d, r: tables(c, d, lambda p: shutil.copy(c.front_x2, p["front"]), [front, F, "width"]))
    b.add(I, "kitti image_2 1x1", REFUSE, lambda c, d, r: kitti(c, d, lambda p: write(p["image"], png(1, 1)),
                                                                ["000000.png", "P2"]))
    b.add(I, "kitti image_2 612x185 (half size)", REFUSE,
          lambda c, d, r: kitti(c, d, lambda p: write(p["image"], png(612, 185)), ["000000.png", "P2"]))

    # -- other commands on corrupt infos: mine index ---------------------------------------------------------------
    MI = "mine index"
    for name, mutate, names in (
            ("info json cut at half", lambda p: truncate(p["info"], content_len(p["info"]) // 2), []),
            ("lidar2cam reflected", lambda p: edit_json(p["info"], lambda j: mat(
                j["data_list"][0]["images"][F]["lidar2cam"], lambda i, k, v: -v if k == 0 and i < 3 else v)),
             ["lidar2cam"]),
            ("img_path /etc/passwd", lambda p: edit_json(p["info"], lambda j: j["data_list"][0]["images"][F].update(
                img_path="/etc/passwd")), ["img_path", "passwd", "data root"]),
            ("data_list holds its record twice", lambda p: edit_json(p["info"], lambda j: j["data_list"].append(
                json.loads(json.dumps(j["data_list"][0])))), ["twice", "duplicate"])):
        b.add(MI, name, REFUSE, lambda c, d, r, m=mutate, n=names: mine(c, d, m, n))

    # -- eval geometry on corrupt meshes ---------------------------------------------------------------------------
    E = "eval geometry"
    b.add(E, "--pred mesh.glb cut at half", REFUSE,
          lambda c, d, r: eval_glb(c, d, lambda g: truncate(g, os.path.getsize(g) // 2)))
    b.add(E, "--pred mesh.glb JSON chunk length 0xFFFFFFF0", REFUSE,
          lambda c, d, r: eval_glb(c, d, lambda g: patch(g, 12, struct.pack("<I", 0xFFFFFFF0))))
    b.add(E, "--gt obj face index 99999", REFUSE, lambda c, d, r: eval_geo(c, d, lambda o: obj_face(o, "f 1 2 99999")))
    b.add(E, "--gt obj vertex nan, existing metrics file", REFUSE,
          lambda c, d, r: eval_geo(c, d, lambda o: obj_vertex(o, "v nan 0 0")), preexisting=True)
    b.add(MF, "obj face index 0 (asset import)", REFUSE,
          lambda c, d, r: obj_import(c, d, lambda o: obj_face(o, "f 0 1 2")))
    b.add(N, "obj vertex nan (asset import), existing OUT", REFUSE,
          lambda c, d, r: obj_import(c, d, lambda o: obj_vertex(o, "v nan 0 0")), preexisting=True)


# ----------------------------------------------------------------------------------------------------------------
# Per-input preparation

def j(*parts):
    return os.path.join(*parts)


def patch(path, at, data):
    b = bytearray(read(path))
    b[at:at + len(data)] = data
    write(path, bytes(b))


def tables(ctx, d, mutate, names):
    root = ctx.copy(NUS, d, "log")
    shutil.rmtree(j(root, "mmdet3d_info"))
    shutil.rmtree(j(root, "bevfusion_demo_info"))
    t = j(root, "v1.0-subset")
    p = {n: j(t, n + ".json") for n in ("sample", "sample_data", "calibrated_sensor", "ego_pose")}
    p["front"] = j(root, NUS_FRONT)
    mutate(p)
    return ctx.synth(root, d, list(names), "tables")


def lyft(ctx, d, mutate, names):
    root = ctx.copy(LYFT, d, "log")
    t = j(root, LYFT_TABLES)
    p = {n: j(t, n + ".json") for n in ("sample", "sample_data", "calibrated_sensor", "ego_pose", "sample_annotation")}
    mutate(p)
    # The Lyft sample has sweeps but no camera images: a dry run (the placement plan) reads every table.
    return ctx.synth(root, d, list(names), "lyft", extra=["--dry-run"])


def kpkl(ctx, d, mutate, names):
    root = ctx.copy(KPKL, d, "log")
    p = {"info": j(root, KPKL_INFO), "bin": j(root, KPKL_BIN)}
    mutate(p)
    return ctx.synth(p["info"], d, ["000008.pkl"] + list(names), "kpkl", scenario=ctx.kitti_cone)


def kitti(ctx, d, mutate, names, all_frames=False):
    root = ctx.copy(KITTI, d, "log")
    tr = j(root, "training")
    if not all_frames:  # frame 000000 alone: each case reads the one frame it corrupts
        for sub in ("calib", "label_2", "velodyne", "image_2"):
            for n in os.listdir(j(tr, sub)):
                if not n.startswith("000000."):
                    os.remove(j(tr, sub, n))
    p = {"calib": j(tr, "calib", "000000.txt"), "label": j(tr, "label_2", "000000.txt"),
         "velo": j(tr, "velodyne", "000000.bin"), "image": j(tr, "image_2", "000000.png")}
    mutate(p)
    return ctx.synth(root, d, list(names), "kitti3" if all_frames else "kitti", scenario=ctx.kitti_cone,
                     extra=["--frame", "000000"])


def scen(ctx, d, mutate, names=()):
    s = j(d, "demo.json")
    shutil.copy(ctx.src("scenarios/demo.json"), s)
    mutate(s)
    log = ctx.src(j(NUS, NUS_INFO))
    return ctx.synth(log, d, ["demo.json"] + list(names), "nus", scenario=s,
                     assets=[ctx.cone, ctx.barrier, ctx.car])


def asset(ctx, d, mutate, names):
    a = j(d, "cone")
    shutil.copytree(ctx.cone, a)
    mutate(a)
    return ctx.synth(ctx.src(j(NUS, NUS_INFO)), d, list(names), "nus", assets=[a])


def obj_import(ctx, d, mutate, extra=(), names=None):
    src = j(d, "barrier")
    shutil.copytree(ctx.src("assets/procedural_jersey_barrier"), src)
    o = j(src, "jersey_barrier.obj")
    mutate(o)
    out = j(d, "out")
    return Run(["asset", "import", "--mesh", o, "--category", "barrier"] + list(extra) + ["--out", out], out,
               names or ["jersey_barrier.obj"], "asset_import")


def gltf_import(ctx, d, mutate, names):
    src = j(d, "cone_src")
    shutil.copytree(ctx.src("assets/metadrive_traffic_cone"), src)
    mutate(src)
    out = j(d, "out")
    return Run(["asset", "import", "--mesh", j(src, "scene.gltf"), "--up", "+y", "--height", "0.7", "--category",
                "traffic_cone", "--out", out], out, list(names), "asset_import")


def obj_vertex(path, line):
    lines = read(path).decode().splitlines()
    k = next(i for i, l in enumerate(lines) if l.startswith("v "))
    lines[k] = line
    write(path, "\n".join(lines) + "\n")


def obj_face(path, line):
    lines = read(path).decode().splitlines()
    k = next(i for i, l in enumerate(lines) if l.startswith("f "))
    lines[k] = line
    write(path, "\n".join(lines) + "\n")


def calib_edit(path, key, fn):
    lines = read(path).decode().splitlines()
    for i, l in enumerate(lines):
        if l.startswith(key + ":"):
            lines[i] = key + ": " + " ".join(fn(l.split()[1:]))
    write(path, "\n".join(lines) + "\n")


def calib_drop(path, key):
    lines = [l for l in read(path).decode().splitlines() if not l.startswith(key + ":")]
    write(path, "\n".join(lines) + "\n")


def label_edit(path, column, value):
    lines = read(path).decode().splitlines()
    f = lines[0].split()
    f[column] = value
    lines[0] = " ".join(f)
    write(path, "\n".join(lines) + "\n")


def mine(ctx, d, mutate, names):
    root = ctx.copy(NUS, d, "log")
    p = {"info": j(root, NUS_INFO)}
    mutate(p)
    out = j(d, "out")
    return Run(["mine", "index", "--log", p["info"], "--clip", "none", "--out", out], out,
               [os.path.basename(NUS_INFO)] + list(names), "mine")


def eval_geo(ctx, d, mutate):
    src = j(d, "barrier")
    shutil.copytree(ctx.src("assets/procedural_jersey_barrier"), src)
    o = j(src, "jersey_barrier.obj")
    mutate(o)
    out = j(d, "geo.json")
    return Run(["eval", "geometry", "--pred", j(ctx.barrier, "mesh.glb"), "--gt", o, "--samples", "2000",
                "--iou-resolution", "32", "--out", out], out, ["jersey_barrier.obj"], "eval")


def eval_glb(ctx, d, mutate):
    g = j(d, "pred.glb")
    shutil.copy(j(ctx.cone, "mesh.glb"), g)
    mutate(g)
    out = j(d, "geo.json")
    return Run(["eval", "geometry", "--pred", g, "--gt", ctx.src("assets/metadrive_traffic_cone/scene.gltf"),
                "--samples", "2000", "--iou-resolution", "32", "--out", out], out, ["pred.glb"], "eval")


# ----------------------------------------------------------------------------------------------------------------

def main():
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("binary")
    ap.add_argument("data")
    ap.add_argument("--jobs", type=int, default=2, help="cases run at once (default 2)")
    ap.add_argument("--timeout", type=int, default=60, help="seconds a case may run before it counts as a hang")
    ap.add_argument("--only", default="", help="run only cases whose family/name contains this")
    ap.add_argument("--keep", action="store_true", help="keep the temporary folder (printed)")
    args = ap.parse_args()
    start = time.time()
    work = tempfile.mkdtemp(prefix="sd_corruption_")
    b = Battery(args.binary, args.data, work, args.timeout)
    b.keep = args.keep
    try:
        b.setup()
        add_cases(b)
        cases = [c for c in b.cases if args.only in c.family + "/" + c.name or c.family == "control"]
        controls = [(i, c) for i, c in enumerate(cases) if c.family == "control"]
        rest = [(i, c) for i, c in enumerate(cases) if c.family != "control"]
        results = []
        fails = []
        gaps = []

        def report(res):
            case, ok, rc, why, secs, line = res
            tag = "PASS" if ok else ("GAP " if case.name in KNOWN_GAPS else "FAIL")
            print("%s  %-34s %-62s exit %-4s %5.1fs  %s%s" % (
                tag, case.family, case.name, "-" if rc is None else rc, secs, "" if ok else "[" + why + "] ",
                line), flush=True)
            if not ok and getattr(case, "command", None):  # the command, to reproduce it with --keep
                print("      $ " + case.command, flush=True)
            results.append(res)
            if not ok:
                (gaps if case.name in KNOWN_GAPS else fails).append(res)

        # Controls first: each gives its input's complete output (the file set a success must hold, report/ aside:
        # its asset cards follow the assets).
        with ThreadPoolExecutor(max_workers=max(1, args.jobs)) as pool:
            for res in pool.map(lambda ic: b.run_case(*ic, control=True), controls):
                report(res)
            for res in pool.map(lambda ic: b.run_case(*ic), rest):
                report(res)

        by_family = {}
        for case, ok, *_ in results:
            f = by_family.setdefault(case.family, [0, 0])
            f[0 if ok else 1] += 1
        print("\nper family (passed / failed):")
        for fam, (p, f) in by_family.items():
            print("  %-34s %3d / %d" % (fam, p, f))
        print("%d cases: %d passed, %d failed%s, %.0f s" % (
            len(results), len(results) - len(fails) - len(gaps), len(fails),
            ", %d known gaps" % len(gaps) if gaps else "", time.time() - start))
        return 1 if fails else 0
    finally:
        if args.keep:
            print("kept", work)
        else:
            shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    sys.exit(main())
