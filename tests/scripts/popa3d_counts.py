#!/usr/bin/env python3
"""Independent truth for `geofit citygml2popa3d` (tests/popa3d.rs).

Usage: popa3d_counts.py IN.gml OUT.popa3d
Prints JSON: per-file counts computed from the CityGML polygon soup with numpy (polygons, rings,
points, distinct nodes at 1 mm, distinct edges, planes/normals after merging within 0.01 deg and
1 mm) and, from the popa3d document, the largest distance between a node recomputed from its
planes (numpy least squares) and every source vertex its provenance names.
"""
import json, sys
import xml.etree.ElementTree as ET
import numpy as np

GML = ["http://www.opengis.net/gml", "http://www.opengis.net/gml/3.2"]
XL = "{http://www.w3.org/1999/xlink}href"
gml_path, popa_path = sys.argv[1], sys.argv[2]
root = ET.parse(gml_path).getroot()

def local(t):
    return t.rsplit("}", 1)[-1]

def gid(e):
    for ns in GML:
        v = e.get("{%s}id" % ns)
        if v:
            return v
    return None

by_id = {gid(e): e for e in root.iter() if gid(e)}

def ring_points(r):
    pts = []
    for e in r.iter():
        n = local(e.tag)
        if n == "posList":
            v = [float(x) for x in e.text.split()]
            pts += [v[i:i + 3] for i in range(0, len(v), 3)]
        elif n == "pos":
            pts.append([float(x) for x in e.text.split()])
        elif n == "coordinates":
            pts += [[float(c) for c in t.split(",")] for t in e.text.split()]
    if len(pts) > 1 and pts[0] == pts[-1]:
        pts.pop()
    return pts

def polygons_of_solid(s):
    out = []
    for m in s.iter():
        if local(m.tag) == "surfaceMember":
            href = m.get(XL)
            target = by_id[href.lstrip("#")] if href else (list(m)[0] if len(m) else None)
            if target is None:
                continue
            for p in ([target] if local(target.tag) == "Polygon" else [x for x in target.iter() if local(x.tag) == "Polygon"]):
                out.append(p)
    return out

polys = []
for s in root.iter():
    if local(s.tag) in ("lod2Solid", "lod3Solid"):
        polys += polygons_of_solid(s)
rings, verts = [], {}
for p in polys:
    pr = []
    for k, r in enumerate([x for x in p.iter() if local(x.tag) == "LinearRing"]):
        pts = ring_points(r)
        pr.append(pts)
        for i, q in enumerate(pts):
            verts[(gid(p), k, i)] = q
    rings.append(pr)

allp = np.array([q for pr in rings for r in pr for q in r])
keys = [tuple(np.round(q / 0.001).astype(np.int64)) for q in allp]
uniq = {}
for k in keys:
    uniq.setdefault(k, len(uniq))
edges = set()
i = 0
for pr in rings:
    for r in pr:
        ids = [uniq[keys[i + j]] for j in range(len(r))]
        i += len(r)
        for a, b in zip(ids, ids[1:] + ids[:1]):
            edges.add((min(a, b), max(a, b)))

# planes: SVD normal per polygon, canonical direction, merge within 0.01 deg and 1 mm
normals, ds = [], []
for pr in rings:
    P = np.array([q for r in pr for q in r])
    c = P.mean(axis=0)
    n = np.linalg.svd(P - c)[2][-1]
    for k in range(3):
        if abs(n[k]) > 1e-12:
            if n[k] < 0:
                n = -n
            break
    normals.append(n)
    ds.append(float(n @ c))
cos_tol = np.cos(np.radians(0.01))
groups = []
for i, n in enumerate(normals):
    for g in groups:
        if abs(normals[g[0]] @ n) >= cos_tol:
            g.append(i)
            break
    else:
        groups.append([i])
planes = 0
for g in groups:
    ref = normals[g[0]]
    d = sorted(float(ref @ normals[i]) * ds[i] for i in g)
    start = None
    for x in d:
        if start is None or x - start > 0.001:
            planes += 1
            start = x

# popa3d: recompute nodes from planes and compare with the source vertices
P = ET.parse(popa_path).getroot()
ns = {"p": "urn:geofit:popa3d:1"}
org = P.find("p:origin", ns)
origin = np.array([float(org.get(k)) for k in "xyz"])
par = {int(e.get("id")): float(e.get("value")) for e in P.iterfind("p:parameters/p:parameter", ns)}
nv = {}
for e in P.iterfind("p:normals/p:normal", ns):
    nv[int(e.get("id"))] = np.array([int(e.get("s" + k)) * par[int(e.get(k))] for k in "xyz"])
pl = {}
for e in P.iterfind("p:planes/p:plane", ns):
    pl[int(e.get("id"))] = (int(e.get("sign")) * nv[int(e.get("normal"))], float(e.get("d")))
face_plane = {int(e.get("id")): int(e.get("plane")) for e in P.iterfind("p:faces/p:face", ns)}
edge_nodes = {int(e.get("id")): (int(e.get("start")), int(e.get("end"))) for e in P.iterfind("p:edges/p:edge", ns)}
node_planes = {}
for h in P.iterfind("p:halfedges/p:halfedge", ns):
    a, b = edge_nodes[int(h.get("edge"))]
    for n in (a, b):
        node_planes.setdefault(n, set()).add(face_plane[int(h.get("face"))])
worst, checked = 0.0, 0
for e in P.iterfind("p:nodes/p:node", ns):
    n = int(e.get("id"))
    A = np.array([pl[p][0] for p in sorted(node_planes[n])])
    d = np.array([pl[p][1] for p in sorted(node_planes[n])])
    x = np.linalg.lstsq(A, d, rcond=None)[0] + origin
    for s in e.iterfind("p:src", ns):
        q = verts.get((s.get("polygon"), int(s.get("ring")), int(s.get("index"))))
        if q is not None:
            worst = max(worst, float(np.linalg.norm(x - np.array(q))))
            checked += 1

print(json.dumps({
    "polygons": len(polys), "rings": sum(len(p) for p in rings), "points": len(allp),
    "nodes": len(uniq), "edges": len(edges), "faces": len(polys),
    "planes": planes, "normals": len(groups),
    "max_node_distance": worst, "vertices_checked": checked,
}))
