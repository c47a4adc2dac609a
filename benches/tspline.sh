#!/usr/bin/env bash
# T-spline benchmark (spec A18: the thesis reports no timings, so these are ours):
#  1. evaluation throughput, 10^7 points of a cubic mesh with ~10^5 control points:
#     PoCL vs single-thread CPU vs rayon CPU, with the flop count per point;
#  2. control points a fit needs for max error E vs the vertices of a Garland-Heckbert TIN
#     (pydelatin) for the same E, stored bytes, run time and peak memory of both.
# usage: benches/tspline.sh path/to/geofit   (writes benches/results/tspline.md)
set -uo pipefail
BIN="${1:?usage: tspline.sh path/to/geofit}"
cd "$(dirname "$0")/.."
SHARED="${GEOFIT_SHARED:-../shared}"
T="$(mktemp -d)"
trap 'rm -rf "$T"' EXIT
RES=benches/results/tspline.md
mkdir -p benches/results
{
echo "# T-spline benchmark"
echo
echo "Machine: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | xargs); $(date -u +%Y-%m-%d)"
echo
echo "## Evaluation throughput (cubic, ~10^5 control points, ~10^7 points)"
echo
python3 benches/tspline_mesh.py "$T/bench.tmesh" 315 10 2>&1
echo
echo '| path | points | seconds | M points/s | flops/point |'
echo '|---|---|---|---|---|'
for mode in opencl cpu1 cpu; do
  case $mode in
    opencl) line=$("$BIN" eval "$T/bench.tmesh" -o "$T/e.tif" --no-mask --device opencl --timing 2>&1 | grep timing) ;;
    cpu1) line=$(RAYON_NUM_THREADS=1 "$BIN" eval "$T/bench.tmesh" -o "$T/e.tif" --no-mask --device cpu --timing 2>&1 | grep timing) ;;
    cpu) line=$("$BIN" eval "$T/bench.tmesh" -o "$T/e.tif" --no-mask --device cpu --timing 2>&1 | grep timing) ;;
  esac
  # "timing: N points in S s = R M points/s, F flops/point (...)"
  echo "$line" | sed -E "s/.*timing: ([0-9]+) points in ([0-9.]+) s = ([0-9.]+) M points\/s, ([0-9]+) flops\/point \((.*)\)/| $mode: \5 | \1 | \2 | \3 | \4 |/"
done
echo
echo "Target: 20 M points/s on 2 cores."
echo
echo "## Fit vs TIN for the same maximum error"
echo
echo '| raster | E | degree | T-spline control points | T-mesh bytes (file / binary) | fit s | fit peak MiB | exit | TIN vertices | TIN bytes | TIN s | TIN peak MiB |'
echo '|---|---|---|---|---|---|---|---|---|---|---|---|'
for spec in "gmt_tut_bathy.nc 10" "gmt_tut_bathy.nc 50" "gmt_Kilauea.utm.nc 5" "gmt_Kilauea.utm.nc 20" "gmt_guinea_bay.nc 20"; do
  set -- $spec
  f="$SHARED/fixtures/terrain/$1"; e=$2
  [ -f "$f" ] || { echo "| $1 | missing |"; continue; }
  tin=$(python3 benches/tspline_tin.py "$f" "$e" 2>/dev/null || echo '{}')
  for d in 1 3; do
    /usr/bin/time -f "%e %M" -o "$T/time" "$BIN" -q fit "$f" -o "$T/m.tmesh" --max-error "$e" --degree "$d" --report "$T/r.json" 2>/dev/null
    rc=$?
    read secs kib < "$T/time"
    cps=$(python3 -c "import json;r=json.load(open('$T/r.json'));print(r['control_points'])")
    cells=$(python3 -c "import json;r=json.load(open('$T/r.json'));print(r['cells'])")
    fbytes=$(stat -c %s "$T/m.tmesh")
    bbytes=$((cps * 48 + cells * 16))
    tv=$(echo "$tin" | python3 -c "import json,sys;r=json.load(sys.stdin);print(r.get('vertices','-'), r.get('bytes','-'), r.get('seconds','-'), r.get('peak_rss_mib','-'))")
    set -- $tv
    echo "| $(basename "$f") | $e | $d | $cps | $fbytes / $bbytes | $secs | $((kib / 1024)) | $rc | $1 | $2 | $3 | $4 |"
  done
done
echo
echo "T-mesh binary bytes = 48 per control point (s t x y z w as f64) + 16 per cell (4 x u32);"
echo "TIN bytes = 24 per vertex + 12 per triangle. Kilauea's nodata cells are filled with the nearest"
echo "valid value for the TIN (delatin needs a full grid); the T-spline fit leaves them out."
} | tee "$RES"
