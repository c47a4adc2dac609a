# The raster pipeline of workflows/Snakefile (docs/decisions.md#raster-tiles-and-seams):
#   plan → fit(t) → stitch(t) [needs the fits of t and its neighbours] → eval(t) → mosaic.vrt
#                                                                      ├→ seams.json
#   zrange ──────────────────────────────────────────────────────────→ glb(t) → tileset.json
# Every job is one line of workflows/jobs.sh that reads its {input} and writes its {output}
# (storage plugins stage both); tile lists are read from the plan by the job, never passed on the
# command line; the plan is parsed once per workflow run
# (docs/decisions.md#raster-jobs-read-input-write-output). Tiles without data (work 0) have no jobs.

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
JOB = f"env {ENV} bash {JOBS}"

_PLAN = {}


def plan():
    """The plan's tiles with data, by id, and their ids in plan order: parsed once per plan file
    (its path, size and mtime), however often the DAG asks."""
    path = checkpoints.plan.get().output[0]
    st = os.stat(path)
    key = (path, st.st_size, st.st_mtime_ns)
    if key not in _PLAN:
        tiles = {}
        with open(path) as f:
            for line in f:
                if line.strip():
                    t = json.loads(line)
                    if t["work"] > 0:
                        tiles[t["id"]] = t["neighbours"]
        _PLAN.clear()
        _PLAN[key] = (tiles, list(tiles))
    return _PLAN[key]


def tile_ids():
    return plan()[1]


def neighbour_fits(wildcards):
    """A tile's stitch reads its neighbours' first-pass meshes (its own is `fit`)."""
    return [f"{OUT}/fit/{i}.tmb" for i in plan()[0][wildcards.tile]]


def every(pattern):
    return lambda wc: [pattern.format(i) for i in tile_ids()]


# the targets of `rule all` (workflows/Snakefile); the per-tile rasters too, so a deleted one is
# made again
TARGETS = [
    f"{OUT}/mosaic.vrt",
    f"{OUT}/seams.json",
    f"{OUT}/tileset.json",
    every(f"{OUT}/eval/{{}}.tif"),
    every(f"{OUT}/glb/{{}}.glb"),
]


checkpoint plan:
    input:
        RASTER,
    output:
        f"{OUT}/plan.jsonl",
    shell:
        JOB + " rplan {output} {input}"


rule fit:
    input:
        plan=f"{OUT}/plan.jsonl",
        raster=RASTER,
    output:
        f"{OUT}/fit/{{tile}}.tmb",
    shell:
        JOB + " rfit {input.plan} {input.raster} {wildcards.tile} {output}"


rule stitch:
    input:
        neighbour_fits,
        fit=f"{OUT}/fit/{{tile}}.tmb",
        plan=f"{OUT}/plan.jsonl",
        raster=RASTER,
    output:
        mesh=f"{OUT}/stitched/{{tile}}.tmb",
        report=f"{OUT}/stitched/{{tile}}.json",
    shell:
        JOB + " stitch {input.plan} {input.raster} {wildcards.tile} {input.fit} {output.mesh} {output.report}"


rule eval:
    input:
        f"{OUT}/stitched/{{tile}}.tmb",
    output:
        f"{OUT}/eval/{{tile}}.tif",
    shell:
        JOB + " reval {input} {output}"


rule seams:
    input:
        every(f"{OUT}/stitched/{{}}.tmb"),
        plan=f"{OUT}/plan.jsonl",
        zrange=f"{OUT}/zrange.txt",
    output:
        f"{OUT}/seams.json",
    params:
        one=lambda wc, input: input[0],
    shell:
        JOB + " seams {input.plan} {input.zrange} {params.one} {output}"


rule mosaic:
    input:
        every(f"{OUT}/eval/{{}}.tif"),
        plan=f"{OUT}/plan.jsonl",
    output:
        f"{OUT}/mosaic.vrt",
    params:
        one=lambda wc, input: input[0],
    shell:
        JOB + " mosaic {input.plan} {params.one} {output}"


rule zrange:
    input:
        RASTER,
    output:
        f"{OUT}/zrange.txt",
    shell:
        JOB + " rrange {input} {output}"


rule glb:
    input:
        mesh=f"{OUT}/stitched/{{tile}}.tmb",
        zrange=f"{OUT}/zrange.txt",
    output:
        f"{OUT}/glb/{{tile}}.glb",
    shell:
        JOB + " rglb {input.mesh} {input.zrange} {output}"


rule tileset:
    input:
        every(f"{OUT}/glb/{{}}.glb"),
        plan=f"{OUT}/plan.jsonl",
    output:
        f"{OUT}/tileset.json",
    params:
        one=lambda wc, input: input[0],
    shell:
        JOB + " rtileset {input.plan} {params.one} {output}"
