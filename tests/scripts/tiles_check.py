#!/usr/bin/env python3
"""Independent check of a tiled raster run (geofit tile plan → fit → tile stitch), numpy and
GDAL's command-line tools only, with the T-mesh decoder and evaluator of tmb_decode_eval.py
(written from docs/tmb-format.md and the spec, no geofit code):

- every valid cell of SRC inside a tile's core window is within E of that tile's stitched
  surface (cells on a domain border, where every blending function vanishes, are evaluated
  1e-6 px inside: the surface there is the limit from inside);
- control points: the stitched tiles' sum, and with --first TEMPLATE the first-pass fits' sum;
- tiles the plan marks empty (work 0) must have no valid cell in their core, and no mesh is read
  for them.

usage: tiles_check.py PLAN.jsonl SRC E STITCHED_TEMPLATE [--first FIT_TEMPLATE]
       (templates hold {id}). Prints JSON; exit 0 when every valid cell is within E, 1 otherwise.
"""
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import tmb_decode_eval as tmb  # noqa: E402

NUDGE = 1e-6


def tile_errors(m, v, ok, gt, core):
    """max |surface − data| over the valid cells of the core window, and the count over E."""
    c0, r0, w, h = core
    x0, y0, dx, dy = m["georef"]
    cx = gt[0] + (c0 + np.arange(w) + 0.5) * gt[1]
    cy = gt[3] + (r0 + np.arange(h) + 0.5) * gt[5]
    s, t = (cx - x0) / dx, (cy - y0) / dy
    lo, hi = m["st"].min(axis=0), m["st"].max(axis=0)
    s = np.clip(s, lo[0] + NUDGE, hi[0] - NUDGE)
    t = np.clip(t, lo[1] + NUDGE, hi[1] - NUDGE)
    so, to = np.argsort(s), np.argsort(t)
    surf = np.empty((h, w))
    surf[np.ix_(to, so)] = tmb.evaluate(m, s[so], t[to])
    vv, oo = v[r0:r0 + h, c0:c0 + w], ok[r0:r0 + h, c0:c0 + w]
    err = np.where(oo, np.abs(surf - vv), 0.0)
    err[oo & ~np.isfinite(surf)] = np.inf
    return err, int(oo.sum())


def main():
    args = sys.argv[1:]
    first = None
    if "--first" in args:
        i = args.index("--first")
        first = args[i + 1]
        del args[i:i + 2]
    plan, src, e, stitched = args[0], args[1], float(args[2]), args[3]
    tiles = [json.loads(line) for line in open(plan) if line.strip()]
    v, ok, gt = tmb.load_raster(src, 1)
    out = {"E": e, "tiles": 0, "empty_tiles": 0, "valid_cells": 0, "max_error": 0.0, "cells_over": 0,
           "control_points": 0, "first_pass_control_points": 0, "empty_with_data": []}
    for t in tiles:
        c0, r0, w, h = t["core"]["pixels"]
        if t["work"] == 0:
            out["empty_tiles"] += 1
            if ok[r0:r0 + h, c0:c0 + w].any():
                out["empty_with_data"].append(t["id"])
            continue
        out["tiles"] += 1
        m = tmb.decode(open(stitched.replace("{id}", t["id"]), "rb").read())
        err, valid = tile_errors(m, v, ok, gt, t["core"]["pixels"])
        out["valid_cells"] += valid
        out["max_error"] = max(out["max_error"], float(err.max()))
        out["cells_over"] += int((err > e).sum())
        out["control_points"] += int(len(m["z"]))
        if first:
            out["first_pass_control_points"] += int(len(tmb.decode(open(first.replace("{id}", t["id"]), "rb").read())["z"]))
    out["all_valid_cells"] = int(ok.sum())
    print(json.dumps(out))
    good = out["cells_over"] == 0 and out["valid_cells"] == out["all_valid_cells"] and not out["empty_with_data"]
    return 0 if good else 1


if __name__ == "__main__":
    sys.exit(main())
