#!/usr/bin/env python3
"""Makes a raster that is mostly no-data (numpy and GDAL's command-line tools): the cells of IN
outside a disc are set to the no-data value -9999, the disc holding KEEP (a fraction) of the
cells, centred at 30 % of the width and height, so whole tiles of any plan in the far corner have
no valid cell. Prints JSON {"cells", "valid"}.

usage: tiles_holes.py IN.tif OUT.tif KEEP
"""
import json
import math
import os
import subprocess
import sys
import tempfile

import numpy as np


def main():
    src, dst, keep = sys.argv[1], sys.argv[2], float(sys.argv[3])
    env = dict(os.environ, GDAL_PAM_ENABLED="NO")
    info = json.loads(subprocess.run(["gdalinfo", "-json", src], check=True, capture_output=True, env=env).stdout)
    w, h = info["size"]
    with tempfile.TemporaryDirectory() as d:
        raw = os.path.join(d, "r.bin")
        subprocess.run(["gdal_translate", "-q", "-b", "1", "-ot", "Float32", "-of", "ENVI", src, raw], check=True, capture_output=True, env=env)
        v = np.fromfile(raw, dtype="<f4").reshape(h, w)
        r = math.sqrt(keep * w * h / math.pi)
        yy, xx = np.mgrid[0:h, 0:w]
        inside = (xx - 0.3 * w) ** 2 + (yy - 0.3 * h) ** 2 <= r * r
        v[~inside] = -9999.0
        v.astype("<f4").tofile(raw)
        subprocess.run(["gdal_translate", "-q", "-a_nodata", "-9999", "-of", "GTiff", raw, dst], check=True, capture_output=True, env=env)
    print(json.dumps({"cells": w * h, "valid": int(inside.sum())}))


if __name__ == "__main__":
    sys.exit(main())
