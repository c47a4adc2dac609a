#!/usr/bin/env python3
"""Independent truth for `geofit diff`: reads both rasters with `gdal_translate -of XYZ`
(same grid required), computes |dz| statistics with numpy over the cells valid in both.

usage: raster_diff_truth.py A B TOLERANCE BOUND1,BOUND2,...
"""
import json
import os
import subprocess
import sys

import numpy as np

from asc_grid import read_asc_values

def load(path):
    env = dict(os.environ, GDAL_PAM_ENABLED="NO")
    info = json.loads(subprocess.run(["gdalinfo", "-json", path], check=True, capture_output=True, env=env).stdout)
    nodata = info["bands"][0].get("noDataValue")
    if path.lower().endswith(".asc"):
        v = read_asc_values(path)
    else:
        xyz = subprocess.run(["gdal_translate", "-q", "-of", "XYZ", "-co", "SIGNIFICANT_DIGITS=17", path, "/vsistdout/"],
                             check=True, capture_output=True, env=env).stdout
        v = np.loadtxt(xyz.decode().splitlines(), usecols=2, dtype=np.float64)
    ok = np.isfinite(v)
    if nodata is not None:
        ok &= v != float(nodata)
    return v, ok


a, va = load(sys.argv[1])
b, vb = load(sys.argv[2])
tol = float(sys.argv[3])
bounds = np.array([float(x) for x in sys.argv[4].split(",")])
both = va & vb
e = np.abs(b[both] - a[both])
d = b[both] - a[both]
classes = np.searchsorted(bounds, e, side="right")
print(json.dumps({
    "cells_compared": int(both.sum()),
    "only_in_a": int((va & ~vb).sum()),
    "only_in_b": int((vb & ~va).sum()),
    "mean_abs": float(e.mean()),
    "std_abs": float(e.std()),
    "median_abs": float(np.median(e)),
    "max_abs": float(e.max()),
    "rms": float(np.sqrt(np.mean(d * d))),
    "mean_signed": float(d.mean()),
    "over_tolerance": int((e > tol).sum()),
    "histogram": [int(c) for c in np.bincount(classes, minlength=bounds.size + 1)],
}))
