#!/usr/bin/env python3
"""Independent truth for raster reading: size, geotransform and nodata from `gdalinfo -json`,
cell values from `gdal_translate -of XYZ` counted with numpy. Prints one JSON object.

usage: raster_gdal_truth.py RASTER
"""
import json
import os
import subprocess
import sys

import numpy as np

from asc_grid import read_asc_values

path = sys.argv[1]
env = dict(os.environ, GDAL_PAM_ENABLED="NO")
info = json.loads(subprocess.run(["gdalinfo", "-json", path], check=True, capture_output=True, env=env).stdout)
band = info["bands"][0]
w, h = info["size"]
nodata = band.get("noDataValue")
if isinstance(nodata, str):  # "nan"
    nodata = float(nodata)
if path.lower().endswith(".asc"):
    vals = read_asc_values(path)
else:
    xyz = subprocess.run(
        ["gdal_translate", "-q", "-of", "XYZ", "-co", "SIGNIFICANT_DIGITS=17", "-b", "1", path, "/vsistdout/"],
        check=True, capture_output=True, env=env,
    ).stdout
    vals = np.loadtxt(xyz.decode().splitlines(), usecols=2, dtype=np.float64)
assert vals.size == w * h, (vals.size, w, h)
# the band type's precision decides equality with the nodata marker
if band["type"] == "Float32" and nodata is not None:
    invalid = vals.astype(np.float32) == np.float32(nodata)
elif nodata is not None and np.isnan(nodata):
    invalid = np.isnan(vals)
elif nodata is not None:
    invalid = vals == nodata
else:
    invalid = np.zeros(vals.shape, dtype=bool)
invalid |= ~np.isfinite(vals)
valid = vals[~invalid]
out = {
    "width": w,
    "height": h,
    "geotransform": info["geoTransform"],
    "nodata": nodata,
    "nodata_count": int(invalid.sum()),
    "valid_count": int(valid.size),
    "min": float(valid.min()) if valid.size else None,
    "max": float(valid.max()) if valid.size else None,
    "mean": float(valid.mean()) if valid.size else None,
}
print(json.dumps(out))
