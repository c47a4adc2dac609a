#!/usr/bin/env python3
"""Independent check of `geofit fit --max-error E`: reads the original raster A and the
evaluated surface B (same grid, written by `geofit eval`) with GDAL's command-line tools and
numpy, and checks max |B - A| <= E over EVERY cell valid in A (a cell valid in A but missing in
B counts as a failure). Prints a JSON summary; exit 0 when the bound holds, 1 otherwise.

usage: tspline_maxerror.py A B E
"""
import json
import os
import subprocess
import sys

import numpy as np


def load(path, b=1):
    """Band `b` of a raster as (x y, value, valid, (width, height)): valid = finite and not the
    band's no-data marker (also at float32 precision for a Float32 band, as GDAL matches it)."""
    env = dict(os.environ, GDAL_PAM_ENABLED="NO")
    info = json.loads(subprocess.run(["gdalinfo", "-json", path], check=True, capture_output=True, env=env).stdout)
    bi = info["bands"][b - 1]
    nodata = bi.get("noDataValue")
    xyz = subprocess.run(["gdal_translate", "-q", "-b", str(b), "-of", "XYZ", "-co", "SIGNIFICANT_DIGITS=17", path, "/vsistdout/"],
                         check=True, capture_output=True, env=env).stdout
    a = np.loadtxt(xyz.decode().splitlines(), dtype=np.float64)
    v = a[:, 2]
    ok = np.isfinite(v)
    if nodata is not None:
        ok &= v != float(nodata)
        if bi.get("type") == "Float32":
            ok &= v.astype(np.float32) != np.float32(nodata)
    return a[:, :2], v, ok, info["size"]


def main():
    pa, pb, e = sys.argv[1], sys.argv[2], float(sys.argv[3])
    xa, va, oka, sa = load(pa)
    xb, vb, okb, sb = load(pb)
    if sa != sb or not np.allclose(xa, xb, rtol=0, atol=1e-6 * max(1.0, np.abs(xa).max())):
        print(json.dumps({"error": "grids differ", "size_a": sa, "size_b": sb}))
        return 1
    missing = int(np.count_nonzero(oka & ~okb))
    d = np.abs(vb[oka & okb] - va[oka & okb])
    out = {
        "valid_a": int(oka.sum()),
        "missing_in_b": missing,
        "max": float(d.max()) if d.size else 0.0,
        "mean": float(d.mean()) if d.size else 0.0,
        "over": int(np.count_nonzero(d > e)),
        "tolerance": e,
    }
    print(json.dumps(out))
    return 0 if missing == 0 and out["over"] == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
