"""Reads a pyramidal TIFF we wrote with the readers of that world and checks every level
against a naive pyramid of the source (tests/it/tiff_out.rs runs it with VORTEX_PYVIPS).

    tiff_out.py ome|generic TIFF SOURCE TILE exact|jpeg

ome: tifffile reads one OME series with every level (SubIFDs), libvips every `subifd=`, and
the OME-XML validates against the OME schema (ome-types);
generic: tifffile reads a page a level, libvips every `page=`, OpenSlide 4 opens it as
generic-tiff with every level and `read_region` gives the source (8-bit RGB sources).
exact: each level equals the oracle sample for sample; jpeg: within JPEG's error of it, and
every level's JPEG tiles share its JPEGTables (no tile holds a DQT or DHT segment).
Prints one JSON line of what it measured; exits 1 with the reason on a mismatch.
"""

import json
import sys

import numpy as np
import ome_types
import pyvips
import tifffile

from tiff_oracle import compare, fail, levels_of, oracle


def source(path):
    """The source image as rows x columns x samples."""
    a = pyvips.Image.new_from_file(path).numpy()
    return a[:, :, None] if a.ndim == 2 else a


def libvips_decodes(path, measured):
    """Whether this libvips' libtiff has the file's codec: pyvips-binary 8.18.7's is built
    without ZSTD ("ZSTD compression support is not configured"); any other failure fails."""
    try:
        pyvips.Image.new_from_file(path, fail=True).avg()
        return True
    except pyvips.Error as e:
        if "ZSTD compression support is not configured" in str(e):
            measured["libvips"] = "skipped: its libtiff has no zstd"
            return False
        fail(f"libvips: {e}")


def check_predictor(what, page, src):
    """Float samples, compressed, take the floating-point predictor (3); integers the
    horizontal one (2)."""
    if page.compression == 1 or page.compression == 7:
        return
    want = 3 if src.dtype.kind == "f" else 2
    if int(page.predictor) != want:
        fail(f"{what}: Predictor {int(page.predictor)}, expected {want}")


def tables_of(stream):
    """The DQT and DHT segments of a JPEG stream's header, as they are, in order."""
    out, at = b"", 2
    while at + 4 <= len(stream) and stream[at] == 0xFF and stream[at + 1] not in (0xDA, 0xD9):
        end = at + 2 + int.from_bytes(stream[at + 2 : at + 4], "big")
        if stream[at + 1] in (0xDB, 0xC4):
            out += stream[at:end]
        at = end
    return out


def check_shared_tables(what, page, measured):
    """A JPEG level's tables are its JPEGTables (quantisation and Huffman tables), and its
    tiles are abbreviated streams without them, as libvips and scanners write them; a tile of
    other tables (a copied tile of another encoder) holds its own."""
    if page.compression != 7:
        return
    shared = tables_of(page.jpegtables or b"")
    if not (b"\xff\xdb" in shared and b"\xff\xc4" in shared):
        fail(f"{what}: JPEGTables {page.jpegtables[:16]!r}..., expected SOI, DQT and DHT")
    fh = page.parent.filehandle
    abbreviated = 0
    for i, (offset, count) in enumerate(zip(page.dataoffsets, page.databytecounts)):
        fh.seek(offset)
        own = tables_of(fh.read(min(count, 4096)))
        if own == shared:
            fail(f"{what}: tile {i} holds the level's shared tables")
        abbreviated += not own
    if abbreviated == 0:
        fail(f"{what}: no tile takes the shared tables")
    measured["sharedTables"] = measured.get("sharedTables", 0) + 1


def check_ome(path, src, tile, mode, measured):
    n = levels_of(src, tile)
    with tifffile.TiffFile(path) as t:
        if not t.is_ome:
            fail("tifffile does not take it for an OME-TIFF")
        if len(t.series) != 1:
            fail(f"{len(t.series)} series, expected 1")
        s = t.series[0]
        if len(s.levels) != n:
            fail(f"{len(s.levels)} levels in the series, expected {n}")
        xml = t.ome_metadata
        # ome-types checks the document against the OME 2016-06 schema (its bundled XSD,
        # through lxml) and parses it.
        try:
            pixels = ome_types.from_xml(xml, validate=True).images[0].pixels
        except Exception as e:
            fail(f"the OME-XML does not validate against the OME schema: {e}")
        h, w, c = src.shape
        if (pixels.size_x, pixels.size_y, pixels.size_c) != (w, h, c):
            fail(f"OME-XML says {pixels.size_x}x{pixels.size_y}x{pixels.size_c}, expected {w}x{h}x{c}")
        measured["ome-types"] = "valid"
        for k, level in enumerate(s.levels):
            check_predictor(f"level {k}", level.keyframe, src)
            check_shared_tables(f"level {k}", level.keyframe, measured)
            compare(f"tifffile level {k}", level.asarray(), oracle(src, k), mode, measured)
    for k in range(n) if libvips_decodes(path, measured) else ():
        image = pyvips.Image.new_from_file(path, subifd=k - 1)
        compare(f"libvips subifd={k - 1}", image.numpy(), oracle(src, k), mode, measured)


def check_generic(path, src, tile, mode, measured):
    n = levels_of(src, tile)
    with tifffile.TiffFile(path) as t:
        if len(t.pages) != n:
            fail(f"{len(t.pages)} pages, expected {n}")
        for k, page in enumerate(t.pages):
            if k > 0 and page.subfiletype != 1:
                fail(f"page {k}: NewSubfileType {page.subfiletype}, expected 1")
            check_predictor(f"page {k}", page, src)
            check_shared_tables(f"page {k}", page, measured)
            compare(f"tifffile page {k}", page.asarray(), oracle(src, k), mode, measured)
    for k in range(n) if libvips_decodes(path, measured) else ():
        image = pyvips.Image.new_from_file(path, page=k)
        compare(f"libvips page={k}", image.numpy(), oracle(src, k), mode, measured)
    if src.shape[2] != 3 or src.dtype != np.uint8:
        # OpenSlide gives 8-bit RGBA: it reads 8-bit RGB pyramids as they are.
        return
    import openslide

    slide = openslide.OpenSlide(path)
    vendor = slide.properties.get("openslide.vendor")
    if vendor != "generic-tiff":
        fail(f"OpenSlide's vendor: {vendor}")
    if slide.level_count != n:
        fail(f"OpenSlide sees {slide.level_count} levels, expected {n}")
    h, w = src.shape[:2]
    for k in range(n):
        want = (-(-w // (1 << k)), -(-h // (1 << k)))
        if slide.level_dimensions[k] != want:
            fail(f"OpenSlide level {k}: {slide.level_dimensions[k]}, expected {want}")
        if abs(slide.level_downsamples[k] - (1 << k)) > 0.01 * (1 << k):
            fail(f"OpenSlide level {k}: downsample {slide.level_downsamples[k]}")
    # The whole image at level 0, and level 1 (at a level's own pixels, no resampling).
    for k in (0, 1) if n > 1 else (0,):
        want = oracle(src, k)
        size = (want.shape[1], want.shape[0])
        region = np.asarray(slide.read_region((0, 0), k, size))
        if not (region[:, :, 3] == 255).all():
            fail(f"OpenSlide level {k}: transparent pixels inside the image")
        compare(f"OpenSlide read_region level {k}", region[:, :, :3], want, mode, measured)
    slide.close()


def main():
    flavour, path, src_path, tile, mode = sys.argv[1:6]
    src = source(src_path)
    measured = {}
    if flavour == "ome":
        check_ome(path, src, int(tile), mode, measured)
    else:
        check_generic(path, src, int(tile), mode, measured)
    print(json.dumps(measured))


main()
