#!/usr/bin/env python3
"""Per-cell tolerance of `geofit fit --max-error-from-uncertainty K [--max-error FLOOR]`
(issue 19), checked independently with GDAL's command-line tools and numpy.

usage:
  tspline_cell_tolerance.py make OUT_DIR
      writes OUT_DIR/survey.tif: a two-band GeoTIFF (band 1 elevation, band 2 uncertainty) of
      120 x 90 cells, 2 m, UTM-like origin: a smooth seabed, with small-scale roughness
      (+-0.4) added in the eastern half; uncertainty 0.05 in the western half, 1.0 in the
      eastern half, no uncertainty (nodata) in a 6 x 6 block of the western half, one nodata
      elevation cell. Built from two ASCII grids stacked by gdalbuildvrt -separate and
      gdal_translate.
  tspline_cell_tolerance.py check A B K [FLOOR]
      A: the two-band input (GeoTIFF or BAG), B: the evaluated surface (same grid). Checks at
      every cell valid in A's band 1: |B - A| <= max(FLOOR, K * u), u = band 2 (a cell without
      uncertainty gets FLOOR; without FLOOR it is a failure). Prints JSON: counts, the largest
      |dz| / tolerance, and the largest |dz| among the cells of the smallest tolerance class and
      of the others; exit 0 when every cell holds its own tolerance.
"""
import json
import os
import subprocess
import sys

import numpy as np

from tspline_maxerror import load as band

ENV = dict(os.environ, GDAL_PAM_ENABLED="NO")


def write_asc(path, v, ok, x0, y0, cell):
    h, w = v.shape
    with open(path, "w") as f:
        f.write(f"ncols {w}\nnrows {h}\nxllcorner {x0!r}\nyllcorner {y0!r}\ncellsize {cell!r}\nNODATA_value -9999\n")
        for r in range(h):
            f.write(" ".join(repr(float(x)) if k else "-9999" for x, k in zip(v[r], ok[r])) + "\n")


def make(out):
    w, h, cell = 120, 90, 2.0
    x0, y0 = 500000.0, 7000000.0
    rng = np.random.default_rng(7)
    cols, rows = np.meshgrid(np.arange(w), np.arange(h))
    east = cols >= w // 2
    z = -40.0 + 3.0 * np.sin(cols / 17.0) + 2.0 * np.cos(rows / 13.0) + np.where(east, rng.uniform(-0.4, 0.4, (h, w)), 0.0)
    z = np.round(z, 3)
    u = np.where(east, 1.0, 0.05)
    ok = np.ones((h, w), bool)
    ok[40, 10] = False
    uok = np.ones((h, w), bool)
    uok[30:36, 20:26] = False
    write_asc(os.path.join(out, "z.asc"), z, ok, x0, y0, cell)
    write_asc(os.path.join(out, "u.asc"), u, uok, x0, y0, cell)
    vrt = os.path.join(out, "stack.vrt")
    subprocess.run(["gdalbuildvrt", "-q", "-separate", vrt, os.path.join(out, "z.asc"), os.path.join(out, "u.asc")], check=True, env=ENV)
    subprocess.run(["gdal_translate", "-q", "-ot", "Float64", vrt, os.path.join(out, "survey.tif")], check=True, env=ENV)
    print(json.dumps({"width": w, "height": h}))
    return 0


def check(pa, pb, k, floor):
    xa, za, oka, sa = band(pa, 1)
    _, ua, oku, _ = band(pa, 2)
    xb, zb, okb, sb = band(pb, 1)
    if sa != sb or not np.allclose(xa, xb, rtol=0, atol=1e-6 * max(1.0, np.abs(xa).max())):
        print(json.dumps({"error": "grids differ", "size_a": sa, "size_b": sb}))
        return 1
    tol = np.where(oku, k * ua, np.nan)
    if floor is not None:
        tol = np.where(oku, np.maximum(tol, floor), floor)
    no_tol = oka & ~np.isfinite(tol)
    both = oka & okb & np.isfinite(tol)
    d = np.abs(zb - za)
    out = {
        "valid_a": int(oka.sum()),
        "missing_in_b": int(np.count_nonzero(oka & ~okb)),
        "without_tolerance": int(no_tol.sum()),
        "over": int(np.count_nonzero(d[both] > tol[both])),
        "max": float(d[both].max()),
        "max_ratio": float((d[both] / tol[both]).max()),
        "tolerance_min": float(tol[both].min()),
        "tolerance_max": float(tol[both].max()),
    }
    classes = np.unique(tol[both])
    if len(classes) <= 10:
        out["classes"] = [{"tolerance": float(t), "cells": int((both & (tol == t)).sum()), "max": float(d[both & (tol == t)].max())} for t in classes]
    print(json.dumps(out))
    return 0 if out["missing_in_b"] == 0 and out["over"] == 0 and out["without_tolerance"] == 0 else 1


def main():
    if sys.argv[1] == "make":
        return make(sys.argv[2])
    floor = float(sys.argv[5]) if len(sys.argv) > 5 else None
    return check(sys.argv[2], sys.argv[3], float(sys.argv[4]), floor)


if __name__ == "__main__":
    sys.exit(main())
