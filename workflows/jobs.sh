#!/usr/bin/env bash
# The jobs of the buildings workflow, one `geofit …` line each. Snakemake (workflows/Snakefile),
# make (workflows/tiles.mk), a Slurm array, GNU parallel or Spark's RDD.pipe all run these same
# lines (workflows/README.md), so their outputs are the same bytes.
#
#   jobs.sh plan     OUT SOURCE.gml...   → OUT/plan.jsonl
#   jobs.sh planmk   OUT SOURCE.gml...   → OUT/plan.mk   (TILES := ..., for make)
#   jobs.sh extract  OUT TILE            → OUT/tiles/TILE.gml
#   jobs.sh validate OUT TILE            → OUT/validate/TILE.validate.json
#   jobs.sh heal     OUT TILE            → OUT/healed/TILE.gml + OUT/healed/TILE.heal.json
#   jobs.sh export   OUT TILE            → OUT/glb/TILE.glb
#   jobs.sh report   OUT TILE...         → OUT/report.json
#   jobs.sh tileset  OUT TILE...         → OUT/tileset.json
#   jobs.sh tile     OUT TILE            → extract, validate, heal, export of one tile (skips done steps)
#
# The raster pipeline (docs/decisions.md#raster-tiles-and-seams), SRC any GDAL raster:
#   jobs.sh rplan    OUT SRC             → OUT/plan.jsonl (core windows of GEOFIT_TILE_PIXELS)
#   jobs.sh rplanmk  OUT SRC             → OUT/plan.mk
#   jobs.sh rfit     OUT SRC TILE        → OUT/fit/TILE.tmb (the tile's window only, read by GDAL)
#   jobs.sh stitch   OUT SRC TILE        → OUT/stitched/TILE.tmb (+ .json): C0 with its neighbours
#   jobs.sh reval    OUT TILE            → OUT/eval/TILE.tif (the surface on the tile's cells)
#   jobs.sh seams    OUT                 → OUT/seams.json (gap and normal-angle jump per seam)
#   jobs.sh mosaic   OUT TILE...         → OUT/mosaic.vrt (gdalbuildvrt over the tiles' rasters)
#   jobs.sh rrange   OUT SRC             → OUT/zrange.txt (the source's min and max: one colour ramp)
#   jobs.sh rglb     OUT TILE            → OUT/glb/TILE.glb (the stitched surface, every
#                                          GEOFIT_SURFACE_STEP cells; tiles share their seam vertices)
#   jobs.sh rtileset OUT TILE...         → OUT/tileset.json (3D Tiles 1.1 over the tiles' glb)
#
# Every output is written atomically (geofit writes a temporary file and renames it; the one
# stdout capture below does the same), so a killed job leaves no half-written file.
#
# Environment: GEOFIT (binary, default `geofit`), GEOFIT_BUILDINGS_PER_TILE (2000),
# GEOFIT_HEAL_ARGS (`--precision 3`: heal writes new numbers with the decimals of its input
# document, and a tile mixes documents — fixing them keeps per-building bytes independent of the
# tiling), GEOFIT_VALIDATE_ARGS, GEOFIT_TILESET_ARGS (e.g. `--crs EPSG:25832`).
#
# Raster settings: GEOFIT_MAX_ERROR (0.5), GEOFIT_TILE_PIXELS (1024), GEOFIT_FIT_ARGS (''),
# GEOFIT_SURFACE_STEP (4; must divide GEOFIT_TILE_PIXELS so that adjacent tiles' glb share the
# vertices along their seam), GEOFIT_TILESET_ARGS as for buildings.
#
# Fault injection for tests: GEOFIT_FAIL_ONCE=TILE makes the heal job (raster: the fit job) of
# TILE fail once: the
# first attempt creates the marker $GEOFIT_FAIL_ONCE_DIR/TILE (default OUT/.fail-once) and exits
# 75; later attempts find the marker and run normally.
set -euo pipefail

GEOFIT=${GEOFIT:-geofit}
BPT=${GEOFIT_BUILDINGS_PER_TILE:-2000}
read -r -a HEAL_ARGS <<<"${GEOFIT_HEAL_ARGS---precision 3}"
read -r -a VALIDATE_ARGS <<<"${GEOFIT_VALIDATE_ARGS:-}"
read -r -a TILESET_ARGS <<<"${GEOFIT_TILESET_ARGS:-}"

step=${1:?usage: jobs.sh STEP OUT [TILE|SOURCES...]}
out=${2:?usage: jobs.sh STEP OUT [TILE|SOURCES...]}
shift 2

# Exit status 1 of validate (findings) and export (polygons skipped) is a result, listed in the
# output; anything above is a failed job.
findings_ok() {
    local rc=0
    "$@" || rc=$?
    [ "$rc" -le 1 ] || exit "$rc"
}

fail_once() {
    local tile=$1 dir=${GEOFIT_FAIL_ONCE_DIR:-$out/.fail-once}
    if [ "${GEOFIT_FAIL_ONCE:-}" = "$tile" ] && [ ! -e "$dir/$tile" ]; then
        mkdir -p "$dir" && : >"$dir/$tile"
        echo "jobs.sh: GEOFIT_FAIL_ONCE=$tile: injected failure of the heal job (once)" >&2
        exit 75
    fi
}

case $step in
plan)
    mkdir -p "$out"
    "$GEOFIT" -q tile plan --buildings-per-tile "$BPT" -o "$out/plan.jsonl" "$@"
    ;;
planmk)
    mkdir -p "$out"
    "$GEOFIT" -q tile plan --buildings-per-tile "$BPT" --format make -o "$out/plan.mk" "$@"
    ;;
extract)
    t=$1
    mkdir -p "$out/tiles"
    "$GEOFIT" -q tile extract "$out/plan.jsonl" --tile "$t" -o "$out/tiles/$t.gml"
    ;;
validate)
    t=$1
    mkdir -p "$out/validate"
    tmp=$(mktemp "$out/validate/.$t.XXXXXX")
    trap 'rm -f "$tmp"' EXIT
    findings_ok "$GEOFIT" -q validate --json "${VALIDATE_ARGS[@]}" "$out/tiles/$t.gml" >"$tmp"
    chmod 644 "$tmp" && mv "$tmp" "$out/validate/$t.validate.json"
    ;;
heal)
    t=$1
    fail_once "$t"
    mkdir -p "$out/healed"
    "$GEOFIT" -q heal "${HEAL_ARGS[@]}" "$out/tiles/$t.gml" -o "$out/healed/$t.gml" --report "$out/healed/$t.heal.json"
    ;;
export)
    t=$1
    mkdir -p "$out/glb"
    # --keep-partial: a tile with a polygon export cannot triangulate (exit 1, listed) is
    # still delivered without that polygon
    findings_ok "$GEOFIT" -q --keep-partial export "$out/healed/$t.gml" -o "$out/glb/$t.glb"
    ;;
report)
    args=()
    for t in "$@"; do args+=("$out/healed/$t.heal.json" "$out/validate/$t.validate.json"); done
    "$GEOFIT" -q tile report "${args[@]}" -o "$out/report.json"
    ;;
tileset)
    args=()
    for t in "$@"; do args+=("$out/glb/$t.glb"); done
    "$GEOFIT" -q tile tileset "${TILESET_ARGS[@]}" "${args[@]}" -o "$out/tileset.json"
    ;;
tile)
    t=$1 here=$0
    [ -e "$out/tiles/$t.gml" ] || bash "$here" extract "$out" "$t"
    [ -e "$out/validate/$t.validate.json" ] || bash "$here" validate "$out" "$t"
    [ -e "$out/healed/$t.heal.json" ] || bash "$here" heal "$out" "$t"
    [ -e "$out/glb/$t.glb" ] || bash "$here" export "$out" "$t"
    ;;
rplan)
    mkdir -p "$out"
    "$GEOFIT" -q tile plan --tile-size "${GEOFIT_TILE_PIXELS:-1024}" --halo 2 -o "$out/plan.jsonl" "$1"
    ;;
rplanmk)
    mkdir -p "$out"
    "$GEOFIT" -q tile plan --tile-size "${GEOFIT_TILE_PIXELS:-1024}" --halo 2 --format make -o "$out/plan.mk" "$1"
    ;;
rfit)
    src=$1 t=$2
    fail_once "$t"
    mkdir -p "$out/fit"
    read -r -a FIT_ARGS <<<"${GEOFIT_FIT_ARGS:-}"
    "$GEOFIT" -q fit "$src" --plan "$out/plan.jsonl" --tile "$t" --max-error "${GEOFIT_MAX_ERROR:-0.5}" "${FIT_ARGS[@]}" -o "$out/fit/$t.tmb"
    ;;
stitch)
    src=$1 t=$2
    mkdir -p "$out/stitched"
    "$GEOFIT" -q tile stitch "$src" --plan "$out/plan.jsonl" --tile "$t" --meshes "$out/fit/{id}.tmb" --max-error "${GEOFIT_MAX_ERROR:-0.5}" -o "$out/stitched/$t.tmb" --report "$out/stitched/$t.json"
    ;;
reval)
    t=$1
    mkdir -p "$out/eval"
    "$GEOFIT" -q eval "$out/stitched/$t.tmb" -o "$out/eval/$t.tif"
    ;;
seams)
    "$GEOFIT" -q tile seams "$out/plan.jsonl" --meshes "$out/stitched/{id}.tmb" -o "$out/seams.json"
    ;;
mosaic)
    args=()
    for t in "$@"; do args+=("$out/eval/$t.tif"); done
    tmp="$out/.mosaic.$$.vrt"
    trap 'rm -f "$tmp"' EXIT
    gdalbuildvrt -q "$tmp" "${args[@]}"
    # the VRT names its sources relative to itself: same directory, so the rename keeps them valid
    mv "$tmp" "$out/mosaic.vrt"
    ;;
rrange)
    src=$1
    # runs beside the plan job (it needs only the source), so OUT may not exist yet
    mkdir -p "$out"
    tmp=$(mktemp "$out/.zrange.XXXXXX")
    trap 'rm -f "$tmp"' EXIT
    # GDAL computes the exact min/max block by block (bounded memory, no .aux.xml written)
    gdalinfo -mm "$src" | sed -n 's/.*Computed Min\/Max=\([^,]*\),\(.*\)$/\1 \2/p' | head -n 1 >"$tmp"
    [ -s "$tmp" ] || { echo "jobs.sh rrange: gdalinfo -mm gave no Min/Max for $src" >&2; exit 1; }
    chmod 644 "$tmp" && mv "$tmp" "$out/zrange.txt"
    ;;
rglb)
    t=$1 step=${GEOFIT_SURFACE_STEP:-4}
    read -r zmin zmax <"$out/zrange.txt"
    # a flat source (min = max at gdalinfo's 3 decimals) has no ramp to share
    range=(--height-range "$zmin" "$zmax")
    [ "$zmin" != "$zmax" ] || range=()
    mkdir -p "$out/glb"
    "$GEOFIT" -q surface "$out/stitched/$t.tmb" --step "$step" --no-cell-edges "${range[@]}" -o "$out/glb/$t.glb"
    ;;
rtileset)
    args=()
    for t in "$@"; do args+=("$out/glb/$t.glb"); done
    "$GEOFIT" -q tile tileset "${TILESET_ARGS[@]}" "${args[@]}" -o "$out/tileset.json"
    ;;
*)
    echo "jobs.sh: unknown step '$step'" >&2
    exit 2
    ;;
esac
