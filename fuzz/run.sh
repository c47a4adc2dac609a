#!/usr/bin/env bash
# fuzz/run.sh SECONDS [TARGET...] — builds geofit's fuzz targets (nightly toolchain, AddressSanitizer,
# SanitizerCoverage: the flags cargo-fuzz passes, without needing cargo-fuzz) and runs each target
# for SECONDS with libFuzzer. Seeds: the committed fuzz/corpus/TARGET plus small shipped fixtures
# (read in place from ../shared, never copied into the project). New corpus entries go to a
# scratch directory; a crash stops with exit 1 and leaves its reproducer in
# fuzz/artifacts/TARGET/ — commit it under fuzz/regressions/TARGET/ with the fix (the crates'
# tests read that folder, e.g. normalize's `fuzz_regressions_do_not_panic`; the runs here seed
# from it too).
set -euo pipefail
cd "$(dirname "$0")"
SECONDS_PER_TARGET="${1:-60}"; shift || true
TARGETS=("$@"); [ ${#TARGETS[@]} -gt 0 ] || TARGETS=(citygml popa3d tmesh obj points grid netcdf las gfim)
SHARED="${GEOFIT_SHARED:-$(cd .. && pwd)/../shared}"
TRIPLE=x86_64-unknown-linux-gnu
export CARGO_TARGET_DIR="${GEOFIT_FUZZ_TARGET_DIR:-$HOME/.cache/geofit/fuzz-target}"
if ! cargo +nightly --version >/dev/null 2>&1; then
  echo "fuzz: no nightly Rust toolchain (rustup toolchain list); libFuzzer needs one" >&2
  exit 3
fi
export RUSTFLAGS="-Cpasses=sancov-module -Cllvm-args=-sanitizer-coverage-level=4 \
 -Cllvm-args=-sanitizer-coverage-inline-8bit-counters -Cllvm-args=-sanitizer-coverage-pc-table \
 -Cllvm-args=-sanitizer-coverage-trace-compares --cfg fuzzing -Zsanitizer=address -Cdebug-assertions -Coverflow-checks"
export RUSTDOCFLAGS="$RUSTFLAGS"
cargo +nightly build --release --locked --target "$TRIPLE" $(printf -- '--bin %s ' "${TARGETS[@]}")
seeds_for() {  # shipped fixtures under 64 KiB that a target's parser reads
  case "$1" in
    citygml) find "$SHARED/fixtures/citygml" ../fixtures -name '*.gml' -size -64k ;;
    popa3d) find ../fixtures -name '*.popa3d' -size -64k ;;
    tmesh) find ../fixtures -name '*.tmesh' -size -64k ;;
    obj) find ../fixtures "$SHARED/fixtures" -name '*.obj' -size -64k ;;
    points) find "$SHARED/fixtures/terrain" ../fixtures -name '*.txt' -size -64k -o -name '*.csv' -size -64k -o -name '*.xyz' -size -64k ;;
    grid) find "$SHARED/fixtures/terrain" ../fixtures -name '*.asc' -size -64k ;;
    netcdf) find "$SHARED/fixtures/terrain" -name '*.nc' -size -64k ;;
    las) find "$SHARED/fixtures/terrain" ../fixtures -name '*.la[sz]' -size -64k ;;
    gfim) find ../fixtures -name '*.gfim' -size -64k ;;
  esac 2>/dev/null | sort | head -n 200
}
scratch=$(mktemp -d); trap 'rm -rf "$scratch"' EXIT
status=0
for t in "${TARGETS[@]}"; do
  mkdir -p "$scratch/$t/new" "$scratch/$t/seeds" "artifacts/$t"
  seeds_for "$t" | while read -r f; do ln -sf "$(cd "$(dirname "$f")" && pwd)/$(basename "$f")" "$scratch/$t/seeds/$(echo "$f" | tr '/' '_')"; done
  dirs=("$scratch/$t/new" "$scratch/$t/seeds"); [ -d "corpus/$t" ] && dirs+=("corpus/$t"); [ -d "regressions/$t" ] && dirs+=("regressions/$t")
  echo "fuzz: $t for ${SECONDS_PER_TARGET} s ($(ls "$scratch/$t/seeds" | wc -l) fixture seeds)"
  if ! "$CARGO_TARGET_DIR/$TRIPLE/release/$t" -max_total_time="$SECONDS_PER_TARGET" -max_len=65536 -rss_limit_mb=2048 \
       -timeout=10 -print_final_stats=1 -artifact_prefix="artifacts/$t/" "${dirs[@]}" 2> "$scratch/$t.log"; then
    tail -n 40 "$scratch/$t.log" >&2
    echo "fuzz: $t FOUND A CRASH: reproducer in fuzz/artifacts/$t/" >&2
    status=1
  else
    grep -E '^stat::number_of_executed_units|^Done' "$scratch/$t.log" | sed "s/^/fuzz: $t: /" || true
  fi
done
exit $status
