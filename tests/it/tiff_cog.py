"""Reads a Cloud Optimized GeoTIFF we wrote with GDAL and checks it as the GIS world does
(tests/it/tiff_out.rs runs it with /usr/bin/python3, where Debian's python3-gdal lives).

    tiff_cog.py COG SOURCE TILE exact|jpeg

GDAL's COG validator (osgeo_utils.samples.validate_cloud_optimized_geotiff, with its full
check of every tile's leader and trailer) must find no error and no warning; GDAL must see the
full resolution and every reduced level as its overviews, tiled at TILE; and each level, read
by GDAL, must equal the naive pyramid of the source (exact), or be within JPEG's error of it.
Prints one JSON line of what it measured; exits 1 with the reason on a mismatch.
"""

import json
import sys

import numpy as np
from osgeo import gdal
from osgeo_utils.samples import validate_cloud_optimized_geotiff as cog

from tiff_oracle import compare, fail, levels_of, oracle

gdal.UseExceptions()


def read(ds_or_band_list):
    """Rows x columns x samples from a list of bands (a dataset's or an overview level's)."""
    planes = [b.ReadAsArray() for b in ds_or_band_list]
    return np.stack(planes, axis=2)


def main():
    path, src_path, tile, mode = sys.argv[1:5]
    tile = int(tile)
    src_ds = gdal.Open(src_path)
    src = read([src_ds.GetRasterBand(i + 1) for i in range(src_ds.RasterCount)])
    measured = {}

    warnings, errors, details = cog.validate(path, full_check=True)
    if errors or warnings:
        fail(f"the COG validator: errors {errors}, warnings {warnings}")
    measured["validator"] = "ok"
    measured["ifd_offsets"] = details.get("ifd_offsets")

    ds = gdal.Open(path)
    if ds.GetDriver().ShortName != "GTiff":
        fail(f"GDAL's driver is {ds.GetDriver().ShortName}")
    layout = ds.GetMetadata("IMAGE_STRUCTURE").get("LAYOUT")
    if layout != "COG":
        fail(f"GDAL says LAYOUT={layout}, not COG")
    n = levels_of(src, tile)
    bands = [ds.GetRasterBand(i + 1) for i in range(ds.RasterCount)]
    if len(bands) != src.shape[2]:
        fail(f"{len(bands)} bands, expected {src.shape[2]}")
    if bands[0].GetOverviewCount() != n - 1:
        fail(f"{bands[0].GetOverviewCount()} overviews, expected {n - 1}")
    for k in range(n):
        level = bands if k == 0 else [b.GetOverview(k - 1) for b in bands]
        if level[0].GetBlockSize() != [tile, tile]:
            fail(f"level {k}: blocks of {level[0].GetBlockSize()}, expected {tile}")
        compare(f"GDAL level {k}", read(level), oracle(src, k), mode, measured)
    print(json.dumps(measured))


main()
