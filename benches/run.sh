#!/usr/bin/env bash
# `make bench`: runs every benches/<area>.sh with the release binary; each prints its figures
# side by side (ours vs a reference or the ceiling) and writes benches/results/<area>.md.
set -uo pipefail
BIN="${1:?usage: run.sh path/to/geofit}"
cd "$(dirname "$0")/.."
status=0
for s in benches/*.sh; do
  [ "$s" = benches/run.sh ] && continue
  echo "== $s"
  bash "$s" "$BIN" || { echo "bench $s failed"; status=1; }
done
# BENCHMARKS.md: today's figures from every benches/results/<area>.tsv (issue 39).
python3 benches/summary.py || status=1
exit $status
