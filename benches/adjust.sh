#!/usr/bin/env bash
# Adjustment time and peak memory versus problem size (issue 4 bench): one building (the
# three-storey fixture), the largest NRW tile, and synthetic cities of box buildings up to 10^5
# planes (target: the 10^5-plane adjustment in < 10 s on 2 cores). Conversion (citygml2popa3d) is
# timed separately, the figure that counts is `geofit adjust`.
# Usage: benches/adjust.sh path/to/geofit   (writes benches/results/adjust.md)
set -euo pipefail
BIN="${1:?usage: adjust.sh path/to/geofit}"
cd "$(dirname "$0")/.."
TMP="$(mktemp -d)"
trap 'rm -rf "$TMP"' EXIT
OUT=benches/results/adjust.md
mkdir -p benches/results
measure() { # label file.popa3d
  local label="$1" in="$2"
  /usr/bin/time -f "%e %M" -o "$TMP/t" "$BIN" adjust -q "$in" -o "$TMP/out.popa3d" --report "$TMP/r.json" 2>/dev/null || true
  read -r secs kb < "$TMP/t"
  python3 - "$label" "$secs" "$kb" "$TMP/r.json" "$in" <<'PY' | tee -a "$OUT"
import json, sys, re
label, secs, kb, rep, src = sys.argv[1:6]
r = json.load(open(rep))
planes = open(src).read().count("<plane ")
print(f"| {label} | {planes} | {r['unknowns']} | {r['conditions']} | {r['components']} | {r['iterations']} | {float(secs):.2f} | {int(kb)/1024:.0f} |")
PY
}
{
  echo "# adjust benchmark"
  echo
  echo "\`geofit adjust\` (free datum, full statistics incl. redundancy numbers) on $(nproc) cores, $(date -u +%F)."
  echo
  echo "| problem | planes | unknowns | conditions | components | iterations | adjust time (s) | peak memory (MiB) |"
  echo "|---|---|---|---|---|---|---|---|"
} > "$OUT"
"$BIN" citygml2popa3d -q fixtures/citygml/three_storey.gml -o "$TMP/b.popa3d"
measure "three-storey building (spec §8.2)" "$TMP/b.popa3d"
NRW=../shared/fixtures/citygml/nrw/LoD2_32_332_5729_1_NW.gml
if [ -f "$NRW" ]; then
  "$BIN" citygml2popa3d -q "$NRW" -o "$TMP/nrw.popa3d" || true
  [ -s "$TMP/nrw.popa3d" ] && measure "NRW tile LoD2_32_332_5729_1_NW" "$TMP/nrw.popa3d"
fi
python3 benches/adjust_city.py 100 > "$TMP/city.gml"
"$BIN" citygml2popa3d -q "$TMP/city.gml" -o "$TMP/city.popa3d"
measure "synthetic city, 100 box buildings (via citygml2popa3d)" "$TMP/city.popa3d"
# The 10^5-plane problem is built in memory by the engine example (citygml2popa3d of 16667
# buildings is the conversion's own benchmark, not this one's).
CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-/root/.cache/geofit/target}" cargo build -q --release -p adjust --example city_bench
EX="${CARGO_TARGET_DIR:-/root/.cache/geofit/target}/release/examples/city_bench"
{
  echo
  echo "Engine alone (\`crates/adjust/examples/city_bench.rs\`: box buildings, 6 planes, 3 normals / 9 parameters each,"
  echo "sketch priors, relative angles, unit-norm restrictions, laser distances, weak identity observations; full statistics):"
  echo
  echo "| buildings | planes | wall time incl. build (s) | peak memory (MiB) | engine output |"
  echo "|---|---|---|---|---|"
} >> "$OUT"
for n in 100 1667 16667; do
  /usr/bin/time -f "%e %M" -o "$TMP/t" "$EX" "$n" > "$TMP/o"
  read -r secs kb < "$TMP/t"
  echo "| $n | $((6 * n)) | $secs | $((kb / 1024)) | $(cat "$TMP/o") |" | tee -a "$OUT"
done
echo >> "$OUT"
echo "Target: 10^5 planes (16667 buildings) adjusted in < 10 s on 2 cores." >> "$OUT"
cat "$OUT"
