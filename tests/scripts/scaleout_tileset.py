#!/usr/bin/env python3
"""Independent reader of a 3D Tiles 1.1 tileset.json over glb content (numpy + PROJ's cs2cs).

Usage:
    scaleout_tileset.py TILESET.json [--crs EPSG:25832] [--height-offset M]

Checks (3D Tiles 1.1 §Tileset JSON, §Bounding volumes, glTF 2.0 §3.5, §5.10):
- asset.version == "1.1"; geometricError >= 0 on tileset, root and every tile; root refine
  ADD/REPLACE; every boundingVolume.box has 12 finite numbers; every transform 16;
- every content.uri names a glb next to the tileset; its vertices (POSITION data read from the
  BIN chunk, through the scene's node matrices — geofit's root node turns Z-up into Y-up — and
  then 3D Tiles' glTF Y-up → Z-up (x, y, z) → (x, −z, y)) lie in the tile's box;
- the tile's box corners, through the tile transform, lie in the root box (ECEF);
- with --crs: for sampled vertices, transform · v equals the vertex's world position
  (E₀+x, N₀+y, h₀+z+offset, origin from the glb's root node extras) converted by cs2cs from the
  CRS to EPSG:4978, within 5 mm + 1.5·d²/2R (the tangent map's first-order error at distance d).
Prints one JSON line {"tiles": n, "vertices": n, "max_box_excess_m": x, "max_ecef_error_m": x,
"errors": [...]}.
"""
import argparse
import json
import os
import struct
import subprocess

import numpy as np

TOL = 1e-6


def read_glb(path):
    data = open(path, "rb").read()
    magic, version, length = struct.unpack_from("<4sII", data, 0)
    assert magic == b"glTF" and version == 2 and length == len(data), path
    jlen, jtype = struct.unpack_from("<II", data, 12)
    assert jtype == 0x4E4F534A
    doc = json.loads(data[20:20 + jlen])
    blen, btype = struct.unpack_from("<II", data, 20 + jlen)
    assert btype == 0x004E4942
    return doc, data[28 + jlen:28 + jlen + blen]


def node_matrix(n):
    if "matrix" in n:
        return np.array(n["matrix"], dtype=float).reshape(4, 4).T  # column-major
    m = np.eye(4)
    if "rotation" in n:
        x, y, z, w = n["rotation"]
        m[:3, :3] = [[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]]
    if "scale" in n:
        m[:3, :3] = m[:3, :3] @ np.diag(n["scale"])
    if "translation" in n:
        m[:3, 3] = n["translation"]
    return m


def positions(doc, binary):
    """All POSITION vertices in the glTF scene frame (Y-up), node matrices applied."""
    out = []

    def walk(i, parent):
        n = doc["nodes"][i]
        m = parent @ node_matrix(n)
        if "mesh" in n:
            for prim in doc["meshes"][n["mesh"]]["primitives"]:
                acc = doc["accessors"][prim["attributes"]["POSITION"]]
                assert acc["componentType"] == 5126 and acc["type"] == "VEC3"
                bv = doc["bufferViews"][acc["bufferView"]]
                stride = bv.get("byteStride", 12)
                off = bv.get("byteOffset", 0) + acc.get("byteOffset", 0)
                raw = np.frombuffer(binary, dtype="<f4", count=(acc["count"] - 1) * stride // 4 + 3, offset=off)
                v = np.lib.stride_tricks.as_strided(raw, shape=(acc["count"], 3), strides=(stride, 4)).astype(float)
                out.append(v @ m[:3, :3].T + m[:3, 3])
        for c in n.get("children", []):
            walk(c, m)

    for r in doc["scenes"][doc.get("scene", 0)]["nodes"]:
        walk(r, np.eye(4))
    return np.vstack(out) if out else np.zeros((0, 3))


def box_excess(box, pts):
    """How far (m) points stick out of an oriented box (0 when all inside)."""
    c, axes = np.array(box[:3]), np.array(box[3:]).reshape(3, 3)  # rows: half-axis vectors
    worst = 0.0
    for a in axes:
        ln = np.linalg.norm(a)
        d = np.abs((pts - c) @ a) / ln if ln > 0 else np.abs((pts - c) @ a)
        worst = max(worst, float(np.max(d - ln)) if len(pts) else 0.0)
    return max(worst, 0.0)


def corners(box):
    c, axes = np.array(box[:3]), np.array(box[3:]).reshape(3, 3)
    return np.array([c + sx * axes[0] + sy * axes[1] + sz * axes[2] for sx in (-1, 1) for sy in (-1, 1) for sz in (-1, 1)])


def cs2cs(crs, pts):
    text = "".join("%.6f %.6f %.6f\n" % tuple(p) for p in pts)
    r = subprocess.run(["cs2cs", "-f", "%.6f", crs, "EPSG:4978"], input=text, capture_output=True, text=True, check=True)
    return np.array([[float(t) for t in line.split()[:3]] for line in r.stdout.strip().splitlines()])


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("tileset")
    ap.add_argument("--crs")
    ap.add_argument("--height-offset", type=float, default=0.0)
    a = ap.parse_args()
    ts = json.load(open(a.tileset))
    base = os.path.dirname(os.path.abspath(a.tileset))
    errors = []

    def need(ok, msg):
        if not ok:
            errors.append(msg)

    need(ts.get("asset", {}).get("version") == "1.1", "asset.version is not 1.1")
    need(ts.get("geometricError", -1) >= 0, "tileset geometricError missing or negative")
    root = ts["root"]
    need(root.get("refine") in ("ADD", "REPLACE"), "root refine")
    nverts, excess, ecef_err = 0, 0.0, 0.0
    root_box = root["boundingVolume"]["box"]
    for t in [root] + root.get("children", []):
        need(t.get("geometricError", -1) >= 0, "tile geometricError")
        box = t.get("boundingVolume", {}).get("box", [])
        need(len(box) == 12 and all(np.isfinite(box)), "box of 12 finite numbers")
    for t in root.get("children", []):
        m = np.array(t["transform"], dtype=float).reshape(4, 4).T
        need(m.shape == (4, 4) and np.allclose(m[3], [0, 0, 0, 1]), "affine transform")
        path = os.path.join(base, t["content"]["uri"])
        need(t["content"]["uri"].endswith(".glb") and os.path.exists(path), "content %s exists" % t["content"]["uri"])
        doc, binary = read_glb(path)
        yup = positions(doc, binary)
        zup = np.column_stack([yup[:, 0], -yup[:, 2], yup[:, 1]])  # 3D Tiles: glTF Y-up → Z-up
        nverts += len(zup)
        e = box_excess(t["boundingVolume"]["box"], zup)
        excess = max(excess, e)
        need(e <= TOL * (1 + np.abs(zup).max()), "%s: vertices outside the tile box by %.3g m" % (path, e))
        world_box = corners(t["boundingVolume"]["box"]) @ m[:3, :3].T + m[:3, 3]
        re = box_excess(root_box, world_box)
        need(re <= 1e-6 * 6.4e6, "%s: tile box outside the root box by %.3g m" % (path, re))
        if a.crs:
            root_node = doc["nodes"][doc["scenes"][doc.get("scene", 0)]["nodes"][0]]
            origin = np.array(root_node["extras"]["origin"], dtype=float)
            idx = np.linspace(0, len(zup) - 1, min(25, len(zup))).astype(int)
            sample = zup[idx]
            got = sample @ m[:3, :3].T + m[:3, 3]
            world = sample + origin + [0, 0, a.height_offset]
            want = cs2cs(a.crs, world)
            d = np.linalg.norm(sample[:, :2], axis=1)
            err = np.linalg.norm(got - want, axis=1)
            allowed = 0.005 + 1.5 * d ** 2 / (2 * 6.371e6)
            ecef_err = max(ecef_err, float(err.max()))
            need(bool(np.all(err <= allowed)), "%s: ECEF position off by %.4f m (allowed %.4f)" % (path, err.max(), allowed[np.argmax(err)]))
    print(json.dumps({"tiles": len(root.get("children", [])), "vertices": int(nverts), "max_box_excess_m": excess,
                      "max_ecef_error_m": ecef_err, "errors": errors}))


if __name__ == "__main__":
    main()
