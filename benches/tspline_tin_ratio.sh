#!/usr/bin/env bash
# The fit's CPU time against a Garland–Heckbert TIN's (pydelatin) for the same raster and maximum
# error, interleaved in one run so that both see the same machine load (issue 19: "fit wall time
# ≤ 5× pydelatin's"). Per row, RUNS (3) alternating runs of each; the median CPU seconds
# (user + sys). geofit: the whole `geofit fit … --device cpu -o x.tmb` command (reading the
# raster included). pydelatin: the triangulation alone (process CPU time around `Delatin(...)`;
# reading and no-data filling not counted, which favours the TIN). Control points vs TIN vertices
# in the same table.
# usage: benches/tspline_tin_ratio.sh path/to/geofit  (markdown on stdout and benches/results/tspline_tin_ratio.md)
set -uo pipefail
BIN="$(realpath "${1:?usage: benches/tspline_tin_ratio.sh path/to/geofit}")"
cd "$(dirname "$0")/.."
TER="${GEOFIT_SHARED:-../shared}/fixtures/terrain"
PY="${GEOFIT_PYTHON:-python3}"
RUNS="${RUNS:-3}"
T="$(mktemp -d)"
trap 'rm -rf "$T"' EXIT
export GDAL_PAM_ENABLED=NO
RES=benches/results/tspline_tin_ratio.md
mkdir -p benches/results
. benches/lib/current.sh
current_reset tspline_tin_ratio
"$PY" -c "import pydelatin" 2>/dev/null || { echo "tspline_tin_ratio: pydelatin missing (make setup-bench)"; exit 1; }

cat >"$T/tin.py" <<'EOF'
import json, sys, time
import numpy as np
from pydelatin import Delatin
sys.path.insert(0, "benches")
from terrain_grid import load_filled
grid, ok, filled = load_filled(sys.argv[1])
h, w = grid.shape
runs = []
for _ in range(int(sys.argv[3])):
    t0 = time.process_time()
    tin = Delatin(grid.astype(np.float32), width=w, height=h, max_error=float(sys.argv[2]))
    runs.append(time.process_time() - t0)
print(json.dumps({"vertices": len(tin.vertices), "cpu": runs}))
EOF

median() { printf '%s\n' "$@" | sort -g | awk '{a[NR]=$1} END {print (NR % 2) ? a[(NR + 1) / 2] : (a[NR / 2] + a[NR / 2 + 1]) / 2}'; }

{
  echo "## Fit vs pydelatin CPU time, interleaved (issue 19)"
  echo
  echo "\`benches/tspline_tin_ratio.sh\`, release binary, $(nproc) cores, load before: $(cut -d' ' -f1-3 /proc/loadavg);"
  echo "median of $RUNS CPU s (user + sys); pydelatin's triangulation alone (reading not counted)."
  echo
  echo "| raster | E | fit CPU s | pydelatin CPU s | ratio | control points | TIN vertices | points / vertices |"
  echo "|---|---|---|---|---|---|---|---|"
  for row in "giswqs-lidar_dem.tif 0.5" "giswqs-lidar_dem.tif 0.25" "ons-bag_JD211_public_Release_1-4_UTM.bag 0.25" \
    "ons-bag_JD211_public_Release_1-4_UTM.bag 0.1" "gmt_Kilauea.utm.nc 20" "gmt_Kilauea.utm.nc 5"; do
    set -- $row
    f="$TER/$1" e="$2"
    [ -f "$f" ] || { echo "| $1 | $e | missing | | | | | |"; continue; }
    fits=() tins=()
    for _ in $(seq "$RUNS"); do
      /usr/bin/time -f "%U %S" -o "$T/time" "$BIN" -q fit "$f" --max-error "$e" --device cpu -o "$T/x.tmb" --report "$T/x.json" 2>/dev/null
      read -r u s <"$T/time"
      fits+=("$(echo "$u + $s" | bc)")
      tins+=("$("$PY" "$T/tin.py" "$f" "$e" 1 | "$PY" -c "import json,sys; d=json.load(sys.stdin); print(d['cpu'][0], d['vertices'])")")
    done
    fit=$(median "${fits[@]}")
    tin=$(median "$(printf '%s\n' "${tins[@]}" | cut -d' ' -f1)")
    nv=$(printf '%s\n' "${tins[@]}" | head -1 | cut -d' ' -f2)
    cp=$("$PY" -c "import json,sys; print(json.load(open(sys.argv[1]))['control_points'])" "$T/x.json")
    printf '| %s | %s | %.2f | %.3f | %.1f× | %s | %s | %.2f |\n' "$1" "$e" "$fit" "$tin" "$(echo "$fit / $tin" | bc -l)" "$cp" "$nv" "$(echo "$cp / $nv" | bc -l)"
    current_row tspline_tin_ratio "fit CPU, ${1%%.*} at E=$e" "$fit" "CPU s" pydelatin "$tin"
  done
} | tee "$RES"
