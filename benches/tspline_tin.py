#!/usr/bin/env python3
"""Garland-Heckbert TIN reference for the T-spline benchmark: vertices and triangles pydelatin
needs for a maximum error E on a raster (read with gdal_translate -of XYZ; nodata cells are
filled with the value of the nearest valid cell because delatin needs a complete grid; those
cells then cost the TIN little — stated in the output). Prints one JSON line: vertices, triangles, bytes (f64 xyz + u32 indices), seconds,
peak RSS (MiB).

usage: tspline_tin.py RASTER E
"""
import json
import os
import resource
import sys
import time

import numpy as np
from pydelatin import Delatin

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from terrain_grid import load_filled  # noqa: E402

path, e = sys.argv[1], float(sys.argv[2])
grid, ok, filled = load_filled(path)
h, w = grid.shape
t0 = time.time()
tin = Delatin(grid.astype(np.float32), width=w, height=h, max_error=e)
secs = time.time() - t0
nv, nt = len(tin.vertices), len(tin.triangles)
print(json.dumps({"vertices": nv, "triangles": nt, "bytes": nv * 24 + nt * 12, "seconds": round(secs, 3),
                  "peak_rss_mib": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1),
                  "nodata_filled": filled, "max_error_tin": float(tin.error)}))
