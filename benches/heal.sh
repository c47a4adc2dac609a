#!/usr/bin/env bash
# `geofit heal` throughput and harm on every NRW tile and on the largest tile repeated 20 times
# (1500 buildings, ids renamed, copies shifted 2 km), side by side with an earlier binary when
# GEOFIT_BEFORE names one (e.g. a build of the commit before the "do no harm" change).
# Harm is measured independently of geofit's heal code: validation findings per code before vs
# after (`geofit validate`), total surface area and closed solids (tests/scripts/citygml_invariants.py,
# lxml + numpy). Writes benches/results/heal.md.
set -euo pipefail
BIN="${1:?usage: benches/heal.sh path/to/geofit}"
BEFORE="${GEOFIT_BEFORE:-}"
cd "$(dirname "$0")/.."
SHARED="${GEOFIT_SHARED:-../shared}"
OUT="$(mktemp -d)"
trap 'rm -rf "$OUT"' EXIT
res=benches/results/heal.md
mkdir -p benches/results

big=$(ls -S "$SHARED"/fixtures/citygml/nrw/*.gml | head -1)
python3 benches/citygml_copies.py "$big" "$OUT/x20.gml" 20

# Findings per code of a file, as JSON (validate exits 1 when it finds something).
codes() { { "$BIN" -q validate --no-xsd --json "$1" || true; } | python3 -c "
import json, sys, collections
j = json.load(sys.stdin)
print(json.dumps(collections.Counter(str(f['code']) for f in j['geometry']['findings'])))"; }

# One row: file, binary label, binary.
row() {
  local f="$1" label="$2" bin="$3" name t best=999
  name=$(basename "$f" .gml)
  for i in 1 2 3; do
    rm -f "$OUT/h.gml"
    /usr/bin/time -f "%e %M" -o "$OUT/t" "$bin" -q heal "$f" -o "$OUT/h.gml" --report "$OUT/r.json" 2>/dev/null || true
    read -r t rss < <(tail -n 1 "$OUT/t")
    best=$(python3 -c "print(min($best, $t))")
    [ "$name" = x20 ] && break
  done
  [ -s "$OUT/h.gml" ] || { echo "| $name | $label | failed | | | | | | |"; return; }
  codes "$f" > "$OUT/cb.json"
  codes "$OUT/h.gml" > "$OUT/ca.json"
  python3 tests/scripts/citygml_invariants.py "$f" "$OUT/h.gml" > "$OUT/inv.json"
  python3 - "$name" "$label" "$best" "$rss" "$OUT" <<'PY'
import json, sys
name, label, t, rss, out = sys.argv[1], sys.argv[2], float(sys.argv[3]), int(sys.argv[4]), sys.argv[5]
r = json.load(open(f"{out}/r.json"))
inv = json.load(open(f"{out}/inv.json"))
cb, ca = json.load(open(f"{out}/cb.json")), json.load(open(f"{out}/ca.json"))
n = r["buildings"]
healed = r["healed"]
new = sum(max(0, ca[c] - cb.get(c, 0)) for c in ca)
opened = sum(1 for u in inv["units"].values() for b, a in zip(u["before"]["solids"], u["after"]["solids"]) if b["closed"] and not a["closed"])
shrunk = sum(1 for u in inv["units"].values() if abs(u["area_change_rel"] or 0) >= 0.005)
area = 100 * inv["total"]["area_change_rel"]
print(f"| {name} | {label} | {n} | {t:.2f} | {n / max(t, 1e-3):.0f} | {healed} | {area:+.3f} | {new} | {opened} | {shrunk} | {rss // 1024} |")
PY
}

{
  echo "# heal: throughput and harm"
  echo
  echo "Machine: $(nproc) cores, $(uname -m). Release binary; tiles best of 3 runs, ×20 one run."
  echo "Harm columns come from outside heal: validation findings per code that grew (geofit validate),"
  echo "solids closed before and open after and buildings whose area changed by ≥ 0.5 % (lxml/numpy"
  echo "edge-use count and Newell areas, tests/scripts/citygml_invariants.py). \"before\" is the binary"
  echo "in GEOFIT_BEFORE (heal as of commit eceaaaa, before the do-no-harm change), \"now\" this one."
  echo
  echo "| file | binary | buildings | heal s | buildings/s | healed | area change % | new findings | solids opened | buildings ≥0.5 % area change | peak RSS MB |"
  echo "|---|---|---|---|---|---|---|---|---|---|---|"
} > "$res"
for f in "$SHARED"/fixtures/citygml/nrw/*.gml "$OUT/x20.gml"; do
  if [ -n "$BEFORE" ]; then row "$f" before "$BEFORE" | tee -a "$res"; fi
  row "$f" now "$BIN" | tee -a "$res"
done
