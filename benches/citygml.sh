#!/usr/bin/env bash
# CityGML reading: parse throughput (MB/s) and peak memory on the largest fixtures, side by side
# with a bare quick-xml tokenizer pass over the same bytes (the ceiling: events only, nothing
# decoded). Also a ~100 MB tile made of repeated NRW buildings, to show that the object stream
# (`geofit info`) keeps memory at "file bytes + one building" while a whole model grows.
# Writes benches/results/citygml.md. Usage: benches/citygml.sh path/to/geofit
set -euo pipefail
BIN="${1:?usage: citygml.sh path/to/geofit}"
cd "$(dirname "$0")/.."
SHARED="${GEOFIT_SHARED:-../shared}"
FIX="$SHARED/fixtures/citygml"
[ -d "$FIX" ] || { echo "citygml bench: $FIX missing, skipped"; exit 0; }
OUT=benches/results/citygml.md
export CARGO_TARGET_DIR="${CARGO_TARGET_DIR:-$HOME/.cache/geofit/target}"
# The tokenizer ceiling and the library passes live in an example of citygml-io
# (CITYGML_BENCH=path skips the build, e.g. to reuse a binary while cargo's lock is busy).
EX="${CITYGML_BENCH:-$CARGO_TARGET_DIR/release/examples/citygml_bench}"
[ -n "${CITYGML_BENCH:-}" ] || cargo build --release -q -p citygml-io --example citygml_bench
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT

# The ~100 MB tile: the members of the largest NRW tile repeated (ids repeat, but every XLink of
# an NRW building points into the building itself, so each copy resolves on its own).
python3 - "$FIX/nrw/LoD2_32_332_5729_1_NW.gml" "$TMP/nrw_x85.gml" <<'PY'
import sys
s = open(sys.argv[1], "rb").read()
a = s.index(b"<core:cityObjectMember>")
b = s.rindex(b"</core:cityObjectMember>") + len(b"</core:cityObjectMember>")
open(sys.argv[2], "wb").write(s[:a] + s[a:b] * 85 + s[b:])
PY

# peak resident set (MiB) of one run
peak() {
  if [ -x /usr/bin/time ]; then
    /usr/bin/time -f '%M' "$@" 2>&1 >/dev/null | tail -1 | awk '{printf "%.1f", $1/1024}'
  else
    echo "n/a"
  fi
}
mbs() { REPEAT=${REPEAT:-7} "$EX" "$1" "${@:2}" | awk '{print $2}'; }

mapfile -t BIG < <(ls -S "$FIX"/*/*.gml "$FIX"/*/*/*.gml 2>/dev/null | head -4)
{
  echo "# CityGML reading: throughput and memory"
  echo
  echo "Machine: $(nproc) cores, $(grep -m1 'model name' /proc/cpuinfo | cut -d: -f2 | sed 's/^ *//'); load average $(cut -d' ' -f1-3 /proc/loadavg)."
  echo "Best of ${REPEAT:-7} runs of each pass over bytes already in memory (\`citygml-io/examples/citygml_bench.rs\`)."
  echo "*tokenize* = bare quick-xml event loop (the ceiling); *parse* = \`citygml_io::parse\` (whole model, XLinks"
  echo "resolved); *stream* = \`ObjectStream\` (one top-level object at a time). Peak RSS from \`/usr/bin/time -v\`-style"
  echo "\`%M\`, one run each; *info* = \`geofit info\` (stream + counts, file read into memory)."
  echo
  echo "*tokenize+numbers* = the ceiling plus std f64 parsing of every text token: the cost any reader that"
  echo "decodes the coordinates pays on top of the tokenizer."
  echo
  echo "| file | MB | tokenize MB/s | tokenize+numbers MB/s | parse MB/s | stream MB/s | parse / ceiling | parse / (tokenize+numbers) | RSS tokenize MiB | RSS parse MiB | RSS info MiB |"
  echo "|---|---|---|---|---|---|---|---|---|---|---|"
  for f in "${BIG[@]}" "$TMP/nrw_x85.gml"; do
    size=$(stat -c %s "$f")
    t=$(mbs tokenize "$f"); n=$(mbs numbers "$f"); p=$(mbs parse "$f"); s=$(mbs stream "$f")
    ratio=$(awk -v p="$p" -v t="$t" 'BEGIN{printf "%.0f %%", 100*p/t}')
    ratio2=$(awk -v p="$p" -v t="$n" 'BEGIN{printf "%.0f %%", 100*p/t}')
    rt=$(REPEAT=1 peak "$EX" tokenize "$f"); rp=$(REPEAT=1 peak "$EX" parse "$f"); ri=$(peak "$BIN" info "$f")
    name=${f#"$FIX/"}; [ "$f" = "$TMP/nrw_x85.gml" ] && name="nrw/LoD2_32_332_5729 members ×85 (synthetic)"
    printf '| %s | %.1f | %s | %s | %s | %s | %s | %s | %s | %s | %s |\n' "$name" "$(echo "$size/1000000" | bc -l)" "$t" "$n" "$p" "$s" "$ratio" "$ratio2" "$rt" "$rp" "$ri"
  done
  echo
  echo "Reading: the bare tokenizer only finds '<' and '>' (memchr over the coordinate texts), so decoding the"
  echo "numbers alone already costs several times the tokenizer pass (column *tokenize+numbers*); the target"
  echo "\"parse ≥ 50 % of the tokenizer ceiling\" is therefore out of reach for any reader that decodes coordinates."
  echo "Memory: \`geofit info\` (object stream) stays at file bytes + the binary's ~37 MiB baseline (GDAL/PROJ linked),"
  echo "while a whole-document model (*RSS parse*) grows to ~3.3× the file size."
} | tee "$OUT.tmp"
mv "$OUT.tmp" "$OUT"
echo "wrote $OUT"
