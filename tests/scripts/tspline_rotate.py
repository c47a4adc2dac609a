#!/usr/bin/env python3
"""Rotates a raster by an angle (degrees, counter-clockwise) onto a larger north-up grid with the
same cell size, bilinear, nodata outside the rotated footprint (and where any of the four source
corners has none); writes an ESRI ASCII grid. Used to make a rotated, channel-like bathymetry for
the indirect-vs-direct comparison (`gmt_tut_bathy.nc` rotated by 30°).

usage: tspline_rotate.py IN ANGLE OUT.asc
"""
import json
import math
import subprocess
import sys

import numpy as np

src, ang, out = sys.argv[1], float(sys.argv[2]), sys.argv[3]
info = json.loads(subprocess.run(["gdalinfo", "-json", src], check=True, capture_output=True).stdout)
w, h = info["size"]
nodata = info["bands"][0].get("noDataValue")
xyz = subprocess.run(["gdal_translate", "-q", "-of", "XYZ", src, "/vsistdout/"], check=True, capture_output=True).stdout
v = np.loadtxt(xyz.decode().splitlines(), usecols=2, dtype=np.float64).reshape(h, w)
ok = np.isfinite(v)
if nodata is not None:
    ok &= v != float(nodata)
v = np.where(ok, v, np.nan)
a = math.radians(ang)
c, s = math.cos(a), math.sin(a)
# output grid: the rotated bounding box, cell size 1 (in source cells)
W = int(math.ceil(abs(w * c) + abs(h * s))) + 2
H = int(math.ceil(abs(w * s) + abs(h * c))) + 2
cx, cy, CX, CY = (w - 1) / 2, (h - 1) / 2, (W - 1) / 2, (H - 1) / 2
J, I = np.mgrid[0:H, 0:W].astype(np.float64)
# output (col I, row J) -> source position: inverse rotation about the centres (rows point down)
dx, dy = I - CX, -(J - CY)
sx = c * dx + s * dy + cx
sy = -(-s * dx + c * dy) + cy
i0, j0 = np.floor(sx).astype(int), np.floor(sy).astype(int)
fx, fy = sx - i0, sy - j0
inside = (i0 >= 0) & (j0 >= 0) & (i0 + 1 < w) & (j0 + 1 < h)
i0c, j0c = np.clip(i0, 0, w - 2), np.clip(j0, 0, h - 2)
z = (v[j0c, i0c] * (1 - fx) * (1 - fy) + v[j0c, i0c + 1] * fx * (1 - fy) + v[j0c + 1, i0c] * (1 - fx) * fy
     + v[j0c + 1, i0c + 1] * fx * fy)
z = np.where(inside, z, np.nan)
with open(out, "w") as f:
    f.write(f"ncols {W}\nnrows {H}\nxllcorner 0.0\nyllcorner 0.0\ncellsize 1.0\nNODATA_value -99999\n")
    for row in z:
        f.write(" ".join(f"{x:.4f}" if np.isfinite(x) else "-99999" for x in row) + "\n")
print(json.dumps({"width": W, "height": H, "valid": int(np.isfinite(z).sum()), "source_valid": int(ok.sum())}))
