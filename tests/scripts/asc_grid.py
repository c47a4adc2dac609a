"""ESRI ASCII grid reading shared by the raster truth scripts (imported from the script folder)."""
import numpy as np

HEADER_KEYS = ("ncols", "nrows", "xllcorner", "yllcorner", "xllcenter", "yllcenter", "cellsize", "nodata_value", "dx", "dy")


def read_asc_values(path):
    """ESRI ASCII grid values with numpy alone (GDAL's AAIGrid reader rounds to Float32)."""
    with open(path) as f:
        lines = f.read().split("\n")
    k = 0
    while lines[k].split() and lines[k].split()[0].lower() in HEADER_KEYS:
        k += 1
    return np.array([float(v) for line in lines[k:] for v in line.split()], dtype=np.float64)
