#!/usr/bin/env python3
"""Where a tileset puts each tile origin, checked against pyproj (no geofit code).

Usage:
    tileset_origins.py TILESET.json --from CRS [--dz M]

For each tile: the origin (E0, N0, H0) from its extras.origin, and the ECEF position the tile's
transform gives it (the translation column), converted by pyproj from EPSG:4978 to EPSG:4979
(latitude, longitude, ellipsoidal height). The truth: pyproj's transformation of (E0, N0, H0 + dz)
from --from (e.g. EPSG:25832+5773: UTM with EGM96 heights, whose geoid grid pyproj finds in PROJ's
system search paths, added from `projinfo --searchpaths`) to EPSG:4979.
Prints one JSON line {"tiles": n, "max_dh_m": x, "max_horizontal_m": x, "min_abs_h_minus_H_m": x}.
"""
import argparse
import json
import math
import subprocess

import pyproj
from pyproj import Transformer


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("tileset")
    ap.add_argument("--from", dest="src", required=True)
    ap.add_argument("--dz", type=float, default=0.0)
    a = ap.parse_args()
    try:
        out = subprocess.run(["projinfo", "--searchpaths"], capture_output=True, text=True, check=True).stdout
        for d in out.split():
            pyproj.datadir.append_data_dir(d)
    except (OSError, subprocess.CalledProcessError):
        pass
    to_geod = Transformer.from_crs("EPSG:4978", "EPSG:4979")
    truth = Transformer.from_crs(a.src, "EPSG:4979")
    t = json.load(open(a.tileset))
    max_dh = max_hz = 0.0
    min_shift = math.inf
    n = 0
    for tile in t["root"]["children"]:
        e0, n0, h0 = tile["extras"]["origin"]
        m = tile["transform"]
        lat, lon, h = to_geod.transform(m[12], m[13], m[14])
        tlat, tlon, th = truth.transform(e0, n0, h0 + a.dz)
        max_dh = max(max_dh, abs(h - th))
        dn = math.radians(lat - tlat) * 6371000.0
        de = math.radians(lon - tlon) * 6371000.0 * math.cos(math.radians(lat))
        max_hz = max(max_hz, math.hypot(dn, de))
        min_shift = min(min_shift, abs(th - h0))
        n += 1
    print(json.dumps({"tiles": n, "max_dh_m": max_dh, "max_horizontal_m": max_hz, "min_abs_h_minus_H_m": min_shift}))


if __name__ == "__main__":
    main()
