#!/usr/bin/env python3
"""Loads a mesh file (glb, gltf, obj) with pymeshlab (MeshLab's importers) and reports, as one
JSON line: number of meshes MeshLab made of it, total faces (and per mesh), total vertices, total area (computed
here with numpy from the loaded vertex/face matrices) and the bounding box of all vertices.

    python3 tests/scripts/export_meshlab.py FILE
"""
import json
import sys

import numpy as np
import pymeshlab

ms = pymeshlab.MeshSet()
ms.load_new_mesh(sys.argv[1])
faces = verts = 0
per_mesh = []
area = 0.0
lo = np.full(3, np.inf)
hi = np.full(3, -np.inf)
for i in range(ms.mesh_number()):
    ms.set_current_mesh(i)
    m = ms.current_mesh()
    v = m.vertex_matrix().astype(np.float64)
    f = m.face_matrix()
    faces += f.shape[0]
    per_mesh.append(int(f.shape[0]))
    verts += v.shape[0]
    if f.shape[0]:
        a, b, c = v[f[:, 0]], v[f[:, 1]], v[f[:, 2]]
        area += 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1).sum()
    if v.shape[0]:
        lo = np.minimum(lo, v.min(axis=0))
        hi = np.maximum(hi, v.max(axis=0))
print(json.dumps({"meshes": ms.mesh_number(), "faces": int(faces), "faces_per_mesh": per_mesh, "vertices": int(verts), "area": float(area),
                  "min": lo.tolist(), "max": hi.tolist()}))
