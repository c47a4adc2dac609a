#!/usr/bin/env bash
# Scale-out of a raster on paper and in a measured slice (issue 17): a 10⁹-cell raster (the 1 m
# LiDAR DEM resampled by GDAL to 31 623² cells in a VRT: windowed reads resample on the fly, the
# big raster is never written) is planned in 1024² tiles; then the jobs of one 3×3 block are run
# as the workflow runs them (workflows/jobs.sh: 9 windowed fits, the centre tile's stitch, eval
# and glb), each under /usr/bin/time: wall, CPU and peak RSS per job. The extrapolation to the
# whole plan on N nodes is printed under the table.
# usage: benches/tiles.sh path/to/geofit   (markdown on stdout, also benches/results/tiles.md)
set -uo pipefail
BIN="$(realpath "${1:?usage: benches/tiles.sh path/to/geofit}")"
cd "$(dirname "$0")/.."
SHARED="${GEOFIT_SHARED:-../shared}"
DEM="$SHARED/fixtures/terrain/giswqs-lidar_dem.tif"
SIDE="${TILES_SIDE:-31623}"
E="${TILES_MAX_ERROR:-0.05}"
T="$(mktemp -d)"
trap 'rm -rf "$T"' EXIT
export GDAL_PAM_ENABLED=NO GEOFIT="$BIN" GEOFIT_MAX_ERROR="$E" GEOFIT_TILE_PIXELS=1024
RES=benches/results/tiles.md
mkdir -p benches/results

gdal_translate -q -of VRT -r cubic -outsize "$SIDE" "$SIDE" "$DEM" "$T/big.vrt"
start=$(date +%s.%N)
bash workflows/jobs.sh rplan "$T/out/plan.jsonl" "$T/big.vrt"
plan_s=$(printf "%.2f" "$(echo "$(date +%s.%N) - $start" | bc)")
tiles=$(wc -l <"$T/out/plan.jsonl")

# one job under /usr/bin/time: prints "| step | tile | wall | cpu | peak MiB |"
job() {
  local step="$1" tile="$2"
  shift 2
  /usr/bin/time -f "%e %U %S %M" -o "$T/time" bash workflows/jobs.sh "$step" "$@" 2>"$T/log" \
    || { echo "| $step | $tile | failed: $(tail -1 "$T/log") | | |"; return; }
  read -r wall user sys kib <"$T/time"
  printf '| %s | %s | %.2f | %.2f | %d |\n' "$step" "$tile" "$wall" "$(echo "$user + $sys" | bc)" "$((kib / 1024))"
}

{
  echo "## Raster scale-out: a measured slice of a 10⁹-cell plan (issue 17)"
  echo
  echo "\`benches/tiles.sh\`: the LiDAR DEM resampled (cubic) to ${SIDE}² = $(echo "$SIDE * $SIDE" | bc) cells"
  echo "in a VRT, planned in 1024² tiles with a 2-px halo ($tiles tiles, plan $plan_s s, reading"
  echo "only size and geotransform); E = $E m; release binary; the jobs of the 3×3 block around"
  echo "c5_r5 as workflows/jobs.sh runs them, one at a time on a 2-core machine."
  echo
  echo "| job | tile | wall s | CPU s | peak RSS MiB |"
  echo "|---|---|---|---|---|"
  for r in 4 5 6; do
    for c in 4 5 6; do
      job rfit "c${c}_r${r}" "$T/out/plan.jsonl" "$T/big.vrt" "c${c}_r${r}" "$T/out/fit/c${c}_r${r}.tmb"
    done
  done
  job stitch c5_r5 "$T/out/plan.jsonl" "$T/big.vrt" c5_r5 "$T/out/fit/c5_r5.tmb" "$T/out/stitched/c5_r5.tmb" "$T/out/stitched/c5_r5.json"
  job reval c5_r5 "$T/out/stitched/c5_r5.tmb" "$T/out/eval/c5_r5.tif"
  bash workflows/jobs.sh rrange "$DEM" "$T/out/zrange.txt" 2>/dev/null
  job rglb c5_r5 "$T/out/stitched/c5_r5.tmb" "$T/out/zrange.txt" "$T/out/glb/c5_r5.glb"
  echo
  for f in fit stitched; do
    cp=$("$BIN" info "$T/out/$f/c5_r5.tmb" | sed -n 's/^control points: *//p')
    echo "- c5_r5 $f: $cp control points for 1 048 576 cells; $(stat -c %s "$T/out/$f/c5_r5.tmb") bytes (.tmb)"
  done
} | tee "$T/table.md"

# extrapolation from the measured medians: every tile runs fit + stitch + eval + glb once
python3 - "$T/table.md" "$tiles" <<'EOF' | tee -a "$T/table.md"
import statistics, sys
rows = [l.split("|")[1:-1] for l in open(sys.argv[1]) if l.startswith("| r") or l.startswith("| s")]
per = {}
for step, _tile, wall, cpu, rss in rows:
    try:
        per.setdefault(step.strip(), []).append((float(wall), float(cpu), int(rss)))
    except ValueError:
        pass
tiles = int(sys.argv[2])
cpu = sum(statistics.median(c for _, c, _ in v) for v in per.values())
rss = max(r for v in per.values() for _, _, r in v)
print()
print(f"Per tile (medians): {cpu:.1f} CPU s for fit + stitch + eval + glb; the largest job peaked at "
      f"{rss} MiB, set by the tile (1024² cells), not the raster.")
print(f"Whole plan: {tiles} tiles × {cpu:.1f} s = {tiles * cpu / 3600:.1f} core-hours. Jobs are independent within a wave "
      "(fits, then stitches: each stitch needs its neighbours' fits), memory-bound at "
      f"~{rss} MiB per job:")
for nodes, cores in [(1, 32), (10, 32), (100, 32)]:
    print(f"- {nodes} node(s) × {cores} cores: ≈ {tiles * cpu / (nodes * cores) / 60:.1f} min wall "
          f"(+ the serial steps: plan, gdalbuildvrt, tileset, seconds each)")
EOF
cp "$T/table.md" "$RES"
