#!/usr/bin/env python3
"""W3C Canonical XML comparison of two XML files with lxml (independent of geofit).

Usage: citygml_c14n.py A B
Prints a JSON object:
  {"equal": bool,            # C14N(A) == C14N(B) byte for byte
   "structure_equal": bool,  # same elements, attributes, namespaces, order, and all text
                             # outside the differing nodes
   "text_diffs": [{"line": L, "tag": "{ns}local", "a": text, "b": text}, ...]}
`text_diffs` lists the elements whose text differs (line = sourceline in A); any other
difference (tags, attributes, tails, comments, namespaces) makes structure_equal false.
"""
import json
import sys

from lxml import etree


def load(path):
    parser = etree.XMLParser(remove_blank_text=False, resolve_entities=False, huge_tree=True)
    return etree.parse(path, parser)


def main(a_path, b_path):
    a, b = load(a_path), load(b_path)
    ca = etree.tostring(a, method="c14n")
    cb = etree.tostring(b, method="c14n")
    out = {"equal": ca == cb, "structure_equal": True, "text_diffs": []}
    ea, eb = list(a.getroot().iter()), list(b.getroot().iter())
    if len(ea) != len(eb):
        out["structure_equal"] = False
    else:
        for x, y in zip(ea, eb):
            if x.tag != y.tag or dict(x.attrib) != dict(y.attrib) or x.tail != y.tail or x.nsmap != y.nsmap:
                out["structure_equal"] = False
                out.setdefault("other", []).append({"line": x.sourceline, "tag": str(x.tag)})
            if x.text != y.text:
                out["text_diffs"].append({"line": x.sourceline, "tag": str(x.tag), "a": x.text, "b": y.text})
    json.dump(out, sys.stdout)
    print()


if __name__ == "__main__":
    main(sys.argv[1], sys.argv[2])
