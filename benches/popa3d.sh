#!/usr/bin/env bash
# Conversion time and peak memory of `geofit citygml2popa3d` on every NRW fixture tile (the largest
# is LoD2_32_332_5729_1_NW, 1.2 MB, 75 solids), next to the time `geofit info` needs just to parse the
# same file (the floor any conversion pays). Writes benches/results/popa3d.md.
set -euo pipefail
BIN="${1:?usage: benches/popa3d.sh path/to/geofit}"
cd "$(dirname "$0")/.."
SHARED="${GEOFIT_SHARED:-../shared}"
OUT="$(mktemp -d)"
trap 'rm -rf "$OUT"' EXIT
res=benches/results/popa3d.md
mkdir -p benches/results
{
  echo "# popa3d conversion (citygml2popa3d)"
  echo
  echo "Machine: $(nproc) cores, $(uname -m). Binary: release. Times are the best of 3 runs."
  echo
  echo "| tile | size | buildings | converted | rejected | convert s | per building ms | peak RSS MB | parse-only (info) s |"
  echo "|---|---|---|---|---|---|---|---|---|"
} > "$res"
for f in "$SHARED"/fixtures/citygml/nrw/*.gml; do
  name=$(basename "$f" .gml)
  best=999; rss=0
  for i in 1 2 3; do
    /usr/bin/time -f "%e %M" -o "$OUT/t" "$BIN" -q citygml2popa3d "$f" -o "$OUT/o.popa3d" --report "$OUT/r.json" 2>/dev/null || true
    read -r t m < <(tail -n 1 "$OUT/t")
    best=$(python3 -c "print(min($best, $t))"); rss=$m
  done
  pbest=999
  for i in 1 2 3; do
    /usr/bin/time -f "%e" -o "$OUT/p" "$BIN" -q info "$f" >/dev/null 2>&1 || true
    pbest=$(python3 -c "print(min($pbest, $(tail -n 1 "$OUT/p")))")
  done
  read -r conv rej <<<"$(python3 -c "import json;r=json.load(open('$OUT/r.json'));print(r['converted'], len(r['rejected']))")"
  n=$((conv + rej))
  per=$(python3 -c "print(round(1000*$best/max($n,1), 2))")
  size=$(du -k "$f" | cut -f1)
  line="| $name | ${size} KB | $n | $conv | $rej | $best | $per | $((rss / 1024)) | $pbest |"
  echo "$line"
  echo "$line" >> "$res"
done

# Scaling in the number of buildings: the largest tile repeated k times, every copy with its own
# gml:ids (suffix _c, XLinks renamed with them) and shifted 2 km east, so the copies are distinct
# buildings side by side, as in a real tile of k times the size.
big=$(ls -S "$SHARED"/fixtures/citygml/nrw/*.gml | head -1)
{
  echo
  echo "## Scaling with the number of buildings ($(basename "$big" .gml) repeated, ids renamed, copies shifted 2 km)"
  echo
  echo "| copies | size MB | buildings | citygml2popa3d s | heal s | peak RSS MB (heal) |"
  echo "|---|---|---|---|---|---|"
} >> "$res"
for k in 5 10 20; do
  python3 benches/citygml_copies.py "$big" "$OUT/x$k.gml" "$k"
  /usr/bin/time -f "%e %M" -o "$OUT/t" "$BIN" -q citygml2popa3d "$OUT/x$k.gml" -o "$OUT/o.popa3d" --report "$OUT/r.json" 2>/dev/null || true
  read -r tc _ < <(tail -n 1 "$OUT/t")
  /usr/bin/time -f "%e %M" -o "$OUT/t" "$BIN" -q heal "$OUT/x$k.gml" -o "$OUT/h.gml" 2>/dev/null || true
  read -r th mh < <(tail -n 1 "$OUT/t")
  n=$(python3 -c "import json;r=json.load(open('$OUT/r.json'));print(r['converted'] + len(r['rejected']))")
  line="| $k | $(python3 -c "print(round($(stat -c %s "$OUT/x$k.gml")/1e6, 1))") | $n | $tc | $th | $((mh / 1024)) |"
  echo "$line"
  echo "$line" >> "$res"
done
echo "wrote $res"
