#!/usr/bin/env python3
"""Helpers of benches/tspline_speed.sh.

mesh PATH N C: writes a regular cubic T-mesh of N x N cells of size C (integer lattice, smooth
  random heights) as XML; without T-junctions it is a tensor-product B-spline with (N+1)^2
  control points, evaluated by `geofit eval` on (N*C+1)^2 integer points.
bisplev N C: times scipy's FITPACK `bisplev` on a cubic tensor spline with (N+1)^2 coefficients
  (uniform knots, the evaluation grid of `mesh`) and prints a markdown table row with points per
  CPU-second (process time: robust to a shared machine).
"""
import sys
import time

import numpy as np


def write_mesh(path, n, c):
    rng = np.random.default_rng(7)
    z = np.cumsum(np.cumsum(rng.normal(size=(n + 1, n + 1)), axis=0), axis=1) * 0.1
    idx = lambda i, j: j * (n + 1) + i
    with open(path, "w") as f:
        f.write('<tmesh xmlns="urn:geofit:tmesh:1" version="1" degree="3">\n')
        f.write('<georef x0="0" y0="0" dx="1" dy="1"><crs></crs></georef>\n')
        f.write('<points count="%d">\n' % ((n + 1) ** 2))
        for j in range(n + 1):
            for i in range(n + 1):
                f.write(f"{i * c} {j * c} {i * c} {j * c} {float(z[j, i])!r} 1\n")
        f.write("</points>\n<cells count=\"%d\">\n" % (n * n))
        for j in range(n):
            for i in range(n):
                f.write(f"{idx(i, j + 1)} {idx(i + 1, j + 1)} {idx(i, j)} {idx(i + 1, j)}\n")
        f.write("</cells>\n</tmesh>\n")
    print(f"Mesh: {n}x{n} cubic cells of size {c}, {(n + 1) ** 2} control points, grid {n * c + 1}^2 = {(n * c + 1) ** 2} points.")


def bench_bisplev(n, c):
    from scipy.interpolate import bisplev
    k = 3
    # (N+1)^2 coefficients: len(knots) = N + 1 + k + 1 per direction, uniform over [0, N*C]
    m = n + 1
    inner = np.linspace(0.0, n * c, m - k + 1)
    tx = np.concatenate([[0.0] * k, inner, [n * c] * k])
    coef = np.random.default_rng(1).normal(size=m * m)
    x = np.arange(n * c + 1, dtype=float)
    tck = (tx, tx, coef, k, k)
    t0 = time.process_time()
    w0 = time.perf_counter()
    z = bisplev(x, x, tck)
    cpu = time.process_time() - t0
    wall = time.perf_counter() - w0
    pts = z.size
    print(f"| scipy bisplev ({m * m} coefficients) | {pts} | {cpu:.3f} | {pts / cpu / 1e6:.1f} M |")


if __name__ == "__main__":
    if sys.argv[1] == "mesh":
        write_mesh(sys.argv[2], int(sys.argv[3]), int(sys.argv[4]))
    else:
        bench_bisplev(int(sys.argv[2]), int(sys.argv[3]))
