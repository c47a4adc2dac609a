#!/usr/bin/env bash
# Issue 37: the `.tmb` T-mesh against GDAL's LERC_ZSTD GeoTIFF at the same guaranteed maximum
# error E, side by side in one run. Per row: `geofit fit RASTER --max-error E -o x.tmb` (heights
# stored to the error budget, the default share) and `gdal_translate -b 1 -co COMPRESS=LERC_ZSTD
# -co MAX_Z_ERROR=E`; both files checked cell by cell by numpy, independently of geofit: the .tmb
# decoded and its T-spline evaluated by tests/scripts/tmb_decode_eval.py, the LERC file read back
# by GDAL. Fit CPU (user + sys of the whole command) beside pydelatin's CPU for the same E (its
# triangulation alone, when pydelatin is installed: make setup-bench).
# Rows: every raster fixture of ../shared/fixtures/terrain at 0.5 % and 0.1 % of its z range; the
# BAG and the 1 m LiDAR DEM at 0.5 / 0.25 / 0.1 m. Heights are taken as metres (--z-unit m), so E
# is in the raster's own unit. Then the storage share measured: lossless and q = 0.1 / 0.15 / 0.2 / 0.3 / 0.5 E.
# usage: benches/tmb.sh path/to/geofit   (writes benches/results/tmb.md and tmb.tsv)
set -uo pipefail
BIN="$(realpath "${1:?usage: benches/tmb.sh path/to/geofit}")"
cd "$(dirname "$0")/.."
TER="${GEOFIT_SHARED:-../shared}/fixtures/terrain"
PY="${GEOFIT_PYTHON:-python3}"
FIT_TIMEOUT="${FIT_TIMEOUT:-240}"
T="$(mktemp -d)"
trap 'rm -rf "$T"' EXIT
export GDAL_PAM_ENABLED=NO
RES=benches/results/tmb.md
TSV=benches/results/tmb.tsv
mkdir -p benches/results
DATE="$(date -u +%F)" COMMIT="$(git rev-parse --short HEAD)"
BAG=ons-bag_JD211_public_Release_1-4_UTM.bag
DEM=giswqs-lidar_dem.tif

cat >"$T/tin.py" <<'EOF'
import sys, time
import numpy as np
try:
    from pydelatin import Delatin
except ImportError:
    print("-"); sys.exit(0)
sys.path.insert(0, "benches")
from terrain_grid import load_filled
grid, ok, filled = load_filled(sys.argv[1])
h, w = grid.shape
t0 = time.process_time()
Delatin(grid.astype(np.float32), width=w, height=h, max_error=float(sys.argv[2]))
print(f"{time.process_time() - t0:.3f}")
EOF

cat >"$T/lerc_check.py" <<'EOF'
import sys
sys.path.insert(0, "tests/scripts")
import numpy as np
from tmb_decode_eval import load_raster
a, ok, _ = load_raster(sys.argv[1], 1)
b, okb, _ = load_raster(sys.argv[2], 1)
err = np.where(ok, np.abs(np.where(okb, b, np.inf) - a), 0.0)
print(f"{err.max():.6g}")
EOF

range_of() { gdalinfo -json -mm "$1" 2>/dev/null | "$PY" -c "import json,sys; b=json.load(sys.stdin)['bands'][0]; print(b['computedMax']-b['computedMin'])"; }

# one row: fit with $3 extra options, LERC, both checks. Prints "bytes lerc_bytes tmb_max lerc_max fit_cpu points".
row() {
  local f="$1" e="$2" extra="$3"
  rm -f "$T/x.tmb" "$T/x.json" "$T/x.tif"
  if ! /usr/bin/time -f "%U %S" -o "$T/time" timeout "$FIT_TIMEOUT" "$BIN" -q fit "$f" --max-error "$e" --z-unit m --device cpu $extra \
    -o "$T/x.tmb" --report "$T/x.json" 2>"$T/err"; then
    echo "fit-failed"; return
  fi
  read -r u s <"$T/time"
  local cpu bytes pts chk tmax
  cpu="$(echo "$u + $s" | bc)"
  bytes="$(stat -c %s "$T/x.tmb")"
  pts="$("$PY" -c "import json; print(json.load(open('$T/x.json'))['control_points'])")"
  chk="$("$PY" tests/scripts/tmb_decode_eval.py "$T/x.tmb" "$f" "$e")"
  tmax="$(echo "$chk" | "$PY" -c "import json,sys; d=json.load(sys.stdin); print(f\"{d['max_abs_error']:.6g}\" + ('' if d['cells_over'] == 0 else ' OVER'))")"
  echo "$bytes $tmax $cpu $pts"
}

lerc() {
  local f="$1" e="$2"
  gdal_translate -q -b 1 -co COMPRESS=LERC_ZSTD -co MAX_Z_ERROR="$e" "$f" "$T/l.tif" >/dev/null 2>&1 || { echo "- -"; return; }
  echo "$(stat -c %s "$T/l.tif") $("$PY" "$T/lerc_check.py" "$f" "$T/l.tif")"
  rm -f "$T/l.tif"
}

rows=()
for f in "$TER"/*.nc "$TER"/*.tif "$TER"/*.tiff "$TER"/*.asc "$TER"/*.bag; do
  [ -f "$f" ] || continue
  r="$(range_of "$f")"
  for pct in 0.5 0.1; do
    rows+=("$(basename "$f") $(echo "$r * $pct / 100" | bc -l | xargs printf '%.4g') $pct%")
  done
done
for e in 0.5 0.25 0.1; do
  rows+=("$DEM $e survey" "$BAG $e survey")
done

printf 'benchmark\tfigure\tunit\tpeer\tpeer_figure\tratio\tdate\tcommit\n' >"$TSV"
{
  echo "## .tmb vs LERC_ZSTD at the same maximum error (issue 37)"
  echo
  echo "\`benches/tmb.sh\`, release binary, $(nproc) cores, load before: $(cut -d' ' -f1-3 /proc/loadavg); GDAL $(gdal-config --version 2>/dev/null || echo '?')."
  echo "Bytes of \`fit -o x.tmb\` (default storage share) and of \`gdal_translate -b 1 -co COMPRESS=LERC_ZSTD -co MAX_Z_ERROR=E\`;"
  echo "max |error| of each file decoded and checked by numpy at every valid cell (the .tmb by tests/scripts/tmb_decode_eval.py,"
  echo "an independent T-spline evaluator; OVER marks a cell above E). Fit CPU = user + sys of the fit command; pydelatin = its"
  echo "triangulation's CPU alone at the same E (– when not installed)."
  echo
  echo "| raster | E | of | .tmb bytes | LERC_ZSTD bytes | ratio | .tmb max err | LERC max err | control points | fit CPU s | pydelatin CPU s | CPU ratio |"
  echo "|---|---|---|---|---|---|---|---|---|---|---|---|"
  for r in "${rows[@]}"; do
    set -- $r
    name="$1" e="$2" kind="$3" f="$TER/$1"
    out="$(row "$f" "$e" "")"
    if [ "$out" = fit-failed ]; then
      echo "| $name | $e | $kind | fit failed or over ${FIT_TIMEOUT} s: $(tail -c 200 "$T/err" | tr '\n|' '  ') | | | | | | | | |"
      continue
    fi
    read -r bytes tmax cpu pts <<<"$out"
    read -r lbytes lmax <<<"$(lerc "$f" "$e")"
    tin="$("$PY" "$T/tin.py" "$f" "$e" 2>/dev/null || echo -)"
    ratio="$(echo "$bytes / $lbytes" | bc -l | xargs printf '%.2f')"
    cr="-"
    [ "$tin" != - ] && cr="$(echo "$cpu / $tin" | bc -l | xargs printf '%.1f')"
    echo "| $name | $e | $kind | $bytes | $lbytes | **$ratio** | $tmax | $lmax | $pts | $cpu | $tin | $cr |"
    printf '.tmb bytes, %s at E=%s (%s)\t%s\tbytes\tLERC_ZSTD\t%s\t%s\t%s\t%s\n' "${name%.*}" "$e" "$kind" "$bytes" "$lbytes" "$ratio" "$DATE" "$COMMIT" >>"$TSV"
  done
  echo
  echo "### The storage share q (docs/decisions.md#heights-quantised-to-the-error-budget-issue-37)"
  echo
  echo "\`fit --max-error E\` fits at (1 − s)·E and rounds heights to steps of 2q, q = s·E. Bytes of the .tmb (control points)"
  echo "per share s; lossless = the fit at E with exact f64 heights (\`--lossless\`)."
  echo
  echo "| raster | E | lossless | s = 0.1 | s = 0.15 | s = 0.2 | s = 0.3 | s = 0.5 |"
  echo "|---|---|---|---|---|---|---|---|"
  for r in "$DEM 0.5" "$DEM 0.25" "$DEM 0.1" "$BAG 0.25" "$BAG 0.1" "gmt_Kilauea.utm.nc 5"; do
    set -- $r
    line="| $1 | $2 |"
    for opt in "--lossless" "--storage-share 0.1" "--storage-share 0.15" "--storage-share 0.2" "--storage-share 0.3" "--storage-share 0.5"; do
      out="$(row "$TER/$1" "$2" "$opt")"
      if [ "$out" = fit-failed ]; then line="$line failed |"; continue; fi
      read -r bytes tmax cpu pts <<<"$out"
      line="$line $bytes ($pts) |"
    done
    echo "$line"
  done
} | tee "$RES"
