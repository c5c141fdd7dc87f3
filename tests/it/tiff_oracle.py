"""The naive pyramid every TIFF reader's levels are checked against, and how they are compared:
shared by tiff_out.py (tifffile, libvips, OpenSlide) and tiff_cog.py (GDAL), which import it
from this folder. Needs numpy only.
"""

import sys

import numpy as np

# JPEG at the default quality 85, 4:2:0, on tiff_out.rs's gradient-plus-noise images measures
# 35 dB against the exact level 0 and more on the smoother levels above (41, 46, 50 dB); a
# reader that took the YCbCr samples for RGB (or the wrong subsampling) gives under 20 dB. The
# bound sits between, clear of both.
JPEG_MIN_PSNR = 30.0


def fail(message):
    print(message, file=sys.stderr)
    sys.exit(1)


def oracle(src, k):
    """Level k as docs/architecture.md defines it: each texel the mean of the real source
    samples under its 2^k x 2^k footprint (fewer at the right and bottom edges), rounded half
    up once: the box filter."""
    f = 1 << k
    h, w, c = src.shape
    rows, cols = -(-h // f), -(-w // f)
    # Float samples are summed in float64 (as docs/sources.md's exact pyramid sums them) and
    # their mean rounded to the sample type once; integers exactly, rounded half up.
    floats = src.dtype.kind == "f"
    acc = np.float64 if floats else np.uint64
    padded = np.zeros((rows * f, cols * f, c), acc)
    padded[:h, :w] = src
    real = np.zeros((rows * f, cols * f), acc)
    real[:h, :w] = 1
    sums = padded.reshape(rows, f, cols, f, c).sum(axis=(1, 3))
    counts = real.reshape(rows, f, cols, f).sum(axis=(1, 3))[:, :, None]
    if floats:
        return (sums / counts).astype(src.dtype)
    return ((2 * sums + counts) // (2 * counts)).astype(src.dtype)


def levels_of(src, tile):
    """Levels down to the first that fits one tile, as the page grid has them."""
    h, w = src.shape[:2]
    k = 0
    while max(-(-w // (1 << k)), -(-h // (1 << k))) > tile:
        k += 1
    return k + 1


def psnr(a, b, peak):
    mse = np.mean((a.astype(np.float64) - b.astype(np.float64)) ** 2)
    return float("inf") if mse == 0 else 10 * np.log10(peak * peak / mse)


def compare(what, got, want, mode, measured):
    got = got[:, :, None] if got.ndim == 2 else got
    if got.shape != want.shape:
        fail(f"{what}: shape {got.shape}, expected {want.shape}")
    if mode == "exact":
        if not np.array_equal(got, want):
            diff = np.argwhere(got != want)[0]
            fail(f"{what}: differs first at {tuple(diff)}: {got[tuple(diff)]} != {want[tuple(diff)]}")
        measured[what] = "exact"
    else:
        peak = 255.0 if want.dtype == np.uint8 else 65535.0
        p = psnr(got, want, peak)
        measured[what] = round(p, 2)
        if p < JPEG_MIN_PSNR:
            fail(f"{what}: {p:.2f} dB from the exact level, under {JPEG_MIN_PSNR}")
