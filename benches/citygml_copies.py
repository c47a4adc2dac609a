#!/usr/bin/env python3
"""A CityGML tile repeated K times as distinct buildings side by side: every copy gets its own
gml:ids (suffix _<copy>, XLinks renamed with them) and is shifted 2 km east per copy, so a file of
K times the size holds K times the buildings, as a real larger tile would.
Usage: citygml_copies.py TILE.gml OUT.gml K   (NRW tiles: core:cityObjectMember, gml:posList)"""
import re
import sys


def shift(t, dx):
    def f(m):
        v = m.group(2).split()
        return m.group(1) + b" ".join(b"%.3f" % (float(x) + dx) if i % 3 == 0 else x for i, x in enumerate(v)) + b"<"
    return re.sub(rb"(<gml:posList[^>]*>)([^<]*)<", f, t)


def main(tile, out, k):
    s = open(tile, "rb").read()
    a = s.index(b"<core:cityObjectMember>")
    b = s.rindex(b"</core:cityObjectMember>") + len(b"</core:cityObjectMember>")
    parts = []
    for c in range(k):
        t = re.sub(rb'gml:id="([^"]+)"', lambda m: b'gml:id="' + m.group(1) + b"_%d" % c + b'"', s[a:b])
        t = re.sub(rb'xlink:href="#([^"]+)"', lambda m: b'xlink:href="#' + m.group(1) + b"_%d" % c + b'"', t)
        parts.append(shift(t, 2000.0 * c))
    open(out, "wb").write(s[:a] + b"".join(parts) + s[b:])


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2], int(sys.argv[3]))
