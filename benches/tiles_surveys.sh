#!/usr/bin/env bash
# Raster scale-out on real surveys (issue 36): windows of the shared BAG, LiDAR DEM and Kilauea
# grids, two tolerances each, three tile sizes (one not a power of two), each run through
# `tile plan` → `fit --plan --tile` (every tile) → `tile stitch` (every tile) → `tile seams`,
# checked by tests/scripts/tiles_check.py (independent T-mesh decoder/evaluator: every valid
# cell within E) and compared with one whole-window fit.
#
# usage: benches/tiles_surveys.sh GEOFIT   → benches/results/tiles_surveys.md and .tsv
set -uo pipefail
G=${1:?usage: benches/tiles_surveys.sh GEOFIT}
root=$(cd "$(dirname "$0")/.." && pwd)
PY=${GEOFIT_PYTHON:-$root/.venv/bin/python3}
FIX=${GEOFIT_FIXTURES:-/work/shared/fixtures}/terrain
JOBS=${GEOFIT_BENCH_JOBS:-2}
work=$(mktemp -d)
trap 'rm -rf "$work"' EXIT
export GDAL_PAM_ENABLED=NO
md=$root/benches/results/tiles_surveys.md
tsv=$root/benches/results/tiles_surveys.tsv
SIZES=(64 100 128)
# name | file | -srcwin | tolerances
CASES=(
  "bag|ons-bag_JD211_public_Release_1-4_UTM.bag|704 960 256 256|0.05 0.1"
  "lidar|giswqs-lidar_dem.tif|100 100 256 256|0.25 0.5"
  "kilauea|gmt_Kilauea.utm.nc|300 300 256 256|5 10"
)
rows=()
worst_first=0 worst_whole=0 finished=0 runs=0
for c in "${CASES[@]}"; do
  IFS='|' read -r name file win tols <<<"$c"
  src=$work/$name.tif
  # shellcheck disable=SC2086
  gdal_translate -q -b 1 -srcwin $win "$FIX/$file" "$src" || { echo "tiles.sh: $file missing" >&2; exit 3; }
  for e in $tols; do
    "$G" -q fit "$src" --max-error "$e" -o "$work/$name-$e-whole.tmb" 2>/dev/null
    whole=$("$PY" "$root/tests/scripts/tmb_decode_eval.py" "$work/$name-$e-whole.tmb" "$src" "$e" | "$PY" -c 'import json,sys; print(json.load(sys.stdin)["control_points"])')
    for side in "${SIZES[@]}"; do
      d=$work/$name-$e-$side
      mkdir -p "$d/fit" "$d/st"
      runs=$((runs + 1))
      t0=$(date +%s.%N)
      "$G" -q tile plan --tile-size "$side" --halo 2 -o "$d/plan.jsonl" "$src"
      "$PY" -c 'import json,sys; [print(t["id"]) for t in map(json.loads, open(sys.argv[1])) if t["work"] > 0]' "$d/plan.jsonl" >"$d/ids.txt"
      fails=0
      xargs -P "$JOBS" -I{} "$G" -q fit "$src" --plan "$d/plan.jsonl" --tile {} --max-error "$e" -o "$d/fit/{}.tmb" <"$d/ids.txt" 2>"$d/fit.err" || fails=$((fails + 1))
      xargs -P "$JOBS" -I{} "$G" -q tile stitch "$src" --plan "$d/plan.jsonl" --tile {} --meshes "$d/fit/{id}.tmb" --max-error "$e" -o "$d/st/{}.tmb" <"$d/ids.txt" 2>"$d/st.err" || fails=$((fails + 1))
      t1=$(date +%s.%N)
      "$G" -q tile seams "$d/plan.jsonl" --meshes "$d/st/{id}.tmb" -o "$d/seams.json" 2>/dev/null
      chk=$("$PY" "$root/tests/scripts/tiles_check.py" "$d/plan.jsonl" "$src" "$e" "$d/st/{id}.tmb" --first "$d/fit/{id}.tmb" 2>"$d/check.err") && ok=yes || ok=no
      [ "$fails" = 0 ] || ok=no
      [ "$ok" = yes ] && finished=$((finished + 1))
      line=$(CHK="$chk" "$PY" - "$name" "$e" "$side" "$whole" "$ok" "$t0" "$t1" "$d/seams.json" "$(wc -l <"$d/ids.txt")" <<'PYEOF'
import json, os, sys
name, e, side, whole, ok, t0, t1, seams, n = sys.argv[1:]
try:
    c = json.loads(os.environ["CHK"])
except ValueError:
    c = {"control_points": 0, "first_pass_control_points": 0, "max_error": float("nan"), "cells_over": -1, "empty_tiles": 0}
try:
    s = json.load(open(seams))
except (OSError, ValueError):
    s = {"max_gap": float("nan"), "max_normal_angle_deg": float("nan")}
st, fp, wh = c["control_points"], c["first_pass_control_points"], int(whole)
r1 = st / fp if fp else float("nan")
r2 = st / wh if wh else float("nan")
print(f"| {name} | {e} | {side} | {n} | {c.get('empty_tiles', 0)} | {ok} | {c['max_error']:.4g} | {c['cells_over']} | {fp} | {st} | {wh} | {r1:.2f} | {r2:.2f} | {s.get('max_gap', float('nan')):.2e} | {s.get('max_normal_angle_deg', float('nan')):.1f} | {float(t1) - float(t0):.1f} |\t{r1}\t{r2}")
PYEOF
)
      rows+=("${line%%	*}")
      r1=$(cut -f2 <<<"$line") r2=$(cut -f3 <<<"$line")
      worst_first=$("$PY" -c "import math,sys; a,b=float(sys.argv[1]),float(sys.argv[2]); print(max(a,b) if not math.isnan(b) else a)" "$worst_first" "$r1")
      worst_whole=$("$PY" -c "import math,sys; a,b=float(sys.argv[1]),float(sys.argv[2]); print(max(a,b) if not math.isnan(b) else a)" "$worst_whole" "$r2")
      echo "${line%%	*}" >&2
    done
  done
done
date=$(date -u +%F)
commit=$(git -C "$root" rev-parse --short HEAD)
{
  echo "# Raster tiles on real surveys (issue 36)"
  echo
  echo "benches/tiles_surveys.sh: 256² windows of three shared rasters, two tolerances, tile sizes ${SIZES[*]} px;"
  echo "each run plans, fits and stitches every tile with data ($JOBS jobs at a time), then"
  echo "tests/scripts/tiles_check.py decodes every stitched .tmb independently and checks every valid"
  echo "cell of its core within E. Control points: first-pass sum, stitched sum, one whole-window fit."
  echo "Date $date, commit $commit, $(nproc) CPUs."
  echo
  echo "| raster | E | tile px | tiles | empty | within E | max error | cells over | first pass | stitched | whole | stitched/first | stitched/whole | max seam gap | max normal jump (°) | fit+stitch s |"
  echo "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|"
  printf '%s\n' "${rows[@]}"
  echo
  echo "Finished within E: $finished of $runs runs. Worst stitched/first-pass: $worst_first; worst stitched/whole: $worst_whole."
} >"$md"
{
  printf 'benchmark\tfigure\tunit\tpeer\tpeer_figure\tratio\tdate\tcommit\n'
  printf 'tiles: runs finished with every cell within E\t%s\truns\tall runs\t%s\t%s\t%s\t%s\n' "$finished" "$runs" "$("$PY" -c "print(round($finished/$runs,3))")" "$date" "$commit"
  printf 'tiles: stitched control points, worst run\t%s\tx first-pass sum\t-\t-\t-\t%s\t%s\n' "$("$PY" -c "print(round($worst_first,3))")" "$date" "$commit"
  printf 'tiles: stitched control points, worst run\t%s\tx whole-raster fit\t-\t-\t-\t%s\t%s\n' "$("$PY" -c "print(round($worst_whole,3))")" "$date" "$commit"
} >"$tsv"
cat "$md"
