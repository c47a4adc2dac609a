#!/usr/bin/env python3
"""Writes the benchmark T-mesh: a cubic mesh of N x N cells (N = 315: 99 856 control points)
of size CELL, with one band of cells split into four (T-junctions), wavy heights.

usage: tspline_mesh.py OUT.tmesh [N] [CELL]
"""
import math
import sys

out = sys.argv[1]
n = int(sys.argv[2]) if len(sys.argv) > 2 else 315
cell = int(sys.argv[3]) if len(sys.argv) > 3 else 10
pts = {}
order = []


def pid(s, t):
    if (s, t) not in pts:
        pts[(s, t)] = len(order)
        order.append((s, t))
    return pts[(s, t)]


cells = []
band = n // 2
for j in range(n):
    for i in range(n):
        s0, t0, s1, t1 = i * cell, j * cell, (i + 1) * cell, (j + 1) * cell
        if j == band:
            sm, tm = (s0 + s1) // 2, (t0 + t1) // 2
            for a, b, c, d in [(s0, tm, sm, t1), (sm, tm, s1, t1), (s0, t0, sm, tm), (sm, t0, s1, tm)]:
                cells.append((pid(a, d), pid(c, d), pid(a, b), pid(c, b)))
        else:
            cells.append((pid(s0, t1), pid(s1, t1), pid(s0, t0), pid(s1, t0)))
with open(out, "w") as f:
    f.write('<tmesh xmlns="urn:geofit:tmesh:1" version="1" degree="3">\n')
    f.write('<georef x0="0" y0="0" dx="1" dy="1"><crs></crs></georef>\n')
    f.write('<points count="%d">\n' % len(order))
    for s, t in order:
        z = 20 * math.sin(s * 0.013) * math.cos(t * 0.011) + 0.01 * s
        f.write(f"{s} {t} {s} {t} {z!r} 1\n")
    f.write("</points>\n")
    f.write('<cells count="%d">\n' % len(cells))
    for c in cells:
        f.write("%d %d %d %d\n" % c)
    f.write("</cells>\n</tmesh>\n")
print(f"{out.rsplit('/', 1)[-1]}: {len(order)} control points, {len(cells)} cells", file=sys.stderr)
