#!/usr/bin/env python3
"""Independent topology check of a surface with pymeshlab (MeshLab's importer and measures):
prints one JSON line with two-manifoldness, boundary edges, connected components and volume.

    python3 tests/scripts/implicit_meshlab.py SURFACE.obj
"""
import json
import sys

import pymeshlab

ms = pymeshlab.MeshSet()
ms.load_new_mesh(sys.argv[1])
topo = ms.get_topological_measures()
geo = ms.get_geometric_measures()
print(json.dumps({
    "two_manifold": bool(topo["is_mesh_two_manifold"]),
    "boundary_edges": int(topo["boundary_edges"]),
    "connected_components": int(topo["connected_components_number"]),
    "volume": float(geo.get("mesh_volume", float("nan"))),
    "faces": int(ms.current_mesh().face_number()),
}))
