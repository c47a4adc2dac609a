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
# The raster pipeline (docs/decisions.md#raster-tiles-and-seams), SRC any GDAL raster. Every
# raster step reads only the paths it is given and writes only its output path (what Snakemake's
# {input} and {output} are: storage plugins stage them); tile lists come from the plan, never from
# the command line (docs/decisions.md#raster-jobs-read-input-write-output):
#   jobs.sh rplan    PLAN SRC                     → PLAN (JSON lines; tiles without data: work 0)
#   jobs.sh rplanmk  PLAN.mk SRC                  → the make fragment (TILES := ids with data)
#   jobs.sh rfit     PLAN SRC TILE OUT.tmb        → the tile's fit (its window only, read by GDAL)
#   jobs.sh stitch   PLAN SRC TILE FIT.tmb OUT.tmb OUT.json
#                                                 → C0 with its neighbours, whose fits lie beside FIT.tmb
#   jobs.sh reval    IN.tmb OUT.tif               → the surface on the tile's cells
#   jobs.sh seams    PLAN ZRANGE ONE.tmb OUT.json → gap and normal-angle jump per seam (meshes beside ONE.tmb)
#   jobs.sh mosaic   PLAN ONE.tif OUT.vrt         → gdalbuildvrt over the tiles' rasters (beside ONE.tif)
#   jobs.sh rrange   SRC OUT.txt                  → the source's min and max (one colour ramp)
#   jobs.sh rglb     IN.tmb ZRANGE OUT.glb        → the stitched surface, every GEOFIT_SURFACE_STEP
#                                                   cells; tiles share their seam vertices
#   jobs.sh rtileset PLAN ONE.glb OUT.json        → 3D Tiles 1.1 over the tiles' glb (beside ONE.glb)
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

# The ids of a raster plan's tiles with data (work > 0), one a line: the JSON lines geofit writes
# hold "id" first and "work" after the windows, so sed reads them without a JSON tool.
plan_ids() {
    sed -n 's/^{"id":"\([^"]*\)".*"work":\([0-9]*\).*/\1 \2/p' "$1" | awk '$2 > 0 { print $1 }'
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
    mkdir -p "$(dirname "$out")"
    # the plan names the source by an absolute path (a job may run elsewhere); /vsi* and URLs as given
    src=$1
    case $src in /* | *://*) ;; *) src=$PWD/$src ;; esac
    "$GEOFIT" -q tile plan --tile-size "${GEOFIT_TILE_PIXELS:-1024}" --halo 2 -o "$out" "$src"
    ;;
rplanmk)
    mkdir -p "$(dirname "$out")"
    "$GEOFIT" -q tile plan --tile-size "${GEOFIT_TILE_PIXELS:-1024}" --halo 2 --format make -o "$out" "$1"
    ;;
rfit)
    plan=$out src=$1 t=$2 dst=$3
    out=$(dirname "$plan") # the fail-once markers' default place
    fail_once "$t"
    mkdir -p "$(dirname "$dst")"
    read -r -a FIT_ARGS <<<"${GEOFIT_FIT_ARGS:-}"
    "$GEOFIT" -q fit "$src" --plan "$plan" --tile "$t" --max-error "${GEOFIT_MAX_ERROR:-0.5}" "${FIT_ARGS[@]}" -o "$dst"
    ;;
stitch)
    plan=$out src=$1 t=$2 fit=$3 dst=$4 report=$5
    mkdir -p "$(dirname "$dst")" "$(dirname "$report")"
    "$GEOFIT" -q tile stitch "$src" --plan "$plan" --tile "$t" --meshes "$(dirname "$fit")/{id}.tmb" --max-error "${GEOFIT_MAX_ERROR:-0.5}" -o "$dst" --report "$report"
    ;;
reval)
    src=$out dst=$1
    mkdir -p "$(dirname "$dst")"
    "$GEOFIT" -q eval "$src" -o "$dst"
    ;;
seams)
    plan=$out zrange=$1 one=$2 dst=$3
    read -r zmin zmax <"$zrange"
    range=(--z-range "$zmin" "$zmax")
    [ "$zmin" != "$zmax" ] || range=()
    mkdir -p "$(dirname "$dst")"
    "$GEOFIT" -q tile seams "$plan" "${range[@]}" --meshes "$(dirname "$one")/{id}.tmb" -o "$dst"
    ;;
mosaic)
    plan=$out one=$1 dst=$2
    dir=$(dirname "$one")
    tmp="$(dirname "$dst")/.mosaic.$$.vrt" list="$(dirname "$dst")/.mosaic.$$.txt"
    trap 'rm -f "$tmp" "$list"' EXIT
    plan_ids "$plan" | sed "s|.*|$dir/&.tif|" >"$list"
    gdalbuildvrt -q -input_file_list "$list" "$tmp"
    # the VRT names its sources relative to itself: same directory, so the rename keeps them valid
    mv "$tmp" "$dst"
    ;;
rrange)
    src=$out dst=$1
    # runs beside the plan job (it needs only the source), so the directory may not exist yet
    mkdir -p "$(dirname "$dst")"
    tmp=$(mktemp "$(dirname "$dst")/.zrange.XXXXXX")
    trap 'rm -f "$tmp"' EXIT
    # GDAL computes the exact min/max block by block (bounded memory, no .aux.xml written)
    gdalinfo -mm "$src" | sed -n 's/.*Computed Min\/Max=\([^,]*\),\(.*\)$/\1 \2/p' | head -n 1 >"$tmp"
    [ -s "$tmp" ] || { echo "jobs.sh rrange: gdalinfo -mm gave no Min/Max for $src" >&2; exit 1; }
    chmod 644 "$tmp" && mv "$tmp" "$dst"
    ;;
rglb)
    src=$out zrange=$1 dst=$2 step=${GEOFIT_SURFACE_STEP:-4}
    read -r zmin zmax <"$zrange"
    # a flat source (min = max at gdalinfo's 3 decimals) has no ramp to share
    range=(--height-range "$zmin" "$zmax")
    [ "$zmin" != "$zmax" ] || range=()
    mkdir -p "$(dirname "$dst")"
    "$GEOFIT" -q surface "$src" --step "$step" --no-cell-edges "${range[@]}" -o "$dst"
    ;;
rtileset)
    plan=$out one=$1 dst=$2
    dir=$(dirname "$one")
    mapfile -t args < <(plan_ids "$plan" | sed "s|.*|$dir/&.glb|")
    mkdir -p "$(dirname "$dst")"
    "$GEOFIT" -q tile tileset "${TILESET_ARGS[@]}" "${args[@]}" -o "$dst"
    ;;
*)
    echo "jobs.sh: unknown step '$step'" >&2
    exit 2
    ;;
esac
