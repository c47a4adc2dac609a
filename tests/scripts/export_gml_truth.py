#!/usr/bin/env python3
"""Independent truth for `geofit export`: polygon count, expected triangle count, total area and
signed volume of the LoD-N polygons of a CityGML file, computed straight from the XML (xml.etree,
no geofit code).

    python3 tests/scripts/export_gml_truth.py FILE.gml --lod N   ->  JSON on stdout

Which polygons: every gml:Polygon inside a `lodN...` property (lod2Solid, lod2MultiSurface,
lod3Geometry, ...; implicit representations excluded), or reached from one through an
`xlink:href` (NRW tiles: the lod2Solid only xlinks the polygons of the thematic surfaces).
Each polygon counts once, however often it is referenced.

Per polygon (rings without the closing point and without consecutive duplicates):
  area      = |Newell(exterior)|/2 - sum |Newell(hole)|/2
  triangles = n_exterior + sum n_hole + 2*holes - 2     (any triangulation of a polygon with holes
                                                       without extra vertices, by Euler's formula)
  volume   += (1/6) c . (Newell(exterior) + sum Newell(hole))   (divergence theorem; c = a point of
                                                       the polygon, the exterior's vertex mean; holes
                                                       are oriented opposite to the exterior in GML)
`gml:OrientableSurface orientation="-"` flips the polygons below it. Coordinates are shifted by
the first point read, which changes no area and, for closed shells, no volume.
"""
import argparse
import json
import math
import re
import sys
import xml.etree.ElementTree as ET

XLINK = "{http://www.w3.org/1999/xlink}href"
LOD_PROP = re.compile(r"^lod(\d)[A-Z]")


def local(tag):
    return tag.rsplit("}", 1)[-1] if isinstance(tag, str) else ""


def gml_id(el):
    for k, v in el.attrib.items():
        if local(k) == "id" and ("opengis.net/gml" in k):
            return v
    return None


def ring_points(ring, dim_default):
    """Points of a gml:LinearRing (posList, pos, coordinates)."""
    pts = []
    for ch in ring:
        name = local(ch.tag)
        if name == "posList":
            dim = int(ch.get("srsDimension", ch.get("dimension", dim_default)))
            vals = [float(v) for v in (ch.text or "").split()]
            pts += [tuple(vals[i:i + dim]) for i in range(0, len(vals) - dim + 1, dim)]
        elif name == "pos":
            pts.append(tuple(float(v) for v in (ch.text or "").split()))
        elif name == "coordinates":
            cs, ts = ch.get("cs", ","), ch.get("ts", " ")
            for tup in (ch.text or "").strip().split(ts if ts.strip() else None):
                if tup.strip():
                    pts.append(tuple(float(v) for v in tup.split(cs)))
        elif name == "pointProperty" or name == "pointRep":
            for p in ch.iter():
                if local(p.tag) == "pos":
                    pts.append(tuple(float(v) for v in p.text.split()))
    return [(p[0], p[1], p[2] if len(p) > 2 else 0.0) for p in pts]


def open_ring(pts):
    out = []
    for p in pts:
        if not out or out[-1] != p:
            out.append(p)
    while len(out) > 1 and out[0] == out[-1]:
        out.pop()
    return out


def newell(pts, o):
    nx = ny = nz = 0.0
    n = len(pts)
    for i in range(n):
        a = [pts[i][k] - o[k] for k in range(3)]
        b = [pts[(i + 1) % n][k] - o[k] for k in range(3)]
        nx += (a[1] - b[1]) * (a[2] + b[2])
        ny += (a[2] - b[2]) * (a[0] + b[0])
        nz += (a[0] - b[0]) * (a[1] + b[1])
    return (nx, ny, nz)


def norm(v):
    return math.sqrt(sum(c * c for c in v))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("file")
    ap.add_argument("--lod", type=int, required=True)
    args = ap.parse_args()
    root = ET.parse(args.file).getroot()
    ids = {}
    for el in root.iter():
        i = gml_id(el)
        if i is not None:
            ids[i] = el

    found = {}  # id(element) -> (element, sign), insertion-ordered

    def visit(el, in_lod, sign, stack):
        name = local(el.tag)
        m = LOD_PROP.match(name)
        if m and "Implicit" not in name:
            in_lod = int(m.group(1)) == args.lod
        if name == "OrientableSurface" and el.get("orientation", "+") == "-":
            sign = -sign
        href = el.get(XLINK)
        if href and in_lod and href.startswith("#"):
            target = ids.get(href[1:])
            if target is not None and href not in stack:
                visit(target, True, sign, stack | {href})
        if name == "Polygon" and in_lod:
            found.setdefault(id(el), (el, sign))
            return
        for ch in el:
            visit(ch, in_lod, sign, stack)

    visit(root, False, 1, frozenset())

    origin = None
    total_area = 0.0
    total_vol = 0.0
    triangles = 0
    polygons = 0
    degenerate = 0
    for el, sign in found.values():
        ext, holes = None, []
        for ch in el:
            name = local(ch.tag)
            rings = [r for r in ch if local(r.tag) == "LinearRing"]
            if not rings:
                continue
            if name in ("exterior", "outerBoundaryIs"):
                ext = open_ring(ring_points(rings[0], 3))
            elif name in ("interior", "innerBoundaryIs"):
                h = open_ring(ring_points(rings[0], 3))
                if len(h) >= 3:
                    holes.append(h)
        if ext is None or len(ext) < 3:
            degenerate += 1
            continue
        if origin is None:
            origin = ext[0]
        ne = newell(ext, origin)
        nh = [newell(h, origin) for h in holes]
        scale = max(norm([p[k] - ext[0][k] for k in range(3)]) for p in ext)
        if norm(ne) <= 1e-12 * scale * scale:
            degenerate += 1
            continue
        polygons += 1
        total_area += norm(ne) / 2 - sum(norm(n) for n in nh) / 2
        triangles += len(ext) + sum(len(h) for h in holes) + 2 * len(holes) - 2
        vec = [ne[k] + sum(n[k] for n in nh) for k in range(3)]
        c = [sum(p[k] - origin[k] for p in ext) / len(ext) for k in range(3)]
        total_vol += sign * sum(c[k] * vec[k] for k in range(3)) / 6.0
    json.dump(
        {
            "file": args.file,
            "lod": args.lod,
            "polygons": polygons,
            "degenerate_polygons": degenerate,
            "triangles": triangles,
            "area": total_area,
            "volume": total_vol,
        },
        sys.stdout,
    )
    print()


if __name__ == "__main__":
    main()
