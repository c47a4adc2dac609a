#!/usr/bin/env bash
# `geofit heal` throughput and harm on every NRW tile and on the largest tile repeated 20 times
# (1500 buildings, ids renamed, copies shifted 2 km), side by side with an earlier binary when
# GEOFIT_BEFORE names one (e.g. a build of the commit before the "do no harm" change).
# Harm is measured independently of geofit's heal code: validation findings per code before vs
# after (`geofit validate`), total surface area and closed solids (tests/scripts/citygml_invariants.py,
# lxml + numpy). Issue 35 adds the share of buildings without any validation finding after heal on
# every shared CityGML fixture (nrw, v2, v3, ogc-*, qie), "before" (GEOFIT_BEFORE) vs "now", from
# `geofit validate` of the healed files. Writes benches/results/heal.md and heal.tsv.
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
    [ "$name" = x20 ] && echo "$label $t" >> "$OUT/x20_times"
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
  echo "Machine: $(nproc) cores, $(uname -m). Binary: $BIN; tiles best of 3 runs, ×20 one run."
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

# Issue 35: share of buildings with no validation finding after heal, every CityGML fixture.
# A building counts as invalid when `geofit validate` names it (or a part of it) in a finding;
# files heal refuses (no building, a geographic CRS) count with their input.
valid_share() {
  local bin="$1" total=0 ok_before=0 ok_after=0
  for f in $(find "$SHARED"/fixtures/citygml/{nrw,v2,v3,ogc-building,ogc-xlink,qie} -name '*.gml' | sort); do
    rm -f "$OUT/v.gml"
    "$bin" -q heal "$f" -o "$OUT/v.gml" 2>/dev/null || cp "$f" "$OUT/v.gml"
    { "$BIN" -q validate --no-xsd --json "$f" || true; } > "$OUT/vb.json"
    { "$BIN" -q validate --no-xsd --json "$OUT/v.gml" || true; } > "$OUT/va.json"
    python3 - "$f" "$OUT/vb.json" "$OUT/va.json" >> "$OUT/share_$2" <<'PY'
import json, sys
from lxml import etree
units = [e for e in etree.parse(sys.argv[1]).iter() if isinstance(e.tag, str) and e.tag.rsplit("}", 1)[-1] in ("Building", "BuildingPart")]
ids = {}
for e in units:
    i = next((v for k, v in e.attrib.items() if k.endswith("}id")), None)
    ids[i] = ids.get(i, 0) + 1
def bad(path):
    try:
        j = json.load(open(path))
    except ValueError:
        return None
    return {f.get("feature") for f in j["geometry"]["findings"]}
b, a = bad(sys.argv[2]), bad(sys.argv[3])
n = len(units)
nb = sum(c for i, c in ids.items() if i not in (b or set()))
na = sum(c for i, c in ids.items() if i not in (a or set()))
print(n, nb, na)
PY
  done
}
: > "$OUT/share_now"; : > "$OUT/share_before"
valid_share "$BIN" now
[ -n "$BEFORE" ] && valid_share "$BEFORE" before
share() { python3 -c "
import sys
rows = [list(map(int, l.split())) for l in open('$1') if l.strip()]
n = sum(r[0] for r in rows); print(n, sum(r[1] for r in rows), sum(r[2] for r in rows))"; }
read -r n vin vnow < <(share "$OUT/share_now")
vbef=""
if [ -n "$BEFORE" ]; then read -r _ _ vbef < <(share "$OUT/share_before"); fi
{
  echo
  echo "## Buildings without any validation finding (issue 35)"
  echo
  echo "Every CityGML fixture under ../shared/fixtures/citygml (nrw, v2, v3, ogc-building, ogc-xlink, qie):"
  echo "$n buildings and parts. A building counts as valid when \`geofit validate\` names neither it nor"
  echo "its id in a finding (parts without ids count with their building)."
  echo
  echo "| binary | valid before heal | valid after heal | share after |"
  echo "|---|---|---|---|"
  if [ -n "$BEFORE" ]; then
    echo "| before | $vin | $vbef | $(python3 -c "print(f'{100*$vbef/$n:.1f} %')") |"
  fi
  echo "| now | $vin | $vnow | $(python3 -c "print(f'{100*$vnow/$n:.1f} %')") |"
} | tee -a "$res"

# Headline figures (issue 39 convention).
tsv=benches/results/heal.tsv
d=$(date -u +%F); c=$(git rev-parse --short HEAD)
x20now=$(awk '$1=="now"{print $2}' "$OUT/x20_times")
x20bef=$(awk '$1=="before"{print $2}' "$OUT/x20_times")
python3 - "$tsv" "$d" "$c" "$x20now" "${x20bef:-}" "$n" "$vnow" "${vbef:-}" <<'PY'
import sys
tsv, d, c, tnow, tbef, n, vnow, vbef = sys.argv[1:9]
rows = ["benchmark\tfigure\tunit\tpeer\tpeer_figure\tratio\tdate\tcommit"]
now = 1500 / max(float(tnow), 1e-3)
if tbef:
    bef = 1500 / max(float(tbef), 1e-3)
    rows.append(f"heal NRW tile x20 (1500 buildings)\t{now:.0f}\tbuildings/s\tgeofit before issue 35\t{bef:.0f}\t{now / bef:.2f}\t{d}\t{c}")
else:
    rows.append(f"heal NRW tile x20 (1500 buildings)\t{now:.0f}\tbuildings/s\t-\t-\t-\t{d}\t{c}")
share = 100 * int(vnow) / int(n)
if vbef:
    sb = 100 * int(vbef) / int(n)
    rows.append(f"buildings valid after heal (all CityGML fixtures)\t{share:.1f}\t%\tgeofit before issue 35\t{sb:.1f}\t{share / sb:.2f}\t{d}\t{c}")
else:
    rows.append(f"buildings valid after heal (all CityGML fixtures)\t{share:.1f}\t%\t-\t-\t-\t{d}\t{c}")
open(tsv, "w").write("\n".join(rows) + "\n")
PY
