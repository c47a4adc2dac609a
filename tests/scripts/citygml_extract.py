#!/usr/bin/env python3
"""Cut a CityGML file down to some top-level city objects, keeping their bytes exactly (no geofit code).

Usage:
    citygml_extract.py IN.gml OUT.gml ID [ID...]

A "member" is a child of the root element whose local name is cityObjectMember or featureMember
(any namespace: CityGML 1.0 / 2.0 core:cityObjectMember, CityGML 3.0 core:cityObjectMember,
gml:featureMember). A member is kept when its top-level object has one of the given gml:ids (GML 3.1
or 3.2), or contains a Building or BuildingPart with one of them (so a BuildingPart id keeps its whole
parent building). All other members are cut out together with the whitespace in front of them.
Everything else (XML declaration, BOM, root start/end tag, gml:boundedBy - NOT recomputed -,
appearanceMembers, comments) stays byte for byte, and so do the kept members.

The file is spliced as bytes: a small tag scanner finds the byte span of every member (skipping
comments, CDATA and processing instructions) and lxml checks that it found the same members.
A warning on stderr lists xlink:hrefs of kept members that point into removed members.
Exit status: 0 on success, 2 (one line on stderr) for bad arguments, malformed input or an ID that
matches no member.
"""
import re
import sys

try:
    from lxml import etree
except ImportError:  # pragma: no cover
    sys.stderr.write("citygml_extract: error: python3 module lxml is required\n")
    sys.exit(2)

from citygml_common import read_bytes, write_bytes, UNIT_NAMES, XLINK_HREF, InputError, arg_parser, gml_id

MEMBER_NAMES = ("cityObjectMember", "featureMember")

SCAN_RE = re.compile(
    rb"<!--.*?-->|<!\[CDATA\[.*?\]\]>|<\?.*?\?>|<!DOCTYPE(?:[^\[>]|\[.*?\])*>"
    rb"|<(/?)([^\s/>!?]+)((?:[^>\"']|\"[^\"]*\"|'[^']*')*?)(/?)>",
    re.S,
)


def local(tag):
    return tag.rsplit("}", 1)[-1] if isinstance(tag, str) else None


def member_spans(data):
    """Byte spans (start, end, local name) of the element children of the root with a member name."""
    depth = 0
    spans = []
    cur = None
    for m in SCAN_RE.finditer(data):
        if m.group(2) is None:
            continue
        closing, qname, selfclose = m.group(1) == b"/", m.group(2), m.group(4) == b"/"
        name = qname.split(b":")[-1].decode("utf-8", "replace")
        if closing:
            depth -= 1
            if depth == 1 and cur is not None:
                spans.append((cur[0], m.end(), cur[1]))
                cur = None
            continue
        if depth == 1 and name in MEMBER_NAMES:
            if selfclose:
                spans.append((m.start(), m.end(), name))
            else:
                cur = (m.start(), name)
        if not selfclose:
            depth += 1
    if depth != 0:
        raise InputError("tag scan ended at depth %d (unbalanced tags?)" % depth)
    return spans


def ids_of_member(member):
    ids = set()
    for child in member:
        if not isinstance(child.tag, str):
            continue
        i = gml_id(child)
        if i is not None:
            ids.add(i)
        for el in child.iter():
            if local(el.tag) in UNIT_NAMES:
                i = gml_id(el)
                if i is not None:
                    ids.add(i)
    return ids


def extract(data, wanted):
    try:
        parser = etree.XMLParser(huge_tree=True, resolve_entities=False)
        root = etree.fromstring(data, parser)
    except etree.XMLSyntaxError as e:
        raise InputError("input is not well-formed XML: %s" % e)
    members = [c for c in root if local(c.tag) in MEMBER_NAMES]
    spans = member_spans(data)
    if len(spans) != len(members) or any(local(m.tag) != s[2] for m, s in zip(members, spans)):
        raise InputError("tag scan found %d members, the XML parser %d" % (len(spans), len(members)))
    keep = []
    found = set()
    for m in members:
        ids = ids_of_member(m)
        hit = ids & wanted
        found |= hit
        keep.append(bool(hit))
    missing = [i for i in wanted if i not in found]
    if missing:
        raise InputError("no cityObjectMember/featureMember holds gml:id %s" % ", ".join(sorted(missing)))
    # dangling references (informational)
    kept_ids, removed_ids = set(), set()
    for m, k in zip(members, keep):
        for el in m.iter():
            if isinstance(el.tag, str):
                i = gml_id(el)
                if i is not None:
                    (kept_ids if k else removed_ids).add(i)
    dangling = set()
    for m, k in zip(members, keep):
        if not k:
            continue
        for el in m.iter():
            if isinstance(el.tag, str):
                h = el.get(XLINK_HREF)
                if h and h.startswith("#") and h[1:] in removed_ids and h[1:] not in kept_ids:
                    dangling.add(h)
    out = []
    pos = 0
    for (start, end, _), k in zip(spans, keep):
        if k:
            continue
        cut = start
        while cut > pos and data[cut - 1:cut] in (b" ", b"\t", b"\r", b"\n"):
            cut -= 1
        out.append(data[pos:cut])
        pos = end
    out.append(data[pos:])
    return b"".join(out), sum(keep), len(members), sorted(dangling)


def main(argv=None):
    ap = arg_parser("citygml_extract", "Keep only the cityObjectMembers holding the given gml:ids, byte-exact.")
    ap.add_argument("input")
    ap.add_argument("output")
    ap.add_argument("ids", nargs="+", metavar="ID")
    args = ap.parse_args(argv)
    try:
        data = read_bytes(args.input)
        result, kept, total, dangling = extract(data, set(args.ids))
        write_bytes(args.output, result)
    except InputError as e:
        sys.stderr.write("citygml_extract: error: %s\n" % e)
        return 2
    if dangling:
        sys.stderr.write("citygml_extract: warning: %d xlink:href(s) of kept members point into removed members: %s\n"
                         % (len(dangling), " ".join(dangling[:10])))
    sys.stderr.write("citygml_extract: kept %d of %d members\n" % (kept, total))
    return 0


if __name__ == "__main__":
    sys.exit(main())
