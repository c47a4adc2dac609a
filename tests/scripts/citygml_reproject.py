#!/usr/bin/env python3
"""Reproject every 3D coordinate of a CityGML file with pyproj (no geofit code): the traps of
tests/traps_buildings.rs build their geographic and compound-CRS inputs with it.

Usage:
    citygml_reproject.py IN.gml OUT.gml --from CRS --to CRS --srs-name NAME [--order latlon|lonlat]
                         [--dz M]

Every posList, pos, lowerCorner and upperCorner (3 values per point) is transformed from --from to
--to by pyproj's Transformer (authority axis order: EPSG:4979 gives latitude, longitude, height);
--order lonlat writes longitude first instead (the order CRS84 declares, and a common error in
files that declare EPSG:4979). Heights get --dz added (default 0). Every srsName attribute becomes
NAME. Numbers are written with repr() (17 significant digits). Exit 0, or 2 with one line.
"""
import argparse
import re
import sys

from pyproj import Transformer

COORD_RE = re.compile(rb"(<(?:[A-Za-z_][\w.-]*:)?(posList|pos|lowerCorner|upperCorner)\b[^>]*>)([^<]*)(</)")
SRS_RE = re.compile(rb'srsName="[^"]*"')


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("inp")
    ap.add_argument("out")
    ap.add_argument("--from", dest="src", required=True)
    ap.add_argument("--to", dest="dst", required=True)
    ap.add_argument("--srs-name", required=True)
    ap.add_argument("--order", choices=["latlon", "lonlat"], default="latlon")
    ap.add_argument("--dz", type=float, default=0.0)
    a = ap.parse_args()
    t = Transformer.from_crs(a.src, a.dst)
    data = open(a.inp, "rb").read()

    def repl(m):
        vals = [float(v) for v in m.group(3).split()]
        if len(vals) % 3:
            sys.stderr.write(f"citygml_reproject: {len(vals)} values in a {m.group(2).decode()}, not 3D points\n")
            sys.exit(2)
        out = []
        for i in range(0, len(vals), 3):
            x, y, z = t.transform(vals[i], vals[i + 1], vals[i + 2])
            if a.order == "lonlat":
                x, y = y, x
            out += [repr(x), repr(y), repr(z + a.dz)]
        return m.group(1) + " ".join(out).encode() + m.group(4)

    data = COORD_RE.sub(repl, data)
    data = SRS_RE.sub(b'srsName="' + a.srs_name.encode() + b'"', data)
    open(a.out, "wb").write(data)


if __name__ == "__main__":
    main()
