#!/usr/bin/env python3
"""A 3D Tiles tileset read back by py3dtiles (a third-party 3D Tiles library), as issue 17 asks.

Usage:
    tileset_py3dtiles.py TILESET.json

py3dtiles parses the tileset into its own model (`TileSet.from_file`: asset, tiles, bounding
volumes, transforms, content URIs) and refuses what it cannot read. On that model this checks:
asset version 1.1; every tile's bounding volume a box of 12 finite numbers; geometric error >= 0
and not above its parent's; every content URI naming a file beside the tileset; every transform
affine (last row 0 0 0 1) with a linear part within 1 % of a rotation (geofit's tile transform is
the tangent map of the CRS to ECEF: a rotation times the projection's scale, e.g. 0.9996 in UTM). py3dtiles 9 reads b3dm/pnts content only,
not glb, so the glb themselves are left to the Khronos validator.
Prints one JSON line {"reader", "tiles", "contents", "errors"}; exit 1 on errors.
"""
import json
import sys
from pathlib import Path

import numpy as np
import py3dtiles
from py3dtiles.tileset import TileSet


def main():
    path = Path(sys.argv[1]).resolve()
    ts = TileSet.from_file(path)
    errors, tiles, contents = [], 0, 0
    version = ts.asset.to_dict().get("version") if hasattr(ts.asset, "to_dict") else getattr(ts.asset, "version", None)
    if version != "1.1":
        errors.append(f"asset.version {version!r}, not 1.1")
    stack = [(ts.root_tile, ts.geometric_error, "root")]
    while stack:
        tile, parent_error, name = stack.pop()
        tiles += 1
        box = tile.bounding_volume.to_dict().get("box") if tile.bounding_volume is not None else None
        if box is None or len(box) != 12 or not np.all(np.isfinite(box)):
            errors.append(f"{name}: bounding volume is not a box of 12 finite numbers")
        if not (0 <= tile.geometric_error <= parent_error):
            errors.append(f"{name}: geometric error {tile.geometric_error} outside [0, {parent_error}]")
        if tile.content_uri is not None:
            contents += 1
            if not (path.parent / tile.content_uri).is_file():
                errors.append(f"{name}: content {tile.content_uri} missing")
        m = np.asarray(tile.transform, dtype=float)
        if m.shape != (4, 4) or not np.allclose(m[3], [0, 0, 0, 1]) or not np.allclose(np.linalg.svd(m[:3, :3], compute_uv=False), 1, atol=1e-2):
            errors.append(f"{name}: transform is not affine with a near-rotation linear part")
        for k, c in enumerate(tile.children):
            stack.append((c, tile.geometric_error, f"{name}.children[{k}]"))
    print(json.dumps({"reader": f"py3dtiles {py3dtiles.__version__}", "tiles": tiles, "contents": contents, "errors": errors}))
    return 1 if errors else 0


if __name__ == "__main__":
    sys.exit(main())
