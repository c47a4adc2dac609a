#!/usr/bin/env python3
"""Independent decoder and evaluator of geofit's binary T-mesh (.tmb, versions 1 and 2), written
from docs/tmb-format.md and the T-spline definition of the terrain spec (§3.2, §3.6), with no
geofit code: reads the file, rebuilds the leaf cells and control points, infers every point's
local knot vectors by ray casting (nearest (K+1)/2 distinct edge coordinates per direction,
stopping at gaps, padded by repetition at the border), and evaluates the rational T-spline
sum(w z N) / sum(w N) at the centre of every valid cell of the raster (GDAL's command-line tools
read it; cell centre -> (s, t) through the file's georeference). Prints a JSON summary; exit 0
when max |surface - raster| <= E at every valid cell (a valid cell the surface does not cover
counts as over), 1 when not, 3 when the file cannot be decoded.

usage: tmb_decode_eval.py FILE.tmb RASTER E [--band N]
       tmb_decode_eval.py FILE.tmb --dump    (the decoded header and heights as JSON, for tests)
       tmb_decode_eval.py FILE.tmb --to-v1 OUT.tmb   (a lossless file rewritten as version 1: zlib)
"""
import json
import os
import struct
import subprocess
import sys
import tempfile
import zlib

import numpy as np

MAGIC = b"\x89TMB\r\n\x1a\n"
QUADTREE, XY, W, MASK, WARP, KDTREE, QUANT = 1, 2, 4, 8, 16, 32, 64


class Body:
    def __init__(self, data):
        self.d, self.p = data, 0

    def take(self, n):
        if self.p + n > len(self.d):
            raise ValueError(f"body ends at byte {len(self.d)}, {n} more needed at {self.p}")
        b = self.d[self.p:self.p + n]
        self.p += n
        return b

    def u8(self):
        return self.take(1)[0]

    def f64(self):
        return struct.unpack("<d", self.take(8))[0]

    def varint(self):
        v, shift = 0, 0
        while True:
            b = self.u8()
            v |= (b & 0x7F) << shift
            shift += 7
            if not b & 0x80:
                return v


def unpack(data):
    if not data.startswith(MAGIC) or len(data) < 21:
        raise ValueError("not a .tmb (magic) or shorter than its header")
    version = data[8]
    body_len = struct.unpack("<Q", data[9:17])[0]
    packed, crc = data[17:-4], struct.unpack("<I", data[-4:])[0]
    if version == 1:
        body = zlib.decompress(packed)
    elif version == 2:
        body = subprocess.run(["zstd", "-d", "-c", "-q"], input=packed, capture_output=True, check=True).stdout
    else:
        raise ValueError(f"version {version}")
    if len(body) != body_len or zlib.crc32(body) != crc:
        raise ValueError("length or CRC-32 mismatch")
    return version, body


def children(form, sym, r):
    s0, t0, s1, t1 = r
    sm, tm = 0.5 * (s0 + s1), 0.5 * (t0 + t1)
    if form == "quad" or sym == 1:
        return [(s0, t0, sm, tm), (sm, t0, s1, tm), (s0, tm, sm, t1), (sm, tm, s1, t1)]
    if sym == 2:
        return [(s0, t0, sm, t1), (sm, t0, s1, t1)]
    return [(s0, t0, s1, tm), (s0, tm, s1, t1)]


def read_tree(b, form):
    s0, t0, c0 = b.f64(), b.f64(), b.f64()
    ns, nt = b.varint(), b.varint()
    nsym = b.varint()
    bits = 1 if form == "quad" else 2
    raw = b.take((nsym * bits + 7) // 8)
    sym = lambda k: (raw[k * bits // 8] >> (k * bits % 8)) & ((1 << bits) - 1)
    leaves, k = [], 0
    for j in range(nt):
        for i in range(ns):
            stack = [(s0 + i * c0, t0 + j * c0, s0 + (i + 1) * c0, t0 + (j + 1) * c0)]
            while stack:
                r = stack.pop()
                v = sym(k)
                k += 1
                if v == 0:
                    leaves.append(r)
                else:
                    stack.extend(reversed(children(form, v, r)))
    assert k == nsym, "tree symbols left over"
    return leaves


def read_explicit(b):
    sv = [b.f64() for _ in range(b.varint())]
    tv = [b.f64() for _ in range(b.varint())]
    leaves = []
    for _ in range(b.varint()):
        a, da, c, dc = (b.varint() for _ in range(4))
        leaves.append((sv[a], tv[c], sv[a + da], tv[c + dc]))
    return leaves


def f64s(b, n):
    planes = np.frombuffer(b.take(8 * n), dtype=np.uint8).reshape(8, n)
    x = np.zeros(n, dtype=np.uint64)
    for p in range(8):
        x |= planes[p].astype(np.uint64) << np.uint64(8 * p)
    return np.bitwise_xor.accumulate(x).view(np.float64)


def quantised(b, n):
    step = b.f64()
    u = np.array([b.varint() for _ in range(n)], dtype=np.int64)
    d = (u >> 1) ^ -(u & 1)
    return np.cumsum(d).astype(np.float64) * step, step


def decode(data):
    version, body = unpack(data)
    b = Body(body)
    degree, flags = b.u8(), b.u8()
    x0, y0, dx, dy = (b.f64() for _ in range(4))
    crs = b.take(b.varint()).decode()
    if flags & QUADTREE:
        leaves = read_tree(b, "quad")
    elif flags & KDTREE:
        leaves = read_tree(b, "kd")
    else:
        leaves = read_explicit(b)
    pts = sorted({(s, t) for r in leaves for s, t in ((r[0], r[1]), (r[2], r[1]), (r[0], r[3]), (r[2], r[3]))}, key=lambda p: (p[1], p[0]))
    n = len(pts)
    step = None
    if flags & QUANT:
        z, step = quantised(b, n)
    else:
        z = f64s(b, n)
    if flags & XY:
        f64s(b, n), f64s(b, n)
    w = f64s(b, n) if flags & W else np.ones(n)
    return dict(version=version, degree=degree, flags=flags, georef=(x0, y0, dx, dy), crs=crs, leaves=np.array(leaves),
                st=np.array(pts), z=z, w=w, step=step)


def line_knots(leaves, pts, k, horizontal):
    """Per point, the k nearest distinct edge coordinates west/east (or south/north) along its
    grid line within the connected run of leaves the point lies in (closed boxes), padded."""
    a_ax, c_lo, c_hi = (0, 1, 3) if horizontal else (1, 0, 2)
    along = pts[:, a_ax]
    across = pts[:, 1 - a_ax]
    lo_ax, hi_ax = (0, 2) if horizontal else (1, 3)
    lower, upper = np.empty((len(pts), k)), np.empty((len(pts), k))
    order = np.argsort(across, kind="stable")
    lines, starts = np.unique(across[order], return_index=True)
    ends = list(starts[1:]) + [len(order)]
    # leaves sorted by their low coordinate across the line, to find those touching a line
    for at, i0, i1 in zip(lines, starts, ends):
        on = (leaves[:, c_lo] <= at) & (at <= leaves[:, c_hi])
        iv = leaves[on][:, [lo_ax, hi_ax]]
        iv = iv[np.lexsort((iv[:, 1], iv[:, 0]))]
        # connected runs (closed union)
        runs, cur = [], [iv[0]]
        reach = iv[0][1]
        for a, bb in iv[1:]:
            if a > reach:
                runs.append(np.array(cur))
                cur = []
            cur.append((a, bb))
            reach = max(reach, bb)
        runs.append(np.array(cur))
        bounds = [(r[:, 0].min(), r[:, 1].max(), np.unique(r.ravel())) for r in runs]
        for idx in order[i0:i1]:
            u = along[idx]
            vals = next(v for lo, hi, v in bounds if lo <= u <= hi)
            j = np.searchsorted(vals, u)
            below = vals[:j][::-1][:k]
            above = vals[j + 1:][:k] if j < len(vals) and vals[j] == u else vals[j:][:k]
            for arr, got in ((lower, below), (upper, above)):
                pad = got[-1] if len(got) else u
                arr[idx] = np.concatenate([got, np.full(k - len(got), pad)])
    return lower, upper


def basis(knots, u):
    """The B-spline basis function on the K+2 `knots` at the points `u` (Cox-de Boor, half-open
    intervals, 0/0 terms = 0)."""
    K = len(knots) - 2
    N = [((knots[i] <= u) & (u < knots[i + 1])).astype(float) for i in range(K + 1)]
    for r in range(1, K + 1):
        nxt = []
        for i in range(K + 1 - r):
            d1, d2 = knots[i + r] - knots[i], knots[i + r + 1] - knots[i + 1]
            a = (u - knots[i]) / d1 * N[i] if d1 > 0 else 0.0
            c = (knots[i + r + 1] - u) / d2 * N[i + 1] if d2 > 0 else 0.0
            nxt.append(a + c)
        N = nxt
    return N[0]


def evaluate(m, s_cells, t_cells):
    """The rational T-spline at the grid s_cells x t_cells (1-D arrays, sorted ascending)."""
    k = (m["degree"] + 1) // 2
    st = m["st"]
    ws, es = line_knots(m["leaves"], st, k, True)
    ss, ns = line_knots(m["leaves"], st, k, False)
    num = np.zeros((len(t_cells), len(s_cells)))
    den = np.zeros_like(num)
    for i in range(len(st)):
        sk = np.concatenate([ws[i][::-1], [st[i, 0]], es[i]])
        tk = np.concatenate([ss[i][::-1], [st[i, 1]], ns[i]])
        a0, a1 = np.searchsorted(s_cells, sk[0], "left"), np.searchsorted(s_cells, sk[-1], "right")
        b0, b1 = np.searchsorted(t_cells, tk[0], "left"), np.searchsorted(t_cells, tk[-1], "right")
        if a0 >= a1 or b0 >= b1:
            continue
        nb = np.outer(basis(tk, t_cells[b0:b1]), basis(sk, s_cells[a0:a1])) * m["w"][i]
        num[b0:b1, a0:a1] += nb * m["z"][i]
        den[b0:b1, a0:a1] += nb
    with np.errstate(invalid="ignore", divide="ignore"):
        return np.where(den > 0, num / den, np.nan)


def load_raster(path, band):
    env = dict(os.environ, GDAL_PAM_ENABLED="NO")
    info = json.loads(subprocess.run(["gdalinfo", "-json", path], check=True, capture_output=True, env=env).stdout)
    bi = info["bands"][band - 1]
    nodata = bi.get("noDataValue")
    w, h = info["size"]
    gt = info["geoTransform"]
    with tempfile.TemporaryDirectory() as d:
        out = os.path.join(d, "r.bin")
        subprocess.run(["gdal_translate", "-q", "-b", str(band), "-of", "ENVI", "-ot", "Float64", path, out],
                       check=True, capture_output=True, env=env)
        v = np.fromfile(out, dtype="<f8").reshape(h, w)
    ok = np.isfinite(v)
    if nodata is not None:
        ok &= v != float(nodata)
        if bi.get("type") == "Float32":
            ok &= v.astype(np.float32) != np.float32(nodata)
    return v, ok, gt


def main():
    path = sys.argv[1]
    try:
        m = decode(open(path, "rb").read())
    except (ValueError, AssertionError, IndexError, struct.error, subprocess.CalledProcessError, zlib.error) as e:
        print(json.dumps({"file": path, "error": str(e)}))
        return 3
    if sys.argv[2] == "--to-v1":
        version, body = unpack(open(path, "rb").read())
        if body[1] & QUANT:
            print(json.dumps({"file": path, "error": "version 1 has no quantised heights"}))
            return 1
        with open(sys.argv[3], "wb") as f:
            f.write(MAGIC + bytes([1]) + struct.pack("<Q", len(body)) + zlib.compress(body, 9) + struct.pack("<I", zlib.crc32(body)))
        print(json.dumps({"file": sys.argv[3], "version": 1}))
        return 0
    if sys.argv[2] == "--dump":
        print(json.dumps({"version": m["version"], "degree": m["degree"], "flags": m["flags"], "step": m["step"],
                          "points": len(m["z"]), "leaves": len(m["leaves"]), "z": m["z"].tolist()}))
        return 0
    raster, e = sys.argv[2], float(sys.argv[3])
    band = int(sys.argv[sys.argv.index("--band") + 1]) if "--band" in sys.argv else 1
    v, ok, gt = load_raster(raster, band)
    h, w = v.shape
    x0, y0, dx, dy = m["georef"]
    cx = gt[0] + (np.arange(w) + 0.5) * gt[1]
    cy = gt[3] + (np.arange(h) + 0.5) * gt[5]
    s_cells, t_cells = (cx - x0) / dx, (cy - y0) / dy
    so, to = np.argsort(s_cells), np.argsort(t_cells)
    surf = np.empty((h, w))
    surf[np.ix_(to, so)] = evaluate(m, s_cells[so], t_cells[to])
    err = np.where(ok, np.abs(surf - v), 0.0)
    err[ok & ~np.isfinite(surf)] = np.inf
    worst = float(err.max())
    over = int((err > e).sum())
    print(json.dumps({"file": path, "version": m["version"], "quantised": m["step"] is not None, "step": m["step"],
                      "control_points": int(len(m["z"])), "valid_cells": int(ok.sum()), "E": e, "max_abs_error": worst,
                      "cells_over": over}))
    return 0 if over == 0 else 1


if __name__ == "__main__":
    sys.exit(main())
