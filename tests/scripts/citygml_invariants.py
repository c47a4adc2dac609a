#!/usr/bin/env python3
"""Independent geometric invariants of CityGML buildings, before and after a change (no geofit code).

Usage:
    citygml_invariants.py BEFORE.gml AFTER.gml [--snap 0.001]   -> JSON comparison on stdout
    citygml_invariants.py FILE.gml [--snap 0.001]               -> JSON measures of one file

Units ("buildings"): every element with local name Building or BuildingPart (any namespace, so
CityGML 1.0 / 2.0 / 3.0). A geometry belongs to its NEAREST Building/BuildingPart ancestor. A unit
is keyed by its gml:id (GML 3.1 or 3.2 namespace), else by "#<n>" (n = 0-based index of the unit
among all Building/BuildingPart elements in document order).

Measured per unit and file:
  area           sum over the gml:Polygon elements DEFINED in the unit (xlink references do not
                 count again) of |Newell(exterior)|/2 - sum |Newell(interior)|/2, in m2
  polygons       number of those defining gml:Polygon elements; rings, vertices likewise
  max_planarity  largest distance of a ring vertex from its polygon's least-squares plane (SVD), m
  solids         one entry per gml:Solid defined in the unit (also the Solids of a CompositeSolid):
                 its exterior shell, with xlink:href members (surfaceMember, baseSurface, ...)
                 resolved anywhere in the document and OrientableSurface orientation="-" applied.
                 Vertices are clustered within --snap m; every ring is a cycle of undirected edges
                 between clusters (zero-length edges skipped); every edge is split at every shell
                 vertex lying within --snap of its interior (T-junctions). Then:
                   boundary_edges     sub-edges used an odd number of times
                   nonmanifold_edges  sub-edges used more than twice
                   orientation_errors sub-edges used exactly twice, both times in the same direction
                   closed             boundary_edges == 0
                   volume             |signed volume| (divergence theorem, fan triangulation), m3
                   volume_signed      the signed value (> 0 for outward-oriented shells)
                   unresolved_hrefs   xlink:hrefs in the shell whose target was not found
Comparison (BEFORE -> AFTER) per unit present in both files:
  area_change_rel  (area_after - area_before) / area_before (0 when both are 0, null if only before is 0)
  max_move         the largest distance of an AFTER vertex to the nearest BEFORE vertex of the same
                   unit (merged and rewritten polygons included: a vertex may go, never stray).
  max_move_matched per-vertex distances of polygons matched by key (polygon gml:id, else
                   "<unit key>/<n>", n = 0-based index of the polygon within its unit) whose rings
                   have identical vertex counts (best cyclic start of each ring); informative only:
                   a merged polygon keeps its key but covers more.
                   Also max_move_matched, max_move_unmatched, matched_vertices, unmatched_vertices,
                   polygons_only_before (BEFORE polygon keys missing in AFTER).
Coordinates: gml:posList (srsDimension on it or an ancestor, else 3), gml:pos, gml:coordinates
(cs / ts / decimal attributes). 2D points get z = 0. A ring's repeated closing point is dropped.
Exit status: 0 on success, 2 (one line on stderr) for unreadable or malformed input.
"""
import json
import math
import sys

import numpy as np

try:
    from lxml import etree
except ImportError:  # pragma: no cover
    sys.stderr.write("citygml_invariants: error: python3 module lxml is required\n")
    sys.exit(2)

from citygml_common import GML_NS, UNIT_NAMES, XLINK_HREF, InputError, arg_parser, gml_id, srs_dimension


def local(el):
    tag = el.tag
    if not isinstance(tag, str):
        return None
    return tag.rsplit("}", 1)[-1]


def ns_of(el):
    tag = el.tag
    if not isinstance(tag, str) or not tag.startswith("{"):
        return ""
    return tag[1:].split("}", 1)[0]


def is_gml(el, name=None):
    return ns_of(el) in GML_NS and (name is None or local(el) == name)


# ---------------------------------------------------------------------------------------------
# coordinates


def _floats(tokens, what):
    try:
        return [float(t) for t in tokens]
    except ValueError as e:
        raise InputError("bad number in %s: %s" % (what, e))


def parse_points(container):
    """All points of gml:posList / gml:pos / gml:coordinates under container, document order, Nx3."""
    pts = []
    for el in container.iter():
        if not is_gml(el):
            continue
        name = local(el)
        text = el.text or ""
        if name == "posList":
            vals = _floats(text.split(), "posList (line %s)" % el.sourceline)
            d = srs_dimension(el) or 3
            if len(vals) % d:
                raise InputError("posList with %d numbers is not a multiple of srsDimension %d (line %s)"
                                 % (len(vals), d, el.sourceline))
            for i in range(0, len(vals), d):
                pts.append(vals[i:i + d])
        elif name == "pos":
            vals = _floats(text.split(), "pos (line %s)" % el.sourceline)
            if vals:
                pts.append(vals)
        elif name == "coordinates":
            cs = el.get("cs", ",")
            ts = el.get("ts")
            dec = el.get("decimal", ".")
            tuples = text.split() if ts is None or ts.isspace() else [t for t in text.strip().split(ts) if t.strip()]
            for t in tuples:
                comps = [c.strip() for c in t.split(cs)]
                if dec != ".":
                    comps = [c.replace(dec, ".") for c in comps]
                pts.append(_floats(comps, "coordinates (line %s)" % el.sourceline))
    out = np.zeros((len(pts), 3))
    for i, p in enumerate(pts):
        if len(p) < 2:
            raise InputError("point with %d coordinate(s) (line %s)" % (len(p), container.sourceline))
        out[i, :min(3, len(p))] = p[:3]
    return out


def ring_points(ring):
    p = parse_points(ring)
    if len(p) >= 2 and np.allclose(p[0], p[-1], rtol=0.0, atol=1e-9):
        p = p[:-1]
    return p


def polygon_rings(poly):
    """[exterior, interior...] as Nx3 arrays (closing point dropped) of a Polygon / PolygonPatch / Triangle."""
    ext, ints = [], []
    for child in poly:
        name = local(child)
        if name in ("exterior", "outerBoundaryIs"):
            ext.append(ring_points(child))
        elif name in ("interior", "innerBoundaryIs"):
            ints.append(ring_points(child))
    return ext[:1] + ints


# ---------------------------------------------------------------------------------------------
# geometry


def newell(ring):
    if len(ring) < 3:
        return np.zeros(3)
    r = ring - ring[0]
    return np.cross(r, np.roll(r, -1, axis=0)).sum(axis=0)


def polygon_area(rings):
    if not rings:
        return 0.0
    a = np.linalg.norm(newell(rings[0])) / 2.0
    for r in rings[1:]:
        a -= np.linalg.norm(newell(r)) / 2.0
    return float(a)


def planarity(rings):
    pts = np.vstack(rings) if rings else np.zeros((0, 3))
    if len(pts) < 4:
        return 0.0
    c = pts - pts.mean(axis=0)
    _, _, vt = np.linalg.svd(c, full_matrices=False)
    return float(np.abs(c @ vt[2]).max())


class UnionFind:
    def __init__(self, n):
        self.p = list(range(n))

    def find(self, i):
        p = self.p
        while p[i] != i:
            p[i] = p[p[i]]
            i = p[i]
        return i

    def union(self, a, b):
        a, b = self.find(a), self.find(b)
        if a != b:
            if a < b:
                self.p[b] = a
            else:
                self.p[a] = b


def cluster(points, snap):
    """Cluster ids (0..k-1) and representative positions: points closer than snap are merged (transitively)."""
    uniq, inverse = np.unique(points, axis=0, return_inverse=True)
    inverse = inverse.reshape(-1)
    n = len(uniq)
    uf = UnionFind(n)
    cells = {}
    keys = np.floor(uniq / snap).astype(np.int64)
    for i in range(n):
        cells.setdefault(tuple(keys[i]), []).append(i)
    snap2 = snap * snap
    for (kx, ky, kz), members in cells.items():
        cand = []
        for dx in (-1, 0, 1):
            for dy in (-1, 0, 1):
                for dz in (-1, 0, 1):
                    cand.extend(cells.get((kx + dx, ky + dy, kz + dz), ()))
        cand = np.array(cand)
        for i in members:
            d2 = ((uniq[cand] - uniq[i]) ** 2).sum(axis=1)
            for j in cand[(d2 < snap2) & (cand > i)]:
                uf.union(i, int(j))
    roots = np.array([uf.find(i) for i in range(n)])
    _, cid = np.unique(roots, return_inverse=True)
    cid = cid.reshape(-1)
    reps = np.zeros((cid.max() + 1 if n else 0, 3))
    # representative: the first (lexicographically smallest) unique point of the cluster
    for i in range(n - 1, -1, -1):
        reps[cid[i]] = uniq[i]
    return cid[inverse], reps


def shell_measures(faces, snap):
    """faces: list of ring lists (already oriented). Returns the solid measures (without id)."""
    rings = [r for f in faces for r in f if len(r) >= 1]
    allpts = np.vstack(rings) if rings else np.zeros((0, 3))
    res = {"faces": len(faces), "closed": False, "boundary_edges": 0, "nonmanifold_edges": 0,
           "orientation_errors": 0, "volume": 0.0, "volume_signed": 0.0}
    if len(allpts) == 0:
        return res
    origin = allpts.mean(axis=0)
    # volume (divergence theorem, fan triangulation of every ring, relative to the shell centroid)
    vol = 0.0
    for r in rings:
        if len(r) < 3:
            continue
        q = r - origin
        vol += float(np.einsum("ij,ij->", np.broadcast_to(q[0], q[1:-1].shape), np.cross(q[1:-1], q[2:]))) / 6.0
    res["volume_signed"] = vol
    res["volume"] = abs(vol)
    # edge-use count
    cid, reps = cluster(allpts - origin, snap)
    directed = []  # (a, b) cluster ids, one per edge use
    k = 0
    for r in rings:
        ids = cid[k:k + len(r)]
        k += len(r)
        nxt = np.roll(ids, -1)
        for a, b in zip(ids.tolist(), nxt.tolist()):
            if a != b:
                directed.append((a, b))
    if not directed:
        return res
    d = np.array(directed)
    und = np.sort(d, axis=1)
    uedges, inv, ucount = np.unique(und, axis=0, return_inverse=True, return_counts=True)
    inv = inv.reshape(-1)
    # per unique edge: number of uses in direction (min -> max)
    fwd = np.zeros(len(uedges), dtype=np.int64)
    np.add.at(fwd, inv, (d[:, 0] == und[:, 0]).astype(np.int64))
    # split every unique edge at shell vertices within snap of its interior
    A = reps[uedges[:, 0]]
    B = reps[uedges[:, 1]]
    D = B - A
    L2 = (D * D).sum(axis=1)
    sub_use = {}  # (u, v) u<v -> [count, fwd-in-(u<v)-direction count]
    nv = len(reps)
    chunk = max(1, 2_000_000 // max(nv, 1))
    for s in range(0, len(uedges), chunk):
        e = slice(s, s + chunk)
        t = ((reps[None, :, :] - A[e, None, :]) * D[e, None, :]).sum(axis=2) / L2[e, None]
        closest = A[e, None, :] + t[:, :, None] * D[e, None, :]
        dist2 = ((reps[None, :, :] - closest) ** 2).sum(axis=2)
        on = (t > 0.0) & (t < 1.0) & (dist2 < snap * snap)
        ei = np.arange(s, min(s + chunk, len(uedges)))
        on[np.arange(len(ei)), uedges[ei, 0]] = False
        on[np.arange(len(ei)), uedges[ei, 1]] = False
        for row, idx in enumerate(ei):
            a, b = int(uedges[idx, 0]), int(uedges[idx, 1])
            cnt, f = int(ucount[idx]), int(fwd[idx])
            mids = np.nonzero(on[row])[0]
            if len(mids):
                order = mids[np.argsort(t[row, mids])]
                chain = [a] + order.tolist() + [b]
            else:
                chain = [a, b]
            for u, v in zip(chain[:-1], chain[1:]):
                if u == v:
                    continue
                if u < v:
                    key, ff = (u, v), f
                else:
                    key, ff = (v, u), cnt - f
                acc = sub_use.setdefault(key, [0, 0])
                acc[0] += cnt
                acc[1] += ff
    boundary = nonman = orient = 0
    for cnt, f in sub_use.values():
        if cnt % 2:
            boundary += 1
        if cnt > 2:
            nonman += 1
        if cnt == 2 and f != 1:
            orient += 1
    res.update(closed=boundary == 0, boundary_edges=boundary, nonmanifold_edges=nonman,
               orientation_errors=orient)
    return res


# ---------------------------------------------------------------------------------------------
# document model


class Doc:
    def __init__(self, path):
        self.path = path
        try:
            parser = etree.XMLParser(huge_tree=True, remove_blank_text=False, resolve_entities=False)
            self.tree = etree.parse(path, parser)
        except OSError as e:
            raise InputError("cannot read %s: %s" % (path, e))
        except etree.XMLSyntaxError as e:
            raise InputError("%s is not well-formed XML: %s" % (path, e))
        self.root = self.tree.getroot()
        self.ids = {}
        for el in self.root.iter():
            if not isinstance(el.tag, str):
                continue
            i = gml_id(el)
            if i is not None and i not in self.ids:
                self.ids[i] = el
        self.unresolved = 0
        self._build_units()

    def resolve(self, href):
        frag = href.split("#", 1)[1] if "#" in href else href
        return self.ids.get(frag)

    def nearest_unit(self, el):
        e = el.getparent()
        while e is not None:
            if local(e) in UNIT_NAMES:
                return e
            e = e.getparent()
        return None

    def _build_units(self):
        self.units = {}  # key -> dict(element, polygons=[(key, rings)], solids=[el])
        unit_key = {}
        n = 0
        for el in self.root.iter():
            if local(el) in UNIT_NAMES:
                key = gml_id(el)
                if key is None or key in self.units:
                    key = "#%d" % n if key is None else "%s#%d" % (key, n)
                n += 1
                unit_key[el] = key
                self.units[key] = {"polygons": [], "solids": []}
        for el in self.root.iter():
            if not is_gml(el):
                continue
            name = local(el)
            if name not in ("Polygon", "Solid"):
                continue
            u = self.nearest_unit(el)
            if u is None:
                continue
            key = unit_key[u]
            if name == "Polygon":
                polys = self.units[key]["polygons"]
                pid = gml_id(el)
                pkey = pid if pid is not None else "%s/%d" % (key, len(polys))
                polys.append((pkey, polygon_rings(el)))
            else:
                self.units[key]["solids"].append(el)

    # --- shells -----------------------------------------------------------------------------

    def collect_faces(self, el, flip, out, stack, counter):
        """Append oriented ring lists of every surface reachable from el (geometry or property)."""
        if el is None or not isinstance(el.tag, str):
            return
        if id(el) in stack:
            return
        stack.add(id(el))
        try:
            name = local(el)
            href = el.get(XLINK_HREF)
            if href is not None and len(el) == 0:
                target = self.resolve(href)
                if target is None:
                    counter[0] += 1
                else:
                    self.collect_faces(target, flip, out, stack, counter)
                return
            if is_gml(el) and name in ("Polygon", "PolygonPatch", "Triangle", "Rectangle"):
                rings = polygon_rings(el)
                if flip:
                    rings = [r[::-1] for r in rings]
                out.append(rings)
                return
            if is_gml(el) and name == "OrientableSurface":
                f = flip ^ (el.get("orientation", "+").strip() == "-")
                for child in el:
                    if local(child) == "baseSurface":
                        self.collect_faces(child, f, out, stack, counter)
                return
            for child in el:
                self.collect_faces(child, flip, out, stack, counter)
        finally:
            stack.discard(id(el))

    def solid_measures(self, solid, ukey, ordinal, snap):
        faces, counter = [], [0]
        for child in solid:
            if local(child) == "exterior":
                self.collect_faces(child, False, faces, set(), counter)
        m = shell_measures(faces, snap)
        sid = gml_id(solid)
        out = {"id": sid if sid is not None else "%s/solid%d" % (ukey, ordinal)}
        out.update(m)
        out["unresolved_hrefs"] = counter[0]
        return out

    def measures(self, snap):
        res = {}
        for key, u in self.units.items():
            polys = u["polygons"]
            area = sum(polygon_area(r) for _, r in polys)
            plan = max((planarity(r) for _, r in polys), default=0.0)
            solids = [self.solid_measures(s, key, i, snap) for i, s in enumerate(u["solids"])]
            res[key] = {
                "area": area,
                "polygons": len(polys),
                "rings": sum(len(r) for _, r in polys),
                "vertices": sum(len(x) for _, r in polys for x in r),
                "max_planarity": plan,
                "solids": solids,
                "closed_solids": sum(1 for s in solids if s["closed"]),
            }
        return res


def nearest_dist(q, pts):
    """For each row of q, distance to the nearest row of pts (brute force, chunked)."""
    if len(q) == 0:
        return np.zeros(0)
    if len(pts) == 0:
        return np.full(len(q), np.inf)
    out = np.empty(len(q))
    chunk = max(1, 4_000_000 // len(pts))
    for s in range(0, len(q), chunk):
        d2 = ((q[s:s + chunk, None, :] - pts[None, :, :]) ** 2).sum(axis=2)
        out[s:s + chunk] = np.sqrt(d2.min(axis=1))
    return out


def ring_move(x, y):
    """Largest per-vertex distance between two rings of equal length, taking the best cyclic
    start (a rewritten ring may start at another vertex: the same ring, not a move)."""
    return float(min(np.linalg.norm(x - np.roll(y, k, axis=0), axis=1).max() for k in range(len(y))))


def compare_unit(ub, ua):
    before = {k: r for k, r in ub["polygons"]}
    allb = [x for _, r in ub["polygons"] for x in r]
    origin = allb[0][0] if allb and len(allb[0]) else np.zeros(3)
    bpts = np.vstack(allb) - origin if allb else np.zeros((0, 3))
    mm = 0.0
    mu = 0.0
    matched = unmatched = 0
    after_keys = set()
    pending = []
    for k, ra in ua["polygons"]:
        after_keys.add(k)
        rb = before.get(k)
        if rb is not None and len(rb) == len(ra) and all(len(x) == len(y) for x, y in zip(rb, ra)):
            for x, y in zip(rb, ra):
                if len(x):
                    mm = max(mm, ring_move(x, y))
                    matched += len(x)
        for y in ra:
            if len(y):
                pending.append(y - origin)
    if pending:
        q = np.vstack(pending)
        unmatched = len(q) - matched
        d = nearest_dist(q, bpts)
        mu = float(d.max()) if len(d) else 0.0
        if not math.isfinite(mu):
            mu = None  # the unit has no BEFORE vertex: distance undefined
    only_before = [k for k, _ in ub["polygons"] if k not in after_keys]
    return {
        "max_move": mu,
        "max_move_matched": mm,
        "max_move_unmatched": mu,
        "matched_vertices": matched,
        "unmatched_vertices": unmatched,
        "polygons_only_before": only_before,
    }


def rel(b, a):
    if b == 0.0:
        return 0.0 if a == 0.0 else None
    return (a - b) / b


UNITS_OF_MEASURE = {"area": "m2", "move": "m", "planarity": "m", "volume": "m3"}


def main(argv=None):
    ap = arg_parser("citygml_invariants", "Independent CityGML building invariants (area, closedness, volume, planarity, moves).")
    ap.add_argument("before", help="CityGML file (BEFORE, or the only file)")
    ap.add_argument("after", nargs="?", help="CityGML file after the change (optional)")
    ap.add_argument("--snap", type=float, default=0.001, help="vertex snapping distance in m (default 0.001)")
    args = ap.parse_args(argv)
    if not (args.snap > 0 and math.isfinite(args.snap)):
        ap.error("--snap must be a positive number")
    try:
        db = Doc(args.before)
        mb = db.measures(args.snap)
        if args.after is None:
            out = {
                "file": args.before,
                "snap": args.snap,
                "units": mb,
                "total": {
                    "units": len(mb),
                    "area": sum(u["area"] for u in mb.values()),
                    "polygons": sum(u["polygons"] for u in mb.values()),
                    "solids": sum(len(u["solids"]) for u in mb.values()),
                    "closed_solids": sum(u["closed_solids"] for u in mb.values()),
                    "max_planarity": max((u["max_planarity"] for u in mb.values()), default=0.0),
                },
                "units_of_measure": UNITS_OF_MEASURE,
            }
        else:
            da = Doc(args.after)
            ma = da.measures(args.snap)
            units = {}
            for k in mb:
                if k not in ma:
                    continue
                u = {"before": mb[k], "after": ma[k],
                     "area_change_rel": rel(mb[k]["area"], ma[k]["area"])}
                u.update(compare_unit(db.units[k], da.units[k]))
                units[k] = u
            ab = sum(u["area"] for u in mb.values())
            aa = sum(u["area"] for u in ma.values())
            out = {
                "before_file": args.before,
                "after_file": args.after,
                "snap": args.snap,
                "units": units,
                "only_before": [k for k in mb if k not in ma],
                "only_after": [k for k in ma if k not in mb],
                "total": {
                    "area_before": ab,
                    "area_after": aa,
                    "area_change_rel": rel(ab, aa),
                    "max_move": max((u["max_move"] for u in units.values()), default=0.0),
                    "solids_before": sum(len(u["solids"]) for u in mb.values()),
                    "solids_after": sum(len(u["solids"]) for u in ma.values()),
                    "closed_solids_before": sum(u["closed_solids"] for u in mb.values()),
                    "closed_solids_after": sum(u["closed_solids"] for u in ma.values()),
                    "max_planarity_before": max((u["max_planarity"] for u in mb.values()), default=0.0),
                    "max_planarity_after": max((u["max_planarity"] for u in ma.values()), default=0.0),
                },
                "units_of_measure": UNITS_OF_MEASURE,
            }
    except InputError as e:
        sys.stderr.write("citygml_invariants: error: %s\n" % e)
        return 2
    json.dump(out, sys.stdout, indent=1, allow_nan=False, default=float)
    sys.stdout.write("\n")
    return 0


if __name__ == "__main__":
    sys.exit(main())
