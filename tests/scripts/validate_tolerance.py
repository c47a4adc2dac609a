#!/usr/bin/env python3
"""Independent measurements for the tolerance cases of `geofit validate` (QIE t*.gml files).

Reads every gml:Polygon of a GML file (gml:posList or gml:pos, any namespace prefix) with the
standard library XML parser and prints, as JSON:

  plane_distance: the largest distance of a vertex to the least-squares plane of its polygon
                  (plane through the centroid, normal = right singular vector of the smallest
                  singular value of the centred coordinates, numpy SVD), over all polygons;
  min_vertex_gap: the smallest non-zero distance between two distinct vertices of the file
                  (what a snap tolerance has to bridge).

Usage: validate_tolerance.py FILE.gml
"""
import json
import sys
import xml.etree.ElementTree as ET

import numpy as np

GML = ("http://www.opengis.net/gml", "http://www.opengis.net/gml/3.2")


def ring_points(ring):
    pts = []
    for el in ring.iter():
        tag = el.tag.split("}")[-1]
        if tag == "posList":
            dim = int(el.get("srsDimension", "3"))
            v = [float(x) for x in el.text.split()]
            pts += [v[i:i + dim] for i in range(0, len(v), dim)]
        elif tag == "pos":
            pts.append([float(x) for x in el.text.split()])
    return pts


def main(path):
    root = ET.parse(path).getroot()
    polys = []
    for el in root.iter():
        if el.tag.split("}")[-1] == "Polygon":
            pts = []
            for ring in el.iter():
                if ring.tag.split("}")[-1] == "LinearRing":
                    pts += ring_points(ring)[:-1]  # drop the closing point
            polys.append(np.array(pts, dtype=float))
    dmax = 0.0
    for p in polys:
        if len(p) <= 3:
            continue
        c = p.mean(axis=0)
        _, _, vt = np.linalg.svd(p - c)
        n = vt[-1]
        dmax = max(dmax, float(np.abs((p - c) @ n).max()))
    allp = np.unique(np.vstack(polys), axis=0)
    gaps = np.sqrt(((allp[:, None, :] - allp[None, :, :]) ** 2).sum(-1))
    gaps = gaps[gaps > 0]
    print(json.dumps({"polygons": len(polys), "plane_distance": dmax, "min_vertex_gap": float(gaps.min())}))


if __name__ == "__main__":
    main(sys.argv[1])
