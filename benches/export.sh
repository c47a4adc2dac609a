#!/usr/bin/env bash
# `geofit export`: wall time and peak memory on the largest NRW tile (and a ~24 MB tile of its
# buildings repeated ×20), per output format, side by side with `geofit info` on the same file
# (read + parse + walk: the floor every export pays before triangulating and writing).
# Writes benches/results/export.md. Usage: benches/export.sh path/to/geofit
set -euo pipefail
BIN="${1:?usage: export.sh path/to/geofit}"
cd "$(dirname "$0")/.."
SHARED="${GEOFIT_SHARED:-../shared}"
TILE="$SHARED/fixtures/citygml/nrw/LoD2_32_332_5729_1_NW.gml"
[ -f "$TILE" ] || { echo "export bench: $TILE missing, skipped"; exit 0; }
OUT=benches/results/export.md
REPEAT=${REPEAT:-5}
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT

# The members of the tile repeated (every XLink of an NRW building points into itself).
python3 - "$TILE" "$TMP/nrw_x20.gml" <<'PY'
import sys
s = open(sys.argv[1], "rb").read()
a = s.index(b"<core:cityObjectMember>")
b = s.rindex(b"</core:cityObjectMember>") + len(b"</core:cityObjectMember>")
open(sys.argv[2], "wb").write(s[:a] + s[a:b] * 20 + s[b:])
PY

# best wall time in ms of $REPEAT runs
best_ms() {
  local best=""
  for _ in $(seq "$REPEAT"); do
    local t0 t1
    t0=$(date +%s%N); "$@" >/dev/null 2>&1 || true; t1=$(date +%s%N)
    local ms=$(( (t1 - t0) / 1000000 ))
    if [ -z "$best" ] || [ "$ms" -lt "$best" ]; then best=$ms; fi
  done
  echo "$best"
}
peak() { /usr/bin/time -f '%M' "$@" 2>&1 >/dev/null | tail -1 | awk '{printf "%.1f", $1/1024}'; }

{
  echo "# geofit export: time and memory"
  echo
  echo "Machine: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ *//'); load average $(cut -d' ' -f1-3 /proc/loadavg)."
  echo "Release binary, best of $REPEAT runs, file in the page cache. *info* = \`geofit info\` on the same file"
  echo "(read + parse + walk, the floor of any export). Peak RSS with \`/usr/bin/time -f %M\`, one run."
  echo
  echo "| file | MB | polygons | triangles | info ms | glb ms | gltf ms | obj ms | glb / info | RSS info MiB | RSS glb MiB |"
  echo "|---|---|---|---|---|---|---|---|---|---|---|"
  for f in "$TILE" "$TMP/nrw_x20.gml"; do
    size=$(stat -c %s "$f")
    "$BIN" -q export "$f" -o "$TMP/r.glb" --report "$TMP/r.json"
    polys=$(python3 -c "import json;print(json.load(open('$TMP/r.json'))['polygons'])")
    tris=$(python3 -c "import json;print(json.load(open('$TMP/r.json'))['triangles'])")
    ti=$(best_ms "$BIN" -q info "$f")
    tg=$(best_ms "$BIN" -q export "$f" -o "$TMP/o.glb")
    tt=$(best_ms "$BIN" -q export "$f" -o "$TMP/o.gltf")
    to=$(best_ms "$BIN" -q export "$f" -o "$TMP/o.obj")
    ratio=$(awk -v a="$tg" -v b="$ti" 'BEGIN{ if (b>0) printf "%.1f×", a/b; else print "n/a" }')
    ri=$(peak "$BIN" -q info "$f"); rg=$(peak "$BIN" -q export "$f" -o "$TMP/o.glb")
    name=${f#"$SHARED/fixtures/"}; [ "$f" = "$TMP/nrw_x20.gml" ] && name="nrw/LoD2_32_332_5729 members ×20 (synthetic)"
    printf '| %s | %.2f | %s | %s | %s | %s | %s | %s | %s | %s | %s |\n' \
      "$name" "$(echo "$size/1000000" | bc -l)" "$polys" "$tris" "$ti" "$tg" "$tt" "$to" "$ratio" "$ri" "$rg"
  done
} | tee "$OUT.tmp"
# Keep the hand-written notes below the generated table (build cost of proj, etc.).
if [ -f "$OUT" ] && grep -q '^## Notes' "$OUT"; then
  sed -n '/^## Notes/,$p' "$OUT" > "$TMP/notes"
  { cat "$OUT.tmp"; echo; cat "$TMP/notes"; } > "$OUT"
  rm -f "$OUT.tmp"
else
  mv "$OUT.tmp" "$OUT"
fi
