"""Shared by the TIN reference scripts of the T-spline benchmark: a raster as a full grid.

`load_filled(path)` reads the raster through GDAL (gdalinfo -json, gdal_translate -of XYZ, top row
first) and fills its no-data cells with the value of the nearest valid cell, because the TIN
builders need a complete grid. Returns (grid as an h x w float64 array, valid mask, count filled).
"""
import json
import subprocess

import numpy as np


def load_filled(path):
    info = json.loads(subprocess.run(["gdalinfo", "-json", path], check=True, capture_output=True).stdout)
    w, h = info["size"]
    nodata = info["bands"][0].get("noDataValue")
    xyz = subprocess.run(["gdal_translate", "-q", "-of", "XYZ", path, "/vsistdout/"], check=True, capture_output=True).stdout
    v = np.loadtxt(xyz.decode().splitlines(), usecols=2, dtype=np.float64)
    ok = np.isfinite(v)
    if nodata is not None:
        ok &= v != float(nodata)
    ok = ok.reshape(h, w)
    grid = v.reshape(h, w)
    filled = int((~ok).sum())
    if filled:
        from scipy import ndimage
        _, (ii, jj) = ndimage.distance_transform_edt(~ok, return_indices=True)
        grid = grid[ii, jj]
    return grid, ok, filled
