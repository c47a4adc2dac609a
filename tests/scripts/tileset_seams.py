#!/usr/bin/env python3
"""Independent check that the per-tile glb of a tiled terrain meet without gaps, overlaps or colour
jumps (numpy; glTF 2.0 read from the bytes, geofit's root-node `extras.origin` convention: vertex
data = source Z-up coordinates minus the origin).

Usage:
    tileset_seams.py PLAN.jsonl GLB_DIR STEP

For every tile of the plan, GLB_DIR/<id>.glb's node `surface`:
- its vertices reach the tile's core bounds on every side that is a whole number of STEPs from the
  core's lower-left corner (so the tiles' surfaces touch: no strip without triangles between them);
- the xy areas of all triangles of all tiles add up to the area of the plan's cores (every core
  covered once: no gap, no overlap, as long as every cell has data);
- vertices at the same (x, y) in two or more tiles (the seams) have the same height and colour.
Prints one JSON line {"tiles", "vertices", "shared_vertices", "max_seam_dz", "max_seam_colour_diff",
"triangle_area", "core_area", "errors"}.
"""
import json
import struct
import sys

import numpy as np

COMPONENT = {5126: ("<f4", 1.0), 5121: ("<u1", 255.0), 5123: ("<u2", 65535.0)}
WIDTH = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4}


def read_glb(path):
    data = open(path, "rb").read()
    magic, version, length = struct.unpack_from("<4sII", data, 0)
    if magic != b"glTF" or version != 2 or length != len(data):
        raise ValueError(f"{path}: not a glb 2.0")
    jlen, _ = struct.unpack_from("<II", data, 12)
    doc = json.loads(data[20:20 + jlen])
    blen, _ = struct.unpack_from("<II", data, 20 + jlen)
    return doc, data[28 + jlen:28 + jlen + blen]


def accessor(doc, binary, i):
    acc = doc["accessors"][i]
    dtype, scale = COMPONENT[acc["componentType"]] if acc["componentType"] in COMPONENT else ("<u4", 1.0)
    width = WIDTH[acc["type"]]
    bv = doc["bufferViews"][acc["bufferView"]]
    item = np.dtype(dtype).itemsize
    stride = bv.get("byteStride", item * width)
    off = bv.get("byteOffset", 0) + acc.get("byteOffset", 0)
    raw = np.frombuffer(binary, dtype=dtype, count=(acc["count"] - 1) * stride // item + width, offset=off)
    v = np.lib.stride_tricks.as_strided(raw, shape=(acc["count"], width), strides=(stride, item)).astype(float)
    return v / scale if acc.get("normalized") else v


def surface(path):
    doc, binary = read_glb(path)
    origin = next(n for n in doc["nodes"] if n.get("name") == "origin")["extras"]["origin"]
    node = next(n for n in doc["nodes"] if n.get("name") == "surface")
    prim = doc["meshes"][node["mesh"]]["primitives"][0]
    xyz = accessor(doc, binary, prim["attributes"]["POSITION"]) + np.array(origin)
    rgb = accessor(doc, binary, prim["attributes"]["COLOR_0"])[:, :3]
    tris = accessor(doc, binary, prim["indices"]).astype(np.int64).reshape(-1, 3)
    return xyz, rgb, tris


def main():
    plan_path, glb_dir, step = sys.argv[1], sys.argv[2], float(sys.argv[3])
    plan = [json.loads(line) for line in open(plan_path) if line.strip()]
    errors, seen = [], {}
    area, core_area, vertices = 0.0, 0.0, 0
    for t in plan:
        x0, y0, x1, y1 = t["core"]["bounds"]
        _, _, w, h = t["core"]["pixels"]
        cell = (x1 - x0) / w
        core_area += (x1 - x0) * (y1 - y0)
        xyz, rgb, tris = surface(f"{glb_dir}/{t['id']}.glb")
        vertices += len(xyz)
        tol = 1e-3 * cell
        reach = {"west": xyz[:, 0].min() - x0, "south": xyz[:, 1].min() - y0}
        if w % step == 0:
            reach["east"] = x1 - xyz[:, 0].max()
        if h % step == 0:
            reach["north"] = y1 - xyz[:, 1].max()
        for side, gap in reach.items():
            if abs(gap) > tol:
                errors.append(f"{t['id']}: vertices stop {gap:.6g} short of the core's {side} edge")
        a, b, c = xyz[tris[:, 0]], xyz[tris[:, 1]], xyz[tris[:, 2]]
        area += float(np.sum(np.abs((b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (c[:, 0] - a[:, 0]) * (b[:, 1] - a[:, 1]))) / 2)
        for p, col in zip(xyz, rgb):
            key = (round(p[0] / tol), round(p[1] / tol))
            seen.setdefault(key, []).append((t["id"], p[2], col))
    shared = [v for v in seen.values() if len({tid for tid, _, _ in v}) >= 2]
    dz = max((max(z for _, z, _ in v) - min(z for _, z, _ in v) for v in shared), default=0.0)
    dc = max((float(np.max(np.ptp(np.array([c for _, _, c in v]), axis=0))) for v in shared), default=0.0)
    if abs(area - core_area) > 1e-6 * core_area:
        errors.append(f"triangles cover {area:.6f} of the cores' {core_area:.6f} (gap or overlap)")
    print(json.dumps({
        "tiles": len(plan), "vertices": vertices, "shared_vertices": len(shared), "max_seam_dz": dz,
        "max_seam_colour_diff": dc, "triangle_area": area, "core_area": core_area, "errors": errors,
    }))
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main())
