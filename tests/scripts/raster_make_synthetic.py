#!/usr/bin/env python3
"""Writes the synthetic rasters the raster tests need, as ESRI ASCII grids (numpy only):

  channel DIR   channel.asc: a 240x180 grid (1 m cells) holding a sinuous channel along 30°
                with depth varying along and across it, nodata elsewhere
  perturb IN OUT SEED   OUT = IN + noise on a copy of IN's grid (via XYZ) with some cells removed
  allnodata OUT         a 5x4 grid without any value
  single OUT            a 1x1 grid
"""
import math
import sys

import numpy as np


def write_asc(path, z, x0, y0, cell, nodata=-9999.0):
    h, w = z.shape
    with open(path, "w") as f:
        f.write(f"ncols {w}\nnrows {h}\nxllcorner {x0!r}\nyllcorner {y0!r}\ncellsize {cell!r}\nNODATA_value {nodata!r}\n")
        for row in z:
            f.write(" ".join(repr(float(v)) if np.isfinite(v) else repr(nodata) for v in row) + "\n")


def channel(w=240, h=180):
    z = np.full((h, w), np.nan)
    t = math.radians(30.0)
    cx, cy = w / 2.0, h / 2.0
    for r in range(h):
        for c in range(w):
            x, y = c + 0.5, (h - r) - 0.5
            along = (x - cx) * math.cos(t) + (y - cy) * math.sin(t)
            across = -(x - cx) * math.sin(t) + (y - cy) * math.cos(t)
            half = 18.0 + 9.0 * math.sin(along / 25.0)
            if abs(along) < 0.42 * w and abs(across) < half:
                z[r, c] = -12.0 - 0.04 * along - 6.0 * (1.0 - (across / half) ** 2)
    return z


cmd = sys.argv[1]
if cmd == "channel":
    write_asc(sys.argv[2] + "/channel.asc", channel(), 500000.0, 5700000.0, 1.0)
elif cmd == "perturb":
    src, out, seed = sys.argv[2], sys.argv[3], int(sys.argv[4])
    lines = open(src).read().split("\n")
    header = {l.split()[0].lower(): l.split()[1] for l in lines[:6]}
    w, h = int(header["ncols"]), int(header["nrows"])
    nd = float(header["nodata_value"])
    z = np.array([[float(v) for v in l.split()] for l in lines[6:6 + h]])
    z[z == nd] = np.nan
    rng = np.random.default_rng(seed)
    z = z + rng.normal(0.0, 0.3, z.shape) * rng.choice([0.1, 1.0, 5.0], z.shape)
    z[rng.random(z.shape) < 0.05] = np.nan
    write_asc(out, z, float(header["xllcorner"]), float(header["yllcorner"]), float(header["cellsize"]), nd)
elif cmd == "allnodata":
    write_asc(sys.argv[2], np.full((4, 5), np.nan), 0.0, 0.0, 1.0)
elif cmd == "single":
    write_asc(sys.argv[2], np.array([[3.5]]), 10.0, 20.0, 2.0)
else:
    sys.exit(f"unknown command {cmd}")
