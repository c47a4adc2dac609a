#!/usr/bin/env python3
"""Independent check that a change of a CityGML file keeps semantics, identity and every input
vertex within bounds (issue 35; lxml + numpy, no geofit code).

Usage:
    heal_semantics.py BEFORE.gml AFTER.gml [--snap 0.001]   -> JSON on stdout

Units ("buildings") are read as tests/scripts/citygml_invariants.py reads them (every Building /
BuildingPart, a polygon belongs to its nearest one; keyed by gml:id, else "#<n>"). Per unit present
in both files:
  type_area_before / type_area_after   area (m2) of the polygons defined in the unit per thematic
                 type: the local name of the polygon's nearest ancestor that is a thematic surface
                 or opening (WallSurface, RoofSurface, GroundSurface, ClosureSurface, Window, ...,
                 "none" without one); area = |Newell(exterior)|/2 - sum |Newell(interior)|/2
  type_change_rel  largest |after - before| / before over the types (before > 0.01 m2; a type
                 with before <= 0.01 m2 counts its absolute change in m2 over 1 m2)
  max_vertex_distance  the largest distance (m) from a vertex of the unit BEFORE to the unit's
                 surface AFTER: per polygon, the distance to its plane (Newell normal through the
                 ring centroid) where the point's projection falls inside the polygon (even-odd
                 over all rings in the dominant projection), else to its nearest boundary edge
  closed_before / closed_after  per solid of the unit, whether its shell is closed (edge-use count
                 of citygml_invariants.shell_measures)
Whole file:
  lost_ids       gml:ids of BEFORE missing in AFTER whose element had area (polygons inside it,
                 XLinks not followed, > 0.01 m2)
  lost_attributed_surfaces  thematic surfaces without gml:id but with attributes (child elements
                 other than lodN geometry, openings, boundedBy) present in BEFORE and missing in
                 AFTER, compared as a multiset of (unit, type, attribute text)
Exit status: 0 on success, 2 (one line on stderr) for unreadable input.
"""
import json
import os
import sys

import numpy as np

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
import citygml_invariants as inv  # noqa: E402  (independent lxml/numpy reader, no geofit code)

OPENINGS = {"Window", "Door"}
GEOMETRY_PROPS = ("lod", "opening", "fillingSurface", "boundedBy")
ZERO_AREA = 0.01


def thematic(el):
    """The nearest ancestor of el that is a thematic surface or opening, or None."""
    e = el.getparent()
    while e is not None:
        name = inv.local(e)
        if not inv.is_gml(e) and name[:1].isupper() and (name.endswith("Surface") or name in OPENINGS):
            return e
        if name in inv.UNIT_NAMES:
            return None
        e = e.getparent()
    return None


def attribute_text(surface):
    """The attribute children of a thematic surface as one text ('' when it has none)."""
    parts = []
    for c in surface:
        if not isinstance(c.tag, str):
            continue
        if inv.local(c).startswith(GEOMETRY_PROPS):
            continue
        parts.append(inv.local(c) + "=" + " ".join("".join(c.itertext()).split()))
    return "|".join(sorted(parts))


class Semantics:
    """Per unit: polygons (rings) by thematic type; the document's ids and attributed surfaces."""

    def __init__(self, path):
        self.doc = inv.Doc(path)
        keys = {}
        n = 0
        for el in self.doc.root.iter():
            if isinstance(el.tag, str) and inv.local(el) in inv.UNIT_NAMES:
                key = inv.gml_id(el)
                if key is None or key in keys.values():
                    key = "#%d" % n if key is None else "%s#%d" % (key, n)
                n += 1
                keys[el] = key
        self.unit_key = keys
        self.polys = {k: [] for k in keys.values()}  # key -> [(type, rings)]
        self.id_area = {}
        self.attributed = []
        for el in self.doc.root.iter():
            if not isinstance(el.tag, str):
                continue
            if inv.is_gml(el, "Polygon"):
                u = self.doc.nearest_unit(el)
                if u is None:
                    continue
                t = thematic(el)
                self.polys[keys[u]].append((inv.local(t) if t is not None else "none", inv.polygon_rings(el)))
            elif not inv.is_gml(el) and inv.local(el)[:1].isupper() and inv.local(el).endswith("Surface") and inv.gml_id(el) is None:
                text = attribute_text(el)
                u = self.doc.nearest_unit(el)
                if text and u is not None:
                    self.attributed.append((keys[u], inv.local(el), text))
        for i, el in self.doc.ids.items():
            area = 0.0
            for p in el.iter():
                if isinstance(p.tag, str) and inv.is_gml(p, "Polygon"):
                    area += inv.polygon_area(inv.polygon_rings(p))
            if inv.is_gml(el, "Polygon") or area > 0.0:
                self.id_area[i] = area

    def type_areas(self, key):
        out = {}
        for t, rings in self.polys[key]:
            out[t] = out.get(t, 0.0) + inv.polygon_area(rings)
        return out

    def closed(self, key):
        unit = self.doc.units.get(key)
        if unit is None:
            return []
        return [self.doc.solid_measures(s, key, i, SNAP)["closed"] for i, s in enumerate(unit["solids"])]


def point_polygon_distances(q, rings):
    """Distances from the points q (n x 3) to the polygon given by its rings."""
    ext = np.asarray(rings[0], dtype=float)
    nrm = inv.newell(ext)
    ln = np.linalg.norm(nrm)
    edge = np.full(len(q), np.inf)
    inside = np.zeros(len(q), dtype=bool)
    if ln > 0:
        nrm = nrm / ln
        h = (q - ext.mean(axis=0)) @ nrm
        proj = q - np.outer(h, nrm)
        k = int(np.argmax(np.abs(nrm)))
        u, v = (k + 1) % 3, (k + 2) % 3
    for r in rings:
        r = np.asarray(r, dtype=float)
        for i in range(len(r)):
            a, b = r[i], r[(i + 1) % len(r)]
            ab = b - a
            l2 = ab @ ab
            t = np.clip(((q - a) @ ab) / l2, 0.0, 1.0) if l2 > 0 else np.zeros(len(q))
            edge = np.minimum(edge, np.linalg.norm(q - (a + np.outer(t, ab)), axis=1))
            if ln > 0 and a[v] != b[v]:
                crosses = (a[v] > proj[:, v]) != (b[v] > proj[:, v])
                x = a[u] + (proj[:, v] - a[v]) * (b[u] - a[u]) / (b[v] - a[v])
                inside ^= crosses & (proj[:, u] < x)
    if ln > 0:
        return np.where(inside, np.minimum(np.abs(h), edge), edge)
    return edge


def max_vertex_distance(before_polys, after_polys):
    pts = [p for _, rings in before_polys for r in rings for p in r]
    if not pts:
        return 0.0
    q = np.asarray(pts, dtype=float)
    if not after_polys:
        return float("inf")
    best = np.full(len(q), np.inf)
    for _, rings in after_polys:
        best = np.minimum(best, point_polygon_distances(q, rings))
    return float(best.max())


def type_change(tb, ta):
    worst = 0.0
    for t in set(tb) | set(ta):
        b, a = tb.get(t, 0.0), ta.get(t, 0.0)
        worst = max(worst, abs(a - b) / b if b > ZERO_AREA else abs(a - b))
    return worst


SNAP = 0.001


def main(argv):
    global SNAP
    args = [a for a in argv if not a.startswith("--")]
    if "--snap" in argv:
        SNAP = float(argv[argv.index("--snap") + 1])
        args.remove(argv[argv.index("--snap") + 1])
    if len(args) != 2:
        print("usage: heal_semantics.py BEFORE.gml AFTER.gml [--snap 0.001]", file=sys.stderr)
        return 2
    try:
        before, after = Semantics(args[0]), Semantics(args[1])
    except inv.InputError as e:
        print(str(e), file=sys.stderr)
        return 2
    units = {}
    for key in before.polys:
        if key not in after.polys:
            continue
        tb, ta = before.type_areas(key), after.type_areas(key)
        units[key] = {
            "type_area_before": tb,
            "type_area_after": ta,
            "type_change_rel": type_change(tb, ta),
            "max_vertex_distance": max_vertex_distance(before.polys[key], after.polys[key]),
            "closed_before": before.closed(key),
            "closed_after": after.closed(key),
        }
    lost_ids = sorted(i for i, a in before.id_area.items() if i not in after.doc.ids and a > ZERO_AREA)
    remaining = list(after.attributed)
    lost_attr = []
    for x in before.attributed:
        if x in remaining:
            remaining.remove(x)
        else:
            lost_attr.append(list(x))
    json.dump({"units": units, "missing_units": sorted(set(before.polys) - set(after.polys)), "lost_ids": lost_ids, "lost_attributed_surfaces": lost_attr}, sys.stdout)
    print()
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv[1:]))
