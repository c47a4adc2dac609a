#!/usr/bin/env python3
"""Independent check of the tiled raster workflow (workflows/raster.smk), GDAL's command-line
tools and numpy only:

1. max error: every cell valid in the source raster SRC has a value in the merged surface
   MOSAIC (the VRT over the per-tile `geofit eval` rasters) within E of it, seams included;
2. C0: the tiles' surfaces, evaluated by `geofit eval` on one grid whose cell centres lie on
   every pixel edge and eighth of a pixel of SRC (EDGES, one Float64 raster per tile, no data
   outside the tile's domain), agree where two or more tiles are defined (their shared borders:
   the seams, corners included) to GAP relative to max |z| there.

usage: scaleout_raster.py SRC MOSAIC E GAP EDGE_TIF...
Prints a JSON summary; exit 0 when both bounds hold, 1 otherwise.
"""
import json
import os
import sys

import subprocess
import tempfile

import numpy as np


def load(path):
    """Band 1 as (geotransform, value, valid, (width, height)) in full f64 precision: GDAL's XYZ
    text driver writes Float32 values, so the band goes through a raw ENVI copy (bit for bit)."""
    env = dict(os.environ, GDAL_PAM_ENABLED="NO")
    info = json.loads(subprocess.run(["gdalinfo", "-json", path], check=True, capture_output=True, env=env).stdout)
    bi = info["bands"][0]
    nodata = bi.get("noDataValue")
    with tempfile.TemporaryDirectory() as d:
        raw = os.path.join(d, "band.bin")
        subprocess.run(["gdal_translate", "-q", "-b", "1", "-ot", "Float64", "-of", "ENVI", path, raw], check=True, capture_output=True, env=env)
        v = np.fromfile(raw, dtype="<f8")
    ok = np.isfinite(v)
    if nodata is not None:
        ok &= v != float(nodata)
        if bi.get("type") == "Float32":
            ok &= v.astype(np.float32) != np.float32(nodata)
    return tuple(info["geoTransform"]), v, ok, info["size"]


def main():
    src, mosaic, e, gap_tol = sys.argv[1], sys.argv[2], float(sys.argv[3]), float(sys.argv[4])
    edges = sys.argv[5:]
    xa, va, oka, sa = load(src)
    xb, vb, okb, sb = load(mosaic)
    out = {"tolerance": e, "gap_tolerance_relative": gap_tol}
    if sa != sb or not np.allclose(xa, xb, rtol=0, atol=1e-6):
        print(json.dumps({"error": "source and mosaic grids differ", "size_src": sa, "size_mosaic": sb}))
        return 1
    d = np.abs(vb[oka & okb] - va[oka & okb])
    out.update(valid_cells=int(oka.sum()), missing_in_mosaic=int(np.count_nonzero(oka & ~okb)), max_error=float(d.max()) if d.size else 0.0,
               over=int(np.count_nonzero(d > e)))
    # seams: points where two or more tiles' surfaces are defined
    stack = []
    grid = None
    for p in edges:
        x, v, ok, size = load(p)
        if grid is None:
            grid = (x, size)
        elif size != grid[1] or x != grid[0]:
            print(json.dumps({"error": f"{p}: not on the common edge grid"}))
            return 1
        stack.append(np.where(ok, v, np.nan))
    z = np.vstack(stack)
    n = np.sum(np.isfinite(z), axis=0)
    seam = n >= 2
    zmax = np.nanmax(np.abs(z[:, seam]), axis=0)
    gaps = np.nanmax(z[:, seam], axis=0) - np.nanmin(z[:, seam], axis=0)
    out.update(seam_points=int(seam.sum()), corner_points=int(np.count_nonzero(n >= 3)), max_gap=float(gaps.max()) if gaps.size else 0.0,
               max_gap_relative=float((gaps / np.maximum(zmax, 1e-300)).max()) if gaps.size else 0.0)
    print(json.dumps(out))
    good = out["missing_in_mosaic"] == 0 and out["over"] == 0 and out["seam_points"] > 0 and out["max_gap_relative"] <= gap_tol
    return 0 if good else 1


if __name__ == "__main__":
    sys.exit(main())
