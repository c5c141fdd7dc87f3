import itertools, json, os, shutil, subprocess, sys
import numpy as np, tifffile

out = sys.argv[1]
which = sys.argv[2]  # "tifffile" or "vips"
os.makedirs(out, exist_ok=True)
rng = np.random.default_rng(41)
manifest = []


def values(dtype, shape):
    """Every bit of the type exercised: noise over the whole range, ramps, and (floats) signs,
    fractions and a NaN-free spread of magnitudes."""
    dt = np.dtype(dtype)
    if dt.kind == "f":
        v = rng.standard_normal(shape) * 10.0 ** rng.integers(-3, 4, shape)
        return v.astype(dt)
    info = np.iinfo(dt)
    return rng.integers(info.min, info.max, shape, endpoint=True, dtype=dt)


def delivered(arr, dtype):
    """What we give for samples of `dtype`: as stored, half floats and signed 16-bit widened to
    32-bit floats (exactly)."""
    if np.dtype(dtype) in (np.dtype("float16"), np.dtype("int16")):
        return arr.astype(np.float32)
    return arr


def record(name, kind, expect=None, refuse=None, what=""):
    """kind: texels (rows of the delivered texels), channels (one grey image per sample), or
    refused (with the words the message must hold)."""
    entry = {"name": name, "kind": kind, "what": what}
    if expect is not None:
        expect = np.ascontiguousarray(expect)
        entry["dtype"] = expect.dtype.str
        entry["shape"] = list(expect.shape)
        expect.astype(expect.dtype.newbyteorder("<")).tofile(os.path.join(out, name + ".expect"))
    if refuse is not None:
        entry["refuse"] = refuse
    manifest.append(entry)


def as_read(path):
    """tifffile's decode of the first page, texels last: (h, w, samples)."""
    with tifffile.TiffFile(path) as t:
        p = t.pages[0]
        a = p.asarray()
        if p.planarconfig == 2 and p.samplesperpixel > 1:
            a = np.moveaxis(a, 0, -1)
        if a.ndim == 2:
            a = a[..., None]
        info = dict(colormap=p.colormap, photometric=int(p.photometric), extrasamples=tuple(int(e) for e in p.extrasamples))
        return info, a


def expectation(name, path, source, dtype, photometric, extras, compression=None):
    """Checks tifffile reads back the pixels written (where `source` is given: tiffcp mangles
    some 16-bit planes, which both readers must then read alike), and records what we must give."""
    page, got = as_read(path)
    assert source is None or np.array_equal(got, source, equal_nan=True), name
    s = got.shape[-1]
    dt = np.dtype(dtype)
    refused = {
        ("i", 1): ["8-bit signed", "SampleFormat 2"],
        ("i", 4): ["32-bit signed", "SampleFormat 2"],
        ("i", 8): ["64-bit signed", "SampleFormat 2"],
        ("u", 8): ["64-bit"],
        ("f", 8): ["64-bit floating-point"],
    }.get((dt.kind, dt.itemsize))
    if refused:
        return record(name, "refused", refuse=refused)
    if compression == "zstd":
        # Not read (yet): refused naming the compression ("a|b": either words).
        return record(name, "refused", refuse=["compression", "Zstandard|50000"])
    if s > 4:
        # Every sample a channel, whatever the photometric calls them.
        return record(name, "channels", np.moveaxis(delivered(got, dtype), -1, 0))
    alpha = bool(extras) and extras[0] in (1, 2)
    if photometric == "palette":
        cmap = page["colormap"]
        idx = got[..., 0].astype(np.intp)
        rgb = np.moveaxis(cmap[:, idx], 0, -1)
        if (cmap < 256).all():
            rgb = rgb.astype(np.uint8)
        elif (cmap % 257 == 0).all():
            rgb = (rgb >> 8).astype(np.uint8)
        return record(name, "texels", rgb)
    if photometric == "miniswhite":
        if dt.kind != "u":
            return record(name, "refused", refuse=["WhiteIsZero"])
        return record(name, "texels", np.iinfo(dt).max - got[..., :1])
    keep = (3 if photometric == "rgb" else 1) + alpha
    return record(name, "texels", delivered(got[..., :keep], dtype))


# (photometric, samples, extrasamples)
LAYOUTS = [
    ("minisblack", 1, ()),
    ("minisblack", 2, (0,)),
    ("minisblack", 2, (2,)),
    ("rgb", 3, ()),
    ("rgb", 4, (2,)),
    ("rgb", 4, (0,)),
    ("rgb", 5, (2, 0)),
    ("minisblack", 5, (0, 0, 0, 0)),
    ("minisblack", 6, (0, 0, 0, 0, 0)),
    ("rgb", 6, (0, 0, 0)),
]
DTYPES = ["uint8", "uint16", "uint32", "float32", "float16", "int16", "int8", "int32", "float64"]
# (name, compression, predictor for integers, predictor for floats)
CODINGS = [
    ("none", None, None, None),
    ("lzw", "lzw", None, None),
    ("lzwpred", "lzw", "horizontal", "floatingpoint"),
    ("deflate", "zlib", None, None),
    ("deflatepred", "zlib", "horizontal", "floatingpoint"),
    ("packbits", "packbits", None, None),
    ("zstd", "zstd", None, None),
]
SIZES = [(37, 23), (129, 65)]

made = {}
if which == "tifffile":
    n = 0
    for (photometric, s, extras), dtype, planar, tiled, coding in itertools.product(
        LAYOUTS, DTYPES, ["contig", "separate"], [False, True], CODINGS
    ):
        if planar == "separate" and s == 1:
            continue
        cname, compression, ipred, fpred = coding
        dt = np.dtype(dtype)
        predictor = fpred if dt.kind == "f" else ipred
        if cname.endswith("pred") and predictor is None:
            continue
        # 8-bit predictors, half-float predictors and the refused types: fewer combinations.
        if dtype in ("int8", "int32", "float64") and (tiled or cname not in ("none", "deflatepred")):
            continue
        # Zstandard is refused: its strips suffice.
        if cname == "zstd" and tiled:
            continue
        w, h = SIZES[n % 2]
        n += 1
        # Big-endian and BigTIFF files in turn.
        byteorder = ">" if n % 5 == 0 else "<"
        bigtiff = n % 7 == 0
        name = f"tf-{photometric}{s}-x{''.join(map(str, extras))}-{dtype}-{planar}-{'tiles' if tiled else 'strips'}-{cname}-{'be' if byteorder == '>' else 'le'}{'-big' if bigtiff else ''}"
        source = values(dtype, (h, w, s))
        data = source if planar == "contig" or s == 1 else np.moveaxis(source, -1, 0)
        if s == 1:
            data = data[..., 0]
        kw = dict(
            photometric=photometric,
            compression=compression,
            predictor=predictor,
            byteorder=byteorder,
            bigtiff=bigtiff,
            metadata=None,
        )
        if s > 1:
            kw["planarconfig"] = planar
        if extras:
            kw["extrasamples"] = extras
        if tiled:
            kw["tile"] = (16, 16)
        else:
            kw["rowsperstrip"] = 7
        path = os.path.join(out, name + ".tif")
        tifffile.imwrite(path, data, **kw)
        expectation(name, path, source, dtype, photometric, extras, compression)
        if dtype in ("uint8", "uint16") and cname == "none" and byteorder == "<" and not bigtiff:
            made[name] = (path, source, dtype, photometric, extras)
    # WhiteIsZero grey and 8-bit palettes (of an 8-bit map, and a 16-bit one).
    for dtype, tiled, cname in itertools.product(["uint8", "uint16", "float32"], [False, True], ["none", "lzw"]):
        name = f"tf-miniswhite-{dtype}-{'tiles' if tiled else 'strips'}-{cname}"
        source = values(dtype, (23, 37, 1))
        path = os.path.join(out, name + ".tif")
        kw = dict(tile=(16, 16)) if tiled else dict(rowsperstrip=5)
        tifffile.imwrite(path, source[..., 0], photometric="miniswhite", compression=None if cname == "none" else cname, metadata=None, **kw)
        expectation(name, path, source, dtype, "miniswhite", ())
    for bits, cmap_kind, tiled in itertools.product([8], ["8bit", "16bit", "wide"], [False, True]):
        name = f"tf-palette{bits}-{cmap_kind}-{'tiles' if tiled else 'strips'}"
        source = values("uint8", (65, 129, 1))
        cmap = rng.integers(0, 256, (3, 256), dtype=np.uint16)
        if cmap_kind == "16bit":
            cmap = cmap * 257
        elif cmap_kind == "wide":
            cmap = rng.integers(0, 65536, (3, 256), dtype=np.uint16)
        path = os.path.join(out, name + ".tif")
        kw = dict(tile=(16, 16)) if tiled else dict(rowsperstrip=9)
        tifffile.imwrite(path, source[..., 0], photometric="palette", colormap=cmap, compression="zlib", metadata=None, **kw)
        expectation(name, path, source, "uint8", "palette", ())

# libtiff's tiffcp re-writing some of them in layouts of its own: big-endian, one-row strips,
# tiles of other sizes, LZW and Deflate with predictor, planes separated or joined.
TIFFCP = [
    ("be-lzw2", ["-B", "-c", "lzw:2", "-r", "1"]),
    ("tiles-zip2", ["-c", "zip:2", "-t", "-w", "32", "-l", "48"]),
    ("separate-packbits", ["-p", "separate", "-c", "packbits", "-r", "5"]),
    ("contig-lzw", ["-p", "contig", "-c", "lzw", "-r", "11"]),
]
if which == "tifffile" and shutil.which("tiffcp"):
    for name, (path, source, dtype, photometric, extras) in made.items():
        if name.endswith("-tiles-none-le") or "-x2" in name:
            continue
        for tag, args in TIFFCP:
            to = os.path.join(out, f"{name}-tiffcp-{tag}.tif")
            done = subprocess.run(["tiffcp", *args, path, to], capture_output=True)
            if done.returncode != 0:
                # tiffcp refuses some (16-bit planes separated): not a layout it writes.
                continue
            expectation(f"{name}-tiffcp-{tag}", to, None, dtype, photometric, extras)

if which == "vips":
    import pyvips

    FORMATS = {"uint8": "uchar", "uint16": "ushort", "uint32": "uint", "float32": "float", "int16": "short"}
    n = 0
    for bands, dtype, tiled, (cname, compression, predictor) in itertools.product(
        range(1, 7),
        FORMATS,
        [False, True],
        [
            ("none", "none", "none"),
            ("lzw", "lzw", "horizontal"),
            ("deflate", "deflate", "none"),
            ("deflatepred", "deflate", "horizontal"),
            ("packbits", "packbits", "none"),
        ],
    ):
        w, h = SIZES[n % 2]
        n += 1
        if dtype == "float32" and predictor == "horizontal":
            predictor = "float"
        name = f"vips-{bands}-{dtype}-{'tiles' if tiled else 'strips'}-{cname}"
        source = values(dtype, (h, w, bands))
        image = pyvips.Image.new_from_array(source)
        path = os.path.join(out, name + ".tif")
        kw = dict(compression=compression, predictor=predictor)
        if tiled:
            kw.update(tile=True, tile_width=16, tile_height=16)
        image.tiffsave(path, **kw)
        page, got = as_read(path)
        photometric = {1: "minisblack", 2: "rgb"}[page["photometric"]]
        extras = page["extrasamples"]
        expectation(name, path, source, dtype, photometric, extras)

json.dump(manifest, open(os.path.join(out, "manifest.json"), "w"), indent=0)
print(len(manifest), "files")
