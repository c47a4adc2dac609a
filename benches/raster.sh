#!/usr/bin/env bash
# Raster side of the terrain work: rasterize throughput (points/s, cells/s) for Gauss splatting
# and TIN-linear, side by side with `gdal_grid -a linear` (the reference tool) on the same
# points and grid; warp (rotation + landmark warp + splat + dilation) and unwarp times on the
# terrain fixtures and a generated 2000×1500 channel. Writes benches/results/raster.md.
# Usage: benches/raster.sh path/to/geofit
set -euo pipefail
BIN="${1:?usage: raster.sh path/to/geofit}"
cd "$(dirname "$0")/.."
SHARED="${GEOFIT_SHARED:-../shared}"
FIX="$SHARED/fixtures/terrain"
OUT=benches/results/raster.md
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
now() { date +%s.%N; }
# best of N wall-clock seconds of a command
best() {
  local n=$1; shift
  local b=""
  for _ in $(seq "$n"); do
    local t0 t1
    t0=$(now); "$@" >/dev/null 2>&1; t1=$(now)
    b=$(python3 -c "import sys; t=float(sys.argv[2])-float(sys.argv[1]); b=sys.argv[3]; print(t if b=='' else min(t,float(b)))" "$t0" "$t1" "$b")
  done
  printf '%.3f' "$b"
}
rate() { python3 -c "import sys; print(f'{float(sys.argv[1])/float(sys.argv[2])/1e6:.2f}')" "$1" "$2"; }

# Generated inputs: 1,000,000 scattered points on a 2 km square (a smooth seabed + ripples),
# and a 2000×1500 ESRI grid holding a rotated channel.
python3 - "$TMP/big.xyz" <<'PY'
import sys, numpy as np
rng = np.random.default_rng(1)
n = 1_000_000
x = rng.uniform(0, 2000, n); y = rng.uniform(0, 2000, n)
z = -15 - 0.004 * x + 3 * np.sin(x / 90) * np.cos(y / 130) + 0.2 * np.sin(x / 7)
np.savetxt(sys.argv[1], np.column_stack([x + 480000, y + 5930000, z]), fmt="%.3f")
PY
python3 - "$TMP/channel.asc" <<'PY'
import sys, numpy as np
w, h = 2000, 1500
c, r = np.meshgrid(np.arange(w) + 0.5, h - np.arange(h) - 0.5)
t = np.radians(30); cx, cy = w / 2, h / 2
al = (c - cx) * np.cos(t) + (r - cy) * np.sin(t); ac = -(c - cx) * np.sin(t) + (r - cy) * np.cos(t)
half = 160 + 70 * np.sin(al / 230)
z = -12 - 0.004 * al - 6 * (1 - (ac / half) ** 2)
z[(np.abs(al) > 0.42 * w) | (np.abs(ac) > half)] = -9999
with open(sys.argv[1], "w") as f:
    f.write(f"ncols {w}\nnrows {h}\nxllcorner 500000\nyllcorner 5700000\ncellsize 1\nNODATA_value -9999\n")
    np.savetxt(f, z, fmt="%.4f")
PY

gdal_grid_linear() { # POINTS_TXT GRID_REPORT OUT
  awk 'BEGIN{print "x,y,z"} !/^#/ && NF>=3 {print $1","$2","$3}' "$1" > "$TMP/pts.csv"
  printf '<OGRVRTDataSource><OGRVRTLayer name="pts"><SrcDataSource>%s</SrcDataSource><GeometryType>wkbPoint</GeometryType><GeometryField encoding="PointFromColumns" x="x" y="y" z="z"/></OGRVRTLayer></OGRVRTDataSource>' "$TMP/pts.csv" > "$TMP/pts.vrt"
  read -r a b c d w h < <(python3 -c "
import json,sys; d=json.load(open(sys.argv[1])); g=d['geotransform']; w,h=d['width'],d['height']
print(repr(g[0]), repr(g[0]+w*g[1]), repr(g[3]+h*g[5]), repr(g[3]), w, h)" "$2")
  echo gdal_grid -q -zfield z -a linear:radius=0:nodata=-9999 -txe "$a" "$b" -tye "$c" "$d" -outsize "$w" "$h" -ot Float64 -of GTiff "$TMP/pts.vrt" "$3"
}

{
echo "# Raster benchmarks (rasterize, warp)"
echo
echo "Machine: $(nproc) cores, $(python3 -c "import os; print(round(os.sysconf('SC_PAGE_SIZE')*os.sysconf('SC_PHYS_PAGES')/2**30))") GiB; release build; best of 3 wall-clock runs; $(date -u +%Y-%m-%d)."
echo
echo "## Rasterize: points/s (M) and grid cells/s (M)"
echo
echo "| input | points | grid | gauss (σ ½, r 1.5 cells) | tin | gdal_grid -a linear (same grid) |"
echo "|---|---:|---|---|---|---|"
} > "$OUT"

rasterize_row() { # LABEL POINTS CELL [extra args...]
  local label=$1 pts=$2 cell=$3; shift 3
  "$BIN" -q rasterize "$pts" -o "$TMP/r.tif" --cell "$cell" --method tin --report "$TMP/rep.json" "$@" >/dev/null
  local n w h cells
  n=$(python3 -c "import json; print(json.load(open('$TMP/rep.json'))['points'])")
  read -r w h < <(python3 -c "import json; d=json.load(open('$TMP/rep.json')); print(d['width'], d['height'])")
  cells=$((w * h))
  local tg tt tr ref=""
  tg=$(best 3 "$BIN" -q rasterize "$pts" -o "$TMP/g.tif" --cell "$cell" --method gauss "$@")
  tt=$(best 3 "$BIN" -q rasterize "$pts" -o "$TMP/t.tif" --cell "$cell" --method tin "$@")
  if [[ "$pts" != *.la[sz] ]] && command -v gdal_grid >/dev/null; then
    local cmd; cmd=$(gdal_grid_linear "$pts" "$TMP/rep.json" "$TMP/ref.tif")
    tr=$(best 1 $cmd)
    ref="${tr} s ($(rate "$n" "$tr") Mpt/s)"
  else
    ref="n/a (LAS input)"
  fi
  echo "| $label | $n | ${w}×${h} @ $cell | ${tg} s ($(rate "$n" "$tg") Mpt/s, $(rate "$cells" "$tg") Mcell/s) | ${tt} s ($(rate "$n" "$tt") Mpt/s, $(rate "$cells" "$tt") Mcell/s) | $ref |" >> "$OUT"
  echo "rasterize $label: gauss ${tg}s tin ${tt}s reference ${ref}"
}

if [ -d "$FIX" ]; then
  rasterize_row "gmt_ship_03.txt (ship track, lon/lat)" "$FIX/gmt_ship_03.txt" 0.01
  rasterize_row "lidR_Topography.laz (all classes)" "$FIX/lidR_Topography.laz" 0.5
fi
rasterize_row "generated 1 M points, 2 km square" "$TMP/big.xyz" 1

{
echo
echo "gdal_grid's time includes reading the CSV through OGR; ours includes parsing the text and writing the GeoTIFF."
echo "TIN: spade bulk-loaded Delaunay, then every triangle is scan-converted over the cell centres in its"
echo "bounding box (O(points log points + cells)); gdal_grid locates each cell in a qhull triangulation."
echo "Gauss: one pass over the points, (2r+1)² cells each; both outputs are identical to gdal_grid's model"
echo "where checked (tests/raster.rs: tin_matches_gdal_grid_linear)."
echo
echo "## Warp and unwarp (rotation + landmark warp + Gauss splat + dilation fill; default spacing 20 cells)"
echo
echo "| raster | grid | rotation | target grid | warp | unwarp |"
echo "|---|---:|---:|---|---:|---:|"
} >> "$OUT"

warp_row() { # LABEL RASTER
  "$BIN" -q warp "$2" -o "$TMP/w.tif" --report "$TMP/w.json"
  local tw tu
  tw=$(best 3 "$BIN" -q warp "$2" -o "$TMP/w.tif")
  tu=$(best 3 "$BIN" -q unwarp "$TMP/w.tif" -o "$TMP/u.tif")
  local info
  info=$(python3 - "$TMP/w.json" "$2" <<'PY'
import json, subprocess, sys
d = json.load(open(sys.argv[1]))
g = json.loads(subprocess.run(["gdalinfo", "-json", sys.argv[2]], capture_output=True, check=True).stdout)
w, h = g["size"]
print(f"{w}×{h} | {d['rotation_deg']:.1f}° | {d['target_width']}×{d['target_height']} ({d['cells_filled']} filled)")
PY
)
  echo "| $1 | $info | ${tw} s | ${tu} s |" >> "$OUT"
  echo "warp $1: ${tw}s unwarp ${tu}s"
}
if [ -d "$FIX" ]; then
  warp_row "gmt_Kilauea.utm.nc" "$FIX/gmt_Kilauea.utm.nc"
  warp_row "gmt_tut_relief.nc" "$FIX/gmt_tut_relief.nc"
  warp_row "gmt_tut_bathy.nc" "$FIX/gmt_tut_bathy.nc"
fi
warp_row "generated channel 2000×1500 (30°)" "$TMP/channel.asc"
echo >> "$OUT"
echo "bench: wrote $OUT"
