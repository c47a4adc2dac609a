# The buildings workflow without Snakemake: the same job lines (workflows/jobs.sh) under make.
#
#   make -j2 -f workflows/tiles.mk SOURCES="$(ls data/*.gml)" OUT=out GEOFIT=geofit
#
# The plan's tile ids come in as a Makefile fragment written by `geofit tile plan --format make`
# (make builds it, then restarts with the ids known). Settings travel as the same environment
# variables Snakemake sets (jobs.sh lists them).

SHELL := /bin/bash
JOBS := $(abspath $(dir $(lastword $(MAKEFILE_LIST))))/jobs.sh
OUT ?= out
SOURCES ?=
export GEOFIT ?= geofit
export GEOFIT_BUILDINGS_PER_TILE ?= 2000
export GEOFIT_HEAL_ARGS ?= --precision 3
export GEOFIT_VALIDATE_ARGS ?=
export GEOFIT_TILESET_ARGS ?=

.DELETE_ON_ERROR:
.SECONDARY:

ifneq ($(strip $(RASTER)),)
# The raster pipeline (workflows/raster.smk): RASTER=dem.tif, settings as in jobs.sh.
#   make -j2 -f workflows/tiles.mk RASTER=dem.tif OUT=out GEOFIT_MAX_ERROR=0.5 GEOFIT_TILE_PIXELS=1024
export GEOFIT_MAX_ERROR ?= 0.5
export GEOFIT_TILE_PIXELS ?= 1024
export GEOFIT_FIT_ARGS ?=
export GEOFIT_SURFACE_STEP ?= 4

TILES :=
-include $(OUT)/plan.mk

all: $(OUT)/mosaic.vrt $(OUT)/seams.json $(OUT)/tileset.json $(TILES:%=$(OUT)/eval/%.tif) $(TILES:%=$(OUT)/glb/%.glb)
.PHONY: all
.DEFAULT_GOAL := all

$(OUT)/plan.jsonl: $(RASTER)
	bash $(JOBS) rplan $@ $(RASTER)

$(OUT)/plan.mk: $(RASTER)
	bash $(JOBS) rplanmk $@ $(RASTER)

$(OUT)/fit/%.tmb: $(OUT)/plan.jsonl $(RASTER)
	bash $(JOBS) rfit $(OUT)/plan.jsonl $(RASTER) $* $@

# a stitch reads its neighbours' fits: make waits for all of them (Snakemake for the neighbours only)
$(OUT)/stitched/%.tmb $(OUT)/stitched/%.json: $(TILES:%=$(OUT)/fit/%.tmb)
	bash $(JOBS) stitch $(OUT)/plan.jsonl $(RASTER) $* $(OUT)/fit/$*.tmb $(OUT)/stitched/$*.tmb $(OUT)/stitched/$*.json

$(OUT)/eval/%.tif: $(OUT)/stitched/%.tmb
	bash $(JOBS) reval $< $@

$(OUT)/seams.json: $(TILES:%=$(OUT)/stitched/%.tmb) $(OUT)/plan.mk $(OUT)/zrange.txt
	bash $(JOBS) seams $(OUT)/plan.jsonl $(OUT)/zrange.txt $(OUT)/stitched/$(firstword $(TILES)).tmb $@

$(OUT)/mosaic.vrt: $(TILES:%=$(OUT)/eval/%.tif) $(OUT)/plan.mk
	bash $(JOBS) mosaic $(OUT)/plan.jsonl $(OUT)/eval/$(firstword $(TILES)).tif $@

$(OUT)/zrange.txt: $(RASTER)
	bash $(JOBS) rrange $(RASTER) $@

$(OUT)/glb/%.glb: $(OUT)/stitched/%.tmb $(OUT)/zrange.txt
	bash $(JOBS) rglb $< $(OUT)/zrange.txt $@

$(OUT)/tileset.json: $(TILES:%=$(OUT)/glb/%.glb) $(OUT)/plan.mk
	bash $(JOBS) rtileset $(OUT)/plan.jsonl $(OUT)/glb/$(firstword $(TILES)).glb $@

else
ifeq ($(strip $(SOURCES)),)
$(error give the CityGML files: make -f workflows/tiles.mk SOURCES="a.gml b.gml", or a raster: RASTER=dem.tif)
endif

.DELETE_ON_ERROR:
# every intermediate (extracted and healed tiles) is kept, as Snakemake keeps it
.SECONDARY:

TILES :=
-include $(OUT)/plan.mk

# per-tile deliverables are targets too, so a deleted one is made again (as in the Snakefile)
PRODUCTS := $(foreach t,$(TILES),$(OUT)/healed/$(t).gml $(OUT)/healed/$(t).heal.json $(OUT)/validate/$(t).validate.json $(OUT)/glb/$(t).glb)
all: $(OUT)/report.json $(OUT)/tileset.json $(PRODUCTS)
.PHONY: all
.DEFAULT_GOAL := all

$(OUT)/plan.jsonl: $(SOURCES)
	bash $(JOBS) plan $(OUT) $(SOURCES)

$(OUT)/plan.mk: $(SOURCES)
	bash $(JOBS) planmk $(OUT) $(SOURCES)

$(OUT)/tiles/%.gml: $(OUT)/plan.jsonl $(SOURCES)
	bash $(JOBS) extract $(OUT) $*

$(OUT)/validate/%.validate.json: $(OUT)/tiles/%.gml
	bash $(JOBS) validate $(OUT) $*

# a pattern rule with two targets: one recipe run makes both
$(OUT)/healed/%.gml $(OUT)/healed/%.heal.json: $(OUT)/tiles/%.gml
	bash $(JOBS) heal $(OUT) $*

$(OUT)/glb/%.glb: $(OUT)/healed/%.gml
	bash $(JOBS) export $(OUT) $*

$(OUT)/report.json: $(TILES:%=$(OUT)/healed/%.heal.json) $(TILES:%=$(OUT)/validate/%.validate.json) $(OUT)/plan.mk
	bash $(JOBS) report $(OUT) $(TILES)

$(OUT)/tileset.json: $(TILES:%=$(OUT)/glb/%.glb) $(OUT)/plan.mk
	bash $(JOBS) tileset $(OUT) $(TILES)
endif
