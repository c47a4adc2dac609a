# geofit — set-up, build, test, demo and benchmarks.
# `make demo` and `make test` each start with `setup`, so one command works on a fresh machine.

SHELL := /bin/bash
# A persistent target directory outside the clone: repeated runs (and fresh CI clones) reuse builds.
export CARGO_TARGET_DIR ?= $(HOME)/.cache/geofit/target
CARGO ?= cargo
BIN := $(CARGO_TARGET_DIR)/release/geofit
SHARED ?= $(abspath ../shared)
export GEOFIT_SHARED := $(SHARED)

# Debian packages the project uses (libraries it links and tools its tests call).
APT_PACKAGES := pkg-config libgdal-dev gdal-bin libproj-dev proj-bin ocl-icd-opencl-dev \
  pocl-opencl-icd clinfo libxml2-utils libxml2-dev libclang-dev python3-numpy freecad-python3 nodejs time
# Python packages for independent checks and reference tools.
PIP_PACKAGES := numpy scipy lxml pymeshlab trimesh loopstructural pydelatin pymartini
# npm: the Khronos glTF validator. It is a library: tests run it through the small CLI
# tests/scripts/gltf_validator.js, which finds the package in $(NPM_PREFIX) (no PATH wrapper).
NPM_PREFIX := $(HOME)/.cache/geofit/npm
export GEOFIT_NPM_PREFIX := $(NPM_PREFIX)
GLTF_VALIDATOR_VERSION := 2.0.0-dev.3.10

.PHONY: setup setup-apt setup-pip setup-npm build release test demo bench clean-demo

setup: setup-apt setup-pip setup-npm

setup-apt:
	@missing=""; for p in $(APT_PACKAGES); do \
	  dpkg-query -W -f='$${Status}' $$p 2>/dev/null | grep -q "install ok installed" || missing="$$missing $$p"; \
	done; \
	if [ -n "$$missing" ]; then \
	  echo "setup: installing Debian packages:$$missing"; \
	  SUDO=""; [ "$$(id -u)" = 0 ] || SUDO=sudo; \
	  $$SUDO apt-get update -qq && DEBIAN_FRONTEND=noninteractive $$SUDO apt-get install -y -qq --no-install-recommends $$missing >/dev/null; \
	else echo "setup: Debian packages present"; fi

setup-pip:
	@python3 -c "import numpy, scipy, lxml, pymeshlab, trimesh, pydelatin, pymartini, LoopStructural" 2>/dev/null \
	  && echo "setup: Python packages present" \
	  || { echo "setup: installing Python packages: $(PIP_PACKAGES)"; \
	       python3 -m pip --version >/dev/null 2>&1 || { SUDO=""; [ "$$(id -u)" = 0 ] || SUDO=sudo; \
	         $$SUDO apt-get install -y -qq --no-install-recommends python3-pip >/dev/null; }; \
	       PIP_BREAK_SYSTEM_PACKAGES=1 python3 -m pip install -q $(PIP_PACKAGES); }
	@# FreeCAD's Python modules (Debian freecad-python3) are built for the system interpreter.
	@/usr/bin/python3 tests/scripts/export_freecad.py --check >/dev/null 2>&1 \
	  && echo "setup: FreeCAD Python modules importable" \
	  || echo "setup: WARNING: FreeCAD (freecad-python3) not importable by /usr/bin/python3"

setup-npm:
	@node tests/scripts/gltf_validator.js --version >/dev/null 2>&1 && echo "setup: gltf-validator present" || { \
	  command -v npm >/dev/null || { SUDO=""; [ "$$(id -u)" = 0 ] || SUDO=sudo; \
	    $$SUDO apt-get install -y -qq --no-install-recommends npm >/dev/null; }; \
	  echo "setup: installing npm gltf-validator into $(NPM_PREFIX)"; mkdir -p $(NPM_PREFIX); \
	  npm install -g --silent --prefix $(NPM_PREFIX) gltf-validator@$(GLTF_VALIDATOR_VERSION) >/dev/null && \
	  node tests/scripts/gltf_validator.js --version >/dev/null; }

build: setup
	$(CARGO) build --workspace

release: setup
	$(CARGO) build --release -p geofit

test: setup
	$(CARGO) test --workspace --no-fail-fast

demo: setup release
	@bash fixtures/demo.sh "$(BIN)"

bench: setup release
	@bash benches/run.sh "$(BIN)"
