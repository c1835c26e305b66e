#!/usr/bin/env python3
"""Adds four wheels to a car body OBJ whose source has none (TORCS draws its wheels in code, so its car models
are bodies with empty wheel arches: a perception engineer drops such a sample at once).

Each wheel is a tyre (tread, both sidewalls) around a rim recessed into its outer face, in two materials appended
to the OBJ's MTL ("tyre", "rim"). The block is written after a marker line and replaced on every run, so the
script can be rerun with other sizes. Standard library only.

usage: scripts/car_wheels.py OBJ --centres X1,Y1,Z1 X2,Y2,Z2 ... --radius R --rim R --width W [--segments N]
The OBJ's axes are kept: the wheel axle is the OBJ's z axis (x forward, y up, z to the side, as TORCS models
are). Centres are in the OBJ's units; a centre's z sign says which side its outer face is on.
"""
import argparse
import math
import pathlib

MARKER = "# --- wheels added by scripts/car_wheels.py (rerunning replaces everything below) ---"


def sub(a, b):
    return tuple(x - y for x, y in zip(a, b))


def cross(a, b):
    return (a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0])


def dot(a, b):
    return sum(x * y for x, y in zip(a, b))


class Block:
    def __init__(self, first_v, first_vt, first_vn):
        self.v, self.vn, self.lines = [], [], []
        self.first_v, self.first_vn, self.vt = first_v, first_vn, first_vt
        self.material = None

    def vertex(self, p, n):
        self.v.append(p)
        self.vn.append(n)
        return len(self.v) - 1

    def use(self, material):
        if material != self.material:
            self.lines.append(f"usemtl {material}")
            self.material = material

    def tri(self, a, b, c, outward):
        """A triangle of local vertex indices, wound so that its normal points along `outward`."""
        n = cross(sub(self.v[b], self.v[a]), sub(self.v[c], self.v[a]))
        if dot(n, outward) < 0:
            b, c = c, b
        f = [f"{self.first_v + i}/{self.vt}/{self.first_vn + i}" for i in (a, b, c)]
        self.lines.append("f " + " ".join(f))


def add_wheel(block, centre, radius, rim, width, segments):
    cx, cy, cz = centre
    side = 1.0 if cz >= 0 else -1.0
    outer_z, inner_z = cz + side * width / 2, cz - side * width / 2
    recess_z = outer_z - side * min(0.02, width / 4)
    ring = [(math.cos(2 * math.pi * k / segments), math.sin(2 * math.pi * k / segments)) for k in range(segments)]

    def circle(r, z, normal_of):
        return [block.vertex((cx + r * c, cy + r * s, z), normal_of(c, s)) for c, s in ring]

    def band(a, b, outward_of):  # quads between two rings of equal length
        for k in range(segments):
            k1 = (k + 1) % segments
            c, s = ring[k]
            out = outward_of(c, s)
            block.tri(a[k], a[k1], b[k1], out)
            block.tri(a[k], b[k1], b[k], out)

    radial = lambda c, s: (c, s, 0.0)
    inward = lambda c, s: (-c, -s, 0.0)
    out_face = lambda c, s: (0.0, 0.0, side)
    in_face = lambda c, s: (0.0, 0.0, -side)

    block.use("tyre")
    band(circle(radius, inner_z, radial), circle(radius, outer_z, radial), radial)        # tread
    band(circle(rim, outer_z, out_face), circle(radius, outer_z, out_face), out_face)     # outer sidewall
    band(circle(rim, inner_z, in_face), circle(radius, inner_z, in_face), in_face)        # inner sidewall
    inner_centre = block.vertex((cx, cy, inner_z), (0.0, 0.0, -side))
    inner_rim = circle(rim, inner_z, in_face)
    for k in range(segments):
        block.tri(inner_centre, inner_rim[k], inner_rim[(k + 1) % segments], (0.0, 0.0, -side))
    block.use("rim")
    band(circle(rim, outer_z, inward), circle(rim, recess_z, inward), inward)             # the rim's lip
    centre_v = block.vertex((cx, cy, recess_z), (0.0, 0.0, side))
    disc = circle(rim, recess_z, out_face)
    for k in range(segments):
        block.tri(centre_v, disc[k], disc[(k + 1) % segments], (0.0, 0.0, side))
    # Five spoke-like dark slots would need a texture; a flat grey disc reads as a steel wheel with a hubcap.


def main():
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("obj", type=pathlib.Path)
    ap.add_argument("--centres", nargs=4, required=True)
    ap.add_argument("--radius", type=float, required=True)
    ap.add_argument("--rim", type=float, required=True)
    ap.add_argument("--width", type=float, required=True)
    ap.add_argument("--segments", type=int, default=32)
    a = ap.parse_args()

    text = a.obj.read_text()
    body = text.split("\n" + MARKER + "\n")[0].rstrip("\n") + "\n"
    n_v = sum(1 for l in body.splitlines() if l.startswith("v "))
    n_vt = sum(1 for l in body.splitlines() if l.startswith("vt "))
    n_vn = sum(1 for l in body.splitlines() if l.startswith("vn "))
    block = Block(n_v + 1, n_vt + 1, n_vn + 1)
    for c in a.centres:
        add_wheel(block, tuple(float(x) for x in c.split(",")), a.radius, a.rim, a.width, a.segments)
    out = [MARKER, "vt 0.5 0.5 0"]
    out += [f"v {p[0]:.5f} {p[1]:.5f} {p[2]:.5f}" for p in block.v]
    out += [f"vn {n[0]:.5f} {n[1]:.5f} {n[2]:.5f}" for n in block.vn]
    out += block.lines
    tmp = a.obj.with_suffix(".obj.tmp")
    tmp.write_text(body + "\n".join(out) + "\n")
    tmp.replace(a.obj)

    mtl = a.obj.with_suffix(".mtl")
    if mtl.exists():
        m = mtl.read_text().split("\n" + MARKER + "\n")[0].rstrip("\n") + "\n"
        m += MARKER + "\nnewmtl tyre\nKd 0.035 0.035 0.035\nKs 0.05 0.05 0.05\nNs 10\nd 1\nillum 2\n\n"
        m += "newmtl rim\nKd 0.55 0.56 0.58\nKs 0.6 0.6 0.6\nNs 80\nd 1\nillum 2\n"
        tmpm = mtl.with_suffix(".mtl.tmp")
        tmpm.write_text(m)
        tmpm.replace(mtl)
    print(f"{a.obj}: {len(block.v)} wheel vertices, {sum(1 for l in block.lines if l.startswith('f '))} faces")


if __name__ == "__main__":
    main()
