#!/usr/bin/env python3
"""Recompute a merged `geofit tile report` from the per-tile reports (no geofit code).

Usage:
    scaleout_report.py MERGED.json --heal H1.json ... --validate V1.json ...

Sums, independently of geofit: buildings, healed, kept (as (tile, building, reason) triples),
areas (relative 1e-12), findings per code before/after heal, validate findings per code,
features, valid files; the largest vertex move. The tile id of a report is its file name up to
the first dot. Prints one JSON line {"checked": n, "mismatches": [...]}.
"""
import argparse
import collections
import json
import os


def tile_of(path):
    return os.path.basename(path).split(".")[0]


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("merged")
    ap.add_argument("--heal", nargs="*", default=[])
    ap.add_argument("--validate", nargs="*", default=[])
    a = ap.parse_args()
    m = json.load(open(a.merged))
    bad, checked = [], 0

    def same(what, got, want, rel=None):
        nonlocal checked
        checked += 1
        ok = abs(got - want) <= rel * max(abs(want), 1e-300) if rel is not None else got == want
        if not ok:
            bad.append({"what": what, "merged": got, "sum": want})

    heals = [(tile_of(p), json.load(open(p))) for p in a.heal]
    vals = [(tile_of(p), json.load(open(p))) for p in a.validate]
    h = m["heal"]
    same("heal.reports", h["reports"], len(heals))
    same("heal.buildings", h["buildings"], sum(r["buildings"] for _, r in heals))
    same("heal.healed", h["healed"], sum(r["healed"] for _, r in heals))
    same("heal.kept", sorted((k["tile"], k["building"], k["reason"]) for k in h["kept"]),
         sorted((t, k["building"], k["reason"]) for t, r in heals for k in r["kept"]))
    same("heal.area_before_m2", h["area_before_m2"], sum(r["area_before_m2"] for _, r in heals), 1e-12)
    same("heal.area_after_m2", h["area_after_m2"], sum(r["area_after_m2"] for _, r in heals), 1e-12)
    for key in ("findings_before", "findings_after"):
        c = collections.Counter()
        for _, r in heals:
            c.update({str(k): v for k, v in r[key].items()})
        same("heal." + key, {k: v for k, v in h[key].items()}, dict(c))
    same("heal.max_move_m", h["max_move_m"], max([r["back"]["max_move"] for _, r in heals] or [0.0]))
    v = m["validate"]
    same("validate.reports", v["reports"], len(vals))
    same("validate.valid", v["valid"], sum(1 for _, r in vals if r["valid"]))
    same("validate.features", v["features"], sum(r["geometry"]["features"] for _, r in vals))
    codes = collections.Counter(str(f["code"]) for _, r in vals for f in r["geometry"]["findings"])
    same("validate.findings_by_code", v["findings_by_code"], dict(codes))
    same("tiles", m["tiles"], len({t for t, _ in heals} | {t for t, _ in vals}))
    print(json.dumps({"checked": checked, "mismatches": bad}))


if __name__ == "__main__":
    main()
