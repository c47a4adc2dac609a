#!/usr/bin/env bash
# Bounded memory on big inputs (issue 13): peak resident set and wall time of
#  - `geofit info` and `geofit validate --no-xsd` on a >= 1 GiB CityGML tile (NRW tile 332's
#    buildings repeated with their own gml:ids), beside `xmllint --stream` (libxml2's streaming
#    reader, well-formedness only) on the same file;
#  - `geofit rasterize --method gauss` of 5·10⁷ LAS points onto 10⁶ cells, beside what holding the
#    points alone would take (24 bytes a point).
# Writes benches/results/memory.md. Usage: benches/memory.sh path/to/geofit  (POINTS=N to change
# the point count; needs ~2.2 GB of temporary disk)
set -euo pipefail
BIN="${1:?usage: memory.sh path/to/geofit}"
cd "$(dirname "$0")/.."
SHARED="${GEOFIT_SHARED:-../shared}"
TILE="$SHARED/fixtures/citygml/nrw/LoD2_32_332_5729_1_NW.gml"
[ -f "$TILE" ] || { echo "memory bench: $TILE missing, skipped"; exit 0; }
POINTS="${POINTS:-50000000}"
OUT=benches/results/memory.md
TMP=$(mktemp -d)
trap 'rm -rf "$TMP"' EXIT
PY="${GEOFIT_PYTHON:-python3}"

"$PY" - "$TILE" "$TMP/big.gml" <<'PY'
import sys
src = open(sys.argv[1], "rb").read()
a = src.index(b"<core:cityObjectMember>")
end = b"</core:cityObjectMember>"
b = src.rindex(end) + len(end)
head, members, tail = src[:a], src[a:b], src[b:]
with open(sys.argv[2], "wb") as f:
    f.write(head)
    c = 0
    while len(head) + len(tail) + c * len(members) + 1000 < 1 << 30:
        f.write(members.replace(b'gml:id="', b'gml:id="c%d_' % c).replace(b'xlink:href="#', b'xlink:href="#c%d_' % c))
        c += 1
    f.write(tail)
PY
"$PY" - "$TMP/points.las" "$POINTS" <<'PY'
import struct, sys
import numpy as np
path, n = sys.argv[1], int(sys.argv[2])
h = bytearray(375); h[:4] = b"LASF"; h[24] = 1; h[25] = 4
h[94:96] = struct.pack("<H", 375); h[96:100] = struct.pack("<I", 375); h[105:107] = struct.pack("<H", 20)
for k in range(3):
    h[131 + 8 * k:139 + 8 * k] = struct.pack("<d", 0.01)
h[247:255] = struct.pack("<Q", n)
rng = np.random.default_rng(1)
rec = np.zeros(0, dtype=[("x", "<i4"), ("y", "<i4"), ("z", "<i4"), ("i", "<u2"), ("r", "u1"), ("c", "u1"), ("a", "i1"), ("u", "u1"), ("p", "<u2")])
with open(path, "wb") as f:
    f.write(h)
    for start in range(0, n, 5_000_000):
        m = min(5_000_000, n - start)
        rec = np.zeros(m, dtype=rec.dtype)
        x, y = rng.uniform(0, 2000, m), rng.uniform(0, 2000, m)
        rec["x"], rec["y"] = (x * 100).astype("<i4"), (y * 100).astype("<i4")
        rec["z"] = ((100 + 10 * np.sin(x / 100) * np.cos(y / 150)) * 100).astype("<i4")
        rec["c"] = 2
        f.write(rec.tobytes())
PY

# "peak MiB wall s" of one run
measure() {
  /usr/bin/time -f '%M %e' "$@" 2>&1 >/dev/null | tail -1 | awk '{printf "%.0f | %.1f", $1/1024, $2}'
}
GML_MB=$(( $(stat -c %s "$TMP/big.gml") / 1048576 ))
LAS_MB=$(( $(stat -c %s "$TMP/points.las") / 1048576 ))
{
  echo "# Bounded memory on big inputs"
  echo
  echo "Machine: $(nproc) cores, load average $(cut -d' ' -f1-3 /proc/loadavg). Binary: $BIN."
  echo "Peak resident set from /usr/bin/time (%M), one run each."
  echo
  echo "| input | command | peak MiB | wall s |"
  echo "|---|---|---|---|"
  echo "| CityGML, $GML_MB MiB | geofit info | $(measure "$BIN" info "$TMP/big.gml") |"
  echo "| CityGML, $GML_MB MiB | geofit validate --no-xsd | $(measure "$BIN" -q validate --no-xsd "$TMP/big.gml") |"
  if command -v xmllint >/dev/null; then
    echo "| CityGML, $GML_MB MiB | xmllint --noout --stream (reference) | $(measure xmllint --noout --stream "$TMP/big.gml") |"
  fi
  echo "| LAS, $POINTS points, $LAS_MB MiB | geofit rasterize --cell 2 (gauss, 10⁶ cells) | $(measure "$BIN" -q rasterize "$TMP/points.las" --cell 2 --bounds 0 0 2000 2000 -o "$TMP/r.tif") |"
  echo "| LAS, $POINTS points | the points held as f64 (reference) | $(( POINTS * 24 / 1048576 )) | – |"
} | tee "$OUT"
