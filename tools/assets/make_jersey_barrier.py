#!/usr/bin/env python3
"""Writes a New Jersey concrete safety barrier segment ("Jersey barrier") as a watertight triangulated OBJ + MTL.

Why: the only barrier asset in data/assets (the MetaDrive road barrier) is an open sawhorse barricade that lets
LiDAR beams through, while many real barriers (nuScenes' lane separators, roadworks walls) return like solid low
walls. This is the solid counterpart, made from a public engineering standard rather than a downloaded model.

Shape: the "New Jersey safety shape" profile of the US roadside-design standards (AASHTO Roadside Design Guide,
rigid barriers; FHWA, C. F. McDevitt, "Basics of Concrete Barriers", Public Roads, 2000; state DOT standard
drawings of precast concrete barrier). Only its published dimensions are used, in inches as specified:
  total height 32 in (813 mm), base width 24 in (610 mm), top width 6 in (152 mm);
  on each side, from the road up: a 3 in (76 mm) vertical reveal; a face rising 10 in over 7 in horizontally
  (55.0 degrees from horizontal) to the slope break at 13 in (330 mm); a face rising 19 in over 2 in
  (84.0 degrees) to the top. 3 + 10 + 19 = 32 in; 24 - 2 * (7 + 2) = 6 in.
No drainage slots, joints, lifting holes or edge chamfers. The profile is extruded along the segment's length
(--length, default 3.0 m; precast segments are commonly 10-20 ft) with both end caps closed.

Output frame (like the glTF / OBJ assets in data/assets): metres, y up, base on y = 0; x across the barrier
(the profile's width: the faces toward traffic look along +x and -x, so +x is the asset's front); z along its
length; centred on x = 0, z = 0. Import with named axes and --scale 1 (`--up auto` lays it on its side: the
convex hull's facet across both sloped faces is larger than the base; without --scale it is scaled to the
category's typical height):
  synthdrive asset import --mesh jersey_barrier.obj --category barrier --up +y --front +x --scale 1 --out DIR
Canonical result: x = 0.610 m (front, across), y = length, z = 0.813 m. This matches the nuScenes barrier
convention, whose box length (along its heading) is the barrier's thin side.

Mesh: 16 vertices (the 8-point profile at both ends), 28 triangles: 8 side quads split in two, 6 triangles per
end cap (the profile is not convex: it turns inward at the slope break, so caps are cut at the reveal top and the
slope break into a rectangle and two trapezoids). Every face is counter-clockwise seen from outside (outward
normals); each edge is shared by exactly two faces in opposite directions (checked before writing). One `vn`
per flat face, so shading stays flat at the sharp edges; the `v` indices alone form the closed surface.

Usage: python3 tools/assets/make_jersey_barrier.py [--length 3.0] [--out data/assets/procedural_jersey_barrier]
                                                    [--name jersey_barrier] [--overwrite]
"""
import argparse
import math
import os
import sys
import tempfile

INCH = 0.0254

# Half-profile from the centreline outward, (horizontal offset from the centre, height), metres.
BASE_HALF = 12 * INCH        # 24 in base
REVEAL = 3 * INCH            # vertical lip at the road
BREAK_H = 13 * INCH          # slope break height
BREAK_HALF = (12 - 7) * INCH  # 10 in rise over 7 in run
TOP_H = 32 * INCH            # total height
TOP_HALF = 3 * INCH          # 6 in top; 19 in rise over 2 in run

CONCRETE_KD = (0.55, 0.55, 0.53)


def profile():
    """The closed cross-section (x across, y up), counter-clockwise seen from +z."""
    return [(-BASE_HALF, 0.0), (BASE_HALF, 0.0), (BASE_HALF, REVEAL), (BREAK_HALF, BREAK_H), (TOP_HALF, TOP_H),
            (-TOP_HALF, TOP_H), (-BREAK_HALF, BREAK_H), (-BASE_HALF, REVEAL)]


def build(length):
    """Vertices (x, y, z) and triangles (0-based vertex indices, counter-clockwise from outside)."""
    prof = profile()
    n = len(prof)
    back = [(x, y, -0.5 * length) for x, y in prof]    # indices 0..n-1
    front = [(x, y, 0.5 * length) for x, y in prof]    # indices n..2n-1
    verts = back + front
    tris = []
    for i in range(n):  # sides: for a CCW profile the outward normal lies to the right of each edge
        j = (i + 1) % n
        tris += [(i, j, n + j), (i, n + j, n + i)]
    # Caps: cut at the reveal top (indices 7-2) and the slope break (6-3) into convex pieces.
    cap = [(0, 1, 2), (0, 2, 7), (7, 2, 3), (7, 3, 6), (6, 3, 4), (6, 4, 5)]
    tris += [(n + a, n + b, n + c) for a, b, c in cap]  # front cap, normal +z: profile order
    tris += [(a, c, b) for a, b, c in cap]              # back cap, normal -z: reversed
    return verts, tris


def sub(a, b):
    return (a[0] - b[0], a[1] - b[1], a[2] - b[2])


def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def face_normal(verts, t):
    c = cross(sub(verts[t[1]], verts[t[0]]), sub(verts[t[2]], verts[t[0]]))
    norm = math.sqrt(sum(v * v for v in c))
    if norm <= 0:
        raise AssertionError(f"degenerate triangle {t}")
    return tuple(v / norm for v in c)


def check(verts, tris, length):
    """Closed, consistently wound, outward: every directed edge once with its reverse, positive volume equal to
    the profile area times the length, every face normal pointing away from the solid's centre line."""
    edges = {}
    for t in tris:
        for k in range(3):
            e = (t[k], t[(k + 1) % 3])
            if e in edges:
                raise AssertionError(f"directed edge {e} used twice (inconsistent winding)")
            edges[e] = t
    for a, b in edges:
        if (b, a) not in edges:
            raise AssertionError(f"edge {(a, b)} has no opposite (hole)")
    volume = sum(v0[0] * (v1[1] * v2[2] - v1[2] * v2[1]) - v0[1] * (v1[0] * v2[2] - v1[2] * v2[0]) +
                 v0[2] * (v1[0] * v2[1] - v1[1] * v2[0]) for v0, v1, v2 in
                 ((verts[a], verts[b], verts[c]) for a, b, c in tris)) / 6.0
    prof = profile()
    area = 0.5 * sum(prof[i][0] * prof[(i + 1) % len(prof)][1] - prof[(i + 1) % len(prof)][0] * prof[i][1]
                     for i in range(len(prof)))
    if abs(volume - area * length) > 1e-9 * max(1.0, area * length):
        raise AssertionError(f"volume {volume} != profile area x length {area * length}")
    for t in tris:  # the solid is star-shaped about its axis (x = 0, y = mid-height): outward = away from it
        nrm = face_normal(verts, t)
        c = [sum(verts[i][k] for i in t) / 3.0 for k in range(3)]
        away = (c[0], c[1] - 0.5 * BREAK_H, c[2])
        if sum(nrm[k] * away[k] for k in range(3)) <= 0:
            raise AssertionError(f"triangle {t} faces inward")
    return volume


def write_atomic(path, text):
    fd, tmp = tempfile.mkstemp(prefix=".tmp-", dir=os.path.dirname(path) or ".")
    try:
        with os.fdopen(fd, "w", newline="\n") as f:
            f.write(text)
        os.chmod(tmp, 0o644)
        os.replace(tmp, path)
    except BaseException:
        os.unlink(tmp)
        raise


def fmt(v):
    s = f"{v:.6f}".rstrip("0").rstrip(".")
    return "0" if s in ("-0", "") else s


def main():
    here = os.path.dirname(os.path.realpath(__file__))
    default_out = os.path.normpath(os.path.join(here, "..", "..", "data", "assets", "procedural_jersey_barrier"))
    ap = argparse.ArgumentParser(description="Write a New Jersey concrete barrier segment as OBJ + MTL "
                                             "(metres, y up, x across, z along the length).")
    ap.add_argument("--length", type=float, default=3.0, help="segment length in metres (default 3.0)")
    ap.add_argument("--out", default=default_out, help="output folder (default: the repo's "
                                                       "data/assets/procedural_jersey_barrier)")
    ap.add_argument("--name", default="jersey_barrier", help="file stem (default jersey_barrier)")
    ap.add_argument("--overwrite", action="store_true", help="replace existing output files")
    args = ap.parse_args()
    if not (math.isfinite(args.length) and args.length > 0):
        sys.exit(f"make_jersey_barrier: --length must be a positive number of metres, got {args.length}")

    verts, tris = build(args.length)
    volume = check(verts, tris, args.length)
    normals, normal_of = [], []
    for t in tris:  # one normal per flat face (the two triangles of a quad, the six of a cap share it)
        nrm = tuple(round(v, 6) + 0.0 for v in face_normal(verts, t))
        if nrm not in normals:
            normals.append(nrm)
        normal_of.append(normals.index(nrm) + 1)

    lower = math.degrees(math.atan2(BREAK_H - REVEAL, BASE_HALF - BREAK_HALF))
    upper = math.degrees(math.atan2(TOP_H - BREAK_H, BREAK_HALF - TOP_HALF))
    os.makedirs(args.out, exist_ok=True)
    mtl_name = args.name + ".mtl"
    obj = [f"# New Jersey concrete safety barrier segment, made by tools/assets/make_jersey_barrier.py "
           f"--length {fmt(args.length)}",
           f"# metres, y up, x across (base {fmt(2 * BASE_HALF)}, top {fmt(2 * TOP_HALF)}), "
           f"z along (length {fmt(args.length)}), height {fmt(TOP_H)}; faces {lower:.1f} / {upper:.1f} deg",
           f"# closed: {len(verts)} vertices, {len(tris)} triangles, volume {volume:.6f} m^3",
           f"mtllib {mtl_name}", f"o {args.name}"]
    obj += [f"v {fmt(x)} {fmt(y)} {fmt(z)}" for x, y, z in verts]
    obj += [f"vn {fmt(x)} {fmt(y)} {fmt(z)}" for x, y, z in normals]
    obj += ["usemtl concrete", "s off"]
    obj += [f"f {a + 1}//{k} {b + 1}//{k} {c + 1}//{k}" for (a, b, c), k in zip(tris, normal_of)]
    mtl = ["# plain concrete grey, no texture (make_jersey_barrier.py)", "newmtl concrete",
           "Ka 0 0 0", "Kd " + " ".join(fmt(v) for v in CONCRETE_KD), "Ks 0 0 0", "Ns 10", "d 1", "illum 1"]
    outputs = [(os.path.join(args.out, mtl_name), mtl), (os.path.join(args.out, args.name + ".obj"), obj)]
    for path, _ in outputs:
        if os.path.exists(path) and not args.overwrite:
            sys.exit(f"make_jersey_barrier: {path} exists (pass --overwrite to replace it)")
    for path, lines in outputs:  # MTL first: the OBJ never names a missing MTL
        write_atomic(path, "\n".join(lines) + "\n")
    print(f"wrote {os.path.join(args.out, args.name + '.obj')} (+ {mtl_name}): {len(verts)} vertices, "
          f"{len(tris)} triangles, {fmt(2 * BASE_HALF)} x {fmt(TOP_H)} x {fmt(args.length)} m, "
          f"faces at {lower:.1f} and {upper:.1f} deg, volume {volume:.4f} m^3")


if __name__ == "__main__":
    main()
