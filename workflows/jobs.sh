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
# Every output is written atomically (geofit writes a temporary file and renames it; the one
# stdout capture below does the same), so a killed job leaves no half-written file.
#
# Environment: GEOFIT (binary, default `geofit`), GEOFIT_BUILDINGS_PER_TILE (2000),
# GEOFIT_HEAL_ARGS (`--precision 3`: heal writes new numbers with the decimals of its input
# document, and a tile mixes documents — fixing them keeps per-building bytes independent of the
# tiling), GEOFIT_VALIDATE_ARGS, GEOFIT_TILESET_ARGS (e.g. `--crs EPSG:25832`).
#
# Fault injection for tests: GEOFIT_FAIL_ONCE=TILE makes the heal job of TILE fail once: the
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
    findings_ok "$GEOFIT" -q export "$out/healed/$t.gml" -o "$out/glb/$t.glb"
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
*)
    echo "jobs.sh: unknown step '$step'" >&2
    exit 2
    ;;
esac
