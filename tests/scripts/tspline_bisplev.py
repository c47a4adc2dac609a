#!/usr/bin/env python3
"""Independent truth for T-spline evaluation: a T-mesh without T-junctions is a tensor-product
B-spline. Writes a regular cubic (or linear) .tmesh with random heights, evaluates it with
`geofit eval` on its integer grid (ESRI ASCII, 17 digits), and compares with scipy's FITPACK
`bisplev` using the global knot vector the thesis' border padding implies,
[0]*h + [0, 1, ..., n] + [n]*h with h = (K+1)/2 (the padding by repetition of
spec §3.6), normalised by the same evaluation
with all coefficients 1 (the rational form). Interior points [1, n-1] only: FITPACK's
evaluation domain is [t_K, t_{len-K-1}]. Exit 0 when max |diff| <= 1e-12 (relative).

usage: tspline_bisplev.py GEOFIT WORKDIR DEGREE
"""
import os
import subprocess
import sys

import numpy as np
from scipy.interpolate import bisplev


def main():
    geofit, work, k = sys.argv[1], sys.argv[2], int(sys.argv[3])
    rng = np.random.default_rng(42)
    ns, nt = 9, 7
    z = rng.uniform(-50, 50, size=(nt + 1, ns + 1))  # z[j, i] at (s=i, t=j)
    pts, cells = [], []
    idx = lambda i, j: j * (ns + 1) + i
    for j in range(nt + 1):
        for i in range(ns + 1):
            pts.append(f"{i} {j} {i} {j} {float(z[j, i])!r} 1")
    for j in range(nt):
        for i in range(ns):
            cells.append(f"{idx(i, j + 1)} {idx(i + 1, j + 1)} {idx(i, j)} {idx(i + 1, j)}")
    mesh = os.path.join(work, f"grid{k}.tmesh")
    with open(mesh, "w") as f:
        f.write('<tmesh xmlns="urn:geofit:tmesh:1" version="1" degree="%d">\n' % k)
        f.write('<georef x0="0" y0="0" dx="0.25" dy="0.25"><crs></crs></georef>\n')
        f.write('<points count="%d">\n%s\n</points>\n' % (len(pts), "\n".join(pts)))
        f.write('<cells count="%d">\n%s\n</cells>\n</tmesh>\n' % (len(cells), "\n".join(cells)))
    # evaluate on a 0.25 grid: --like a raster of that grid is not needed, the georef maps
    # parameter steps of 1 to 0.25 world units; evaluate at quarter steps through a like-raster
    like = os.path.join(work, f"like{k}.asc")
    m = 4
    w, h = ns * m + 1, nt * m + 1
    with open(like, "w") as f:
        f.write(f"ncols {w}\nnrows {h}\nxllcorner {-0.125 / m}\nyllcorner {-0.125 / m}\ncellsize {0.25 / m}\nNODATA_value -9999\n")
        for _ in range(h):
            f.write(" ".join(["0"] * w) + "\n")
    out = os.path.join(work, f"eval{k}.asc")
    subprocess.run([geofit, "-q", "eval", mesh, "--like", like, "-o", out, "--device", "cpu"], check=True)
    with open(out) as f:
        lines = f.read().split("\n")
    hdr = {}
    r = 0
    while lines[r].split() and lines[r].split()[0].lower() in ("ncols", "nrows", "xllcorner", "yllcorner", "xllcenter", "yllcenter", "cellsize", "nodata_value", "dx", "dy"):
        a = lines[r].split()
        hdr[a[0].lower()] = float(a[1])
        r += 1
    vals = np.array([[float(v) for v in line.split()] for line in lines[r:] if line.strip()])
    assert vals.shape == (h, w), vals.shape
    hk = (k + 1) // 2  # knots padded per side (the border knot then has multiplicity hk + 1)
    g = np.concatenate([[0.0] * hk, np.arange(ns + 1, dtype=float), [float(ns)] * hk])
    gt = np.concatenate([[0.0] * hk, np.arange(nt + 1, dtype=float), [float(nt)] * hk])
    # bisplev coefficient layout: c[i * ny + j] for basis i in x, j in y
    c = z.T.reshape(-1)
    worst = 0.0
    n = 0
    for row in range(h):
        t = (h - 1 - row) / m
        for col in range(w):
            s = col / m
            if not (1.0 <= s <= ns - 1 and 1.0 <= t <= nt - 1):
                continue
            num = bisplev(s, t, (g, gt, c, k, k))
            den = bisplev(s, t, (g, gt, np.ones_like(c), k, k))
            ref = num / den
            worst = max(worst, abs(vals[row, col] - ref) / max(1.0, abs(ref)))
            n += 1
    print(f"degree {k}: {n} points, max relative difference {worst:.3e}")
    return 0 if n > 100 and worst <= 1e-12 else 1


if __name__ == "__main__":
    sys.exit(main())
