#!/usr/bin/env python3
"""Synthetic city for the adjustment benchmark: N box buildings (LoD2-like solids, 6 planes each,
so N = 16667 gives 10^5 planes) on a grid, each with small random tilts of its walls (up to 0.3°)
and a random roof offset, so citygml2popa3d generates parallelism/orthogonality conditions.
Usage: adjust_city.py N > city.gml"""
import math, random, sys

n = int(sys.argv[1])
random.seed(42)
out = sys.stdout
out.write('<?xml version="1.0" encoding="UTF-8"?>\n<core:CityModel xmlns:core="http://www.opengis.net/citygml/2.0" '
          'xmlns:bldg="http://www.opengis.net/citygml/building/2.0" xmlns:gml="http://www.opengis.net/gml">\n')
side = int(math.ceil(math.sqrt(n)))
def ring(pts):
    return " ".join(f"{x:.4f} {y:.4f} {z:.4f}" for x, y, z in pts + [pts[0]])
for b in range(n):
    ox, oy = (b % side) * 30.0, (b // side) * 30.0
    w, d, h = random.uniform(8, 15), random.uniform(8, 15), random.uniform(5, 12)
    t = math.radians(random.uniform(-0.3, 0.3))
    # corners of the footprint, one corner nudged to tilt the walls slightly
    c = [(ox, oy), (ox + w, oy + w * t), (ox + w, oy + d), (ox, oy + d)]
    z0, z1 = 0.0, h
    faces = [
        ("GroundSurface", [(c[0][0], c[0][1], z0), (c[3][0], c[3][1], z0), (c[2][0], c[2][1], z0), (c[1][0], c[1][1], z0)]),
        ("RoofSurface", [(c[0][0], c[0][1], z1), (c[1][0], c[1][1], z1), (c[2][0], c[2][1], z1), (c[3][0], c[3][1], z1)]),
    ]
    for k in range(4):
        a, bb = c[k], c[(k + 1) % 4]
        faces.append(("WallSurface", [(a[0], a[1], z0), (bb[0], bb[1], z0), (bb[0], bb[1], z1), (a[0], a[1], z1)]))
    out.write(f'<core:cityObjectMember><bldg:Building gml:id="B{b}"><bldg:lod2Solid><gml:Solid><gml:exterior><gml:CompositeSurface>\n')
    for i, (_, pts) in enumerate(faces):
        out.write(f'<gml:surfaceMember><gml:Polygon gml:id="B{b}_{i}"><gml:exterior><gml:LinearRing><gml:posList srsDimension="3">{ring(pts)}</gml:posList></gml:LinearRing></gml:exterior></gml:Polygon></gml:surfaceMember>\n')
    out.write('</gml:CompositeSurface></gml:exterior></gml:Solid></bldg:lod2Solid></bldg:Building></core:cityObjectMember>\n')
out.write('</core:CityModel>\n')
