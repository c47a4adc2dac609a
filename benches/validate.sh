#!/usr/bin/env bash
# Validation time on the largest NRW LoD2 tile: geofit validate (XSD + geometry, XSD alone,
# geometry alone) side by side with xmllint --schema (the reference for the XSD part); then the
# whole CityGML fixture set (66 files) in ONE `geofit validate DIR` call vs one xmllint --schema
# call per file vs one geofit process per file (wall and CPU time).
# Writes benches/results/validate.md. Usage: benches/validate.sh path/to/geofit
set -euo pipefail
BIN="${1:?usage: validate.sh path/to/geofit}"
cd "$(dirname "$0")/.."
SHARED="${GEOFIT_SHARED:-../shared}"
NRW="$SHARED/fixtures/citygml/nrw"
XSD="$SHARED/xsd/citygml-1.0.xsd"
[ -d "$NRW" ] || { echo "validate bench: $NRW missing, skipped"; exit 0; }
FILE=$(ls -S "$NRW"/*.gml | head -1)
RUNS=${RUNS:-7}
OUT=benches/results/validate.md

# median wall time (s) of RUNS runs of "$@" (exit status 0/1 both fine: findings are not failures)
median() {
  local ts=()
  for _ in $(seq "$RUNS"); do
    local t0 t1
    t0=$(date +%s.%N)
    "$@" >/dev/null 2>&1 || true
    t1=$(date +%s.%N)
    ts+=("$(echo "$t1 - $t0" | bc -l)")
  done
  printf '%s\n' "${ts[@]}" | sort -g | awk '{a[NR]=$1} END{printf "%.3f", a[int((NR+1)/2)]}'
}
# peak resident memory (MiB) of one run
peak() {
  if [ -x /usr/bin/time ]; then
    local f
    f=$(mktemp)
    /usr/bin/time -o "$f" -f '%M' "$@" >/dev/null 2>&1 || true
    tail -1 "$f" | awk '{printf "%.1f", $1/1024}'
    rm -f "$f"
  else
    echo "n/a"
  fi
}

SIZE=$(stat -c %s "$FILE")
read -r FEATURES FINDINGS < <("$BIN" -q validate --json --no-xsd "$FILE" 2>/dev/null | python3 -c 'import json,sys; r=json.load(sys.stdin); print(r["geometry"]["features"], len(r["geometry"]["findings"]))' || echo "? ?")
POLYS=$(grep -c '<gml:Polygon' "$FILE" || true)

T_START=$(median "$BIN" --version)
T_FULL=$(median "$BIN" -q validate "$FILE")
T_GEOM=$(median "$BIN" -q validate --no-xsd "$FILE")
T_XSD=$(median "$BIN" -q validate --no-geometry "$FILE")
M_FULL=$(peak "$BIN" -q validate "$FILE")
if command -v xmllint >/dev/null && [ -f "$XSD" ]; then
  T_LINT=$(median xmllint --noout --nonet --schema "$XSD" "$FILE")
  M_LINT=$(peak xmllint --noout --nonet --schema "$XSD" "$FILE")
else
  T_LINT="n/a"; M_LINT="n/a"
fi
# the whole NRW set in one go (6 tiles, one process each)
T_ALL=$(median bash -c "for f in $NRW/*.gml; do $BIN -q validate \"\$f\" >/dev/null 2>&1 || true; done")

{
  echo "# geofit validate — benchmark"
  echo
  echo "Machine: $(nproc) cores, $(uname -sr). Binary: release. Median of $RUNS runs, wall clock."
  echo
  echo "Input: \`$(basename "$FILE")\` (largest NRW LoD2 tile, CityGML 1.0): $SIZE bytes, $FEATURES top-level features, $POLYS gml:Polygon elements; $FINDINGS geometric findings at the default tolerances."
  echo
  echo "| what | geofit | reference |"
  echo "|---|---|---|"
  echo "| XSD + geometry (\`validate FILE\`), s | $T_FULL | – |"
  echo "| geometry only (\`--no-xsd\`), s | $T_GEOM | – |"
  echo "| XSD only (\`--no-geometry\`), s / xmllint --schema, s | $T_XSD | $T_LINT |"
  echo "| peak RSS, MiB (full / xmllint) | $M_FULL | $M_LINT |"
  echo "| all 6 NRW tiles, one process each, s | $T_ALL | – |"
  echo "| process start-up (\`geofit --version\`: dynamic GDAL/PROJ/OpenCL libraries), s | $T_START | – |"
  echo
  echo "The XSD time is dominated by parsing the CityGML 1.0 schema set (done once per run, as in xmllint,"
  echo "with the same libxml2); the geometric checks run on their own threads meanwhile, so a full run costs"
  echo "about start-up + max(XSD, geometry). Subtract the start-up row to compare with xmllint."
} > "$OUT"

# ---- the whole fixture set: one process vs one process per file ----
SET="$SHARED/fixtures/citygml"
RUNS_SET=${RUNS_SET:-3}
mapfile -t SET_FILES < <(find "$SET" -type f \( -name '*.gml' -o -name '*.xml' -o -name '*.citygml' \) | sort)
SET_BYTES=$(cat "${SET_FILES[@]}" | wc -c)
# "wall user+sys" (s) of one run of "$@", findings are not failures
wall_cpu() {
  local f
  f=$(mktemp)
  /usr/bin/time -o "$f" -f '%e %U %S' "$@" >/dev/null 2>&1 || true
  tail -1 "$f" | awk '{printf "%.2f %.2f", $1, $2 + $3}'
  rm -f "$f"
}
# median over RUNS_SET runs, by wall time: "wall cpu"
median_wall_cpu() {
  for _ in $(seq "$RUNS_SET"); do wall_cpu "$@"; echo; done | sort -g | awk '{a[NR]=$0} END{print a[int((NR+1)/2)]}'
}
xmllint_each() {
  local f v
  for f in "${SET_FILES[@]}"; do
    v=$(head -c 20000 "$f" | grep -o 'opengis.net/citygml/[123]\.0"' | head -1 | grep -o '[123]\.0')
    xmllint --noout --nonet --schema "$SHARED/xsd/citygml-$v.xsd" "$f" >/dev/null 2>&1 || true
  done
}
geofit_each() {
  local f
  for f in "${SET_FILES[@]}"; do "$BIN" -q validate "$f" >/dev/null 2>&1 || true; done
}
export BIN SHARED
ONE=$(median_wall_cpu "$BIN" -q validate "$SET")
ONE_1=$(median_wall_cpu env RAYON_NUM_THREADS=1 "$BIN" -q validate "$SET")
ONE_GEOM=$(median_wall_cpu "$BIN" -q validate --no-xsd "$SET")
ONE_XSD=$(median_wall_cpu "$BIN" -q validate --no-geometry "$SET")
EACH=$(median_wall_cpu bash -c "$(declare -p SET_FILES); $(declare -f geofit_each); geofit_each")
if command -v xmllint >/dev/null; then
  LINT=$(median_wall_cpu bash -c "$(declare -p SET_FILES); $(declare -f xmllint_each); xmllint_each")
else
  LINT="n/a n/a"
fi
SUMMARY=$("$BIN" -q validate --json "$SET" 2>/dev/null | tail -1 || true)
row() { read -r w c <<<"$2"; echo "| $1 | $w | $c |"; }
{
  echo
  echo "## The whole CityGML fixture set in one call (issue 14)"
  echo
  echo "Input: all ${#SET_FILES[@]} CityGML files under fixtures/citygml (CityGML 1.0, 2.0, 3.0; $SET_BYTES bytes). Median of $RUNS_SET runs (by wall time); CPU = user + sys."
  echo
  echo "| what | wall, s | CPU, s |"
  echo "|---|---|---|"
  row "\`geofit validate DIR\` (XSD + geometry, one process, $(nproc) threads)" "$ONE"
  row "same, RAYON_NUM_THREADS=1" "$ONE_1"
  row "\`geofit validate --no-xsd DIR\` (geometry only)" "$ONE_GEOM"
  row "\`geofit validate --no-geometry DIR\` (XSD only)" "$ONE_XSD"
  row "\`xmllint --noout --nonet --schema\`, one process per file (XSD only)" "$LINT"
  row "\`geofit validate FILE\`, one process per file" "$EACH"
  echo
  echo "Summary line of the one-call run: \`$SUMMARY\`"
  echo
  echo "One call parses each version's schema set once (three parses here) and checks the files in"
  echo "parallel; one process per file parses a schema set ${#SET_FILES[@]} times, which is most of its time."
} >> "$OUT"
cat "$OUT"
