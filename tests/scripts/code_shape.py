#!/usr/bin/env python3
"""Library code shape (issue 39): files over 800 lines outside their test modules, and functions
over 100 lines, in crates/*/src. A function's length runs from its `fn` line to its closing brace
(braces counted outside strings, chars and comments). Prints one line per offender; with
--check exits 1 when there is one. Usage: python3 tests/scripts/code_shape.py [--check]"""
import pathlib
import re
import sys

ROOT = pathlib.Path(__file__).resolve().parents[2]
MAX_FILE, MAX_FN = 800, 100
FN = re.compile(r"^\s*(pub(\([^)]*\))?\s+)?(const\s+)?(async\s+)?(unsafe\s+)?(extern\s+\"C\"\s+)?fn\s+(\w+)")


def code_only(line, state):
    """The line without comments and string/char contents; state carries an open block comment."""
    out, i = [], 0
    while i < len(line):
        if state["block"]:
            j = line.find("*/", i)
            if j < 0:
                return "".join(out)
            state["block"], i = False, j + 2
            continue
        c = line[i]
        if line.startswith("//", i):
            break
        if line.startswith("/*", i):
            state["block"], i = True, i + 2
            continue
        if c == '"':
            j = i + 1
            while j < len(line) and line[j] != '"':
                j += 2 if line[j] == "\\" else 1
            i = j + 1
            continue
        if c == "'" and re.match(r"'(\\.|[^\\'])'", line[i:]):
            i += len(re.match(r"'(\\.|[^\\'])'", line[i:]).group(0))
            continue
        out.append(c)
        i += 1
    return "".join(out)


def shape(path):
    lines = path.read_text(encoding="utf-8").splitlines()
    test_at = next((k for k, l in enumerate(lines) if l.strip() == "#[cfg(test)]"), len(lines))
    found = []
    if test_at > MAX_FILE:
        found.append(f"{path.relative_to(ROOT)}: {test_at} lines outside tests (max {MAX_FILE})")
    state, stack, depth = {"block": False}, [], 0
    for k, raw in enumerate(lines[:test_at]):
        m = FN.match(raw)
        code = code_only(raw, state)
        if m and "{" in code:
            stack.append((m.group(7), k, depth))
        for ch in code:
            if ch == "{":
                depth += 1
            elif ch == "}":
                depth -= 1
                while stack and depth == stack[-1][2]:
                    name, start, _ = stack.pop()
                    if k - start + 1 > MAX_FN:
                        found.append(f"{path.relative_to(ROOT)}:{start + 1}: fn {name} is {k - start + 1} lines (max {MAX_FN})")
    return found


def main():
    found = [f for p in sorted(ROOT.glob("crates/*/src/**/*.rs")) for f in shape(p)]
    print("\n".join(found) or "code shape: no file or function over the limits")
    if "--check" in sys.argv and found:
        sys.exit(1)


if __name__ == "__main__":
    main()
