#!/usr/bin/env python3
"""Per-building byte comparison of a tiled run against whole-file runs (no geofit code).

Usage:
    scaleout_buildings.py --whole W1.gml [W2.gml ...] --tiled T1.gml [T2.gml ...]

A building's text is the exact byte span of its member element (core:cityObjectMember or
gml:featureMember, a child of the root) as found by citygml_extract.py's tag scanner; lxml parses
each file independently and must find the same members, and gives each member's id (the gml:id
of its top-level object). Only members whose object holds a Building or BuildingPart count.

Prints one JSON line: {"whole": n, "tiled": n, "equal": n, "missing": [...], "extra": [...],
"different": [...], "duplicates": [...]}. Exit 0 when it could compare (the caller judges), 2 on
unreadable input.
"""
import argparse
import json
import os
import sys

sys.path.insert(0, os.path.dirname(os.path.abspath(__file__)))
from lxml import etree  # noqa: E402
from citygml_extract import member_spans, local  # noqa: E402
from citygml_common import gml_id, UNIT_NAMES  # noqa: E402


def buildings(path):
    """{gml:id: member bytes} of the building members of a file, and the ids seen twice."""
    data = open(path, "rb").read()
    spans = member_spans(data)
    root = etree.fromstring(data, etree.XMLParser(huge_tree=True, remove_blank_text=False))
    members = [m for m in root if isinstance(m.tag, str) and local(m.tag) in ("cityObjectMember", "featureMember")]
    if len(members) != len(spans):
        raise SystemExit("%s: lxml finds %d members, the tag scanner %d" % (path, len(members), len(spans)))
    out, dup = {}, []
    for (start, end, _), m in zip(spans, members):
        obj = next((c for c in m if isinstance(c.tag, str)), None)
        if obj is None or not any(local(e.tag) in UNIT_NAMES for e in obj.iter() if isinstance(e.tag, str)):
            continue
        key = gml_id(obj) or "%s@%d" % (os.path.basename(path), start)
        if key in out:
            dup.append(key)
        out[key] = data[start:end]
    return out, dup


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--whole", nargs="+", required=True)
    ap.add_argument("--tiled", nargs="+", required=True)
    a = ap.parse_args()
    whole, tiled, dups = {}, {}, []
    for group, paths in ((whole, a.whole), (tiled, a.tiled)):
        for p in paths:
            b, d = buildings(p)
            dups += d + [k for k in b if k in group]
            group.update(b)
    equal = sorted(k for k in whole if k in tiled and whole[k] == tiled[k])
    print(json.dumps({
        "whole": len(whole),
        "tiled": len(tiled),
        "equal": len(equal),
        "missing": sorted(k for k in whole if k not in tiled),
        "extra": sorted(k for k in tiled if k not in whole),
        "different": sorted(k for k in whole if k in tiled and whole[k] != tiled[k]),
        "duplicates": sorted(set(dups)),
    }))


if __name__ == "__main__":
    main()
