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
# Python tools live in a project-local virtual environment ($(VENV)), never in the system Python:
# `make setup` creates it with the `python3` on PATH and installs the packages the tests use;
# `make bench` adds the peer tools the benchmarks compare against. Make puts $(VENV)/bin first on
# PATH for every recipe, so tests and scripts that call `python3` (or `snakemake`) get the venv's.
VENV ?= $(CURDIR)/.venv
export PATH := $(VENV)/bin:$(PATH)
export GEOFIT_PYTHON := $(VENV)/bin/python3
PIP_TEST_PACKAGES := numpy scipy lxml pymeshlab snakemake jsonschema cjio==0.10.1
PIP_BENCH_PACKAGES := loopstructural pydelatin pymartini
# py3dtiles reads the 3D Tiles tilesets back in the scale-out tests. Installed without its
# dependencies: it pins numpy < 2 (for numba in its point-cloud converter, which the tests do not
# use); its tileset model needs only pyproj and pygltflib.
PY3DTILES_VERSION := 9.0.0
# npm: the Khronos glTF validator. It is a library: tests run it through the small CLI
# tests/scripts/gltf_validator.js, which finds the package in $(NPM_PREFIX) (no PATH wrapper).
NPM_PREFIX := $(HOME)/.cache/geofit/npm
export GEOFIT_NPM_PREFIX := $(NPM_PREFIX)
GLTF_VALIDATOR_VERSION := 2.0.0-dev.3.10

.PHONY: setup setup-apt setup-pip setup-bench setup-npm build release test demo bench clean-demo fuzz lint

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
	@test -x $(VENV)/bin/python3 || { echo "setup: creating the project's Python environment $(VENV)"; python3 -m venv $(VENV); }
	@$(VENV)/bin/python3 -c "import numpy, scipy, lxml, pymeshlab, snakemake, jsonschema, cjio" 2>/dev/null \
	  && echo "setup: Python packages present in $(VENV)" \
	  || { echo "setup: installing into $(VENV): $(PIP_TEST_PACKAGES)"; \
	       $(VENV)/bin/python3 -m pip install -q --disable-pip-version-check $(PIP_TEST_PACKAGES); }
	@$(VENV)/bin/python3 -c "import py3dtiles.tileset" 2>/dev/null \
	  && echo "setup: py3dtiles present in $(VENV)" \
	  || { echo "setup: installing into $(VENV): py3dtiles $(PY3DTILES_VERSION) (without its numpy<2 pin), pyproj, pygltflib"; \
	       $(VENV)/bin/python3 -m pip install -q --disable-pip-version-check pyproj pygltflib \
	       && $(VENV)/bin/python3 -m pip install -q --disable-pip-version-check --no-deps py3dtiles==$(PY3DTILES_VERSION); }
	@# FreeCAD's Python modules (Debian freecad-python3) are built for Debian's own interpreter,
	@# which the FreeCAD checks call as /usr/bin/python3 (read only: nothing is installed into it).
	@/usr/bin/python3 tests/scripts/export_freecad.py --check >/dev/null 2>&1 \
	  && echo "setup: FreeCAD Python modules importable" \
	  || echo "setup: WARNING: FreeCAD (freecad-python3) not importable by /usr/bin/python3"

setup-bench: setup-pip
	@$(VENV)/bin/python3 -c "import pydelatin, pymartini, LoopStructural" 2>/dev/null \
	  && echo "setup: benchmark peers present in $(VENV)" \
	  || { echo "setup: installing benchmark peers into $(VENV): $(PIP_BENCH_PACKAGES)"; \
	       $(VENV)/bin/python3 -m pip install -q --disable-pip-version-check $(PIP_BENCH_PACKAGES); }

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

# The fuzz workspace (fuzz/) is built --locked by `make fuzz`: its lock must follow every path
# dependency the library crates gain. Checked first (0.5 s) instead of after the tests.
test: setup
	@if cargo +nightly --version >/dev/null 2>&1; then \
	  (cd fuzz && cargo +nightly metadata --locked --format-version 1 >/dev/null) || \
	  { echo "test: fuzz/Cargo.lock is stale: run 'cd fuzz && cargo +nightly update --workspace --offline'" >&2; exit 1; }; fi
	python3 tests/scripts/check_citations.py
	$(CARGO) test --workspace --no-fail-fast

demo: setup release
	@bash fixtures/demo.sh "$(BIN)"

bench: setup setup-bench release
	@bash benches/run.sh "$(BIN)"

# Lint (issue 39; docs/decisions.md#lint-gates): rustfmt per rustfmt.toml, clippy with every
# warning denied except the lints listed here (each a reason in the decision), rustdoc with
# warnings denied, and a build with the declared minimum Rust (workspace rust-version) when that
# toolchain is installed (rustup cannot fetch one here; it is reported, not skipped silently).
CLIPPY_ALLOW := -A clippy::neg_cmp_op_on_partial_ord -A clippy::needless_range_loop -A clippy::type_complexity \
  -A clippy::too_many_arguments -A clippy::excessive_precision -A clippy::collapsible_match -A clippy::large_enum_variant
MSRV := $(shell sed -n 's/^rust-version = "\(.*\)"/\1/p' Cargo.toml)
lint:
	python3 docs/index_decisions.py --check
	python3 benches/summary.py --check
	python3 tests/scripts/code_shape.py
	$(CARGO) fmt --all -- --check
	$(CARGO) clippy --workspace --all-targets -- -D warnings $(CLIPPY_ALLOW)
	RUSTDOCFLAGS="-D warnings" $(CARGO) doc --workspace --no-deps -q
	@if rustc --version | grep -q "^rustc $(MSRV) "; then \
	  echo "lint: the default toolchain is the declared minimum Rust $(MSRV): the builds above are the MSRV build"; \
	elif rustup toolchain list 2>/dev/null | grep -q "^$(MSRV)"; then \
	  echo "lint: building with the declared minimum Rust $(MSRV)"; $(CARGO) +$(MSRV) check --workspace -q; \
	else echo "lint: toolchain $(MSRV) (declared rust-version) not installed: MSRV build not run" >&2; \
	  [ "$$CI" != true ] || exit 1; fi

# Fuzzing (issue 13): every parser target for FUZZ_SECONDS each, nightly toolchain + libFuzzer
# (fuzz/run.sh; crash reproducers land in fuzz/artifacts/). CI runs it for 60 s per target.
FUZZ_SECONDS ?= 60
fuzz:
	@bash fuzz/run.sh $(FUZZ_SECONDS)
