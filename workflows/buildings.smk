# The buildings pipeline of workflows/Snakefile (included when no raster is configured).

import glob
import json
import os

SOURCES = sorted(glob.glob(config["sources"])) if "sources" in config else []
if not SOURCES:
    raise ValueError("config 'sources': no CityGML file matches (give --config sources='dir/*.gml')")
OUT = config.get("out", "out")
JOBS = os.path.join(workflow.basedir, "jobs.sh")
# The job lines read their settings from these variables (jobs.sh); set here so every engine
# that runs the lines sees the same ones.
ENV = " ".join(
    f"{k}={json.dumps(str(v))}"
    for k, v in [
        ("GEOFIT", config.get("geofit", "geofit")),
        ("GEOFIT_BUILDINGS_PER_TILE", config.get("buildings_per_tile", 2000)),
        ("GEOFIT_HEAL_ARGS", config.get("heal_args", "--precision 3")),
        ("GEOFIT_VALIDATE_ARGS", config.get("validate_args", "")),
        ("GEOFIT_TILESET_ARGS", config.get("tileset_args", "")),
    ]
)


def tile_ids():
    """The tile ids of the plan (known once the plan checkpoint has run)."""
    with open(checkpoints.plan.get().output[0]) as f:
        return [json.loads(line)["id"] for line in f if line.strip()]


def products(wildcards):
    """Per-tile deliverables: targets of `all`, so a deleted one is made again (Snakemake does
    not redo a missing intermediate whose consumers are up to date)."""
    return expand(
        [f"{OUT}/healed/{{tile}}.gml", f"{OUT}/healed/{{tile}}.heal.json", f"{OUT}/validate/{{tile}}.validate.json", f"{OUT}/glb/{{tile}}.glb"],
        tile=tile_ids(),
    )


# the targets of `rule all` (workflows/Snakefile)
TARGETS = [f"{OUT}/report.json", f"{OUT}/tileset.json", products]


checkpoint plan:
    input:
        SOURCES,
    output:
        f"{OUT}/plan.jsonl",
    params:
        env=ENV,
        jobs=JOBS,
        out=OUT,
    shell:
        "env {params.env} bash {params.jobs} plan {params.out} {input}"


rule extract:
    input:
        plan=f"{OUT}/plan.jsonl",
        sources=SOURCES,
    output:
        f"{OUT}/tiles/{{tile}}.gml",
    params:
        env=ENV,
        jobs=JOBS,
        out=OUT,
    shell:
        "env {params.env} bash {params.jobs} extract {params.out} {wildcards.tile}"


rule validate:
    input:
        f"{OUT}/tiles/{{tile}}.gml",
    output:
        f"{OUT}/validate/{{tile}}.validate.json",
    params:
        env=ENV,
        jobs=JOBS,
        out=OUT,
    shell:
        "env {params.env} bash {params.jobs} validate {params.out} {wildcards.tile}"


rule heal:
    input:
        f"{OUT}/tiles/{{tile}}.gml",
    output:
        gml=f"{OUT}/healed/{{tile}}.gml",
        report=f"{OUT}/healed/{{tile}}.heal.json",
    params:
        env=ENV,
        jobs=JOBS,
        out=OUT,
    shell:
        "env {params.env} bash {params.jobs} heal {params.out} {wildcards.tile}"


rule export:
    input:
        f"{OUT}/healed/{{tile}}.gml",
    output:
        f"{OUT}/glb/{{tile}}.glb",
    params:
        env=ENV,
        jobs=JOBS,
        out=OUT,
    shell:
        "env {params.env} bash {params.jobs} export {params.out} {wildcards.tile}"


rule report:
    input:
        heal=lambda wc: expand(f"{OUT}/healed/{{tile}}.heal.json", tile=tile_ids()),
        validate=lambda wc: expand(f"{OUT}/validate/{{tile}}.validate.json", tile=tile_ids()),
    output:
        f"{OUT}/report.json",
    params:
        env=ENV,
        jobs=JOBS,
        out=OUT,
        tiles=lambda wc: " ".join(tile_ids()),
    shell:
        "env {params.env} bash {params.jobs} report {params.out} {params.tiles}"


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
        "env {params.env} bash {params.jobs} tileset {params.out} {params.tiles}"
