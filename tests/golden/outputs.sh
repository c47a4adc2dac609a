#!/usr/bin/env bash
# The golden outputs of geofit (issue 16): every README pipeline and every subcommand on the
# shipped fixtures, each output written into the current directory. `tests/golden.rs` runs this
# in an empty directory with `geofit` first on PATH and compares the SHA-256 of every file made
# against tests/golden/outputs.sha256, so a move of code between crates that changes any byte of
# any output fails with the file's name.
#
# Outputs that carry timings or memory (JSON reports with wall_seconds / peak_rss_mib) are
# filtered through `drop_timings` before they are hashed; everything else is hashed as written.
# Re-bless after an intended change: GEOFIT_BLESS=1 cargo test -p geofit --test golden
set -euo pipefail
# Inputs are reached through links in the working directory, so paths written into outputs
# (plans, popa3d sources, reports) are the same on every machine.
ln -s "${GEOFIT_SHARED:?}/fixtures" S
ln -s "${GEOFIT_REPO:?}/fixtures" P
ln -s "$GEOFIT_SHARED/xsd" X
export GEOFIT_SCHEMAS=X
TILE=S/citygml/nrw/LoD2_32_332_5729_1_NW.gml
export RAYON_NUM_THREADS=2

# Reports carry run-dependent numbers (seconds, resident memory, file paths of this run) and the
# OpenCL device's name, which PoCL makes from the machine's CPU ("opencl: Portable Computing
# Language / pthread-<cpu>"): the device is hashed as its kind (opencl, cpu) only; the rest of
# each report is kept and hashed.
drop_timings() {
  python3 -c '
import json, sys
VOLATILE = ("seconds", "wall", "rss", "elapsed", "cpu_s", "peak", "time_s", "duration")
def clean(v, key=""):
    if key == "device" and isinstance(v, str):
        return v.split(":")[0]
    if isinstance(v, dict):
        return {k: clean(x, k) for k, x in v.items() if not any(w in k.lower() for w in VOLATILE)}
    if isinstance(v, list):
        return [clean(x) for x in v]
    return v
text = sys.stdin.read()
try:
    docs = [json.loads(text)]
except ValueError:
    docs = [json.loads(line) for line in text.splitlines() if line.strip()]
for doc in docs:
    print(json.dumps(clean(doc), sort_keys=True))
' <"$1" >"$1.clean" && rm "$1"
}

# --- README: buildings
geofit heal "$TILE" -o healed.gml --report heal.json
geofit convert "$TILE" -o tile.city.json --report convert.json
drop_timings heal.json
# issue 35: buildings heal keeps (a GA01 merge it cannot verify) keep their findings: exit 1
geofit validate healed.gml --json > findings.json || [ $? -eq 1 ]
drop_timings findings.json
geofit export healed.gml -o healed.glb
geofit citygml2popa3d "$TILE" | geofit adjust - --report adjust.json \
  | geofit popa3d2citygml - --template "$TILE" --max-move 1 --keep -o adjusted.gml
drop_timings adjust.json

# --- README: terrain
geofit rasterize "S/terrain/lidR_Topography.laz" --cell 2 -o grid.tif
geofit fit grid.tif --max-error 0.5 --report fit.json -o grid.tmesh
drop_timings fit.json
geofit eval grid.tmesh --like grid.tif -o fitted.tif
geofit diff grid.tif fitted.tif --tolerance 0.5 --check --png err.png --hist hist.png > diff.txt
geofit export grid.tmesh -o grid.glb

# --- README: implicit
geofit implicit generate sphere --noise 0.02 -o sphere.xyz
geofit implicit sphere.xyz -o sphere.glb

# --- every other subcommand, on the fixtures
geofit info "$TILE" --json > info-tile.json
geofit info grid.tif > info-grid.txt
geofit info grid.tmesh > info-tmesh.txt
geofit validate "S/citygml/v3" --no-xsd --json > validate-v3.json || true
drop_timings validate-v3.json
geofit export "$TILE" -o tile.obj
geofit citygml2popa3d "P/citygml/three_storey.gml" -o three.popa3d
geofit adjust three.popa3d -o three-adjusted.popa3d
geofit obj2popa3d "P/popa3d/rooms.obj" -o rooms.popa3d
geofit observe rooms.popa3d --add "P/popa3d/rooms_distances.csv" -o rooms-observed.popa3d
geofit rasterize "S/terrain/gmt_ship_03.txt" --cell 0.05 --method tin -o ship-tin.tif
geofit fit "S/terrain/giswqs-lidar_dem.tif" --max-error 1 --method drag -o lidar-drag.tmb
geofit eval lidar-drag.tmb --device cpu -o lidar-drag.tif
geofit surface grid.tmesh -o grid-surface.obj --step 4
geofit surface grid.tmesh -o grid-error.glb --reference grid.tif
geofit warp grid.tif -o grid.warped.tif
geofit unwarp grid.warped.tif -o grid.back.tif
geofit fit grid.tif --max-error 0.5 --indirect -o grid-indirect.tmesh
geofit eval grid-indirect.tmesh --device cpu -o grid-indirect.tif
geofit fit grid.warped.tif --max-error 0.5 --indirect -o warped-indirect.tmesh
geofit eval grid.tmesh --device cpu --no-mask -o grid-nomask.tif
geofit fit grid.tif --max-error 0.5 --outliers-csv grid-blunders.csv -o /dev/null
geofit tile plan "S/terrain/giswqs-lidar_dem.tif" --tile-size 200 --halo 2 -o raster-plan.jsonl
geofit tile plan S/citygml/nrw/LoD2_32_33*.gml --buildings-per-tile 30 -o city-plan.jsonl
geofit completions bash > completions.bash
geofit man > geofit.1
