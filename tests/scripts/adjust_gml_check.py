#!/usr/bin/env python3
"""Independent truth for the popa3d -> CityGML acceptance tests (tests/adjust.rs).

Reads CityGML with lxml (no geofit code) and prints JSON:
  counts: polygons, rings, points (with the repeated closing point), points_unique (per ring)
  polygons: {id: {semantic, owner, n, d, planarity}}   n,d = least-squares plane (numpy SVD),
            planarity = largest vertex distance to that plane over all rings
  max_planarity: the largest planarity over all polygons
Usage: adjust_gml_check.py FILE.gml
"""
import json, sys
import numpy as np
from lxml import etree

GML = "http://www.opengis.net/gml"
SEM = {"WallSurface", "RoofSurface", "GroundSurface", "ClosureSurface", "FloorSurface", "CeilingSurface",
       "InteriorWallSurface", "OuterFloorSurface", "OuterCeilingSurface", "Window", "Door"}

def coords(ring):
    pl = ring.find(f"{{{GML}}}posList")
    if pl is not None:
        dim = int(pl.get("srsDimension", "3"))
        v = [float(t) for t in pl.text.split()]
        return np.array(v).reshape(-1, dim)[:, :3]
    pos = ring.findall(f"{{{GML}}}pos")
    if pos:
        return np.array([[float(t) for t in p.text.split()][:3] for p in pos])
    c = ring.find(f"{{{GML}}}coordinates")
    return np.array([[float(t) for t in tup.split(",")][:3] for tup in c.text.split()])

def main(path):
    tree = etree.parse(path)
    polys = {}
    n_poly = n_ring = n_pts = n_unique = 0
    worst = 0.0
    for p in tree.iter(f"{{{GML}}}Polygon"):
        rings = [coords(r) for r in p.iter(f"{{{GML}}}LinearRing")]
        n_poly += 1
        n_ring += len(rings)
        for r in rings:
            n_pts += len(r)
            n_unique += len(r) - (1 if len(r) > 1 and np.allclose(r[0], r[-1], atol=0, rtol=0) else 0)
        allp = np.vstack(rings)
        c = allp.mean(axis=0)
        _, _, vt = np.linalg.svd(allp - c)
        n = vt[2]
        # canonical direction: first non-zero component positive
        for k in range(3):
            if abs(n[k]) > 1e-12:
                if n[k] < 0:
                    n = -n
                break
        d = float(n @ c)
        plan = float(np.max(np.abs((allp - c) @ n)))
        worst = max(worst, plan)
        sem = owner = building = None
        a = p.getparent()
        while a is not None:
            if etree.QName(a).localname in ("Building", "BuildingPart") and building is None:
                building = a.get(f"{{{GML}}}id")
            a = a.getparent()
        a = p.getparent()
        while a is not None:
            ln = etree.QName(a).localname
            if ln in SEM:
                sem, owner = ln, a.get(f"{{{GML}}}id")
                break
            a = a.getparent()
        pid = p.get(f"{{{GML}}}id") or f"#{n_poly - 1}"
        polys[pid] = {"semantic": sem, "owner": owner, "n": n.tolist(), "d": d, "planarity": plan, "building": building}
    print(json.dumps({"counts": {"polygons": n_poly, "rings": n_ring, "points": n_pts, "points_unique": n_unique},
                      "max_planarity": worst, "polygons": polys}))

if __name__ == "__main__":
    main(sys.argv[1])
