#!/usr/bin/env bash
# T-spline speed, memory and file size side by side (issue 19):
#  solve  - the least-squares solve: sparse Cholesky (default) vs the Jacobi-PCG
#           (GEOFIT_TSPLINE_SOLVER=cg; or BEFORE=path/to/older/geofit for a before/after
#           table) on the 1 m LiDAR DEM, the BAG multibeam grid and Kilauea at two tolerances:
#           wall and CPU time (/usr/bin/time), control points, and the max error checked
#           independently at every valid cell (tests/scripts/tspline_maxerror.py on
#           `geofit eval`'s output);
#  size   - bytes of the input raster file, the XML .tmesh and the binary .tmb of those fits;
#  eval   - grid evaluation throughput: a regular cubic mesh of N×N cells of size 8 evaluated
#           on its integer grid by `geofit eval` (CPU) vs scipy's `bisplev` on a tensor spline
#           with as many coefficients, both in points per CPU-second;
#  memory - peak RSS per cell of a fit on a ~10^7-cell float32 raster (Kilauea resampled up;
#           MEMORY_SIZES="3200x3125 10396x9619" adds 10^8 cells);
#  assembly - BEFORE=path/to/older/geofit against this one on the LiDAR DEM and Kilauea at two
#           tolerances each: CPU time, control points, independent max error (the per-element
#           normal-equation assembly, BENCHMARKS.md "Fit assembly per element");
#  speedup - issue 19's "at least 3× faster than today": BEFORE=path/to/geofit-of-the-issue's-day
#           against this one on the six fixture rows (LiDAR DEM, BAG, Kilauea at two tolerances
#           each), RUNS (3) runs of each interleaved so both see the same load, median CPU s and wall s;
#           control points of both and this binary's max error checked independently.
# usage: benches/tspline_speed.sh path/to/geofit [all|solve|eval|memory|assembly|speedup]  (markdown on stdout)
set -uo pipefail
BIN="$(realpath "${1:?usage: tspline_speed.sh path/to/geofit [all|solve|eval|memory]}")"
PART="${2:-all}"
cd "$(dirname "$0")/.."
SHARED="${GEOFIT_SHARED:-../shared}"
TER="$SHARED/fixtures/terrain"
PY="${GEOFIT_PYTHON:-python3}"
T="$(mktemp -d)"
trap 'rm -rf "$T"' EXIT
export GDAL_PAM_ENABLED=NO

# one fit: prints "wall cpu points maxerr_independent ok bytes peak_mib rc"; EXT = tmesh or tmb
fit_row() {
  local bin="$1" input="$2" e="$3" tag="$4" ext="$5"
  local out="$T/$tag"
  /usr/bin/time -f "%e %U %S %M" -o "$out.time" "$bin" fit "$input" -o "$out.$ext" --max-error "$e" --report "$out.json" --device cpu 2>"$out.log"
  local rc=$?
  read -r wall user sys kib < "$out.time"
  local cp
  cp=$("$PY" -c "import json,sys; print(json.load(open(sys.argv[1]))['control_points'])" "$out.json" 2>/dev/null || echo "-")
  "$bin" eval "$out.$ext" -o "$out.eval.tif" --device cpu 2>/dev/null
  local chk
  chk=$("$PY" tests/scripts/tspline_maxerror.py "$input" "$out.eval.tif" "$e" 2>/dev/null | "$PY" -c "import json,sys; d=json.load(sys.stdin); print('%.6g %s' % (d.get('max', float('nan')), 'ok' if d.get('over') == 0 and d.get('missing_in_b') == 0 else 'FAIL'))" 2>/dev/null || echo "- FAIL")
  echo "$wall $(echo "$user + $sys" | bc) $cp $chk $(stat -c %s "$out.$ext" 2>/dev/null || echo -) $((kib / 1024)) rc=$rc"
}

solve_section() {
  echo "## Least-squares solve: sparse Cholesky vs Jacobi-PCG (fit wall/CPU time, control points, independent max error)"
  echo
  echo "Machine: $(nproc) cores shared with other jobs, load before: $(cut -d' ' -f1-3 /proc/loadavg); $(date -u +%Y-%m-%d)"
  echo
  echo '| raster | E | solver | wall s | CPU s | control points | max error (independent) | check | output | output bytes | input bytes | peak MiB |'
  echo '|---|---|---|---|---|---|---|---|---|---|---|---|'
  for spec in "giswqs-lidar_dem.tif 0.5" "giswqs-lidar_dem.tif 0.25" "ons-bag_JD211_public_Release_1-4_UTM.bag 0.25" "ons-bag_JD211_public_Release_1-4_UTM.bag 0.1" "gmt_Kilauea.utm.nc 20" "gmt_Kilauea.utm.nc 5"; do
    set -- $spec
    local f="$TER/$1" e="$2" insize
    insize=$(stat -c %s "$f")
    if [ -n "${BEFORE:-}" ]; then
      set -- $(fit_row "$(realpath "$BEFORE")" "$f" "$e" before tmesh)
      echo "| $(basename "$f") | $e | before (PCG) | $1 | $2 | $3 | $4 | $5 | .tmesh | $6 | $insize | $7 |"
    else
      set -- $(GEOFIT_TSPLINE_SOLVER=cg fit_row "$BIN" "$f" "$e" cg tmesh)
      echo "| $(basename "$f") | $e | PCG | $1 | $2 | $3 | $4 | $5 | .tmesh | $6 | $insize | $7 |"
    fi
    set -- $(fit_row "$BIN" "$f" "$e" chol tmb)
    echo "| $(basename "$f") | $e | Cholesky | $1 | $2 | $3 | $4 | $5 | .tmb | $6 | $insize | $7 |"
  done
  echo
  echo "Load after: $(cut -d' ' -f1-3 /proc/loadavg)"
  echo
}

eval_section() {
  local n="${TSPLINE_EVAL_CELLS:-384}"
  echo "## Grid evaluation: geofit eval vs scipy bisplev (cubic, ${n}x${n} cells of size 8)"
  echo
  "$PY" benches/tspline_speed.py mesh "$T/reg.tmesh" "$n" 8 > "$T/reg.info"
  cat "$T/reg.info"
  echo
  /usr/bin/time -f "%e %U %S %M" -o "$T/ev.time" "$BIN" eval "$T/reg.tmesh" -o "$T/ev.tif" --no-mask --device cpu --timing 2> "$T/ev.log"
  read -r wall user sys kib < "$T/ev.time"
  grep timing "$T/ev.log" | sed 's/^/    /'
  local pts
  pts=$(grep -o 'timing: [0-9]* points' "$T/ev.log" | grep -o '[0-9]*')
  echo
  echo '| evaluator | points | whole command CPU s | points per CPU-second (whole command) |'
  echo '|---|---|---|---|'
  echo "| geofit eval (incl. reading the mesh, knots, extraction, writing the GeoTIFF) | $pts | $(echo "$user + $sys" | bc) | $(echo "$pts / ($user + $sys) / 1000000" | bc -l | cut -c1-6) M |"
  "$PY" benches/tspline_speed.py bisplev "$n" 8
  echo
}

memory_section() {
  # MEMORY_SIZES: "WxH ..." (default the 10^7-cell grid; add 10396x9619 for 10^8 cells, ~3 GiB
  # of RSS before issue 19's float32 samples, a few minutes on 2 cores)
  local sizes="${MEMORY_SIZES:-3200x3125}"
  echo "## Peak memory per cell (Kilauea resampled up to float32, E = 2 m, degree 1)"
  echo
  echo "| cells | wall s | CPU s | peak RSS MiB | bytes/cell |"
  echo "|---|---|---|---|---|"
  for size in $sizes; do
    local w="${size%x*}" h="${size#*x}"
    gdalwarp -q -overwrite -ts "$w" "$h" -r bilinear -ot Float32 "$TER/gmt_Kilauea.utm.nc" "$T/k.tif" 2>/dev/null
    /usr/bin/time -f "%e %U %S %M" -o "$T/m.time" "$BIN" fit "$T/k.tif" -o "$T/k.tmb" --max-error 2 --degree 1 --device cpu 2>/dev/null
    read -r wall user sys kib < "$T/m.time"
    echo "| $((w * h)) | $wall | $(echo "$user + $sys" | bc) | $((kib / 1024)) | $(echo "$kib * 1024 / ($w * $h)" | bc -l | cut -c1-5) |"
    rm -f "$T/k.tif" "$T/k.tmb"
  done
  echo
}

assembly_section() {
  local before="${BEFORE:?assembly: set BEFORE=path/to/older/geofit}"
  echo "## Fit assembly per element: CPU s before/after, control points, independent max error"
  echo
  echo "Machine: $(nproc) cores shared with other jobs, load before: $(cut -d' ' -f1-3 /proc/loadavg); $(date -u +%Y-%m-%d)"
  echo
  echo '| raster | E | before CPU s | after CPU s | speed-up | control points before / after | max error before / after (independent) | check after |'
  echo '|---|---|---|---|---|---|---|---|'
  for spec in "giswqs-lidar_dem.tif 0.5" "giswqs-lidar_dem.tif 0.25" "gmt_Kilauea.utm.nc 20" "gmt_Kilauea.utm.nc 5"; do
    set -- $spec
    local f="$TER/$1" e="$2" b a
    b=($(fit_row "$(realpath "$before")" "$f" "$e" before tmb))
    a=($(fit_row "$BIN" "$f" "$e" after tmb))
    echo "| $1 | $e | ${b[1]} | ${a[1]} | $(echo "${b[1]} / ${a[1]}" | bc -l | cut -c1-4)x | ${b[2]} / ${a[2]} | ${b[3]} / ${a[3]} | ${a[4]} |"
  done
  echo
  echo "Load after: $(cut -d' ' -f1-3 /proc/loadavg)"
  echo
}

median() { printf '%s\n' "$@" | sort -g | awk '{a[NR]=$1} END {print (NR % 2) ? a[(NR + 1) / 2] : (a[NR / 2] + a[NR / 2 + 1]) / 2}'; }

# "CPU-s wall-s" of one fit (CPU = user + sys), nothing else
fit_cpu() {
  local bin="$1" input="$2" e="$3" ext="$4"
  /usr/bin/time -f "%U %S %e" -o "$T/cpu.time" "$bin" -q fit "$input" -o "$T/cpu.$ext" --max-error "$e" --device cpu 2>/dev/null
  read -r user sys wall < "$T/cpu.time"
  awk -v u="$user" -v s="$sys" -v w="$wall" 'BEGIN { printf "%.2f %.2f", u + s, w }'
}

speedup_section() {
  local before="${BEFORE:?speedup: set BEFORE=path/to/older/geofit}" runs="${RUNS:-3}"
  echo "## Fit CPU time against the issue's day, interleaved (issue 19: at least 3x faster)"
  echo
  echo "Machine: $(nproc) cores shared with other jobs, load before: $(cut -d' ' -f1-3 /proc/loadavg); $(date -u +%Y-%m-%d); median of $runs interleaved runs each"
  echo
  echo '| raster | E | before CPU s | after CPU s | CPU speed-up | before wall s | after wall s | wall speed-up | control points before / after | max error after (independent) | check after |'
  echo '|---|---|---|---|---|---|---|---|---|---|---|'
  for spec in "giswqs-lidar_dem.tif 0.5" "giswqs-lidar_dem.tif 0.25" "ons-bag_JD211_public_Release_1-4_UTM.bag 0.25" "ons-bag_JD211_public_Release_1-4_UTM.bag 0.1" "gmt_Kilauea.utm.nc 20" "gmt_Kilauea.utm.nc 5"; do
    set -- $spec
    local f="$TER/$1" e="$2" bs=() as=() bw=() aw=() b a r
    for _ in $(seq "$runs"); do
      r=($(fit_cpu "$(realpath "$before")" "$f" "$e" tmesh)); bs+=("${r[0]}"); bw+=("${r[1]}")
      r=($(fit_cpu "$BIN" "$f" "$e" tmb)); as+=("${r[0]}"); aw+=("${r[1]}")
    done
    b=($(fit_row "$(realpath "$before")" "$f" "$e" before tmesh))
    a=($(fit_row "$BIN" "$f" "$e" after tmb))
    local mb ma mbw maw
    mb=$(median "${bs[@]}") ma=$(median "${as[@]}") mbw=$(median "${bw[@]}") maw=$(median "${aw[@]}")
    echo "| $1 | $e | $mb | $ma | $(awk -v b="$mb" -v a="$ma" 'BEGIN { printf "%.2f", b / a }')x | $mbw | $maw | $(awk -v b="$mbw" -v a="$maw" 'BEGIN { printf "%.2f", b / a }')x | ${b[2]} / ${a[2]} | ${a[3]} | ${a[4]} |"
  done
  echo
  echo "Load after: $(cut -d' ' -f1-3 /proc/loadavg)"
  echo
}

case "$PART" in
  solve) solve_section ;;
  speedup) speedup_section ;;
  eval) eval_section ;;
  memory) memory_section ;;
  assembly) assembly_section ;;
  all) solve_section; eval_section; memory_section ;;
  *) echo "unknown part $PART" >&2; exit 2 ;;
esac
