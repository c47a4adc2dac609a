#!/usr/bin/env python3
"""Independent check of repaired CityGML solids (issue 35), lxml + numpy only, no geofit code.

For every gml:Solid shell of every Building / BuildingPart (faces reached by xlink:href are
resolved, gml:OrientableSurface orientation="-" reverses its polygon):

- duplicate consecutive points: two consecutive positions of a ring (the closing one included)
  closer than --snap (default 1 mm);
- edge use: vertices are merged within --snap; every undirected edge of the shell's rings must
  be used exactly twice, once in each direction (closed, consistently oriented, no T-junction);
- orientation: the signed volume of an exterior shell is > 0 (faces point outwards), of an
  interior shell < 0.

Also measured, for the no-harm comparison of a file before and after: the area of the polygons
defined in each Building / BuildingPart per thematic surface type (nearest *Surface / Window /
Door ancestor; "none" outside one), |Newell(exterior)|/2 - sum |Newell(interior)|/2, and the
gml:ids of the document, each with the id of the Building / BuildingPart it is in (null when
outside one).

Prints JSON {"shells": n, "problems": [...], "per_feature": {id: [problems]},
"areas": {id: {type: m2}}, "ids": {id: building id}} on stdout.
Usage: heal_repair_check.py FILE.gml [--snap 0.001] [--only ID,ID,...]
"""
import json
import sys

import numpy as np
from lxml import etree

GML_NS = ("http://www.opengis.net/gml", "http://www.opengis.net/gml/3.2")
XLINK = "{http://www.w3.org/1999/xlink}href"


def local(tag):
    return tag.rsplit("}", 1)[-1] if isinstance(tag, str) else ""


def ring_points(ring):
    """Positions of a gml:LinearRing (posList, pos or coordinates)."""
    for el in ring.iter():
        name = local(el.tag)
        if name == "posList":
            dim = int(el.get("srsDimension") or 3)
            v = [float(x) for x in el.text.split()]
            return [tuple(v[i:i + dim]) for i in range(0, len(v), dim)]
        if name == "coordinates":
            return [tuple(float(c) for c in t.split(",")) for t in el.text.split()]
    pts = [tuple(float(x) for x in el.text.split()) for el in ring.iter() if local(el.tag) == "pos"]
    return pts


def polygon_rings(poly):
    rings = []
    for prop in poly:
        if local(prop.tag) in ("exterior", "interior", "outerBoundaryIs", "innerBoundaryIs"):
            for r in prop:
                if local(r.tag) == "LinearRing":
                    rings.append(ring_points(r))
    return rings


def resolve(el, ids):
    href = el.get(XLINK)
    if href and href.startswith("#"):
        return ids.get(href[1:])
    return None


def surfaces(el, ids, reverse=False):
    """(rings, reversed) of every polygon under a surface-like element, xlinks followed."""
    target = resolve(el, ids)
    if target is not None:
        yield from surfaces(target, ids, reverse)
        return
    name = local(el.tag)
    if name == "Polygon":
        yield polygon_rings(el), reverse
        return
    if name == "OrientableSurface":
        rev = reverse ^ (el.get("orientation") == "-")
        for c in el:
            for s in c:
                yield from surfaces(s, ids, rev)
            t = resolve(c, ids)
            if t is not None:
                yield from surfaces(t, ids, rev)
        return
    for c in el:
        yield from surfaces(c, ids, reverse)


class Vertices:
    """Merges points closer than `tol` (first come, like a snapper)."""

    def __init__(self, tol):
        self.tol, self.pts, self.grid = tol, [], {}

    def add(self, p):
        p = np.asarray(p[:3], dtype=float)
        c = tuple(np.floor(p / max(self.tol, 1e-9)).astype(np.int64))
        best = None
        for dx in (-1, 0, 1):
            for dy in (-1, 0, 1):
                for dz in (-1, 0, 1):
                    for i in self.grid.get((c[0] + dx, c[1] + dy, c[2] + dz), ()):
                        if np.linalg.norm(self.pts[i] - p) <= self.tol and (best is None or i < best):
                            best = i
        if best is not None:
            return best
        self.pts.append(p)
        self.grid.setdefault(c, []).append(len(self.pts) - 1)
        return len(self.pts) - 1


def check_shell(polys, tol, interior):
    problems = []
    vs = Vertices(tol)
    uses = {}
    volume = 0.0
    origin = None
    for rings, rev in polys:
        for k, r in enumerate(rings):
            for a, b in zip(r, r[1:]):
                if np.linalg.norm(np.subtract(a[:3], b[:3])) <= tol:
                    problems.append("duplicate consecutive points at %s" % (a,))
            pts = r[:-1] if len(r) > 1 and r[0] == r[-1] else r
            if rev:
                pts = pts[::-1]
            ids = [vs.add(p) for p in pts]
            for i in range(len(ids)):
                a, b = ids[i], ids[(i + 1) % len(ids)]
                if a != b:
                    uses.setdefault((min(a, b), max(a, b)), []).append(a < b)
            P = np.array([p[:3] for p in pts], dtype=float)
            if origin is None and len(P):
                origin = P[0]
            if len(P) >= 3:
                Q = P - origin
                volume += sum(np.dot(Q[0], np.cross(Q[i], Q[i + 1])) for i in range(1, len(Q) - 1)) / 6.0
    for (a, b), u in uses.items():
        if len(u) != 2 or u[0] == u[1]:
            pa, pb = vs.pts[a], vs.pts[b]
            problems.append("edge %s-%s used %d times (%s)" % (np.round(pa, 3).tolist(), np.round(pb, 3).tolist(), len(u), "same direction" if len(u) == 2 else "not twice"))
    if (volume <= 0) if not interior else (volume >= 0):
        problems.append("signed volume %.6f m3 points the wrong way" % volume)
    return problems


def newell_area(pts):
    P = np.array([p[:3] for p in pts], dtype=float)
    if len(P) < 3:
        return 0.0
    P = P - P[0]
    n = np.sum(np.cross(P, np.roll(P, -1, axis=0)), axis=0)
    return 0.5 * float(np.linalg.norm(n))


def unit_of(el):
    """The gml:id of the nearest Building / BuildingPart around an element (itself included)."""
    for anc in [el] + list(el.iterancestors()):
        if local(anc.tag) in ("Building", "BuildingPart"):
            return anc.get("{%s}id" % GML_NS[0]) or anc.get("{%s}id" % GML_NS[1]) or "(no id)"
    return None


def areas(tree):
    """Area per unit (Building / BuildingPart id, else "#n") and thematic type."""
    out = {}
    n = 0
    keys = {}
    for el in tree.iter():
        if local(el.tag) in ("Building", "BuildingPart"):
            keys[el] = el.get("{%s}id" % GML_NS[0]) or el.get("{%s}id" % GML_NS[1]) or "#%d" % n
            n += 1
    for poly in tree.iter():
        if local(poly.tag) != "Polygon":
            continue
        kind, unit = None, None
        for anc in poly.iterancestors():
            name = local(anc.tag)
            if kind is None and (name.endswith("Surface") and name[0].isupper() and name not in ("CompositeSurface", "MultiSurface", "OrientableSurface", "TriangulatedSurface") or name in ("Window", "Door")):
                kind = name
            if name in ("Building", "BuildingPart"):
                unit = keys[anc]
                break
        if unit is None:
            continue
        rings = polygon_rings(poly)
        if not rings:
            continue
        a = newell_area(rings[0]) - sum(newell_area(r) for r in rings[1:])
        d = out.setdefault(unit, {})
        d[kind or "none"] = d.get(kind or "none", 0.0) + a
    return out


def main():
    args = sys.argv[1:]
    tol, only = 0.001, None
    if "--snap" in args:
        i = args.index("--snap")
        tol = float(args[i + 1])
        del args[i:i + 2]
    if "--only" in args:
        i = args.index("--only")
        only = set(args[i + 1].split(","))
        del args[i:i + 2]
    tree = etree.parse(args[0])
    ids = {}
    for el in tree.iter():
        for ns in GML_NS:
            v = el.get("{%s}id" % ns)
            if v:
                ids[v] = el
    report = {"shells": 0, "problems": [], "per_feature": {}}
    for b in tree.iter():
        if local(b.tag) not in ("Building", "BuildingPart"):
            continue
        fid = b.get("{%s}id" % GML_NS[0]) or b.get("{%s}id" % GML_NS[1]) or "(no id)"
        if only is not None and fid not in only:
            continue
        for prop in b:
            if not local(prop.tag).endswith("Solid"):
                continue
            for solid in prop.iter():
                if local(solid.tag) != "Solid":
                    continue
                for shell_prop in solid:
                    kind = local(shell_prop.tag)
                    if kind not in ("exterior", "interior"):
                        continue
                    polys = [p for s in shell_prop for p in surfaces(s, ids)]
                    report["shells"] += 1
                    probs = check_shell(polys, tol, kind == "interior")
                    if probs:
                        report["per_feature"].setdefault(fid, []).extend(probs)
                        report["problems"].extend("%s: %s" % (fid, p) for p in probs)
    report["areas"] = areas(tree)
    report["ids"] = {k: unit_of(el) for k, el in sorted(ids.items())}
    json.dump(report, sys.stdout, indent=1)


if __name__ == "__main__":
    main()
