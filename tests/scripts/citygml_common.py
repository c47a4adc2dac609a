"""Shared by the independent-truth CityGML scripts (citygml_invariants, citygml_shift,
citygml_extract): GML namespaces and ids, srsDimension lookup, the one-line error convention.
No geofit code: lxml only."""
import argparse
import sys

GML_NS = ("http://www.opengis.net/gml", "http://www.opengis.net/gml/3.2")
GML_ID = tuple("{%s}id" % ns for ns in GML_NS)
XLINK_HREF = "{http://www.w3.org/1999/xlink}href"
UNIT_NAMES = ("Building", "BuildingPart")


class InputError(Exception):
    """Bad or unreadable input: reported as one line on stderr, exit status 2."""


def gml_id(el):
    for a in GML_ID:
        v = el.get(a)
        if v is not None:
            return v
    return None


def srs_dimension(el):
    """srsDimension on `el` (or its `dimension`) or the nearest ancestor; None when none says."""
    e = el
    while e is not None:
        v = e.get("srsDimension")
        if v is None and e is el:
            v = e.get("dimension")
        if v is not None:
            try:
                d = int(v)
            except ValueError:
                raise InputError("bad srsDimension %r (line %s)" % (v, el.sourceline))
            if d < 1:
                raise InputError("bad srsDimension %r (line %s)" % (v, el.sourceline))
            return d
        e = e.getparent()
    return None


def arg_parser(prog, description):
    """An ArgumentParser whose usage errors are one `prog: error: ...` line and exit status 2."""

    class P(argparse.ArgumentParser):
        def error(self, message):
            sys.stderr.write("%s: error: %s\n" % (prog, message))
            sys.exit(2)

    return P(prog=prog, description=description)


def read_bytes(path):
    try:
        with open(path, "rb") as f:
            return f.read()
    except OSError as e:
        raise InputError("cannot read %s: %s" % (path, e.strerror))


def write_bytes(path, data):
    try:
        with open(path, "wb") as f:
            f.write(data)
    except OSError as e:
        raise InputError("cannot write %s: %s" % (path, e.strerror))
