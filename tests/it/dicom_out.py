"""Reads a DICOM whole-slide image series we wrote with the readers of that world and checks
every level against a naive pyramid of the source (tests/it/dicom_out.rs runs it with
VORTEX_PYVIPS).

    dicom_out.py DIR SOURCE TILE [COPIED_FROM]
    dicom_out.py levels DIR SLIDE
    dicom_out.py associated DIR SLIDE [native]
    dicom_out.py native DIR SOURCE TILE
    dicom_out.py lossy DIR [SLIDE]
    dicom_out.py j2k DIR SLIDE PHOTOMETRIC TRANSFER
    dicom_out.py jxl DIR SOURCE TILE MODE [JPEG_DIR]


pydicom reads every instance (the IOD's key attributes checked), highdicom parses each as a VL
Whole Slide Microscopy Image, wsidicom opens the directory as one slide and every level read
back is within JPEG's error of the oracle (tiff_oracle.py: the box pyramid of SOURCE, decoded by
libvips), OpenSlide 4 opens the directory as a DICOM slide and `read_region` of every level is
within the same error. With COPIED_FROM (a JPEG-tiled TIFF): the frames whose entropy-coded
data equals that TIFF's stored tile are counted, and printed as "copied".
With `levels` (a series of the slide's own levels, `--levels stored`): one instance a level of
SLIDE (a JPEG-tiled TIFF or SVS, its levels as OpenSlide lists them), pydicom reads each (its
Total Pixel Matrix the level's size, its frames the level's tiles), highdicom parses each,
wsidicom's encoded tiles are the source level's stored tiles made complete (the same
entropy-coded data, SOS to EOI, and the same SOF, DQT and DHT segments as the tile with the
file's JPEGTables), and OpenSlide 4 reads every level of the series exactly as it reads the
same level of SLIDE.
With `associated` (a series made from a slide with associated images): pydicom reads each of
the series' LABEL, OVERVIEW and THUMBNAIL instances (one JPEG frame, the whole image, in the
levels' series), highdicom parses the thumbnail (it cannot open a TILED_FULL image without
Pixel Spacing, which a label and an overview leave out), wsidicom reads the label and the overview, and OpenSlide
4 lists them as `label`, `macro` and `thumbnail`; each within JPEG's error of SLIDE's page as
tifffile decodes it. With `native` too (a series of native frames): each instance's transfer
syntax is explicit VR little endian, and what every reader reads is the page as tifffile
decodes it, exactly for the LZW label, within two JPEG decoders' rounding for the JPEG pages
(`native_close`).
With `native` (a series of native frames, `--codec raw --filter box`): pydicom reads every
instance (transfer syntax explicit VR little endian, the Image Pixel attributes of 8- or 16-bit
samples, Lossy Image Compression 00) and every frame equals the oracle's tile exactly, the edge
frames padded with the level's edge texels repeated (`--background edge`, the default);
highdicom parses each; wsidicom reads every level equal to the oracle; OpenSlide 4 reads every
level of an 8-bit RGB series equal to the oracle (it reads no grey or 16-bit DICOM slide).
Exact, because the frames are the pyramid's samples as they are, and the box pyramid is exact
(tiff_oracle.py).
With `lossy`: each instance's Lossy Image Compression, methods and ratios as pydicom reads
them and, given SLIDE (a JPEG-tiled TIFF), its first page's texel bytes over its tiles' bytes
as tifffile lists them (`sourceRatio`).
With `j2k` (a series of an Aperio JPEG 2000 slide's own levels): one instance a level, of
TRANSFER syntax and PHOTOMETRIC interpretation, every frame pydicom reads the stored
codestream of the slide's tile byte for byte (tifffile's offsets and byte counts), highdicom
parses each, wsidicom hands out the same bytes as each level's encoded tiles, the slide's
thumbnail an instance of one JPEG baseline frame; and where PHOTOMETRIC is one OpenSlide 4 reads
(RGB, YBR_RCT, YBR_ICT), it reads every level of the series exactly as it reads the slide's.
With `jxl` (a series of JPEG XL frames, `--codec jxl`): pydicom reads every instance (the
Image Pixel attributes of 8- or 16-bit grey or RGB samples, interleaved; every frame a JPEG XL
codestream or container), highdicom parses each, and wsidicom (through imagecodecs' libjxl)
reads every level (a JPEG XL JPEG Recompression one, which wsidicom 0.36 does not open, is
decoded frame by frame by imagecodecs' libjxl, wsidicom's own decoder) equal to the oracle (MODE `exact`: lossless frames of a box pyramid) or
within JPEG's error of it (MODE `jpeg`: lossy frames); each instance's transfer syntax,
photometric interpretation and lossy history are printed. With JPEG_DIR (a JPEG baseline
series of the same JPEG-tiled source, its level-0 frames the stored tiles made complete):
every frame that is a recompressed JPEG (it carries libjxl's reconstruction box, `jbrd`) is
decoded to JPEG by `djxl`, which must give JPEG_DIR's frame of the same level and index byte
for byte (counted per level in `rebuilt`; level 0's indexes in `rebuiltFrames`).
Prints one JSON line of what it measured; exits 1 with the reason on a mismatch.
"""

import glob
import json
import os
import sys

import numpy as np
import pydicom
import pyvips

from tiff_oracle import compare, fail, levels_of, oracle

WSI = "1.2.840.10008.5.1.4.1.1.77.1.6"
JPEG_BASELINE = "1.2.840.10008.1.2.4.50"
EXPLICIT_VR_LE = "1.2.840.10008.1.2.1"


def source(path):
    a = pyvips.Image.new_from_file(path).numpy()
    return a[:, :, None] if a.ndim == 2 else a


def rgb_or_grey(a, channels):
    a = np.asarray(a)
    a = a[:, :, None] if a.ndim == 2 else a
    return a[:, :, :channels]


def check_instances(directory, src, tile, measured):
    n = levels_of(src, tile)
    paths = sorted(glob.glob(os.path.join(directory, "level-*.dcm")))
    if len(paths) != n:
        fail(f"{len(paths)} instances, expected {n} (one a level)")
    h, w = src.shape[:2]
    series = set()
    for k in range(n):
        p = os.path.join(directory, f"level-{k}.dcm")
        ds = pydicom.dcmread(p)
        series.add(ds.SeriesInstanceUID)
        want = {
            "SOPClassUID": WSI,
            "TransferSyntaxUID": JPEG_BASELINE,
            "DimensionOrganizationType": "TILED_FULL",
            "TotalPixelMatrixColumns": -(-w // (1 << k)),
            "TotalPixelMatrixRows": -(-h // (1 << k)),
            "Rows": tile,
            "Columns": tile,
            "NumberOfFrames": -(-(-(-w // (1 << k))) // tile) * -(-(-(-h // (1 << k))) // tile),
            "ImageType": ["ORIGINAL", "PRIMARY", "VOLUME", "NONE"] if k == 0 else ["DERIVED", "PRIMARY", "VOLUME", "RESAMPLED"],
        }
        for key, value in want.items():
            got = ds.file_meta.TransferSyntaxUID if key == "TransferSyntaxUID" else ds.get(key)
            got = list(got) if key == "ImageType" else got
            if got != value:
                fail(f"level {k}: {key} {got!r}, expected {value!r}")
        frames = list(pydicom.encaps.generate_frames(ds.PixelData, number_of_frames=ds.NumberOfFrames))
        if len(frames) != ds.NumberOfFrames or not all(f.startswith(b"\xff\xd8") for f in frames):
            fail(f"level {k}: {len(frames)} frames, not {ds.NumberOfFrames} JPEG streams")
        import highdicom

        image = highdicom.imread(p)
        if image.SOPClassUID != WSI:
            fail(f"highdicom: level {k} is {image.SOPClassUID}")
    if len(series) != 1:
        fail(f"{len(series)} series")
    measured["instances"] = n
    return n


def check_wsidicom(directory, src, n, mode, measured):
    from wsidicom import WsiDicom

    c = src.shape[2]
    with WsiDicom.open(directory) as slide:
        if len(slide.levels) != n:
            fail(f"wsidicom: {len(slide.levels)} levels, expected {n}")
        for k, level in enumerate(slide.levels):
            got = rgb_or_grey(slide.read_region((0, 0), k, level.size.to_tuple()), c)
            compare(f"wsidicom level {k}", got, oracle(src, k), mode, measured)


def check_openslide(directory, src, n, mode, measured):
    import openslide

    if tuple(int(v) for v in openslide.__library_version__.split(".")[:1]) < (4,):
        fail(f"OpenSlide {openslide.__library_version__}: DICOM needs 4")
    slide = openslide.OpenSlide(os.path.join(directory, "level-0.dcm"))
    if slide.properties.get("openslide.vendor") != "dicom":
        fail(f"OpenSlide: vendor {slide.properties.get('openslide.vendor')}")
    if slide.level_count != n:
        fail(f"OpenSlide: {slide.level_count} levels, expected {n}")
    c = src.shape[2]
    for k in range(n):
        region = np.asarray(slide.read_region((0, 0), k, slide.level_dimensions[k]))
        if not (region[:, :, 3] == 255).all():
            fail(f"OpenSlide: level {k} has transparent texels")
        got = region[:, :, :3] if c == 3 else region[:, :, :1]
        compare(f"openslide level {k}", got, oracle(src, k), mode, measured)


def scan(jpeg):
    """The entropy-coded data and what follows: from the first SOS marker to EOI."""
    at = jpeg.find(b"\xff\xda")
    end = jpeg.rfind(b"\xff\xd9")
    return jpeg[at : end + 2] if at >= 0 and end > at else None


def count_copied(directory, tiff, measured):
    """Frames of level 0 whose compressed scan equals the source's stored tile's."""
    import tifffile

    ds = pydicom.dcmread(os.path.join(directory, "level-0.dcm"))
    frames = list(pydicom.encaps.generate_frames(ds.PixelData, number_of_frames=ds.NumberOfFrames))
    with tifffile.TiffFile(tiff) as t, open(tiff, "rb") as f:
        page = t.pages[0]
        tiles = []
        for offset, count in zip(page.dataoffsets, page.databytecounts):
            f.seek(offset)
            tiles.append(f.read(count))
        if len(tiles) != len(frames):
            fail(f"{len(frames)} frames at level 0, the source has {len(tiles)} tiles")
    copied = [i for i, (a, b) in enumerate(zip(frames, tiles)) if scan(a) is not None and scan(a) == scan(b)]
    measured["copied"] = len(copied)
    measured["copiedFrames"] = copied
    measured["photometric"] = ds.PhotometricInterpretation
    # The copied frames are the source's own JPEG data: OpenSlide decodes them to the very
    # texels it reads from the source slide (the region they cover, exactly).
    import openslide

    columns = -(-ds.TotalPixelMatrixColumns // ds.Columns)
    if copied:
        right = max(i % columns for i in copied) + 1
        bottom = max(i // columns for i in copied) + 1
        size = (right * ds.Columns, bottom * ds.Rows)
        ours = openslide.OpenSlide(os.path.join(directory, "level-0.dcm")).read_region((0, 0), 0, size)
        theirs = openslide.OpenSlide(tiff).read_region((0, 0), 0, size)
        if not np.array_equal(np.asarray(ours), np.asarray(theirs)):
            diff = np.abs(np.asarray(ours).astype(int) - np.asarray(theirs).astype(int))
            fail(f"OpenSlide reads the copied region {size} otherwise from the series than from the source: max {diff.max()}")
        measured["openslideCopiedRegion"] = f"{size[0]}x{size[1]} equal to the source's"


def segments(jpeg):
    """The marker segments before the first SOS, (marker, body), in order."""
    out, at = [], 2
    while at + 4 <= len(jpeg) and jpeg[at] == 0xFF:
        marker = jpeg[at + 1]
        if marker in (0xDA, 0xD9):
            break
        n = int.from_bytes(jpeg[at + 2 : at + 4], "big")
        out.append((marker, jpeg[at + 4 : at + 2 + n]))
        at += 2 + n
    return out


def tables(jpeg):
    """Its SOF, DQT and DHT segments: what it decodes by (APP markers aside)."""
    return [s for s in segments(jpeg) if s[0] in (0xC0, 0xC1, 0xC2, 0xC4, 0xDB)]


def check_levels(directory, slide_path):
    import highdicom
    import openslide
    import tifffile
    from wsidicom import WsiDicom

    measured = {}
    theirs = openslide.OpenSlide(slide_path)
    n = theirs.level_count
    paths = sorted(glob.glob(os.path.join(directory, "level-*.dcm")))
    if len(paths) != n:
        fail(f"{len(paths)} instances, the slide has {n} levels")
    # The slide's levels as tifffile finds them: the tiled pages of the main chain, largest
    # first, that OpenSlide lists (their sizes).
    sizes = list(theirs.level_dimensions)
    with tifffile.TiffFile(slide_path) as t, open(slide_path, "rb") as f, WsiDicom.open(directory) as wsi:
        pages = []
        for page in t.pages:
            if page.is_tiled and (page.imagewidth, page.imagelength) in sizes[len(pages) :][:1]:
                pages.append(page)
        if len(pages) != n:
            fail(f"tifffile finds {len(pages)} of the slide's {n} levels")
        frames_checked = 0
        for k, page in enumerate(pages):
            p = os.path.join(directory, f"level-{k}.dcm")
            ds = pydicom.dcmread(p)
            want = {
                "SOPClassUID": WSI,
                "DimensionOrganizationType": "TILED_FULL",
                "TotalPixelMatrixColumns": page.imagewidth,
                "TotalPixelMatrixRows": page.imagelength,
                "Rows": page.tilelength,
                "Columns": page.tilewidth,
                "NumberOfFrames": len(page.dataoffsets),
            }
            for key, value in want.items():
                if ds.get(key) != value:
                    fail(f"level {k}: {key} {ds.get(key)!r}, expected {value!r}")
            if ds.file_meta.TransferSyntaxUID != JPEG_BASELINE:
                fail(f"level {k}: transfer syntax {ds.file_meta.TransferSyntaxUID}")
            spacing = [float(v) for v in ds.SharedFunctionalGroupsSequence[0].PixelMeasuresSequence[0].PixelSpacing]
            want_spacing = [0.0005 * pages[0].imagelength / page.imagelength, 0.0005 * pages[0].imagewidth / page.imagewidth]
            if any(abs(a - b) > 1e-9 for a, b in zip(spacing, want_spacing)):
                fail(f"level {k}: Pixel Spacing {spacing}, expected {want_spacing}")
            if highdicom.imread(p).SOPClassUID != WSI:
                fail(f"highdicom: level {k}")
            # wsidicom numbers a level by its scale's power of two (a downsample of 4 is its 2).
            level = wsi.levels[k].level
            across = -(-page.imagewidth // page.tilewidth)
            shared = page.jpegtables or b""
            for i, (offset, count) in enumerate(zip(page.dataoffsets, page.databytecounts)):
                f.seek(offset)
                stored = f.read(count)
                frame = wsi.read_encoded_tile(level, (i % across, i // across), crop_to_image_boundary=False)
                if scan(frame) != scan(stored):
                    fail(f"level {k} tile {i}: the frame's entropy-coded data is not the stored tile's")
                if tables(frame) != tables(shared) + tables(stored):
                    fail(f"level {k} tile {i}: the frame's tables are not the stored tile's and JPEGTables'")
                frames_checked += 1
            # OpenSlide reads the series' level as the slide's, texel for texel.
            ours = openslide.OpenSlide(os.path.join(directory, "level-0.dcm"))
            a = np.asarray(ours.read_region((0, 0), k, ours.level_dimensions[k]))
            b = np.asarray(theirs.read_region((0, 0), k, theirs.level_dimensions[k]))
            if a.shape != b.shape or not np.array_equal(a, b):
                fail(f"OpenSlide reads level {k} of the series otherwise than the slide's")
    measured["instances"] = n
    measured["framesEqual"] = frames_checked
    measured["openslideLevelsEqual"] = n
    print(json.dumps(measured))


def associated_pages(slide_path):
    """The slide's associated images as tifffile decodes them, by kind, as the Aperio
    descriptions name them (the second page, in strips, is the thumbnail)."""
    import tifffile

    out = {}
    with tifffile.TiffFile(slide_path) as t:
        for i, page in enumerate(t.pages):
            words = (page.description or "").lower().replace("\n", " ").split()
            kind = next((k for k in ("label", "macro", "thumbnail") if k in words), None)
            if kind is None and i == 1 and not page.is_tiled:
                kind = "thumbnail"
            if kind:
                out[kind] = page.asarray()
    return out


def native_close(what, got, want, lossless, measured):
    """A native frame against the page as tifffile decodes it: exact where the page is
    lossless (LZW), else at most 2 apart: the same JPEG decoded by our libjpeg-turbo and by
    tifffile's imagecodecs may round the inverse DCT and the chroma upsampling otherwise
    (measured equal here; the measure is printed)."""
    got = got[:, :, None] if got.ndim == 2 else got
    if got.shape != want.shape:
        fail(f"{what}: shape {got.shape}, expected {want.shape}")
    diff = int(np.abs(got.astype(int) - want.astype(int)).max())
    measured[f"{what} max difference"] = diff
    if diff > (0 if lossless else 2):
        fail(f"{what}: {diff} from the page's samples")


def check_associated(directory, slide_path, native=False):
    import highdicom
    import openslide
    from wsidicom import WsiDicom

    measured = {}
    want = associated_pages(slide_path)
    types = {"label": "LABEL", "macro": "OVERVIEW", "thumbnail": "THUMBNAIL"}
    names = {"label": "label.dcm", "macro": "overview.dcm", "thumbnail": "thumbnail.dcm"}
    series = pydicom.dcmread(os.path.join(directory, "level-0.dcm")).SeriesInstanceUID

    def close(what, kind, got, pixels):
        if native:
            # MAKE_SVS_WITH_LABEL's label is LZW; its thumbnail and macro JPEG.
            native_close(what, got, rgb_or_grey(pixels, 3), kind == "label", measured)
        else:
            compare(what, got, rgb_or_grey(pixels, 3), "jpeg", measured)

    for kind, pixels in want.items():
        p = os.path.join(directory, names[kind])
        ds = pydicom.dcmread(p)
        h, w = pixels.shape[:2]
        expect = {
            "SOPClassUID": WSI,
            "SeriesInstanceUID": series,
            "NumberOfFrames": 1,
            "Rows": h,
            "Columns": w,
            "TotalPixelMatrixRows": h,
            "TotalPixelMatrixColumns": w,
        }
        for key, value in expect.items():
            if ds.get(key) != value:
                fail(f"{kind}: {key} {ds.get(key)!r}, expected {value!r}")
        if list(ds.ImageType)[2] != types[kind]:
            fail(f"{kind}: Image Type {list(ds.ImageType)}")
        syntax = EXPLICIT_VR_LE if native else JPEG_BASELINE
        if ds.file_meta.TransferSyntaxUID != syntax:
            fail(f"{kind}: transfer syntax {ds.file_meta.TransferSyntaxUID}")
        # A label's and an overview's photograph has no Pixel Spacing (type 1C: the IOD asks
        # it of VOLUME and THUMBNAIL images only), from which a reader of a TILED_FULL image
        # places its frames (highdicom does): their one frame is placed per frame,
        # TILED_SPARSE. highdicom reads every instance and assembles its pixels.
        organisation = "TILED_FULL" if kind == "thumbnail" else "TILED_SPARSE"
        if ds.DimensionOrganizationType != organisation:
            fail(f"{kind}: {ds.DimensionOrganizationType}, expected {organisation}")
        image = highdicom.imread(p)
        if image.SOPClassUID != WSI:
            fail(f"highdicom: {kind}")
        matrix = image.get_total_pixel_matrix(dtype=np.uint8, apply_icc_profile=False)
        close(f"highdicom {kind}", kind, rgb_or_grey(matrix, 3), pixels)
        close(f"pydicom {kind}", kind, rgb_or_grey(ds.pixel_array, 3), pixels)
    with WsiDicom.open(directory) as slide:
        if "label" in want:
            close("wsidicom label", "label", rgb_or_grey(slide.read_label(), 3), want["label"])
        if "macro" in want:
            close("wsidicom overview", "macro", rgb_or_grey(slide.read_overview(), 3), want["macro"])
    ours = openslide.OpenSlide(os.path.join(directory, "level-0.dcm"))
    listed = sorted(ours.associated_images.keys())
    if listed != sorted(want):
        fail(f"OpenSlide lists {listed}, the slide has {sorted(want)}")
    for kind, pixels in want.items():
        got = np.asarray(ours.associated_images[kind].convert("RGB"))
        close(f"openslide {kind}", kind, got, pixels)
    measured["associated"] = sorted(want)
    print(json.dumps(measured))


def frames_of(level, tile):
    """The TILED_FULL frames of a level, row-major: whole tiles, the right and bottom ones
    padded with the edge texels repeated."""
    h, w, c = level.shape
    rows, cols = -(-h // tile), -(-w // tile)
    padded = np.pad(level, ((0, rows * tile - h), (0, cols * tile - w), (0, 0)), mode="edge")
    return padded.reshape(rows, tile, cols, tile, c).swapaxes(1, 2).reshape(rows * cols, tile, tile, c)


def check_native(directory, source_path, tile):
    import highdicom
    from wsidicom import WsiDicom

    src = source(source_path)
    c = src.shape[2]
    bits = 16 if src.dtype == np.uint16 else 8
    measured = {}
    n = levels_of(src, tile)
    paths = sorted(glob.glob(os.path.join(directory, "level-*.dcm")))
    if len(paths) != n:
        fail(f"{len(paths)} instances, expected {n} (one a level)")
    for k in range(n):
        p = os.path.join(directory, f"level-{k}.dcm")
        ds = pydicom.dcmread(p)
        want = {
            "SOPClassUID": WSI,
            "DimensionOrganizationType": "TILED_FULL",
            "Rows": tile,
            "Columns": tile,
            "SamplesPerPixel": c,
            "PhotometricInterpretation": "RGB" if c == 3 else "MONOCHROME2",
            "PlanarConfiguration": 0 if c == 3 else None,
            "BitsAllocated": bits,
            "BitsStored": bits,
            "HighBit": bits - 1,
            "PixelRepresentation": 0,
            "LossyImageCompression": "00",
            "LossyImageCompressionRatio": None,
            "LossyImageCompressionMethod": None,
        }
        for key, value in want.items():
            if ds.get(key) != value:
                fail(f"level {k}: {key} {ds.get(key)!r}, expected {value!r}")
        if ds.file_meta.TransferSyntaxUID != EXPLICIT_VR_LE:
            fail(f"level {k}: transfer syntax {ds.file_meta.TransferSyntaxUID}")
        vr = ds["PixelData"].VR
        if vr != ("OW" if bits == 16 else "OB"):
            fail(f"level {k}: Pixel Data {vr}")
        level = oracle(src, k)
        frames = np.asarray(ds.pixel_array).reshape(-1, tile, tile, c)
        expected = frames_of(level, tile)
        if frames.dtype != src.dtype or frames.shape != expected.shape:
            fail(f"level {k}: frames {frames.dtype} {frames.shape}, expected {src.dtype} {expected.shape}")
        for i, (got, want_frame) in enumerate(zip(frames, expected)):
            compare(f"pydicom level {k} frame {i}", got, want_frame, "exact", {})
        measured[f"pydicom level {k}"] = f"{len(frames)} frames exact"
        if highdicom.imread(p).SOPClassUID != WSI:
            fail(f"highdicom: level {k}")
    if bits == 16 and c == 3:
        # wsidicom decodes 16-bit samples of grey images only (its native decoder's rule).
        measured["wsidicom"] = "not checked: it reads no 16-bit RGB"
    else:
        with WsiDicom.open(directory) as slide:
            if len(slide.levels) != n:
                fail(f"wsidicom: {len(slide.levels)} levels, expected {n}")
            for k, level in enumerate(slide.levels):
                got = rgb_or_grey(slide.read_region((0, 0), k, level.size.to_tuple()), c)
                # 16-bit grey comes as a PIL "I" image (int32) holding the samples as they are.
                if got.dtype != src.dtype and got.min() >= 0 and got.max() <= np.iinfo(src.dtype).max:
                    got = got.astype(src.dtype)
                compare(f"wsidicom level {k}", got, oracle(src, k), "exact", measured)
    if c == 3 and bits == 8:
        check_openslide(directory, src, n, "exact", measured)
    else:
        measured["openslide"] = "not checked: it reads 8-bit RGB DICOM slides only"
    measured["instances"] = n
    print(json.dumps(measured))


def lossy(directory, slide_path=None):
    """Each instance's lossy history as pydicom reads it; SLIDE's first page's ratio."""
    listed = lambda v: [] if v is None else [str(x) for x in (v if isinstance(v, pydicom.multival.MultiValue) else [v])]
    said = {}
    for name in sorted(os.listdir(directory)):
        ds = pydicom.dcmread(os.path.join(directory, name), stop_before_pixels=True)
        said[name] = {
            "flag": ds.LossyImageCompression,
            "methods": listed(ds.get("LossyImageCompressionMethod")),
            "ratios": [float(r) for r in listed(ds.get("LossyImageCompressionRatio"))],
        }
    if slide_path:
        import tifffile

        with tifffile.TiffFile(slide_path) as tif:
            page = tif.pages[0]
            said["sourceRatio"] = page.imagewidth * page.imagelength * page.samplesperpixel / sum(page.databytecounts)
    print(json.dumps(said))


def check_jpeg_2000(directory, slide_path, photometric, transfer):
    import highdicom
    import openslide
    import tifffile
    from pydicom.encaps import generate_frames
    from wsidicom import WsiDicom

    theirs = openslide.OpenSlide(slide_path)
    n = theirs.level_count
    paths = sorted(glob.glob(os.path.join(directory, "level-*.dcm")))
    if len(paths) != n:
        fail(f"{len(paths)} instances, the slide has {n} levels")
    frames_equal = 0
    with tifffile.TiffFile(slide_path) as t, open(slide_path, "rb") as f, WsiDicom.open(directory) as wsi:
        pages = [page for page in t.pages if page.is_tiled]
        if len(pages) != n:
            fail(f"tifffile finds {len(pages)} tiled pages, OpenSlide {n} levels")
        for k, page in enumerate(pages):
            p = os.path.join(directory, f"level-{k}.dcm")
            ds = pydicom.dcmread(p)
            if ds.file_meta.TransferSyntaxUID != transfer or ds.PhotometricInterpretation != photometric:
                fail(f"level {k}: {ds.file_meta.TransferSyntaxUID} {ds.PhotometricInterpretation}")
            if (ds.Columns, ds.Rows, ds.NumberOfFrames) != (page.tilewidth, page.tilelength, len(page.dataoffsets)):
                fail(f"level {k}: {ds.Columns}x{ds.Rows} frames, {ds.NumberOfFrames} of them")
            if highdicom.imread(p).SOPClassUID != WSI:
                fail(f"highdicom: level {k}")
            stored = []
            for offset, count in zip(page.dataoffsets, page.databytecounts):
                f.seek(offset)
                stored.append(f.read(count))
            frames = list(generate_frames(ds.PixelData, number_of_frames=ds.NumberOfFrames))
            # An item holds an even number of bytes: an odd codestream ends padded with one 0.
            for i, (frame, tile) in enumerate(zip(frames, stored)):
                if frame != tile and frame != tile + b"\0":
                    fail(f"level {k} frame {i}: not the slide's stored codestream")
            across = -(-page.imagewidth // page.tilewidth)
            level = wsi.levels[k].level
            for i, tile in enumerate(stored):
                got = wsi.read_encoded_tile(level, (i % across, i // across), crop_to_image_boundary=False)
                if got.rstrip(b"\0") != tile.rstrip(b"\0"):
                    fail(f"wsidicom: level {k} tile {i} is not the stored codestream")
            frames_equal += len(stored)
    thumbnail = pydicom.dcmread(os.path.join(directory, "thumbnail.dcm"))
    if thumbnail.file_meta.TransferSyntaxUID != JPEG_BASELINE or thumbnail.NumberOfFrames != 1:
        fail(f"thumbnail: {thumbnail.file_meta.TransferSyntaxUID}, {thumbnail.NumberOfFrames} frames")
    measured = {"instances": n, "framesEqual": frames_equal}
    if photometric in ("RGB", "YBR_RCT", "YBR_ICT"):
        ours = openslide.OpenSlide(paths[0])
        for k in range(n):
            a = np.asarray(ours.read_region((0, 0), k, ours.level_dimensions[k]))
            b = np.asarray(theirs.read_region((0, 0), k, theirs.level_dimensions[k]))
            if a.shape != b.shape or not np.array_equal(a, b):
                fail(f"OpenSlide reads level {k} of the series otherwise than the slide's")
        measured["openslideLevelsEqual"] = n
    else:
        measured["openslide"] = f"skipped: it reads no {photometric} JPEG 2000"
    print(json.dumps(measured))


JXL_CODESTREAM = b"\xff\x0a"
JXL_CONTAINER = b"\x00\x00\x00\x0cJXL \r\n\x87\n"
JXL_RECOMPRESSION = "1.2.840.10008.1.2.4.111"


def check_jxl(directory, source_path, tile, mode, jpeg_dir=None):
    import subprocess
    import tempfile

    import highdicom
    from pydicom.encaps import generate_frames
    from wsidicom import WsiDicom

    listed = lambda v: [] if v is None else [str(x) for x in (v if isinstance(v, pydicom.multival.MultiValue) else [v])]
    src = source(source_path)
    c = src.shape[2]
    bits = 16 if src.dtype == np.uint16 else 8
    n = levels_of(src, tile)
    paths = sorted(glob.glob(os.path.join(directory, "level-*.dcm")))
    if len(paths) != n:
        fail(f"{len(paths)} instances, expected {n} (one a level)")
    measured = {"transferSyntaxes": [], "photometric": [], "lossy": [], "methods": []}
    for k in range(n):
        p = os.path.join(directory, f"level-{k}.dcm")
        ds = pydicom.dcmread(p)
        want = {
            "SOPClassUID": WSI,
            "DimensionOrganizationType": "TILED_FULL",
            "Rows": tile,
            "Columns": tile,
            "SamplesPerPixel": c,
            "PlanarConfiguration": 0 if c == 3 else None,
            "BitsAllocated": bits,
            "BitsStored": bits,
            "HighBit": bits - 1,
            "PixelRepresentation": 0,
        }
        for key, value in want.items():
            if ds.get(key) != value:
                fail(f"level {k}: {key} {ds.get(key)!r}, expected {value!r}")
        measured["transferSyntaxes"].append(str(ds.file_meta.TransferSyntaxUID))
        measured["photometric"].append(ds.PhotometricInterpretation)
        measured["lossy"].append(ds.LossyImageCompression)
        measured["methods"].append(listed(ds.get("LossyImageCompressionMethod")))
        frames = list(generate_frames(ds.PixelData, number_of_frames=ds.NumberOfFrames))
        if len(frames) != ds.NumberOfFrames or not all(f.startswith((JXL_CODESTREAM, JXL_CONTAINER)) for f in frames):
            fail(f"level {k}: {len(frames)} frames, not {ds.NumberOfFrames} JPEG XL codestreams or containers")
        if highdicom.imread(p).SOPClassUID != WSI:
            fail(f"highdicom: level {k}")
    # wsidicom 0.36 opens an instance only where it has an encoder for its transfer syntax
    # too (codec.Codec.is_supported), which it has for .110 and .112, not .111: those levels
    # are decoded here by imagecodecs' libjxl, wsidicom's decoder, frame by frame.
    recompression = [k for k, ts in enumerate(measured["transferSyntaxes"]) if ts == JXL_RECOMPRESSION]
    others = [k for k in range(n) if k not in recompression]
    if others:
        with WsiDicom.open(directory) as slide:
            if len(slide.levels) != len(others):
                fail(f"wsidicom: {len(slide.levels)} levels, expected {len(others)}")
            for i, (k, level) in enumerate(zip(others, slide.levels)):
                got = rgb_or_grey(slide.read_region((0, 0), i, level.size.to_tuple()), c)
                # 16-bit grey comes as a PIL "I" image (int32) holding the samples as they are.
                if got.dtype != src.dtype and got.min() >= 0 and got.max() <= np.iinfo(src.dtype).max:
                    got = got.astype(src.dtype)
                compare(f"wsidicom level {k}", got, oracle(src, k), mode, measured)
    for k in recompression:
        import imagecodecs

        ds = pydicom.dcmread(os.path.join(directory, f"level-{k}.dcm"))
        frames = list(generate_frames(ds.PixelData, number_of_frames=ds.NumberOfFrames))
        cols = -(-ds.TotalPixelMatrixColumns // ds.Columns)
        rows = -(-ds.TotalPixelMatrixRows // ds.Rows)
        whole = np.zeros((rows * ds.Rows, cols * ds.Columns, c), np.uint8)
        for i, frame in enumerate(frames[: rows * cols]):
            tile = rgb_or_grey(imagecodecs.jpegxl_decode(frame), c)
            r, q = divmod(i, cols)
            whole[r * ds.Rows : (r + 1) * ds.Rows, q * ds.Columns : (q + 1) * ds.Columns] = tile
        got = whole[: ds.TotalPixelMatrixRows, : ds.TotalPixelMatrixColumns]
        want = oracle(src, k)
        # A slide's own level made by libvips halves rounding down (287 x 187 where the box
        # pyramid has 288 x 188): compared where both have texels.
        if all(0 <= w - g <= 1 for g, w in zip(got.shape[:2], want.shape[:2])):
            want = want[: got.shape[0], : got.shape[1]]
        compare(f"imagecodecs level {k}", got, want, mode, measured)
    if jpeg_dir:
        measured["rebuilt"] = []
        with tempfile.TemporaryDirectory() as scratch:
            for k in range(n):
                ours = pydicom.dcmread(os.path.join(directory, f"level-{k}.dcm"))
                jpegs = pydicom.dcmread(os.path.join(jpeg_dir, f"level-{k}.dcm"))
                frames = list(generate_frames(ours.PixelData, number_of_frames=ours.NumberOfFrames))
                stored = list(generate_frames(jpegs.PixelData, number_of_frames=jpegs.NumberOfFrames))
                if len(frames) != len(stored):
                    fail(f"level {k}: {len(frames)} frames, the JPEG series {len(stored)}")
                rebuilt = []
                for i, (frame, jpeg) in enumerate(zip(frames, stored)):
                    if b"jbrd" not in frame:
                        continue
                    jxl, back = os.path.join(scratch, "frame.jxl"), os.path.join(scratch, "frame.jpg")
                    with open(jxl, "wb") as f:
                        f.write(frame)
                    run = subprocess.run(["djxl", jxl, back], capture_output=True)
                    if run.returncode != 0:
                        fail(f"djxl: level {k} frame {i}: {run.stderr.decode(errors='replace')}")
                    with open(back, "rb") as f:
                        again = f.read()
                    # An item holds an even number of bytes: a JPEG of odd length ends padded with one 0.
                    if again != jpeg and again + b"\0" != jpeg:
                        fail(f"level {k} frame {i}: djxl's JPEG is not the JPEG series' frame (the stored tile)")
                    rebuilt.append(i)
                if k == 0:
                    measured["rebuiltFrames"] = rebuilt
                measured["rebuilt"].append(len(rebuilt))
    print(json.dumps(measured))


def main():
    if sys.argv[1] == "jxl":
        check_jxl(sys.argv[2], sys.argv[3], int(sys.argv[4]), sys.argv[5], *sys.argv[6:7])
        return
    if sys.argv[1] == "j2k":
        check_jpeg_2000(*sys.argv[2:6])
        return
    if sys.argv[1] == "lossy":
        lossy(*sys.argv[2:4])
        return
    if sys.argv[1] == "native":
        check_native(sys.argv[2], sys.argv[3], int(sys.argv[4]))
        return
    if sys.argv[1] == "levels":
        check_levels(sys.argv[2], sys.argv[3])
        return
    if sys.argv[1] == "associated":
        check_associated(sys.argv[2], sys.argv[3], sys.argv[4:] == ["native"])
        return
    directory, source_path, tile = sys.argv[1], sys.argv[2], int(sys.argv[3])
    copied_from = sys.argv[4] if len(sys.argv) > 4 else None
    src = source(source_path)
    measured = {}
    n = check_instances(directory, src, tile, measured)
    check_wsidicom(directory, src, n, "jpeg", measured)
    if src.shape[2] == 3:
        check_openslide(directory, src, n, "jpeg", measured)
    else:
        # libdicom asks every image for Planar Configuration, which the Image Pixel module
        # forbids where Samples per Pixel is 1: OpenSlide 4 opens RGB DICOM slides only.
        measured["openslide"] = "skipped: it reads RGB DICOM slides only"
    if copied_from:
        count_copied(directory, copied_from, measured)
    print(json.dumps(measured))


main()
