#!/usr/bin/env python3
"""Injects blunders (single-cell spikes) into a shipped raster for the outlier test of
`geofit fit --reject-outliers` (issue 19), with GDAL's command-line tools and numpy only.

usage: tspline_spikes.py IN OUT_DIR N AMPLITUDE SEED

Writes into OUT_DIR, all as ESRI ASCII grids with 17 significant digits (exact for the values
read, so the three grids differ only where stated):
  clean.asc   the raster as read (nodata -> -9999)
  spiked.asc  clean + N spikes of +-AMPLITUDE at random valid cells whose 5x5 neighbourhood is
              valid and at least 6 cells from any other spike
  holes.asc   clean with the spike cells as nodata (the reference for "meets E elsewhere")
  spikes.csv  row,col,value_before,value_after of every spike (row 0 = the file's top row)
"""
import json
import os
import subprocess
import sys

import numpy as np

NODATA = -9999.0


def load(path):
    env = dict(os.environ, GDAL_PAM_ENABLED="NO")
    info = json.loads(subprocess.run(["gdalinfo", "-json", path], check=True, capture_output=True, env=env).stdout)
    w, h = info["size"]
    gt = info["geoTransform"]
    nodata = info["bands"][0].get("noDataValue")
    xyz = subprocess.run(["gdal_translate", "-q", "-b", "1", "-of", "XYZ", "-co", "SIGNIFICANT_DIGITS=17", path, "/vsistdout/"],
                         check=True, capture_output=True, env=env).stdout
    v = np.loadtxt(xyz.decode().splitlines(), dtype=np.float64)[:, 2].reshape(h, w)
    ok = np.isfinite(v)
    if nodata is not None:
        ok &= v != float(nodata)
        if info["bands"][0].get("type") == "Float32":
            ok &= v.astype(np.float32) != np.float32(nodata)
    return v, ok, gt


def write_asc(path, v, ok, gt):
    h, w = v.shape
    assert gt[2] == 0 and gt[4] == 0 and abs(gt[1]) == abs(gt[5]), "square, axis-aligned cells"
    ylow = gt[3] + h * gt[5]
    with open(path, "w") as f:
        f.write(f"ncols {w}\nnrows {h}\nxllcorner {gt[0]!r}\nyllcorner {ylow!r}\ncellsize {gt[1]!r}\nNODATA_value {NODATA}\n")
        for r in range(h):
            f.write(" ".join(repr(float(x)) if k else repr(NODATA) for x, k in zip(v[r], ok[r])))
            f.write("\n")


def main():
    src, out, n, amp, seed = sys.argv[1], sys.argv[2], int(sys.argv[3]), float(sys.argv[4]), int(sys.argv[5])
    v, ok, gt = load(src)
    h, w = v.shape
    assert not np.any(ok & (v == NODATA)), "the raster uses -9999 as a value"
    rng = np.random.default_rng(seed)
    spikes = []
    tries = 0
    while len(spikes) < n and tries < 100000:
        tries += 1
        r, c = int(rng.integers(2, h - 2)), int(rng.integers(2, w - 2))
        if not ok[r - 2:r + 3, c - 2:c + 3].all():
            continue
        if any(max(abs(r - a), abs(c - b)) < 6 for a, b, _ in spikes):
            continue
        spikes.append((r, c, amp if rng.random() < 0.5 else -amp))
    assert len(spikes) == n, f"only {len(spikes)} spike positions found"
    spiked = v.copy()
    holes = ok.copy()
    with open(os.path.join(out, "spikes.csv"), "w") as f:
        f.write("row,col,value_before,value_after\n")
        for r, c, d in spikes:
            spiked[r, c] = v[r, c] + d
            holes[r, c] = False
            f.write(f"{r},{c},{v[r, c]!r},{spiked[r, c]!r}\n")
    write_asc(os.path.join(out, "clean.asc"), v, ok, gt)
    write_asc(os.path.join(out, "spiked.asc"), spiked, ok, gt)
    write_asc(os.path.join(out, "holes.asc"), v, holes, gt)
    print(json.dumps({"width": w, "height": h, "valid": int(ok.sum()), "spikes": len(spikes)}))


if __name__ == "__main__":
    sys.exit(main())
