# The raster pipeline of workflows/Snakefile (docs/decisions.md#raster-tiles-and-seams):
#   plan → fit(t) → stitch(t) [needs the fits of t and its neighbours] → eval(t) → mosaic.vrt
#                                                                      ├→ seams.json
#   zrange ──────────────────────────────────────────────────────────→ glb(t) → tileset.json
# Every job is one line of workflows/jobs.sh.

import json
import os

RASTER = config["raster"]
OUT = config.get("out", "out")
JOBS = os.path.join(workflow.basedir, "jobs.sh")
ENV = " ".join(
    f"{k}={json.dumps(str(v))}"
    for k, v in [
        ("GEOFIT", config.get("geofit", "geofit")),
        ("GEOFIT_MAX_ERROR", config.get("max_error", 0.5)),
        ("GEOFIT_TILE_PIXELS", config.get("tile_pixels", 1024)),
        ("GEOFIT_FIT_ARGS", config.get("fit_args", "")),
        ("GEOFIT_SURFACE_STEP", config.get("surface_step", 4)),
        ("GEOFIT_TILESET_ARGS", config.get("tileset_args", "")),
    ]
)


def plan_tiles():
    """The plan's tiles (known once the plan checkpoint has run)."""
    with open(checkpoints.plan.get().output[0]) as f:
        return [json.loads(line) for line in f if line.strip()]


def tile_ids():
    return [t["id"] for t in plan_tiles()]


def stitch_inputs(wildcards):
    """A tile's stitch reads its own first-pass mesh and its neighbours'."""
    t = next(t for t in plan_tiles() if t["id"] == wildcards.tile)
    return [f"{OUT}/fit/{i}.tmb" for i in [t["id"]] + t["neighbours"]]


# the targets of `rule all` (workflows/Snakefile); the per-tile rasters too, so a deleted one is
# made again
TARGETS = [
    f"{OUT}/mosaic.vrt",
    f"{OUT}/seams.json",
    f"{OUT}/tileset.json",
    lambda wc: expand(f"{OUT}/eval/{{tile}}.tif", tile=tile_ids()),
    lambda wc: expand(f"{OUT}/glb/{{tile}}.glb", tile=tile_ids()),
]


checkpoint plan:
    input:
        RASTER,
    output:
        f"{OUT}/plan.jsonl",
    params:
        env=ENV,
        jobs=JOBS,
        out=OUT,
    shell:
        "env {params.env} bash {params.jobs} rplan {params.out} {input}"


rule fit:
    input:
        plan=f"{OUT}/plan.jsonl",
        raster=RASTER,
    output:
        f"{OUT}/fit/{{tile}}.tmb",
    params:
        env=ENV,
        jobs=JOBS,
        out=OUT,
    shell:
        "env {params.env} bash {params.jobs} rfit {params.out} {input.raster} {wildcards.tile}"


rule stitch:
    input:
        stitch_inputs,
        plan=f"{OUT}/plan.jsonl",
        raster=RASTER,
    output:
        mesh=f"{OUT}/stitched/{{tile}}.tmb",
        report=f"{OUT}/stitched/{{tile}}.json",
    params:
        env=ENV,
        jobs=JOBS,
        out=OUT,
    shell:
        "env {params.env} bash {params.jobs} stitch {params.out} {input.raster} {wildcards.tile}"


rule eval:
    input:
        f"{OUT}/stitched/{{tile}}.tmb",
    output:
        f"{OUT}/eval/{{tile}}.tif",
    params:
        env=ENV,
        jobs=JOBS,
        out=OUT,
    shell:
        "env {params.env} bash {params.jobs} reval {params.out} {wildcards.tile}"


rule seams:
    input:
        lambda wc: expand(f"{OUT}/stitched/{{tile}}.tmb", tile=tile_ids()),
    output:
        f"{OUT}/seams.json",
    params:
        env=ENV,
        jobs=JOBS,
        out=OUT,
    shell:
        "env {params.env} bash {params.jobs} seams {params.out}"


rule mosaic:
    input:
        lambda wc: expand(f"{OUT}/eval/{{tile}}.tif", tile=tile_ids()),
    output:
        f"{OUT}/mosaic.vrt",
    params:
        env=ENV,
        jobs=JOBS,
        out=OUT,
        tiles=lambda wc: " ".join(tile_ids()),
    shell:
        "env {params.env} bash {params.jobs} mosaic {params.out} {params.tiles}"


rule zrange:
    input:
        RASTER,
    output:
        f"{OUT}/zrange.txt",
    params:
        env=ENV,
        jobs=JOBS,
        out=OUT,
    shell:
        "env {params.env} bash {params.jobs} rrange {params.out} {input}"


rule glb:
    input:
        mesh=f"{OUT}/stitched/{{tile}}.tmb",
        zrange=f"{OUT}/zrange.txt",
    output:
        f"{OUT}/glb/{{tile}}.glb",
    params:
        env=ENV,
        jobs=JOBS,
        out=OUT,
    shell:
        "env {params.env} bash {params.jobs} rglb {params.out} {wildcards.tile}"


rule tileset:
    input:
        lambda wc: expand(f"{OUT}/glb/{{tile}}.glb", tile=tile_ids()),
    output:
        f"{OUT}/tileset.json",
    params:
        env=ENV,
        jobs=JOBS,
        out=OUT,
        tiles=lambda wc: " ".join(tile_ids()),
    shell:
        "env {params.env} bash {params.jobs} rtileset {params.out} {params.tiles}"
