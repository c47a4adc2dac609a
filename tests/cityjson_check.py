# Independent check of CityGML -> CityJSON -> CityGML round trips (lxml + json + jsonschema).
# argv: schema_dir, then triples orig.gml doc.city.json back.gml report.json ... Prints one line per problem.
import json, sys, os, math
from lxml import etree
import jsonschema, referencing
from scipy.spatial import cKDTree
import numpy as np

schema_dir = sys.argv[1]
res = []
for f in os.listdir(schema_dir):
    if f.endswith('.schema.json'):
        s = json.load(open(os.path.join(schema_dir, f)))
        res.append((s['$id'], referencing.Resource.from_contents(s, default_specification=referencing.jsonschema.DRAFT7)))
reg = referencing.Registry().with_resources(res)
main = json.load(open(os.path.join(schema_dir, 'cityjson.schema.json')))
validator = jsonschema.Draft7Validator(main, registry=reg)

FEATURES = {'Building', 'BuildingPart', 'BuildingInstallation', 'IntBuildingInstallation', 'Room', 'BuildingRoom'}
SURF = {'WallSurface','RoofSurface','GroundSurface','ClosureSurface','FloorSurface','CeilingSurface','InteriorWallSurface',
        'OuterFloorSurface','OuterCeilingSurface','Window','Door','WindowSurface','DoorSurface'}
NORM = {'WindowSurface': 'Window', 'DoorSurface': 'Door'}
SIMPLE = {'name','description','creationDate','terminationDate','class','function','usage','yearOfConstruction','yearOfDemolition',
          'roofType','measuredHeight','storeysAboveGround','storeysBelowGround'}
def gml_id(e):
    for k, v in e.attrib.items():
        if k.startswith('{http://www.opengis.net/gml') and k.endswith('}id'):
            return v
    return None
def local(e): return etree.QName(e).localname if isinstance(e.tag, str) else ''

def model(path):
    t = etree.parse(path)
    feats, surfs, attrs, polys_by_type, pts = set(), set(), {}, {}, []
    kinds = {}
    for e in t.iter():
        ln = local(e)
        gid = gml_id(e)
        if ln in FEATURES:
            k = 'BuildingInstallation' if ln == 'IntBuildingInstallation' else ('Room' if ln == 'BuildingRoom' else ln)
            kinds[k] = kinds.get(k, 0) + 1
        if ln in FEATURES and gid and not gid.startswith('geofit-'):
            feats.add(gid)
            a = {}
            for c in e:
                cl = local(c)
                if cl.endswith('Attribute') and cl != 'genericAttribute' and c.get('name'):
                    v = [x.text for x in c if local(x) == 'value']
                    a[c.get('name')] = (v[0] or '') if v else ''
                elif cl == 'genericAttribute':
                    for g in c:
                        n = [x.text for x in g if local(x) == 'name']; v = [x.text for x in g if local(x) == 'value']
                        if n and v: a[n[0]] = v[0] or ''
                elif cl in SIMPLE and len(c) == 0 and (c.text or '').strip() and cl not in a:
                    a[cl] = c.text
            attrs[gid] = a
        if ln in SURF and gid and not gid.startswith('geofit-'):
            surfs.add((NORM.get(ln, ln), gid))
        if ln == 'Polygon':
            anc = [local(x) for x in e.iterancestors()]
            if not any(x in FEATURES for x in anc):
                continue
            st = next((NORM.get(x, x) for x in anc if x in SURF), None)
            ring = []
            for p in e.iter():
                if local(p) in ('posList', 'pos', 'coordinates') and p.text:
                    txt = p.text.replace(',', ' ') if local(p) != 'coordinates' else p.text.replace(',', ' ')
                    v = [float(x) for x in txt.split()]
                    dim = int(p.get('srsDimension') or (2 if local(p) == 'coordinates' and p.text.strip().split()[0].count(',') == 1 else 3))
                    ring += [tuple(v[i:i+dim] + [0.0]*(3-dim)) for i in range(0, len(v) - dim + 1, dim)]
            pts += ring
            # CityJSON has no shared polygons: one that two features hold by XLink comes back
            # defined twice. Count distinct polygons (by their rounded vertex set) per type.
            polys_by_type.setdefault(st, set()).add(frozenset((round(a, 2), round(b, 2), round(c, 2)) for a, b, c in ring))
    polys_by_type = {k: len(v) for k, v in polys_by_type.items()}
    return feats, surfs, attrs, polys_by_type, np.array(pts).reshape(-1, 3), kinds

def same_value(a, b):
    if a.strip() == b.strip(): return True
    try: return math.isclose(float(a), float(b), rel_tol=1e-9, abs_tol=1e-9)
    except ValueError: return False

args = sys.argv[2:]
for i in range(0, len(args), 4):
    orig, doc, back, rep = args[i:i+4]
    tag = os.path.relpath(orig, os.path.dirname(os.path.dirname(orig)))
    d = json.load(open(doc))
    errs = list(validator.iter_errors(d))
    if errs:
        print(f"{tag}: {len(errs)} CityJSON schema errors, first: {errs[0].message[:200]}")
    report = json.dumps(json.load(open(rep)).get('not_carried', {}))
    f1, s1, a1, p1, x1, k1 = model(orig)
    f2, s2, a2, p2, x2, k2 = model(back)
    for k, n in k1.items():
        if k2.get(k, 0) < n and k not in report:
            print(f"{tag}: {n - k2.get(k, 0)} {k} features lost without a report line")
    if f1 - f2: print(f"{tag}: features lost: {sorted(f1 - f2)[:3]}")
    if f2 - f1: print(f"{tag}: features invented: {sorted(f2 - f1)[:3]}")
    if s1 - s2: print(f"{tag}: surfaces lost: {sorted(s1 - s2)[:3]}")
    for fid in f1 & f2:
        for k, v in a1[fid].items():
            w = a2[fid].get(k)
            if w is None or not same_value(v, w):
                print(f"{tag}: {fid}: attribute {k}={v!r} came back as {w!r}")
    if p1 != p2: print(f"{tag}: polygons per surface type differ: {p1} vs {p2}")
    if len(x1) and len(x2):
        d12, _ = cKDTree(x2).query(x1); d21, _ = cKDTree(x1).query(x2)
        m = max(d12.max(), d21.max())
        if m > 0.00087: print(f"{tag}: coordinates moved by {m:.4f} (more than the 0.001 precision allows)")
    elif len(x1) != len(x2):
        print(f"{tag}: {len(x1)} vs {len(x2)} coordinates")
    print(f"OK {tag} features={len(f1)} surfaces={len(s1)} polygons={sum(p1.values())}", file=sys.stderr)
