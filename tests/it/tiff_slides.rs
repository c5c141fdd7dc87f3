//! The TIFF files gigapixel users hold: JPEG-compressed tiles and strips as libvips and libtiff
//! write them, pyramidal and OME-TIFF, Aperio slides; decoded as the makers' readers decode them.
//!
//! Inputs are made in the test by the makers' tools (`vips tiffsave`, `tiffcp`, tifffile) from
//! a generated image. The references are Debian's libvips (`vips rawsave`), OpenSlide 3.4.1 for
//! slides and tifffile for OME-TIFF, which all decode JPEG through libjpeg-turbo as we do: the
//! same integer IDCT and the same fancy upsampling of each tile on its own, so the texels must
//! be equal (tolerance 0).

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::common::cli::{self, s};
use vortex_tiler::limits::Budget;
use vortex_tiler::source::{self, RowSource};

/// Whether `vips` and `tiffcp` can run; outside CI a missing one skips the test with a note.
pub(crate) fn have_tools() -> bool {
    crate::common::have_program("vips", "--version", "libvips-tools")
        && crate::common::have_program("tiffcp", "-h", "libtiff-tools")
}

pub(crate) fn tool(name: &str, args: &[&str]) {
    let out = Command::new(name).args(args).output().unwrap();
    assert!(out.status.success(), "{name} {args:?}: {}", String::from_utf8_lossy(&out.stderr));
}

/// An RGB image with smooth ramps, hard edges and noisy blocks (what JPEG finds hard), as PNG.
pub(crate) fn pattern_png(dir: &Path, width: u32, height: u32) -> PathBuf {
    let mut state = 0x9E37_79B9u32;
    let img = image::RgbImage::from_fn(width, height, |x, y| {
        state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        let noise = if (x / 16 + y / 16) % 3 == 0 { (state >> 24) % 48 } else { 0 };
        let r = (x * 255 / width + noise).min(255);
        let g = (y * 255 / height + noise).min(255);
        let b = ((x ^ y) & 255).saturating_sub(noise);
        image::Rgb([r as u8, g as u8, b as u8])
    });
    let path = dir.join(format!("pattern-{width}x{height}.png"));
    img.save(&path).unwrap();
    path
}

/// libvips's decode of `path` (8.14, through libtiff): its bands as they are.
pub(crate) fn vips_texels(path: &Path) -> Vec<u8> {
    let raw = path.with_extension("vips.raw");
    tool("vips", &["rawsave", s(path), s(&raw)]);
    std::fs::read(raw).unwrap()
}

pub(crate) fn our_texels(path: &Path, max_memory: u64) -> (Box<dyn RowSource>, Vec<u8>) {
    let mut source = source::open(path, Budget::new(max_memory)).unwrap_or_else(|e| panic!("{}: {e}", path.display()));
    let row = source.width() as usize * source.layout().bytes_per_pixel();
    let mut all = vec![0u8; row * source.height() as usize];
    for chunk in all.chunks_exact_mut(row) {
        source.read_row(chunk).unwrap();
    }
    (source, all)
}

/// The JPEG TIFFs libvips and libtiff write, tiled and in strips, YCbCr (4:2:0 and 4:4:4),
/// RGB and grey, at sizes that leave partial edge tiles: our texels are libvips's exactly.
#[test]
fn jpeg_tiffs_decode_as_libvips_does() {
    if !have_tools() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let d = |name: &str| dir.path().join(name);
    let png = pattern_png(dir.path(), 701, 499);
    let uncompressed = d("plain.tif");
    tool("vips", &["copy", s(&png), s(&uncompressed)]);
    let grey = d("grey.v");
    tool("vips", &["colourspace", s(&png), s(&grey), "b-w"]);
    let png = s(&png);
    // (file, how it was made, what the summary must say)
    let made: Vec<(&str, Vec<&str>, &str)> = vec![
        (
            "vips-q75-tiles.tif",
            vec![
                "vips",
                "tiffsave",
                png,
                "",
                "--tile",
                "--tile-width",
                "128",
                "--tile-height",
                "128",
                "--compression",
                "jpeg",
                "--Q",
                "75",
            ],
            "YCbCr",
        ),
        // At Q >= 90 libvips keeps chroma whole.
        (
            "vips-q92-tiles.tif",
            vec!["vips", "tiffsave", png, "", "--tile", "--compression", "jpeg", "--Q", "92"],
            "tile row (128x128",
        ),
        ("vips-strips.tif", vec!["vips", "tiffsave", png, "", "--compression", "jpeg"], "strip"),
        (
            "vips-pyramid.tif",
            vec!["vips", "tiffsave", png, "", "--tile", "--pyramid", "--compression", "jpeg"],
            "tile row",
        ),
        (
            "vips-bigtiff.tif",
            vec!["vips", "tiffsave", png, "", "--tile", "--bigtiff", "--compression", "jpeg"],
            "bigtiff",
        ),
        ("tiffcp-ycbcr-strips.tif", vec!["tiffcp", "-c", "jpeg", "-r", "16", s(&uncompressed), ""], "YCbCr"),
        (
            "tiffcp-rgb-tiles.tif",
            vec!["tiffcp", "-c", "jpeg:r", "-t", "-w", "64", "-l", "64", s(&uncompressed), ""],
            "RGB",
        ),
        (
            "vips-grey-tiles.tif",
            vec![
                "vips",
                "tiffsave",
                s(&grey),
                "",
                "--tile",
                "--tile-width",
                "64",
                "--tile-height",
                "64",
                "--compression",
                "jpeg",
            ],
            "grey",
        ),
    ];
    for (name, mut args, says) in made {
        let path = d(name);
        let slot = args.iter().position(|a| a.is_empty()).unwrap();
        args[slot] = s(&path);
        tool(args[0], &args[1..]);
        let (source, ours) = our_texels(&path, 1 << 30);
        let described = source.describe();
        assert!(described.contains("jpeg") && described.contains(says), "{name}: {described}");
        let theirs = vips_texels(&path);
        assert_eq!(ours.len(), theirs.len(), "{name}: {described}");
        let differ = ours.iter().zip(&theirs).filter(|(a, b)| a != b).count();
        assert!(differ == 0, "{name}: {differ} samples differ from libvips's decode ({described})");
    }
}

/// `split` takes a JPEG-tiled TIFF end to end: the finest level's texels are the source's.
#[test]
fn split_cuts_a_jpeg_tiled_tiff() {
    if !have_tools() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let png = pattern_png(dir.path(), 600, 300);
    let tif = dir.path().join("slide.tif");
    tool("vips", &["tiffsave", s(&png), s(&tif), "--tile", "--compression", "jpeg", "--Q", "80"]);
    let out = dir.path().join("out");
    let stdout = cli::ok(&["split", s(&tif), "-o", s(&out), "--tile-size", "256", "--border", "0", "--codec", "png"]);
    assert!(stdout.contains("jpeg (YCbCr, shared tables"), "{stdout}");
    let theirs = vips_texels(&tif);
    // The finest level (LOD 0): tiles of 256 texels, edge tiles cropped or padded.
    for entry in std::fs::read_dir(&out).unwrap() {
        let name = entry.unwrap().file_name().into_string().unwrap();
        let Some(rest) = name.strip_prefix("lod00-x") else { continue };
        let (x, y) = rest.trim_end_matches(".png").split_once("-y").unwrap();
        let (tx, ty): (u32, u32) = (x.parse().unwrap(), y.parse().unwrap());
        let tile = image::open(out.join(&name)).unwrap().to_rgb8();
        for (px, py, texel) in tile.enumerate_pixels() {
            let (ix, iy) = (tx * 256 + px, ty * 256 + py);
            if ix < 600 && iy < 300 {
                let at = (iy as usize * 600 + ix as usize) * 3;
                assert_eq!(texel.0, theirs[at..at + 3], "{name} at ({px}, {py})");
            }
        }
    }
}

/// A tile whose JPEG data is damaged, one whose bytes lie past the end of the file and one
/// marked missing: each is an error naming the file and the tile's column and row.
#[test]
fn damaged_jpeg_tiles_are_errors_naming_the_tile() {
    if !have_tools() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let png = pattern_png(dir.path(), 300, 200);
    let tif = dir.path().join("tiles.tif");
    tool(
        "vips",
        &["tiffsave", s(&png), s(&tif), "--tile", "--tile-width", "64", "--tile-height", "64", "--compression", "jpeg"],
    );
    let bytes = std::fs::read(&tif).unwrap();
    let (offsets, counts) = tile_table(&tif);
    // Tile 7 is at column 2, row 1 (5 tiles across).
    let (offset, count) = (offsets[7] as usize, counts[7] as usize);
    let fails = |bytes: &[u8], name: &str, needles: &[&str]| {
        let path = dir.path().join(name);
        std::fs::write(&path, bytes).unwrap();
        let mut source = source::open(&path, Budget::new(1 << 30)).unwrap();
        let mut row = vec![0u8; 300 * 3];
        let err = (0..200).find_map(|_| source.read_row(&mut row).err()).expect("an error");
        let text = err.to_string();
        for needle in [name].iter().chain(needles) {
            assert!(text.contains(needle), "{needle:?} missing from: {text}");
        }
        // Later rows keep failing rather than returning grey.
        assert!(source.read_row(&mut row).is_err());
        err
    };
    let mut damaged = bytes.clone();
    damaged[offset + count / 2..offset + count / 2 + 16].fill(0xFF);
    damaged[offset + count / 2 + 1] = 0xD4; // a restart marker where none may be
    fails(&damaged, "damaged.tif", &["column 2, row 1", "Corrupt JPEG data"]);
    // A byte count pointing past the end (as when the file was cut short).
    let mut past = bytes.clone();
    let at = find_u32(&past, counts[7] as u32);
    past[at..at + 4].copy_from_slice(&(bytes.len() as u32).to_le_bytes());
    fails(&past, "past-end.tif", &["column 2, row 1", "past the end of the file"]);
    let mut missing = bytes.clone();
    missing[at..at + 4].copy_from_slice(&0u32.to_le_bytes());
    fails(&missing, "missing.tif", &["column 2, row 1", "missing"]);
}

/// TileOffsets and TileByteCounts of a TIFF's first image.
fn tile_table(path: &Path) -> (Vec<u64>, Vec<u64>) {
    let mut decoder = tiff::decoder::Decoder::new(std::fs::File::open(path).unwrap()).unwrap();
    let offsets = decoder.get_tag_u64_vec(tiff::tags::Tag::TileOffsets).unwrap();
    let counts = decoder.get_tag_u64_vec(tiff::tags::Tag::TileByteCounts).unwrap();
    (offsets, counts)
}

/// Where the little-endian `value` occurs once in `bytes` (a tag value array entry).
fn find_u32(bytes: &[u8], value: u32) -> usize {
    let hits: Vec<usize> =
        bytes.windows(4).enumerate().filter(|(_, w)| *w == value.to_le_bytes()).map(|(i, _)| i).collect();
    assert_eq!(hits.len(), 1, "{value} occurs {} times", hits.len());
    hits[0]
}

/// A JPEG TIFF several times larger than --max-memory decoded streams a tile row at a time,
/// and gives the same texels as with memory to spare; below one tile row it is refused.
#[test]
fn a_jpeg_tiff_larger_than_max_memory_streams() {
    if !have_tools() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let png = pattern_png(dir.path(), 2048, 1536);
    let tif = dir.path().join("big.tif");
    let tile = ["--tile", "--tile-width", "256", "--tile-height", "256", "--compression", "jpeg"];
    tool("vips", &[&["tiffsave", s(&png), s(&tif)][..], &tile].concat());
    // 9 MiB decoded; a row of 256-texel tiles is 1.5 MiB.
    let (_, roomy) = our_texels(&tif, 1 << 30);
    let (_, tight) = our_texels(&tif, 4 << 20);
    assert!(roomy == tight);
    let err = source::open(&tif, Budget::new(1 << 20)).err().expect("refused").to_string();
    for needle in ["big.tif", "--max-memory", "256x256 JPEG tiles"] {
        assert!(err.contains(needle), "{needle:?} missing from: {err}");
    }
    // The whole tool within the same bound.
    let out = dir.path().join("out");
    cli::ok(&["split", s(&tif), "-o", s(&out), "--max-memory", "6M", "--tile-size", "256"]);
    // In strips (libvips writes JPEG strips of 8 rows): a group of them at a time.
    let strips = dir.path().join("strips.tif");
    tool("vips", &["tiffsave", s(&png), s(&strips), "--compression", "jpeg"]);
    let (source, tight) = our_texels(&strips, 4 << 20);
    assert!(source.describe().contains("streamed by strip"), "{}", source.describe());
    assert!(tight == our_texels(&strips, 1 << 30).1);
}

/// Old-style JPEG (Compression 6) is refused, saying what is read instead.
#[test]
fn old_style_jpeg_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let path = dir.path().join("ojpeg.tif");
    let img = image::RgbImage::from_fn(16, 8, |x, y| image::Rgb([x as u8, y as u8, 0]));
    img.save(&path).unwrap();
    let mut bytes = std::fs::read(&path).unwrap();
    // The Compression entry (tag 259, SHORT, count 1, value 1) becomes value 6.
    let entry = [0x03, 0x01, 0x03, 0x00, 0x01, 0x00, 0x00, 0x00, 0x01, 0x00];
    let at = bytes.windows(entry.len()).position(|w| w == entry).expect("a Compression entry");
    bytes[at + 8] = 6;
    std::fs::write(&path, &bytes).unwrap();
    let err = source::open(&path, Budget::new(1 << 30)).err().expect("refused").to_string();
    for needle in ["ojpeg.tif", "old-style JPEG", "compression 7", "tiffcp -c jpeg"] {
        assert!(err.contains(needle), "{needle:?} missing from: {err}");
    }
    let out = dir.path().join("out");
    cli::fails_with(&cli::run(&["split", s(&path), "-o", s(&out)]), &["old-style JPEG"]);
}

/// A stripe or shard reads only some columns: the tiles under them are decoded, and the texels
/// are those of whole rows, from any starting row (tiles) and for strips too.
#[test]
fn columns_and_skipped_rows_match_whole_rows() {
    if !have_tools() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let png = pattern_png(dir.path(), 333, 210);
    for (name, extra) in
        [("tiles.tif", &["--tile", "--tile-width", "64", "--tile-height", "64"][..]), ("strips.tif", &[][..])]
    {
        let tif = dir.path().join(name);
        tool("vips", &[&["tiffsave", s(&png), s(&tif), "--compression", "jpeg"][..], extra].concat());
        let (_, whole) = our_texels(&tif, 1 << 30);
        for (columns, skip) in [(70..200u32, 0u32), (0..64, 65), (300..333, 130), (1..2, 209)] {
            let mut source = source::open(&tif, Budget::new(1 << 30)).unwrap();
            assert!(source.read_columns(columns.clone()), "{name}");
            source.skip_rows(skip).unwrap();
            let mut row = vec![0u8; columns.len() * 3];
            for y in skip..210 {
                source.read_row(&mut row).unwrap();
                let at = (y as usize * 333 + columns.start as usize) * 3;
                assert!(row == whole[at..at + row.len()], "{name}: columns {columns:?}, row {y}");
            }
        }
    }
}

/// The Python with tifffile and imagecodecs that `.ci/run` makes (VORTEX_PYVIPS), or a skip
/// with a note outside CI.
pub(crate) fn venv_python() -> Option<std::ffi::OsString> {
    let python = std::env::var_os("VORTEX_PYVIPS");
    if python.is_none() {
        crate::common::skip_unless_ci(
            "a tifffile-made TIFF",
            "VORTEX_PYVIPS unset: set it to a Python with tifffile and imagecodecs",
        );
    }
    python
}

/// Runs `script` with `args`; its standard output, or a failure saying what it printed.
pub(crate) fn python(python: &std::ffi::OsStr, script: &str, args: &[&str]) -> String {
    let out = Command::new(python).arg("-c").arg(script).args(args).output().unwrap();
    assert!(out.status.success(), "{script}: {}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stdout).into_owned()
}

/// An Aperio-like SVS as tifffile writes it: a 240-texel JPEG-tiled full resolution, a
/// thumbnail in strips, a tiled reduced level, an LZW label and a JPEG macro; the texels of
/// the image it was made from go to OUT.rgb.
pub(crate) const MAKE_SVS: &str = r#"
import sys, numpy as np, tifffile
out = sys.argv[1]
h, w = 500, 720
y, x = np.mgrid[0:h, 0:w]
img = np.stack([x * 255 // w, y * 255 // h, (x ^ y) & 255], -1).astype(np.int32)
img += np.random.default_rng(7).integers(0, 40, img.shape) * (((x // 16 + y // 16) % 3 == 0)[..., None])
img = np.clip(img, 0, 255).astype(np.uint8)
head = "Aperio Image Library v12.0.15 \r\n%dx%d" % (w, h)
with tifffile.TiffWriter(out) as t:
    t.write(img, tile=(240, 240), compression="jpeg", compressionargs={"level": 80}, photometric="rgb", description=head + " [0,0 %dx%d] (240x240) JPEG/RGB Q=80|AppMag = 20|MPP = 0.5" % (w, h), metadata=None)
    t.write(img[::8, ::8].copy(), compression="jpeg", photometric="rgb", description=head + " -> 90x63", metadata=None)
    t.write(img[::4, ::4].copy(), tile=(240, 240), compression="jpeg", photometric="rgb", description=head + " -> 180x125", metadata=None)
    t.write(img[:100, :80].copy(), compression="lzw", photometric="rgb", subfiletype=1, description="Aperio Image Library v12.0.15\nlabel 80x100", metadata=None)
    t.write(img[:60, :200].copy(), compression="jpeg", photometric="rgb", subfiletype=9, description="Aperio Image Library v12.0.15\nmacro 200x60", metadata=None)
"#;

/// OpenSlide's level 0 of an Aperio slide as RGB texels (Debian's python3-openslide, run by
/// /usr/bin/python3), or a skip with a note outside CI.
pub(crate) fn openslide_texels(slide: &Path) -> Option<Vec<u8>> {
    openslide_region(slide, "aperio", None)
}

/// OpenSlide's level 0 of a slide it must recognise as `vendor`'s, its top-left `size` (the
/// whole level without one), as RGB texels, or a skip with a note outside CI.
pub(crate) fn openslide_region(slide: &Path, vendor: &str, size: Option<(u32, u32)>) -> Option<Vec<u8>> {
    let raw = slide.with_extension("openslide.rgba");
    let script = "import sys, openslide\ns = openslide.OpenSlide(sys.argv[1])\nassert s.properties['openslide.vendor'] == sys.argv[3], s.properties['openslide.vendor']\nsize = (int(sys.argv[4]), int(sys.argv[5])) if len(sys.argv) > 5 else s.dimensions\nopen(sys.argv[2], 'wb').write(s.read_region((0, 0), 0, size).tobytes())";
    let size: Vec<String> = size.map_or(vec![], |(w, h)| vec![w.to_string(), h.to_string()]);
    let out = Command::new("/usr/bin/python3").args(["-c", script, s(slide), s(&raw), vendor]).args(&size).output();
    match out {
        Ok(out) if out.status.success() => {}
        Ok(out) if !String::from_utf8_lossy(&out.stderr).contains("No module named 'openslide'") => {
            panic!("OpenSlide failed: {}", String::from_utf8_lossy(&out.stderr))
        }
        _ => {
            crate::common::skip_unless_ci(
                "the OpenSlide comparison",
                "no python3-openslide (apt-get install python3-openslide)",
            );
            return None;
        }
    }
    let rgba = std::fs::read(raw).unwrap();
    assert!(rgba.chunks_exact(4).all(|t| t[3] == 255), "OpenSlide left texels of the region blank");
    Some(rgba.chunks_exact(4).flat_map(|t| [t[0], t[1], t[2]]).collect())
}

/// An Aperio SVS: recognised, its full-resolution level read as OpenSlide reads it, its
/// thumbnail, label and macro skipped and listed; `--page` reads any directory.
#[test]
fn aperio_svs_reads_level_0_as_openslide_does() {
    let Some(py) = venv_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let svs = dir.path().join("slide.svs");
    python(&py, MAKE_SVS, &[s(&svs)]);
    let (source, ours) = our_texels(&svs, 1 << 30);
    let described = source.describe();
    for needle in [
        "tiff (Aperio SVS, page 0 of 5: full resolution, 1 reduced level(s) not read; ",
        "skipped thumbnail 90x63 (page 1), label 80x100 (page 3), macro 200x60 (page 4)), ",
        // tifffile writes each tile as a complete JPEG (no shared JPEGTables).
        "jpeg (YCbCr, libjpeg-turbo)",
    ] {
        assert!(described.contains(needle), "{needle:?} missing from: {described}");
    }
    if let Some(theirs) = openslide_texels(&svs) {
        assert_eq!(ours.len(), theirs.len());
        let differ = ours.iter().zip(&theirs).filter(|(a, b)| a != b).count();
        assert!(differ == 0, "{differ} samples differ from OpenSlide's level 0");
    }
    // The label by its page, exactly as stored (LZW).
    let label = source::open_picked(&svs, Budget::new(1 << 30), source::Pick { page: Some(3), series: None }).unwrap();
    assert_eq!((label.width(), label.height()), (80, 100));
    assert!(label.describe().contains("page 3 of 5: label; skipped thumbnail"), "{}", label.describe());
    let err =
        source::open_picked(&svs, Budget::new(1 << 30), source::Pick { page: Some(5), series: None }).err().unwrap();
    assert!(err.to_string().contains("--page 5: the TIFF has 5 page(s)"), "{err}");
    // Series: the full-resolution images only (here one).
    let err =
        source::open_picked(&svs, Budget::new(1 << 30), source::Pick { page: None, series: Some(1) }).err().unwrap();
    assert!(err.to_string().contains("1 full-resolution image(s)"), "{err}");
    // The tool says so too.
    let out = dir.path().join("out");
    let stdout = cli::ok(&["split", s(&svs), "-o", s(&out), "--tile-size", "256"]);
    assert!(stdout.contains("Aperio SVS") && stdout.contains("label 80x100"), "{stdout}");
}

/// An OME-TIFF of two series as tifffile writes it: series 0 a Deflate pyramid whose reduced
/// levels are SubIFDs, series 1 a JPEG-tiled image; tifffile's reads of each go to
/// OUT.sN.rgb.
const MAKE_OME: &str = r#"
import sys, numpy as np, tifffile
out = sys.argv[1]
def pattern(h, w, seed):
    y, x = np.mgrid[0:h, 0:w]
    img = np.stack([x * 255 // w, y * 255 // h, (x * 3 ^ y) & 255], -1).astype(np.int32)
    img += np.random.default_rng(seed).integers(0, 40, img.shape) * (((x // 16 + y // 16) % 3 == 0)[..., None])
    return np.clip(img, 0, 255).astype(np.uint8)
a, b = pattern(300, 410, 1), pattern(200, 260, 2)
with tifffile.TiffWriter(out, ome=True) as t:
    t.write(a, subifds=2, tile=(128, 128), compression="zlib", photometric="rgb", metadata={"axes": "YXS"})
    t.write(a[::2, ::2].copy(), tile=(128, 128), compression="zlib", photometric="rgb", subfiletype=1)
    t.write(a[::4, ::4].copy(), tile=(128, 128), compression="zlib", photometric="rgb", subfiletype=1)
    t.write(b, tile=(64, 64), compression="jpeg", photometric="rgb", metadata={"axes": "YXS"})
for n in range(2):
    tifffile.imread(out, series=n, level=0).tofile("%s.s%d.rgb" % (out, n))
"#;

/// `--series N` of an OME-TIFF reads the Nth OME-XML image at full resolution, as tifffile
/// does (series 0 exactly; series 1's JPEG tiles too: imagecodecs decodes with libjpeg-turbo).
#[test]
fn ome_tiff_series_read_as_tifffile_does() {
    let Some(py) = venv_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let ome = dir.path().join("two.ome.tif");
    python(&py, MAKE_OME, &[s(&ome)]);
    for (series, size, says) in [
        (0u32, (410, 300), "tiff (OME-TIFF, series 0, page 0 of 2: full resolution, 2 reduced level(s) not read)"),
        (1, (260, 200), "tiff (OME-TIFF, series 1, page 1 of 2: full resolution)"),
    ] {
        let pick = source::Pick { page: None, series: Some(series) };
        let mut source = source::open_picked(&ome, Budget::new(1 << 30), pick).unwrap();
        assert_eq!((source.width(), source.height()), size);
        assert!(source.describe().starts_with(says), "{}", source.describe());
        let mut ours = vec![0u8; size.0 as usize * size.1 as usize * 3];
        for row in ours.chunks_exact_mut(size.0 as usize * 3) {
            source.read_row(row).unwrap();
        }
        let theirs = std::fs::read(format!("{}.s{series}.rgb", ome.display())).unwrap();
        let differ = ours.iter().zip(&theirs).filter(|(a, b)| a != b).count();
        assert!(ours.len() == theirs.len() && differ == 0, "series {series}: {differ} samples differ from tifffile");
    }
    // The default is series 0; a series past the last is refused, naming the count.
    assert!(source::open(&ome, Budget::new(1 << 30)).unwrap().describe().contains("series 0"));
    let err =
        source::open_picked(&ome, Budget::new(1 << 30), source::Pick { page: None, series: Some(2) }).err().unwrap();
    assert!(err.to_string().contains("--series 2: the OME-TIFF has 2 series"), "{err}");
    let out = dir.path().join("out");
    let stdout = cli::ok(&["split", s(&ome), "-o", s(&out), "--series", "1", "--tile-size", "256"]);
    assert!(stdout.contains("series 1"), "{stdout}");
    let both = cli::run(&["split", s(&ome), "-o", s(&out), "--series", "1", "--page", "0"]);
    assert_eq!(both.status.code(), Some(2), "a usage error");
    assert!(String::from_utf8_lossy(&both.stderr).contains("cannot be used with"));
}

/// Every byte of a small JPEG-tiled TIFF damaged in turn (and the file cut short at many
/// places): each opens and reads to the end or fails with an error naming the file, never a
/// panic or an abort.
#[test]
fn damaged_jpeg_tiffs_never_panic() {
    if !have_tools() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let png = pattern_png(dir.path(), 150, 100);
    let tif = dir.path().join("small.tif");
    tool(
        "vips",
        &["tiffsave", s(&png), s(&tif), "--tile", "--tile-width", "64", "--tile-height", "64", "--compression", "jpeg"],
    );
    let bytes = std::fs::read(&tif).unwrap();
    let path = dir.path().join("mutated.tif");
    let read = |data: &[u8]| {
        std::fs::write(&path, data).unwrap();
        let result = source::open(&path, Budget::new(64 << 20)).and_then(|mut source| {
            let mut row = vec![0u8; source.width() as usize * source.layout().bytes_per_pixel()];
            (0..source.height()).try_for_each(|_| source.read_row(&mut row))
        });
        if let Err(e) = result {
            assert!(e.to_string().contains("mutated.tif"), "{e}");
        }
    };
    let mut state = 12345u32;
    for at in (0..bytes.len()).step_by(3) {
        state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        let mut damaged = bytes.clone();
        damaged[at] ^= (state >> 24) as u8 | 1;
        read(&damaged);
    }
    for keep in (0..bytes.len()).step_by(97) {
        read(&bytes[..keep]);
    }
}

/// A small file carrying Hamamatsu's NDPI tag (65420), its image one JPEG strip as NDPI keeps
/// it: recognised and named, and (it fits in memory) read as libvips reads it (tifffile, seeing
/// the tag, looks for NDPI's 64-bit offsets and cannot read it back).
#[test]
fn ndpi_tag_is_recognised_and_a_small_one_strip_jpeg_is_read() {
    if !have_tools() {
        return;
    }
    let Some(py) = venv_python() else { return };
    let dir = tempfile::tempdir().unwrap();
    let ndpi = dir.path().join("small.ndpi");
    let script = r#"
import sys, numpy as np, tifffile
y, x = np.mgrid[0:120, 0:200]
img = np.stack([x, y * 2, (x ^ y) & 255], -1).astype(np.uint8)
tifffile.imwrite(sys.argv[1], img, photometric="rgb", compression="jpeg", rowsperstrip=120, metadata=None, extratags=[(65420, "I", 1, 1, True)])
"#;
    python(&py, script, &[s(&ndpi)]);
    let (source, ours) = our_texels(&ndpi, 1 << 30);
    assert!(source.describe().contains("Hamamatsu NDPI, page 0 of 1"), "{}", source.describe());
    assert!(source.describe().contains("streamed by strip (120 rows"), "{}", source.describe());
    // Through libvips's TIFF loader: its OpenSlide loader would claim the file and want more tags.
    let loaded = dir.path().join("loaded.v");
    tool("vips", &["tiffload", s(&ndpi), s(&loaded)]);
    assert!(ours == vips_texels(&loaded), "differs from libvips");
}
