//! The rest of TIFF that scanners, slide vendors and document systems write: planar-separate,
//! 1/2/4-bit grey, CCITT fax, palette and CMYK. Inputs are made here by the tools that write
//! them (libvips, libtiff's `tiffcp`, tifffile) from a generated image; the texels are compared
//! with libvips's decode (`vips rawsave`, through libtiff) or tifffile's, exactly: these are
//! lossless kinds (CMYK goes through LittleCMS on both sides and has a stated tolerance).

use std::path::{Path, PathBuf};

use crate::common::cli::{self, s};
use crate::common::compare::{Picture, Tolerance, assert_close};
use crate::tiff_slides::{
    have_tools, openslide_texels, our_texels, pattern_png, python, tool, venv_python, vips_texels,
};
use vortex_tiler::limits::Budget;
use vortex_tiler::pixel::{Channels, Depth, PixelLayout};
use vortex_tiler::source;

/// Each `(file, summary needle)` decodes to libvips's texels exactly.
fn assert_as_vips(files: &[(PathBuf, &str)]) {
    for (path, says) in files {
        let (source, ours) = our_texels(path, 1 << 30);
        let described = source.describe();
        assert!(described.contains(says), "{}: {described} lacks {says:?}", path.display());
        let theirs = vips_texels(path);
        assert_eq!(ours.len(), theirs.len(), "{}: {described}", path.display());
        let differ = ours.iter().zip(&theirs).filter(|(a, b)| a != b).count();
        assert!(differ == 0, "{}: {differ} samples differ from libvips's decode ({described})", path.display());
    }
}

/// `tiffcp ARGS from to`.
fn tiffcp(from: &Path, to: &Path, args: &[&str]) -> PathBuf {
    let mut all = args.to_vec();
    all.extend([s(from), s(to)]);
    tool("tiffcp", &all);
    to.to_path_buf()
}

/// Planar-separate RGB, RGBA and 16-bit, in strips and tiles, with every compression read,
/// predictor included, as libtiff and tifffile write them: libvips's texels of the contiguous
/// file they were made from, exactly (libvips 8.14 reads planar strips but not planar tiles).
#[test]
fn planar_separate_decodes_as_libvips_does() {
    if !have_tools() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let d = |name: &str| dir.path().join(name);
    let png = pattern_png(dir.path(), 301, 203);
    let rgb = d("rgb.tif");
    tool("vips", &["copy", s(&png), s(&rgb)]);
    let rgba = d("rgba.tif");
    tool("vips", &["bandjoin_const", s(&png), s(&rgba), "200"]);
    // (planar file, the contiguous file it was made from)
    let mut files = Vec::new();
    for (name, args) in [
        ("none-strips", vec!["-c", "none", "-r", "16"]),
        ("lzw-strips", vec!["-c", "lzw", "-r", "7"]),
        ("lzw-predictor", vec!["-c", "lzw:2", "-r", "32"]),
        ("zip-tiles", vec!["-c", "zip", "-t", "-w", "64", "-l", "48"]),
        ("packbits-tiles", vec!["-c", "packbits", "-t", "-w", "128", "-l", "128"]),
        ("one-strip", vec!["-c", "zip:2"]),
    ] {
        let mut args = args.clone();
        args.extend(["-p", "separate"]);
        for from in [&rgb, &rgba] {
            let to = d(&format!("{name}-{}", from.file_name().unwrap().to_str().unwrap()));
            files.push((tiffcp(from, &to, &args), from.clone()));
        }
    }
    // libtiff's tiffcp separates 8-bit planes only: 16-bit ones are written by tifffile.
    if let Some(py) = venv_python() {
        python(&py, MAKE_PLANAR_16, &[s(&d("planar16"))]);
        for name in ["planar16-strips.tif", "planar16-tiles.tif"] {
            files.push((d(name), d("planar16-contig.tif")));
        }
    }
    for (path, from) in &files {
        let (source, ours) = our_texels(path, 1 << 30);
        let described = source.describe();
        assert!(described.contains("planar-separate") && described.contains("-bit RGB"), "{described}");
        assert!(
            ours == vips_texels(from),
            "{}: differs from libvips's decode of {} ({described})",
            path.display(),
            from.display()
        );
    }
}

/// 1-bit grey raw, PackBits, LZW, CCITT Group 3 (one- and two-dimensional), Group 4 (strips and
/// tiles) and modified Huffman (Compression 2, written by Pillow through libtiff), 2- and 4-bit
/// grey, WhiteIsZero: libvips's texels (0/255 for bilevel, scaled for 2/4 bits) exactly.
#[test]
fn bilevel_fax_and_sub_byte_grey_decode_as_libvips_does() {
    if !have_tools() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let d = |name: &str| dir.path().join(name);
    let png = pattern_png(dir.path(), 333, 201);
    let grey = d("grey.v");
    tool("vips", &["colourspace", s(&png), s(&grey), "b-w"]);
    let one = d("one.tif");
    tool("vips", &["tiffsave", s(&grey), s(&one), "--bitdepth", "1"]);
    let white_is_zero = d("wiz.tif");
    tool("vips", &["tiffsave", s(&grey), s(&white_is_zero), "--bitdepth", "1", "--miniswhite"]);
    let mut files = vec![(one.clone(), "1-bit grey"), (white_is_zero.clone(), "WhiteIsZero")];
    for (name, args, says) in [
        ("g4", vec!["-c", "g4"], "ccitt g4"),
        ("g4-strips", vec!["-c", "g4", "-r", "10"], "ccitt g4"),
        ("g4-tiles", vec!["-c", "g4", "-t", "-w", "64", "-l", "32"], "ccitt g4"),
        ("g3", vec!["-c", "g3"], "ccitt g3"),
        ("g3-fill", vec!["-c", "g3:fill", "-r", "9"], "ccitt g3"),
        ("g3-2d", vec!["-c", "g3:2d"], "ccitt g3 2-d"),
        ("g3-2d-fill", vec!["-c", "g3:2d:fill", "-r", "9"], "ccitt g3 2-d"),
        ("g3-2d-tiles", vec!["-c", "g3:2d", "-t", "-w", "64", "-l", "32"], "ccitt g3 2-d"),
        ("packbits", vec!["-c", "packbits", "-r", "5"], "packbits"),
        ("lzw-tiles", vec!["-c", "lzw", "-t", "-w", "32", "-l", "32"], "lzw"),
        ("lsb-first", vec!["-c", "g4", "-f", "lsb2msb"], "ccitt g4"),
    ] {
        files.push((tiffcp(&one, &d(&format!("{name}.tif")), &args), says));
        files.push((tiffcp(&white_is_zero, &d(&format!("{name}-wiz.tif")), &args), says));
    }
    for bits in ["2", "4"] {
        let path = d(&format!("grey{bits}.tif"));
        tool("vips", &["tiffsave", s(&grey), s(&path), "--bitdepth", bits]);
        let lzw = tiffcp(&path, &d(&format!("grey{bits}-lzw.tif")), &["-c", "lzw", "-r", "3"]);
        let wiz = d(&format!("grey{bits}-wiz.tif"));
        tool("vips", &["tiffsave", s(&grey), s(&wiz), "--bitdepth", bits, "--miniswhite"]);
        files.extend([(path, "-bit grey"), (lzw, "lzw"), (wiz, "WhiteIsZero")]);
    }
    // Compression 2: libtiff writes it (tiffcp does not offer it), through Pillow.
    if let Some(py) = venv_python() {
        let script =
            "import sys\nfrom PIL import Image\nImage.open(sys.argv[1]).save(sys.argv[2], compression='tiff_ccitt')";
        for from in [&one, &white_is_zero] {
            let to = d(&format!("mh-{}", from.file_name().unwrap().to_str().unwrap()));
            python(&py, script, &[s(from), s(&to)]);
            files.push((to, "ccitt modified huffman"));
        }
    }
    assert_as_vips(&files);

    // Two-dimensional Group 3 data zeroed: an error naming the file, the strip and the fax
    // row, never a panic.
    let mut bytes = std::fs::read(d("g3-2d-fill.tif")).unwrap();
    let zeroed = d("zeroed-2d.tif");
    let data = 8..bytes.len() / 2;
    bytes[data].fill(0);
    std::fs::write(&zeroed, &bytes).unwrap();
    let mut source = source::open(&zeroed, Budget::new(1 << 30)).unwrap();
    let mut row = vec![0u8; 333];
    let err = (0..201).find_map(|_| source.read_row(&mut row).err()).expect("zeroed fax data fails").to_string();
    for needle in ["zeroed-2d.tif", "strip 0 (rows 0..9)", "fax row 0"] {
        assert!(err.contains(needle), "{needle:?} missing from: {err}");
    }
    // Compression 2 whose first strip is zeroed: no white run code is all zeros.
    if let Some(py) = venv_python() {
        let mh = d("mh-one.tif");
        let script = "import sys, tifffile\nwith tifffile.TiffFile(sys.argv[1]) as t:\n    p = t.pages[0]\n    o, n = p.dataoffsets[0], p.databytecounts[0]\nf = open(sys.argv[1], 'r+b'); f.seek(o); f.write(bytes(n))";
        python(&py, script, &[s(&mh)]);
        let mut source = source::open(&mh, Budget::new(1 << 30)).unwrap();
        let err = source.read_row(&mut row).expect_err("zeroed fax data fails").to_string();
        for needle in ["mh-one.tif", "strip 0", "a bad run length in fax row 0"] {
            assert!(err.contains(needle), "{needle:?} missing from: {err}");
        }
    }
}

/// 16-bit planar-separate RGB, Deflate with the predictor, in strips and in tiles.
const MAKE_PLANAR_16: &str = r#"
import sys, numpy as np, tifffile
h, w = 77, 123
y, x = np.mgrid[0:h, 0:w]
img = np.stack([x * 531, y * 850, (x * y * 37) % 65536], -1).astype(np.uint16)
img[::5] = np.random.default_rng(3).integers(0, 65536, img[::5].shape)
kw = dict(planarconfig="separate", photometric="rgb", compression="zlib", predictor=True, metadata=None)
planes = np.ascontiguousarray(np.moveaxis(img, -1, 0))
tifffile.imwrite(sys.argv[1] + "-strips.tif", planes, rowsperstrip=10, **kw)
tifffile.imwrite(sys.argv[1] + "-tiles.tif", planes, tile=(32, 48), **kw)
tifffile.imwrite(sys.argv[1] + "-contig.tif", img, photometric="rgb", metadata=None)
"#;

/// Palette TIFFs of 1, 2, 4 and 8-bit indices. tifffile writes only 8-bit palettes with a
/// ColorMap libtiff accepts, so the smaller ones are written as grey and retagged (the
/// ColorMap added as an extra tag, PhotometricInterpretation set to 3). Maps of 8-bit values
/// (each entry v x 257, as libtiff-based writers store them) go to NAME-BITS.tif; one 4-bit map
/// of full 16-bit values goes to NAME-deep.tif with its expected RGB16 texels (native order)
/// in NAME-deep.rgb, the map applied to the indices tifffile reads back.
const MAKE_PALETTES: &str = r#"
import sys, numpy as np, tifffile
h, w = 61, 83
y, x = np.mgrid[0:h, 0:w]
rng = np.random.default_rng(5)
def write(path, bits, cmap):
    n = 1 << bits
    idx = ((x // 3 + y // 5 + (x * y) % 7) % n).astype(np.uint8)
    idx[::4] = rng.integers(0, n, idx[::4].shape)
    if bits == 8:
        tifffile.imwrite(path, idx, photometric="palette", colormap=cmap, rowsperstrip=9, metadata=None)
    else:
        tifffile.imwrite(path, idx, photometric="minisblack", bitspersample=bits, rowsperstrip=9, metadata=None,
                         extratags=[(320, "H", 3 * n, cmap.ravel(), True)])
        with tifffile.TiffFile(path, mode="r+b") as t:
            t.pages[0].tags["PhotometricInterpretation"].overwrite(3)
    return idx
for bits in (1, 2, 4, 8):
    n = 1 << bits
    cmap = (rng.integers(0, 256, (3, n)) * 257).astype(np.uint16)
    write("%s-%d.tif" % (sys.argv[1], bits), bits, cmap)
deep = rng.integers(0, 65536, (3, 16)).astype(np.uint16)
idx = write(sys.argv[1] + "-deep.tif", 4, deep)
back = tifffile.imread(sys.argv[1] + "-deep.tif")
assert (back == idx).all()
open(sys.argv[1] + "-deep.rgb", "wb").write(np.ascontiguousarray(deep[:, back].transpose(1, 2, 0)).astype("=u2").tobytes())
"#;

/// Palette images of every index depth, uncompressed and recompressed by libtiff: libvips's
/// texels for maps of 8-bit values; a map of full 16-bit values is kept at 16 bits and matches
/// the map applied to tifffile's indices.
#[test]
fn palettes_decode_as_libvips_and_tifffile_do() {
    if !have_tools() {
        return;
    }
    let Some(py) = venv_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let d = |name: &str| dir.path().join(name);
    python(&py, MAKE_PALETTES, &[s(&d("pal"))]);
    let mut files = Vec::new();
    for bits in [1, 2, 4, 8] {
        let plain = d(&format!("pal-{bits}.tif"));
        let lzw = tiffcp(&plain, &d(&format!("pal-{bits}-lzw.tif")), &["-c", "lzw", "-r", "4"]);
        let tiles =
            tiffcp(&plain, &d(&format!("pal-{bits}-tiles.tif")), &["-c", "packbits", "-t", "-w", "32", "-l", "16"]);
        files.extend([(plain, "-bit palette to RGB (16-bit map of 8-bit values)"), (lzw, "lzw"), (tiles, "packbits")]);
    }
    assert_as_vips(&files);

    let deep = d("pal-deep.tif");
    let (source, ours) = our_texels(&deep, 1 << 30);
    assert!(source.describe().contains("4-bit palette to RGB (16-bit map, kept at 16 bits)"), "{}", source.describe());
    assert_eq!(source.layout(), PixelLayout::new(Channels::Rgb, Depth::U16));
    assert!(ours == std::fs::read(d("pal-deep.rgb")).unwrap(), "the 16-bit palette differs from tifffile's");
}

/// CMYK TIFF (InkSet 1) with its embedded profile, contiguous and planar, and without one
/// (the default CMYK profile): converted to sRGB as `vips icc_transform` converts it.
#[test]
fn cmyk_tiff_is_converted_through_its_profile_or_the_default_one() {
    let default = Path::new(source::icc::DEFAULT_CMYK_PROFILE);
    if !have_tools() || !default.is_file() {
        crate::common::skip_unless_ci(
            "the CMYK test",
            &format!("no {} (apt-get install ghostscript)", default.display()),
        );
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let d = |name: &str| dir.path().join(name);
    let png = pattern_png(dir.path(), 97, 66);
    let tagged = d("cmyk.tif");
    tool("vips", &["icc_export", s(&png), s(&tagged), "--output-profile", s(default)]);
    let planar = tiffcp(&tagged, &d("cmyk-planar.tif"), &["-p", "separate", "-c", "lzw", "-r", "8"]);
    let bare = d("bare.tif");
    tool("vips", &["copy", s(&tagged), &format!("{}[strip]", s(&bare))]);
    for (path, embedded) in [(&tagged, true), (&planar, true), (&bare, false)] {
        let source = source::open_with(path, source::OpenOptions::shown(Budget::new(1 << 30))).unwrap().source;
        let described = source.describe();
        let whence = if embedded { "embedded ICC" } else { "no profile embedded" };
        assert!(described.contains("CMYK") && described.contains(whence), "{described}");
        assert!(source.embedded().icc.is_none(), "the profile is used up");
        let theirs = d("theirs.png");
        let mut args = vec!["icc_transform", s(path), s(&theirs), "srgb", "--intent", "relative"];
        match embedded {
            true => args.push("--embedded"),
            false => args.extend(["--input-profile", s(default)]),
        }
        tool("vips", &args);
        let theirs = image::open(&theirs).unwrap().to_rgb8().into_raw();
        let (source, ours) = our_texels(path, 1 << 30);
        let why = "LittleCMS on both sides through the same CLUT profile; libvips goes through Lab in float and we convert 8-bit to 8-bit, so rounding differs by a step or two";
        let (w, h) = (source.width(), source.height());
        let name = format!("cmyk-{}", path.file_name().unwrap().to_string_lossy());
        assert_close(
            &name,
            Picture::new(w, h, 3, &ours),
            Picture::new(w, h, 3, &theirs),
            Tolerance::max_and_mean(3, 0.6, why),
        );
    }
}

/// A strip past the end of the file and fax data that is not fax data: errors naming the file,
/// the strip (and plane) and the rows; a planar image larger than --max-memory streams, and
/// `split` takes it end to end.
#[test]
fn damaged_kinds_name_the_strip_and_large_ones_stream() {
    if !have_tools() {
        return;
    }
    let Some(py) = venv_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let d = |name: &str| dir.path().join(name);
    let png = pattern_png(dir.path(), 512, 384);
    let rgb = d("rgb.tif");
    tool("vips", &["copy", s(&png), s(&rgb)]);

    // Plane 1's third strip moved past the end of the file.
    let planar = tiffcp(&rgb, &d("planar.tif"), &["-p", "separate", "-c", "none", "-r", "16"]);
    let moved = d("moved.tif");
    std::fs::copy(&planar, &moved).unwrap();
    let script = "import sys, tifffile\nwith tifffile.TiffFile(sys.argv[1], mode='r+b') as t:\n    tag = t.pages[0].tags['StripOffsets']\n    v = list(tag.value)\n    v[24 + 2] = 1 << 30\n    tag.overwrite(v)";
    python(&py, script, &[s(&moved)]);
    let mut source = source::open(&moved, Budget::new(1 << 30)).unwrap();
    let mut row = vec![0u8; 512 * 3];
    for _ in 0..32 {
        source.read_row(&mut row).unwrap();
    }
    let err = source.read_row(&mut row).unwrap_err().to_string();
    for needle in ["moved.tif", "row 32", "strip 26 of plane 1 (rows 32..48)", "past the end of the file"] {
        assert!(err.contains(needle), "{needle:?} missing from: {err}");
    }

    // Group 4 strips whose bytes are zeroed: no valid code.
    let grey = d("grey.v");
    tool("vips", &["colourspace", s(&png), s(&grey), "b-w"]);
    let one = d("one.tif");
    tool("vips", &["tiffsave", s(&grey), s(&one), "--bitdepth", "1"]);
    let g4 = tiffcp(&one, &d("g4.tif"), &["-c", "g4", "-r", "64"]);
    let script = "import sys, tifffile\nwith tifffile.TiffFile(sys.argv[1]) as t:\n    p = t.pages[0]\n    o, n = p.dataoffsets[2], p.databytecounts[2]\nf = open(sys.argv[1], 'r+b'); f.seek(o); f.write(bytes(n))";
    python(&py, script, &[s(&g4)]);
    let mut source = source::open(&g4, Budget::new(1 << 30)).unwrap();
    let mut row = vec![0u8; 512];
    let err = (0..384).find_map(|_| source.read_row(&mut row).err()).expect("zeroed fax data fails").to_string();
    for needle in ["g4.tif", "row 128", "strip 2 (rows 128..192)", "fax"] {
        assert!(err.contains(needle), "{needle:?} missing from: {err}");
    }

    // 576 KiB of texels read through 64 KiB: one 16-row strip of each plane at a time.
    let lzw = tiffcp(&rgb, &d("planar-lzw.tif"), &["-p", "separate", "-c", "lzw", "-r", "16"]);
    let (_, ours) = our_texels(&lzw, 64 << 10);
    assert!(ours == vips_texels(&lzw), "streamed planar texels differ from libvips's");
    let err = source::open(&lzw, Budget::new(16 << 10)).err().expect("over --max-memory").to_string();
    assert!(err.contains("--max-memory") && err.contains("planar-lzw.tif"), "{err}");
    // And through `split`, end to end.
    let out = d("out");
    let line = cli::ok(&["split", s(&lzw), "-o", s(&out), "--tile-size", "256", "--border", "0", "--codec", "png"]);
    assert!(line.contains("planar-separate 8-bit RGB"), "{line}");
    let tile = image::open(out.join("lod00-x0001-y0000.png")).unwrap().to_rgb8();
    let theirs = vips_texels(&lzw);
    for (x, y, texel) in tile.enumerate_pixels() {
        let at = ((y as usize) * 512 + 256 + x as usize) * 3;
        assert_eq!(texel.0, theirs[at..at + 3], "lod00-x0001-y0000 at ({x}, {y})");
    }
}

/// Aperio SVS slides with JPEG 2000 tiles as tifffile writes them with imagecodecs' OpenJPEG
/// encoder (lossless, so any difference is the decoder's): Compression 33005 (RGB components)
/// to NAME-rgb.svs, 33003 (Y, Cb, Cr components, no multi-component transform) to
/// NAME-ycbcr.svs, 128-texel tiles, the Aperio ImageDescription OpenSlide recognises.
const MAKE_J2K_SVS: &str = r#"
import sys, numpy as np, tifffile, imagecodecs
h, w, t = 1500, 600, 128
y, x = np.mgrid[0:h, 0:w]
img = np.stack([x * 255 // w, y * 255 // h, (x ^ y) & 255], -1).astype(np.int32)
img += np.random.default_rng(9).integers(0, 40, img.shape) * (((x // 16 + y // 16) % 3 == 0)[..., None])
img = np.clip(img, 0, 255).astype(np.uint8)
f = img.astype(np.float64)
ycc = np.stack([0.299 * f[..., 0] + 0.587 * f[..., 1] + 0.114 * f[..., 2],
                128 - 0.168736 * f[..., 0] - 0.331264 * f[..., 1] + 0.5 * f[..., 2],
                128 + 0.5 * f[..., 0] - 0.418688 * f[..., 1] - 0.081312 * f[..., 2]], -1)
ycc = np.clip(np.round(ycc), 0, 255).astype(np.uint8)
def tiles(a, lossless=True):
    for ty in range(0, h, t):
        for tx in range(0, w, t):
            tile = np.zeros((t, t, 3), np.uint8)
            part = a[ty:ty + t, tx:tx + t]
            tile[:part.shape[0], :part.shape[1]] = part
            if lossless:
                yield imagecodecs.jpeg2k_encode(tile, level=0, codecformat="J2K", mct=False)
            else:
                yield imagecodecs.jpeg2k_encode(tile, level=40, codecformat="J2K", mct=False, reversible=False)
for name, a, code, lossless in (("rgb", img, 33005, True), ("ycbcr", ycc, 33003, True), ("lossy", img, 33005, False)):
    desc = "Aperio Image Library v12.0.15 \r\n%dx%d [0,0 %dx%d] (%dx%d) J2K/KDU Q=70|AppMag = 20|MPP = 0.5" % (w, h, w, h, t, t)
    tifffile.imwrite("%s-%s.svs" % (sys.argv[1], name), tiles(a, lossless), shape=(h, w, 3), dtype="uint8", tile=(t, t),
                     compression=code, photometric="rgb", description=desc, metadata=None)
    if not lossless:
        with tifffile.TiffFile("%s-%s.svs" % (sys.argv[1], name)) as f:
            print(h * w * 3 / sum(f.pages[0].databytecounts))
"#;

/// Aperio JPEG 2000 (33005 RGB, 33003 YCbCr): OpenSlide's level 0, streamed within a
/// --max-memory below the image's size; a damaged tile is an error naming it; `split` takes it.
#[test]
fn aperio_jpeg_2000_decodes_as_openslide_does() {
    let Some(py) = venv_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let d = |name: &str| dir.path().join(name);
    let said = python(&py, MAKE_J2K_SVS, &[s(&d("slide"))]);
    // What the slide's coding lost, as its tiles' COD segments say: nothing for OpenJPEG's
    // reversible wavelet; the irreversible one a JPEG 2000 step, its texels' bytes over its
    // tiles' bytes as tifffile lists them.
    for (name, lossy) in [("slide-rgb.svs", false), ("slide-ycbcr.svs", false), ("slide-lossy.svs", true)] {
        let steps = source::open(&d(name), Budget::new(1 << 30)).unwrap().embedded().lossy;
        match lossy {
            false => assert_eq!(steps, [], "{name}"),
            true => {
                let ratio: f64 = said.trim().parse().unwrap();
                assert_eq!(steps.len(), 1, "{name}: {steps:?}");
                assert_eq!(steps[0].method, "ISO_15444_1", "{name}");
                assert!((steps[0].ratio - ratio).abs() <= ratio * 1e-9, "{name}: {steps:?}, tifffile's {ratio}");
            }
        }
    }
    // 600 x 1500 RGB is 2.6 MiB; a row of 128-texel tiles and the tiles being decoded fit in 2.
    // RGB: lossless tiles decoded by OpenJPEG on both sides, exactly. YCbCr: OpenSlide's own
    // YCbCr tables round the green term once where libjpeg's fixed point (used here) rounds
    // two products: one level apart at most.
    let exact = Tolerance::max(0, "lossless tiles decoded by OpenJPEG on both sides");
    let ycbcr = Tolerance::max(1, "OpenSlide's YCbCr tables round the green term once, libjpeg's fixed point twice");
    for (name, colour, tolerance) in [("slide-rgb.svs", "RGB", exact), ("slide-ycbcr.svs", "YCbCr", ycbcr)] {
        let (source, ours) = our_texels(&d(name), 2 << 20);
        let described = source.describe();
        assert!(
            described.contains("Aperio SVS") && described.contains(&format!("jpeg 2000 ({colour}, OpenJPEG)")),
            "{described}"
        );
        let Some(theirs) = openslide_texels(&d(name)) else { return };
        assert_eq!(ours.len(), theirs.len());
        let (w, h) = (source.width(), source.height());
        assert_close(name, Picture::new(w, h, 3, &ours), Picture::new(w, h, 3, &theirs), tolerance);
    }

    // Tile 7 (tile row 1, column 2) zeroed: not a codestream.
    let slide = d("slide-rgb.svs");
    let script = "import sys, tifffile\nwith tifffile.TiffFile(sys.argv[1]) as t:\n    p = t.pages[0]\n    o, n = p.dataoffsets[7], p.databytecounts[7]\nf = open(sys.argv[1], 'r+b'); f.seek(o); f.write(bytes(n))";
    python(&py, script, &[s(&slide)]);
    let mut source = source::open(&slide, Budget::new(1 << 30)).unwrap();
    let mut row = vec![0u8; 600 * 3];
    let err = (0..1500).find_map(|_| source.read_row(&mut row).err()).expect("a zeroed tile fails").to_string();
    for needle in ["slide-rgb.svs", "row 128", "tile 7 (tile row 1, column 2; rows 128..256)", "JPEG 2000"] {
        assert!(err.contains(needle), "{needle:?} missing from: {err}");
    }
    // `split` on the intact YCbCr slide, end to end.
    let out = d("out");
    let line = cli::ok(&["split", s(&d("slide-ycbcr.svs")), "-o", s(&out), "--tile-size", "256", "--codec", "png"]);
    assert!(line.contains("jpeg 2000 (YCbCr"), "{line}");
}

/// 16-bit CMYK TIFF with its embedded profile: converted at 16 bits (LittleCMS's CMYK_16 to
/// RGB_16) and kept at 16, as `vips icc_transform --depth 16` converts it.
#[test]
fn cmyk_16_bit_tiff_is_converted_at_16_bits() {
    let default = Path::new(source::icc::DEFAULT_CMYK_PROFILE);
    if !have_tools() || !default.is_file() {
        crate::common::skip_unless_ci(
            "the 16-bit CMYK test",
            &format!("no {} (apt-get install ghostscript)", default.display()),
        );
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let d = |name: &str| dir.path().join(name);
    let png = pattern_png(dir.path(), 97, 66);
    let tagged = d("cmyk16.tif");
    tool("vips", &["icc_export", s(&png), s(&tagged), "--output-profile", s(default), "--depth", "16"]);
    let (source, ours) = our_texels(&tagged, 1 << 30);
    let described = source.describe();
    assert!(described.contains("16-bit CMYK") && described.contains("embedded ICC"), "{described}");
    assert_eq!(source.layout(), PixelLayout::new(Channels::Rgb, Depth::U16));
    let theirs = d("theirs.png");
    tool(
        "vips",
        &["icc_transform", s(&tagged), s(&theirs), "srgb", "--intent", "relative", "--embedded", "--depth", "16"],
    );
    let theirs = image::open(&theirs).unwrap().to_rgb16().into_raw();
    let ours: Vec<u16> = ours.chunks_exact(2).map(|b| u16::from_ne_bytes([b[0], b[1]])).collect();
    assert_eq!(ours.len(), theirs.len());
    // The same CLUT profile through LittleCMS on both sides; libvips goes through Lab in float,
    // we convert 16-bit to 16-bit in one transform: rounding apart by 79 of 65535 at worst and 4
    // on average (measured), well under one 8-bit step (257); a wrong profile, channel order or
    // byte order is off by thousands.
    let worst = ours.iter().zip(&theirs).map(|(a, b)| a.abs_diff(*b)).max().unwrap();
    let mean = ours.iter().zip(&theirs).map(|(a, b)| a.abs_diff(*b) as f64).sum::<f64>() / ours.len() as f64;
    assert!(worst <= 257 && mean < 16.0, "worst {worst}, mean {mean}");
    // The texels are not 8-bit values widened: the 16 bits carry more than 8.
    assert!(ours.iter().any(|v| v % 257 != 0), "the 16-bit conversion holds only 8-bit values");
}

/// Aperio 33003 slides whose JPEG 2000 tiles hold subsampled chroma, as OpenJPEG's own encoder
/// writes them from raw planes (`opj_compress -F W,H,3,8,u@1x1:DXxDY:DXxDY`, lossless): NAME-420.svs
/// (Cb, Cr 2x2) and NAME-422.svs (2x1); 128-texel tiles.
const MAKE_J2K_SUBSAMPLED: &str = r#"
import sys, os, subprocess, numpy as np, tifffile
h, w, t = 300, 260, 128
y, x = np.mgrid[0:h, 0:w]
ycc = np.stack([(x * 255 // w) ^ (y & 15), 128 + (y * 90 // h) - (x & 7) * 5, 60 + ((x // 4 + y // 3) % 120)], -1)
ycc = np.clip(ycc, 0, 255).astype(np.uint8)
def tiles(dx, dy):
    raw = sys.argv[1] + ".raw"
    for ty in range(0, h, t):
        for tx in range(0, w, t):
            tile = np.zeros((t, t, 3), np.uint8)
            part = ycc[ty:ty + t, tx:tx + t]
            tile[:part.shape[0], :part.shape[1]] = part
            planes = [tile[..., 0]] + [tile[::dy, ::dx, c] for c in (1, 2)]
            open(raw, "wb").write(b"".join(np.ascontiguousarray(p).tobytes() for p in planes))
            subprocess.run(["opj_compress", "-i", raw, "-o", raw + ".j2k", "-F", "%d,%d,3,8,u@1x1:%dx%d:%dx%d" % (t, t, dx, dy, dx, dy), "-mct", "0"], check=True, capture_output=True)
            yield open(raw + ".j2k", "rb").read()
for name, dx, dy in (("420", 2, 2), ("422", 2, 1)):
    desc = "Aperio Image Library v12.0.15 \r\n%dx%d [0,0 %dx%d] (%dx%d) J2K/KDU Q=70|AppMag = 20|MPP = 0.5" % (w, h, w, h, t, t)
    tifffile.imwrite("%s-%s.svs" % (sys.argv[1], name), tiles(dx, dy), shape=(h, w, 3), dtype="uint8", tile=(t, t),
                     compression=33003, photometric="rgb", description=desc, metadata=None)
"#;

/// Subsampled JPEG 2000 components (4:2:0 and 4:2:2 chroma) are upsampled by nearest neighbour
/// to the texels, as OpenSlide does: its level 0 within a level, the YCbCr rounding apart.
#[test]
fn subsampled_jpeg_2000_is_upsampled_as_openslide_does() {
    let Some(py) = venv_python() else { return };
    if !crate::common::have_program("opj_compress", "-h", "libopenjp2-tools") {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let d = |name: &str| dir.path().join(name);
    python(&py, MAKE_J2K_SUBSAMPLED, &[s(&d("slide"))]);
    for name in ["slide-420.svs", "slide-422.svs"] {
        let (source, ours) = our_texels(&d(name), 1 << 30);
        assert!(source.describe().contains("jpeg 2000 (YCbCr, OpenJPEG)"), "{}", source.describe());
        let Some(theirs) = openslide_texels(&d(name)) else { return };
        assert_eq!(ours.len(), theirs.len());
        // Lossless tiles, the same nearest upsampling: only OpenSlide's YCbCr tables, which round
        // the green term once where libjpeg's fixed point rounds two products, set them apart.
        let worst = ours.iter().zip(&theirs).map(|(a, b)| a.abs_diff(*b)).max().unwrap();
        assert!(worst <= 1, "{name}: {worst} levels from OpenSlide's level 0");
    }
    let out = d("out");
    let line = cli::ok(&["split", s(&d("slide-420.svs")), "-o", s(&out), "--tile-size", "256"]);
    assert!(line.contains("jpeg 2000 (YCbCr"), "{line}");
}
