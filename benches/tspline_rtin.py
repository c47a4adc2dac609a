#!/usr/bin/env python3
"""Restricted quadtree TIN (RTIN, Martini: right-angled triangles from a binary split of the
square, the dyadic counterpart of the T-mesh) for the T-spline benchmark: vertices pymartini
needs for a maximum error E on a raster. The raster is read like tspline_tin.py (nodata cells
filled with the nearest valid value) and padded by edge replication to the square 2^k + 1 grid
Martini needs (a constant extension, which costs the RTIN a handful of vertices). Martini's
error bound is hierarchical (each split vertex against its parent's hypotenuse), not the error
of the final mesh, so the mesh is also rasterised here and its real max |dz| over the valid
cells and the number of cells over E are reported beside the vertex count, with the vertices of
the largest Martini threshold whose mesh does stay within E (bisection). Prints one JSON line:
vertices, triangles, seconds, grid, max_error_reached, cells_over, vertices_within_e,
threshold_within_e.

usage: tspline_rtin.py RASTER E
"""
import json
import os
import sys
import time

import numpy as np
from pymartini import Martini

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from terrain_grid import load_filled  # noqa: E402

path, e = sys.argv[1], float(sys.argv[2])
full, ok, _ = load_filled(path)
h, w = full.shape
n = 2
while n + 1 < max(w, h):
    n *= 2
size = n + 1
grid = np.pad(full, ((0, size - h), (0, size - w)), mode="edge").astype(np.float32)


def mesh_error(vertices, triangles):
    """Max |dz| of the final mesh over the valid cells, and the cells over E (barycentric
    interpolation, triangle by triangle)."""
    P = vertices.astype(np.float64)
    surf = np.full((size, size), np.nan)
    for tri in triangles:
        q = P[tri]
        (x0, y0), (x1, y1) = q.min(0).astype(int), q.max(0).astype(int)
        X, Y = np.meshgrid(np.arange(x0, x1 + 1), np.arange(y0, y1 + 1))
        X, Y = X.ravel(), Y.ravel()
        T = np.array([[q[0, 0] - q[2, 0], q[1, 0] - q[2, 0]], [q[0, 1] - q[2, 1], q[1, 1] - q[2, 1]]])
        l0, l1 = np.linalg.solve(T, np.vstack([X - q[2, 0], Y - q[2, 1]]))
        l2 = 1.0 - l0 - l1
        inside = (l0 >= -1e-9) & (l1 >= -1e-9) & (l2 >= -1e-9)
        z = [float(grid[int(q[k, 1]), int(q[k, 0])]) for k in range(3)]
        surf[Y[inside], X[inside]] = (l0 * z[0] + l1 * z[1] + l2 * z[2])[inside]
    err = np.abs(surf - grid)[:h, :w][ok]
    return float(err.max()), int((err > e).sum())


t0 = time.time()
tile = Martini(size).create_tile(grid.reshape(-1))
vertices, triangles = tile.get_mesh(e)
secs = time.time() - t0
reached, over = mesh_error(vertices, triangles)
# The RTIN that really meets E: the largest Martini threshold whose mesh is within E everywhere
# (bisection on the threshold; 0 always is, the full grid).
lo, hi, best = 0.0, e, None
if over == 0:
    best = (vertices, triangles, reached)
else:
    for _ in range(14):
        mid = 0.5 * (lo + hi)
        vm, tm = tile.get_mesh(mid)
        r, o = mesh_error(vm, tm)
        if o == 0:
            lo, best = mid, (vm, tm, r)
        else:
            hi = mid
    if best is None:
        vm, tm = tile.get_mesh(0.0)
        best = (vm, tm, mesh_error(vm, tm)[0])
print(json.dumps({"vertices": len(vertices), "triangles": len(triangles), "seconds": round(secs, 3), "grid": size,
                  "max_error_reached": round(reached, 4), "cells_over": over,
                  "vertices_within_e": len(best[0]), "threshold_within_e": round(lo if over else e, 4)}))
