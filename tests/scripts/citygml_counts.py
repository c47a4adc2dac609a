#!/usr/bin/env python3
"""Independent counts of CityGML files with Python's xml.etree (no geofit code involved).

Usage: citygml_counts.py FILE...   -> one JSON object per file on stdout (a JSON list).

Counted: the CityGML version from the root element's namespace; Building / BuildingPart
elements; gml:Solid elements; gml:Polygon elements (definitions; TIN triangles are not
polygons); their gml:LinearRings and positions; xlink:href attributes of geometry members
(gml:surfaceMember, gml:baseSurface, ...). These are the figures `geofit info --json` reports.
"""
import json
import re
import sys
import xml.etree.ElementTree as ET

XLINK = "{http://www.w3.org/1999/xlink}href"
GML_NS = ("http://www.opengis.net/gml", "http://www.opengis.net/gml/3.2")


def split(tag):
    m = re.match(r"\{(.*)\}(.*)", tag)
    return (m.group(1), m.group(2)) if m else ("", tag)


def version_of(ns):
    m = re.match(r"http://www\.opengis\.net/citygml/(\d\.\d)$", ns)
    return m.group(1) if m else None


def ring_positions(ring, dim_hint):
    n = 0
    for el in ring.iter():
        ns, local = split(el.tag)
        if ns not in GML_NS:
            continue
        text = (el.text or "").split()
        if local == "posList":
            d = int(el.get("srsDimension") or dim_hint or 3)
            n += len(text) // d
        elif local == "pos":
            n += 1
        elif local == "coordinates":
            n += len(text)
    return n


def counts(path):
    root = ET.parse(path).getroot()
    ns, local = split(root.tag)
    c = {
        "file": path,
        "version": version_of(ns),
        "buildings": 0,
        "building_parts": 0,
        "solids": 0,
        "polygons": 0,
        "rings": 0,
        "interior_rings": 0,
        "points": 0,
        "xlinks": 0,
    }
    for el in root.iter():
        ns, local = split(el.tag)
        if local == "Building" and "citygml" in ns:
            c["buildings"] += 1
        elif local == "BuildingPart" and "citygml" in ns:
            c["building_parts"] += 1
        if ns in GML_NS:
            if local == "Solid":
                c["solids"] += 1
            elif local == "Polygon":
                c["polygons"] += 1
                for prop in el:
                    pns, plocal = split(prop.tag)
                    for ring in prop:
                        rns, rlocal = split(ring.tag)
                        if rlocal == "LinearRing":
                            c["rings"] += 1
                            if plocal in ("interior", "innerBoundaryIs"):
                                c["interior_rings"] += 1
                            c["points"] += ring_positions(ring, None)
            if el.get(XLINK) is not None and local in ("surfaceMember", "baseSurface"):
                c["xlinks"] += 1
    return c


if __name__ == "__main__":
    json.dump([counts(p) for p in sys.argv[1:]], sys.stdout, indent=1)
    print()
