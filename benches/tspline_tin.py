#!/usr/bin/env python3
"""Garland-Heckbert TIN reference for the T-spline benchmark: vertices and triangles pydelatin
needs for a maximum error E on a raster (read with gdal_translate -of XYZ; nodata cells are
filled with the value of the nearest valid cell because delatin needs a complete grid; those
cells then cost the TIN little — stated in the output). Prints one JSON line: vertices, triangles, bytes (f64 xyz + u32 indices), seconds,
peak RSS (MiB).

usage: tspline_tin.py RASTER E
"""
import json
import resource
import subprocess
import sys
import time

import numpy as np
from pydelatin import Delatin

path, e = sys.argv[1], float(sys.argv[2])
info = json.loads(subprocess.run(["gdalinfo", "-json", path], check=True, capture_output=True).stdout)
w, h = info["size"]
nodata = info["bands"][0].get("noDataValue")
xyz = subprocess.run(["gdal_translate", "-q", "-of", "XYZ", path, "/vsistdout/"], check=True, capture_output=True).stdout
v = np.loadtxt(xyz.decode().splitlines(), usecols=2, dtype=np.float64)
ok = np.isfinite(v)
if nodata is not None:
    ok &= v != float(nodata)
filled = int((~ok).sum())
if filled:
    from scipy import ndimage
    grid_ok = ok.reshape(h, w)
    _, (ii, jj) = ndimage.distance_transform_edt(~grid_ok, return_indices=True)
    v = v.reshape(h, w)[ii, jj].reshape(-1)
t0 = time.time()
tin = Delatin(v.reshape(h, w).astype(np.float32), width=w, height=h, max_error=e)
secs = time.time() - t0
nv, nt = len(tin.vertices), len(tin.triangles)
print(json.dumps({"vertices": nv, "triangles": nt, "bytes": nv * 24 + nt * 12, "seconds": round(secs, 3),
                  "peak_rss_mib": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024, 1),
                  "nodata_filled": filled, "max_error_tin": float(tin.error)}))
