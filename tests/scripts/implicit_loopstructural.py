#!/usr/bin/env python3
"""Reference for `benches/implicit.sh`: LoopStructural's PLI interpolator (piecewise-linear on a
tetrahedral mesh, Frank et al. 2007's constant-gradient regularisation) on a LoopStructural-style
CSV (X,Y,Z,val,feature_name,nx,ny,nz). Prints one JSON line: unknowns (mesh nodes), wall and CPU
(all threads) seconds for create_and_add_foliation + model.update(), and mean / max |φ − val| at
the value points.

    python3 tests/scripts/implicit_loopstructural.py CLAUDIUS.csv NELEMENTS
"""
import json
import sys
import time
import warnings

import numpy as np
import pandas as pd

warnings.filterwarnings("ignore")
import logging

logging.disable(logging.CRITICAL)
from LoopStructural import GeologicalModel  # noqa: E402

data = pd.read_csv(sys.argv[1])
nel = int(float(sys.argv[2]))
data = data.drop(columns=[c for c in data.columns if c.startswith("Unnamed")])
data["feature_name"] = "strati"
xyz = data[["X", "Y", "Z"]].to_numpy()
origin, maximum = xyz.min(axis=0), xyz.max(axis=0)
model = GeologicalModel(origin, maximum)
model.set_model_data(data)
t0, c0 = time.perf_counter(), time.process_time()
strati = model.create_and_add_foliation("strati", interpolatortype="PLI", nelements=nel)
model.update()
secs, cpu = time.perf_counter() - t0, time.process_time() - c0
vals = data["val"].to_numpy()
m = ~np.isnan(vals)
phi = model.evaluate_feature_value("strati", xyz[m])
mis = np.abs(phi - vals[m])
interp = strati.interpolator
try:
    unknowns = int(interp.nx)
except Exception:  # attribute names differ across versions
    unknowns = int(interp.support.n_nodes)
import LoopStructural

print(json.dumps({"tool": "LoopStructural " + LoopStructural.__version__ + " PLI", "unknowns": unknowns,
                  "seconds": secs, "cpu_seconds": cpu, "misfit_mean": float(mis.mean()), "misfit_max": float(mis.max())}))
