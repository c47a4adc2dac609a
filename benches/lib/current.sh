# Sourced by the benches/<area>.sh scripts: the headline figures of one area as tab-separated
# rows in benches/results/<area>.tsv, from which benches/summary.py builds the first table of
# BENCHMARKS.md (issue 39: today's figures, the peer's in the same run, the ratio, date, commit).
#   current_reset AREA                    start the area's file (header only)
#   current_row AREA BENCHMARK FIGURE UNIT [PEER PEER_FIGURE]
# The ratio is FIGURE / PEER_FIGURE ("-" without a peer).
current_reset() {
  mkdir -p benches/results
  printf 'benchmark\tfigure\tunit\tpeer\tpeer_figure\tratio\tdate\tcommit\n' >"benches/results/$1.tsv"
}

current_row() {
  local area="$1" name="$2" fig="$3" unit="$4" peer="${5:--}" pfig="${6:--}" ratio="-"
  if [ "$pfig" != "-" ] && [ -n "$pfig" ]; then
    ratio=$(awk -v a="$fig" -v b="$pfig" 'BEGIN { if (b + 0 == 0) print "-"; else printf "%.2f", a / b }')
  fi
  printf '%s\t%s\t%s\t%s\t%s\t%s\t%s\t%s\n' "$name" "$fig" "$unit" "$peer" "$pfig" "$ratio" \
    "$(date -u +%F)" "$(git rev-parse --short HEAD 2>/dev/null || echo -)" >>"benches/results/$area.tsv"
}
