#!/usr/bin/env python3
"""Shift every coordinate of a CityGML/GML file by (DX, DY, DZ), changing nothing else (no geofit code).

Usage:
    citygml_shift.py IN.gml OUT.gml DX DY DZ

Rewritten: the text of every GML (3.1 or 3.2 namespace) posList, pos, coordinates, lowerCorner and
upperCorner element. The dimension of a point is srsDimension on the element or its nearest ancestor
(posList; default 3), the number of values (pos, lowerCorner, upperCorner), or the tuple length
(coordinates, with its cs / ts / decimal attributes). Axis 1 gets DX, axis 2 DY, axis 3 DZ; 2D
points get only DX, DY; further axes are left alone. Everything else (declaration, BOM, comments,
whitespace, separators, attribute order, other elements such as texture coordinates or
transformation matrices) is kept byte for byte: the file is edited as bytes, only the number tokens
inside those elements are replaced.

Arithmetic is exact decimal arithmetic (Python's decimal module); each result is written with as
many decimals as the input number had (an exponent, if any, is kept). So shifting by +d and then by
-d gives back the original bytes whenever d has no more decimals than the numbers (e.g. d with up to
3 decimals on millimetre data; NRW tiles also hold values like "21.7", Teco/KIT files integers, so use
integer shifts for a guaranteed round trip). Numbers that had to be rounded are counted in a warning
on stderr (exit status still 0). A component whose shift is 0 is not touched at all.
Exit status: 0 on success, 2 (one line on stderr) for bad arguments or malformed input.
"""
import decimal
import re
import sys

try:
    from lxml import etree
except ImportError:  # pragma: no cover
    sys.stderr.write("citygml_shift: error: python3 module lxml is required\n")
    sys.exit(2)

from citygml_common import read_bytes, write_bytes, GML_NS, InputError, arg_parser, srs_dimension

NAMES = (b"posList", b"pos", b"coordinates", b"lowerCorner", b"upperCorner")
NAMES_STR = tuple(n.decode() for n in NAMES)

# start tag of one of the coordinate elements (any prefix), or a region to skip
TOKEN_RE = re.compile(
    rb"<!--.*?-->|<!\[CDATA\[.*?\]\]>|<\?.*?\?>"
    rb"|<((?:[A-Za-z_][\w.\-]*:)?(posList|pos|coordinates|lowerCorner|upperCorner))(?=[\s/>])"
    rb"((?:[^>\"']|\"[^\"]*\"|'[^']*')*?)(/?)>",
    re.S,
)
NUM_RE = re.compile(rb"^([+-]?)(\d*)(?:\.(\d*))?([eE][+-]?\d+)?$")

decimal.getcontext().prec = 80
STATS = {"rounded": 0}


def shift_number(tok, delta):
    """tok: bytes of one number; delta: Decimal (non-zero). Returns bytes with the same decimals."""
    m = NUM_RE.match(tok)
    if not m or not (m.group(2) or m.group(3)):
        raise InputError("not a number: %r" % tok.decode("ascii", "replace"))
    decs = len(m.group(3)) if m.group(3) is not None else 0
    has_point = m.group(3) is not None
    exp_txt = m.group(4) or b""
    exp = int(exp_txt[1:]) if exp_txt else 0
    value = decimal.Decimal(tok.decode("ascii")) + delta
    mant = value.scaleb(-exp)
    q = decimal.Decimal(1).scaleb(-decs)
    exact = mant
    mant = mant.quantize(q, rounding=decimal.ROUND_HALF_EVEN)
    if mant != exact:
        STATS["rounded"] += 1
    if mant == 0:
        mant = abs(mant)  # no "-0.000" produced by the shift itself
    s = format(mant, "f")
    if has_point and decs == 0:
        s += "."
    if m.group(2) == b"" and s.startswith(("0.", "-0.")):  # input was like ".5" -> keep that style
        s = s.replace("0.", ".", 1)
    if m.group(1) == b"+" and not s.startswith("-"):
        s = "+" + s
    return s.encode("ascii") + exp_txt


def shift_whitespace_list(content, dim, deltas):
    """content: bytes of whitespace-separated numbers; axis = index % dim."""
    parts = re.split(rb"(\s+)", content)
    out = []
    k = 0
    for p in parts:
        if not p or p.isspace():
            out.append(p)
            continue
        axis = k % dim if dim else k
        k += 1
        d = deltas[axis] if axis < len(deltas) and (axis < 2 or dim >= 3) else None
        out.append(shift_number(p, d) if d else p)
    return b"".join(out), k


def shift_coordinates(content, el, deltas):
    cs = el.get("cs", ",").encode()
    ts = el.get("ts")
    dec = el.get("decimal", ".").encode()
    ts_re = rb"(\s+)" if ts is None or ts.isspace() else b"(" + re.escape(ts.encode()) + b")"
    tuples = re.split(ts_re, content)
    out = []
    for t in tuples:
        if not t.strip() or re.fullmatch(ts_re, t):
            out.append(t)
            continue
        comps = re.split(b"(" + re.escape(cs) + b")", t)
        nums = [c for c in comps if c != cs]
        dim = len(nums)
        axis = 0
        res = []
        for c in comps:
            if c == cs:
                res.append(c)
                continue
            lead = c[: len(c) - len(c.lstrip())]
            trail = c[len(c.rstrip()):]
            core = c.strip()
            d = deltas[axis] if axis < 3 and (axis < 2 or dim >= 3) else None
            if d and core:
                if dec != b".":
                    core = shift_number(core.replace(dec, b"."), d).replace(b".", dec)
                else:
                    core = shift_number(core, d)
            res.append(lead + core + trail)
            axis += 1
        out.append(b"".join(res))
    return b"".join(out)


def shift_bytes(data, deltas):
    try:
        parser = etree.XMLParser(huge_tree=True, resolve_entities=False)
        root = etree.fromstring(data, parser)
    except etree.XMLSyntaxError as e:
        raise InputError("input is not well-formed XML: %s" % e)
    elements = [el for el in root.iter() if isinstance(el.tag, str)
                and el.tag.rsplit("}", 1)[-1] in NAMES_STR]
    out = []
    pos = 0
    idx = 0
    # start after the root start tag is not needed: the XML declaration/comments are skipped by TOKEN_RE
    for m in TOKEN_RE.finditer(data):
        if m.group(1) is None:
            continue  # comment, CDATA or processing instruction
        if idx >= len(elements):
            raise InputError("coordinate element text scan and XML parse disagree (extra %s)" % m.group(1).decode())
        el = elements[idx]
        idx += 1
        if el.tag.rsplit("}", 1)[-1] != m.group(2).decode():
            raise InputError("coordinate element text scan and XML parse disagree at line %s" % el.sourceline)
        if m.group(4) == b"/":
            continue
        ns = el.tag[1:].split("}", 1)[0] if el.tag.startswith("{") else ""
        qname = m.group(1)
        end = data.find(b"</" + qname, m.end())
        if end < 0:
            raise InputError("no end tag for %s (line %s)" % (qname.decode(), el.sourceline))
        if ns not in GML_NS:
            continue
        content = data[m.end():end]
        if b"<" in content or b"&" in content:
            raise InputError("unexpected markup inside %s (line %s)" % (qname.decode(), el.sourceline))
        if content.decode("utf-8", "replace") != (el.text or ""):
            # lxml normalises \r\n to \n; accept that, anything else is a mismatch
            if content.replace(b"\r\n", b"\n").replace(b"\r", b"\n").decode("utf-8", "replace") != (el.text or ""):
                raise InputError("coordinate text mismatch at line %s" % el.sourceline)
        name = m.group(2)
        if name == b"coordinates":
            new = shift_coordinates(content, el, deltas)
        else:
            if name == b"posList":
                dim = srs_dimension(el) or 3
            else:
                dim = len(content.split())
            new, n = shift_whitespace_list(content, dim, deltas)
            if name == b"posList" and n % dim:
                raise InputError("posList with %d numbers is not a multiple of srsDimension %d (line %s)"
                                 % (n, dim, el.sourceline))
        out.append(data[pos:m.end()])
        out.append(new)
        pos = end
    if idx != len(elements):
        raise InputError("coordinate element text scan found %d of %d elements" % (idx, len(elements)))
    out.append(data[pos:])
    return b"".join(out)


def main(argv=None):
    ap = arg_parser("citygml_shift", "Shift all GML coordinates of a file by (DX, DY, DZ), keeping all other bytes.")
    ap.add_argument("input")
    ap.add_argument("output")
    ap.add_argument("dx")
    ap.add_argument("dy")
    ap.add_argument("dz")
    args = ap.parse_args(argv)
    deltas = []
    for name in ("dx", "dy", "dz"):
        v = getattr(args, name)
        try:
            d = decimal.Decimal(v)
        except decimal.InvalidOperation:
            ap.error("%s is not a number: %r" % (name.upper(), v))
        if not d.is_finite():
            ap.error("%s must be finite: %r" % (name.upper(), v))
        deltas.append(d)
    try:
        data = read_bytes(args.input)
        result = shift_bytes(data, deltas)
        write_bytes(args.output, result)
    except InputError as e:
        sys.stderr.write("citygml_shift: error: %s\n" % e)
        return 2
    if STATS["rounded"]:
        sys.stderr.write("citygml_shift: warning: %d number(s) had fewer decimals than the shift and were rounded"
                         " (a reverse shift will not restore them)\n" % STATS["rounded"])
    return 0


if __name__ == "__main__":
    sys.exit(main())
