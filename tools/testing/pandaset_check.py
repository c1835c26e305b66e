#!/usr/bin/env python3
"""Checks a derivative PandaSet sequence the way its users read it: with pandas.

usage: pandaset_check.py INPUT_SEQ OUTPUT_SEQ FRAME MOVED_ROWS(comma list) ADDED_LABEL SEMSEG_CLASS

For the edited FRAME: every file loads with pandas.read_pickle; the lidar frame keeps every row, dtype and value
except the MOVED rows, whose x/y/z changed and whose t and d did not; semseg classes are the input's except the
moved rows, which hold SEMSEG_CLASS; the cuboids are the input's rows followed by one row labelled ADDED_LABEL
with a fresh uuid; the sequence's json tables are byte-identical. Prints "ok" and exits 0, or says what differs
and exits 1.
"""
import os
import sys

import numpy as np
import pandas as pd


def main():
    src, out, frame, moved, label, semseg_class = sys.argv[1:7]
    moved = [int(m) for m in moved.split(",") if m]
    bad = []

    def check(cond, what):
        if not cond:
            bad.append(what)

    lin = pd.read_pickle(os.path.join(src, "lidar", frame + ".pkl.gz"))
    lout = pd.read_pickle(os.path.join(out, "lidar", frame + ".pkl.gz"))
    check(list(lin.columns) == list(lout.columns), "lidar columns differ")
    check(list(lin.dtypes) == list(lout.dtypes), "lidar dtypes differ")
    check(len(lin) == len(lout), "lidar row count differs")
    check(lin.index.equals(lout.index), "lidar index differs")
    keep = np.ones(len(lin), bool)
    keep[moved] = False
    check(lin[keep].equals(lout[keep]), "untouched lidar rows differ")
    for c in ("t", "d"):
        check((lin[c].values[moved] == lout[c].values[moved]).all(), "moved rows changed " + c)
    check((np.abs(lin[["x", "y", "z"]].values[moved] - lout[["x", "y", "z"]].values[moved]).max(axis=1) > 1e-3).all(),
          "moved rows did not move")

    sin = pd.read_pickle(os.path.join(src, "annotations", "semseg", frame + ".pkl.gz"))
    sout = pd.read_pickle(os.path.join(out, "annotations", "semseg", frame + ".pkl.gz"))
    check(sin.dtypes.equals(sout.dtypes), "semseg dtypes differ")
    check(sin[keep].equals(sout[keep]), "untouched semseg rows differ")
    check((sout["class"].values[moved] == int(semseg_class)).all(), "moved rows' class is not " + semseg_class)

    cin = pd.read_pickle(os.path.join(src, "annotations", "cuboids", frame + ".pkl.gz"))
    cout = pd.read_pickle(os.path.join(out, "annotations", "cuboids", frame + ".pkl.gz"))
    check(list(cin.columns) == list(cout.columns), "cuboid columns differ")
    check(len(cout) == len(cin) + 1, "expected one added cuboid, found %d" % (len(cout) - len(cin)))
    check(cout.iloc[: len(cin)].equals(cin), "the input's cuboid rows differ")
    check(list(cin.dtypes) == list(cout.dtypes), "cuboid dtypes differ")
    if len(cout) == len(cin) + 1:
        row = cout.iloc[-1]
        check(row["label"] == label, "added label is %r" % row["label"])
        check(len(row["uuid"]) == 36 and row["uuid"] not in set(cin["uuid"]), "added uuid %r" % row["uuid"])
        check(row["cuboids.sensor_id"] == -1, "added sensor_id")
        check(row["dimensions.z"] > 0, "added height")

    for root, _, files in os.walk(src):
        for f in files:
            if f.endswith(".json"):
                rel = os.path.relpath(os.path.join(root, f), src)
                with open(os.path.join(src, rel), "rb") as a, open(os.path.join(out, rel), "rb") as b:
                    check(a.read() == b.read(), rel + " differs")
    if bad:
        print("\n".join(bad))
        return 1
    print("ok")
    return 0


if __name__ == "__main__":
    sys.exit(main())
