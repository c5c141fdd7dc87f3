"""GeoTIFF sources and the georeferencing our TIFF outputs carry, as GDAL sees them
(tests/it/tiff_out.rs runs it with /usr/bin/python3, where Debian's python3-gdal lives).

    tiff_geo.py make PNG GEOTIFF area|point|rotated
        writes PNG as a GeoTIFF as GDAL does: EPSG:32633 (UTM 33N) with no-data 0, pixel is
        area (ModelPixelScale and ModelTiepoint), pixel is point, or a rotated geotransform
        (ModelTransformation).
    tiff_geo.py check GEOTIFF OUT
        GDAL must read OUT's full resolution with the source's geotransform (exactly, the same
        doubles), its coordinate system (the same WKT), the same AREA_OR_POINT and no-data;
        each reduced level (an overview) must hold no georeferencing but the no-data value, as
        GDAL's COG driver writes its overviews (GDAL derives their transform from their size).
        A COG must also pass GDAL's COG validator. Prints one JSON line; exits 1 with
        the reason on a mismatch.
"""

import json
import sys

from osgeo import gdal
from osgeo_utils.samples import validate_cloud_optimized_geotiff as cog

from tiff_oracle import fail

gdal.UseExceptions()

UTM_33N = "EPSG:32633"


def make(png, out, kind):
    src = gdal.Open(png)
    options = ["-a_srs", UTM_33N, "-a_nodata", "0", "-co", "COMPRESS=DEFLATE"]
    if kind == "point":
        options += ["-mo", "AREA_OR_POINT=Point"]
    ds = gdal.Translate(out, src, options=" ".join(options))
    if kind == "rotated":
        # Rows and columns at an angle to the axes: only ModelTransformation holds it.
        ds.SetGeoTransform((500000.0, 8.0, 6.0, 4600000.0, 6.0, -8.0))
    else:
        ds.SetGeoTransform((500000.0, 10.0, 0.0, 4600000.0, 0.0, -10.0))
    ds = None


def georeferencing(ds):
    return {
        "geotransform": ds.GetGeoTransform(can_return_null=True),
        "wkt": ds.GetProjection(),
        "area_or_point": ds.GetMetadataItem("AREA_OR_POINT"),
        "nodata": ds.GetRasterBand(1).GetNoDataValue(),
    }


def check(source, out):
    want = georeferencing(gdal.Open(source))
    ds = gdal.Open(out)
    got = georeferencing(ds)
    for key in want:
        if got[key] != want[key]:
            fail(f"{out}: {key} {got[key]!r}, the source's {want[key]!r}")
    measured = {"geotransform": got["geotransform"], "area_or_point": got["area_or_point"]}
    band = ds.GetRasterBand(1)
    overviews = band.GetOverviewCount()
    if overviews == 0:
        fail(f"{out}: GDAL sees no overviews")
    for k in range(1, overviews + 1):
        # The reduced level alone, as GDAL opens the Nth directory of a TIFF.
        level = gdal.Open(f"GTIFF_DIR:{k + 1}:{out}")
        if level.GetProjection() or level.GetGeoTransform(can_return_null=True):
            fail(f"{out}: level {k} carries georeferencing; GDAL's overviews carry none")
        o = band.GetOverview(k - 1)
        measured[f"overview {k}"] = [o.XSize, o.YSize]
        if o.GetNoDataValue() != want["nodata"]:
            fail(f"{out}: overview {k}'s no-data {o.GetNoDataValue()!r}, the source's {want['nodata']!r}")
    if out.endswith(".cog.tif"):
        warnings, errors, _ = cog.validate(out, full_check=True)
        if errors or warnings:
            fail(f"{out}: the COG validator: errors {errors}, warnings {warnings}")
        measured["validator"] = "ok"
    print(json.dumps(measured))


def main():
    if sys.argv[1] == "make":
        make(*sys.argv[2:5])
    elif sys.argv[1] == "check":
        check(*sys.argv[2:4])
    else:
        fail(f"unknown command {sys.argv[1]}")


main()
