#!/usr/bin/env python3
"""Loads an OBJ with FreeCAD's Mesh module and reports what FreeCAD sees, as one JSON line.

    /usr/bin/python3 tests/scripts/export_freecad.py FILE.obj    -> JSON (last line of stdout)
    /usr/bin/python3 tests/scripts/export_freecad.py --check     -> exit 0 when FreeCAD imports

Debian's freecad-python3 builds FreeCAD's modules for the system interpreter (/usr/bin/python3)
and installs them outside sys.path, so this script adds the known library folders ($FREECAD_LIB
first). `freecadcmd` would also do, but cannot pass arguments to a script.

Reported: facets, points, area, signed volume as loaded, then after merging duplicated points
(OBJ writers repeat shared vertices per polygon): points, isSolid (closed, every edge shared by two
facets), hasNonManifolds, and the volume again.
"""
import json
import os
import sys

for d in [os.environ.get("FREECAD_LIB"), "/usr/lib/freecad-python3/lib", "/usr/lib/freecad/lib",
          "/usr/share/freecad/lib", "/usr/lib/freecad-daily-python3/lib"]:
    if d and os.path.isdir(d) and d not in sys.path:
        sys.path.append(d)

import FreeCAD  # noqa: E402,F401
import Mesh  # noqa: E402

if sys.argv[1:] == ["--check"]:
    print("FreeCAD", ".".join(FreeCAD.Version()[:3]))
    sys.exit(0)

m = Mesh.Mesh(sys.argv[1])
out = {
    "version": ".".join(FreeCAD.Version()[:3]),
    "facets": m.CountFacets,
    "points": m.CountPoints,
    "area": m.Area,
    "volume": m.Volume,
}
m.removeDuplicatedPoints()
out.update({
    "merged_points": m.CountPoints,
    "merged_facets": m.CountFacets,
    "is_solid": bool(m.isSolid()),
    "non_manifolds": bool(m.hasNonManifolds()),
    "merged_volume": m.Volume,
    "components": m.countComponents(),
})
print(json.dumps(out))
