"""bench/ome-zarr.sh's Python side: the inputs, and the peers it times.

    gen DIR SIDE          the inputs (see bench/ome-zarr.sh), made once
    ome-zarr-py NPY OUT VERSION [labels]   ome_zarr.writer.write_image from a memory-mapped array
    ngff-zarr NPY OUT VERSION              ngff_zarr.to_multiscales + to_ngff_zarr
    mode NPY LEVELS       a numpy 2x2 mode pyramid (and scipy.stats.mode on a crop), Mpx/s

Every writer makes 256-texel chunks and levels down to one chunk (16384: 7 levels), as
vortex-tiler does; 0.5 outputs gather 16 x 16 chunks per shard (vortex-tiler's default).
"""

import sys
import time

import numpy as np

CHUNK = 256
SHARD = 16


def gen(out, side):
    """rgb.npy (3, y, x) uint8, c4.npy (4, y, x) uint16, labels16.npy (y, x) uint16 and
    labels8.npy uint8, and the same as TIFFs for vortex-tiler: rgb.tif (RGB, contiguous),
    c4.tif (4 separate planes), labels16.tif, labels8.tif; all uncompressed, strips of 64 rows.
    Content: gradients and waves with per-pixel noise (compressible as images are), and labels
    as jittered cells, a few thousand objects."""
    import tifffile

    rng = np.random.default_rng(1)
    band = 1024
    x = np.arange(side, dtype=np.float32)[None, :]

    def rows(y0):
        return np.arange(y0, min(y0 + band, side), dtype=np.float32)[:, None]

    def planes(name, count, dtype, scale):
        npy = np.lib.format.open_memmap(f"{out}/{name}.npy", mode="w+", dtype=dtype, shape=(count, side, side))
        for y0 in range(0, side, band):
            y = rows(y0)
            for c in range(count):
                wave = np.sin(x / (97 + 31 * c) + y / (53 + 17 * c)) * 0.25 + 0.5
                ramp = (x + y * (c + 1)) / (side * (c + 2))
                noise = rng.integers(0, 8, size=(y.shape[0], side)) / 255.0
                v = (wave * 0.6 + ramp * 0.3 + noise) * scale
                npy[c, y0 : y0 + y.shape[0]] = np.clip(v, 0, scale).astype(dtype)
        npy.flush()
        return npy

    rgb = planes("rgb", 3, np.uint8, 255)
    tifffile.imwrite(
        f"{out}/rgb.tif", _bands(rgb, interleave=True), shape=(side, side, 3), dtype=np.uint8,
        photometric="rgb", rowsperstrip=64, bigtiff=True,
    )
    c4 = planes("c4", 4, np.uint16, 65535)
    tifffile.imwrite(
        f"{out}/c4.tif", _bands(c4, interleave=False), shape=(4, side, side), dtype=np.uint16,
        photometric="minisblack", planarconfig="separate", rowsperstrip=64, bigtiff=True,
    )
    for name, dtype in (("labels16", np.uint16), ("labels8", np.uint8)):
        lab = np.lib.format.open_memmap(f"{out}/{name}.npy", mode="w+", dtype=dtype, shape=(side, side))
        cell = 300 if dtype == np.uint16 else 900
        for y0 in range(0, side, band):
            y = rows(y0)
            # Wavy cell borders, so that blocks straddle them at every angle.
            cx = np.floor((x + 40 * np.sin(y / 71)) / cell).astype(np.int64)
            cy = np.floor((y + 40 * np.sin(x / 83)) / cell).astype(np.int64)
            ids = (cx * 7919 + cy * 104729) % (np.iinfo(dtype).max - 1) + 1
            ids[(cx + cy) % 5 == 0] = 0  # background between objects
            lab[y0 : y0 + y.shape[0]] = ids.astype(dtype)
        lab.flush()
        tifffile.imwrite(f"{out}/{name}.tif", lab, photometric="minisblack", rowsperstrip=64, bigtiff=True)


def _bands(planes, interleave):
    """The strips of 64 rows of a (c, y, x) memmap, as tifffile writes them from an iterator."""
    count, side, _ = planes.shape
    if interleave:
        for y0 in range(0, side, 64):
            yield np.ascontiguousarray(np.moveaxis(planes[:, y0 : y0 + 64], 0, -1))
    else:
        for c in range(count):
            for y0 in range(0, side, 64):
                yield np.ascontiguousarray(planes[c, y0 : y0 + 64])


def levels_for(side):
    n = 1
    while (side >> (n - 1)) > CHUNK:
        n += 1
    return n


def ome_zarr_py(npy, out, version, labels=False):
    import zarr
    from ome_zarr.format import FormatV04, FormatV05
    from ome_zarr.scale import Methods
    from ome_zarr.writer import write_image

    data = np.load(npy, mmap_mode="r")
    side = data.shape[-1]
    factors = [2**k for k in range(1, levels_for(side))]
    axes = "cyx" if data.ndim == 3 else "yx"
    chunk = (1, CHUNK, CHUNK) if data.ndim == 3 else (CHUNK, CHUNK)
    options = {"chunks": chunk}
    if version == "0.5":
        options["shards"] = tuple(1 if c == 1 else c * SHARD for c in chunk)
    fmt = FormatV04() if version == "0.4" else FormatV05()
    root = zarr.open_group(out, mode="w", zarr_format=2 if version == "0.4" else 3)
    method = Methods.NEAREST if labels else Methods.RESIZE
    write_image(data, root, scale_factors=factors, method=method, fmt=fmt, axes=axes, storage_options=options)


def ngff_zarr(npy, out, version):
    import ngff_zarr as nz

    data = np.load(npy, mmap_mode="r")
    side = data.shape[-1]
    dims = ["c", "y", "x"] if data.ndim == 3 else ["y", "x"]
    image = nz.to_ngff_image(data, dims=dims)
    factors = [2**k for k in range(1, levels_for(side))]
    # The mean of each 2x2 block (no extra package, unlike its default itkwasm Gaussian).
    multiscales = nz.to_multiscales(image, scale_factors=factors, method=nz.Methods.DASK_BIN_SHRINK, chunks=CHUNK)
    shards = SHARD if version == "0.5" else None
    nz.to_ngff_zarr(out, multiscales, version=version, chunks_per_shard=shards)


def mode2x2(a):
    """The most frequent value of each 2x2 block, ties to the smallest value (vortex-tiler
    breaks them by position instead, top-left first; the work is the same):
    the four values sorted, then each counted against the others, all vectorised."""
    h, w = a.shape[0] // 2 * 2, a.shape[1] // 2 * 2
    v = np.stack([a[0:h:2, 0:w:2], a[0:h:2, 1:w:2], a[1:h:2, 0:w:2], a[1:h:2, 1:w:2]], axis=-1)
    v.sort(axis=-1)
    counts = (v[..., :, None] == v[..., None, :]).sum(axis=-1)
    # The first (smallest) of the values with the highest count.
    best = counts.argmax(axis=-1)
    return np.take_along_axis(v, best[..., None], axis=-1)[..., 0]


def mode(npy, levels):
    data = np.load(npy, mmap_mode="r")
    level = np.asarray(data)
    px = 0
    t = time.perf_counter()
    for _ in range(1, int(levels)):
        px += level.size
        level = mode2x2(level)
    numpy_s = time.perf_counter() - t
    # scipy.stats.mode on 2x2 blocks of a 2048^2 crop at most (the whole image would take minutes).
    import scipy.stats

    n = min(2048, data.shape[0], data.shape[1]) // 2
    crop = np.asarray(data[: 2 * n, : 2 * n])
    blocks = crop.reshape(n, 2, n, 2).transpose(0, 2, 1, 3).reshape(n, n, 4)
    t = time.perf_counter()
    scipy.stats.mode(blocks, axis=-1, keepdims=False)
    scipy_s = time.perf_counter() - t
    print(f"numpy {numpy_s:.2f} s {px / numpy_s / 1e6:.1f} Mpx/s scipy {crop.size / scipy_s / 1e6:.2f} Mpx/s")


if __name__ == "__main__":
    what, args = sys.argv[1], sys.argv[2:]
    if what == "gen":
        gen(args[0], int(args[1]))
    elif what == "ome-zarr-py":
        ome_zarr_py(args[0], args[1], args[2], labels=len(args) > 3)
    elif what == "ngff-zarr":
        ngff_zarr(args[0], args[1], args[2])
    elif what == "mode":
        mode(args[0], args[1])
    else:
        sys.exit(f"unknown: {what}")
