//! Pyramidal TIFF out (`-o FILE.tif`, `-o FILE.ome.tif`; docs/tiff.md): the file read back
//! by our own TIFF reader (always), and by the readers of that world through the Python named
//! by VORTEX_PYVIPS (tifffile, libvips 8.18, OpenSlide 4: `tiff_out.py`), which are skipped
//! with a note where they are missing outside CI. Lossless levels must equal a naive box
//! pyramid of the source exactly; JPEG levels must be within JPEG's error of it.

use std::path::{Path, PathBuf};
use std::process::Command;

use vortex_tiler::pixel::{Channels, Depth, PixelLayout};

use crate::common::cli::{fails_with, ok, run, s};
use crate::ome_zarr::input;

const SCRIPT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/it/tiff_out.py");

fn rgb8() -> PixelLayout {
    PixelLayout::new(Channels::Rgb, Depth::U8)
}

/// The Python with tifffile, pyvips and OpenSlide: VORTEX_PYVIPS, if it imports them; else
/// a skip with a note, and a failure under CI.
fn readers() -> Option<PathBuf> {
    crate::common::python_with(
        "tifffile, pyvips, openslide, numpy, ome_types",
        "the TIFF readers",
        "tifffile, pyvips, openslide-python, openslide-bin and ome-types[lxml]",
    )
}

/// Runs `tiff_out.py` on `tiff`; fails with what it said.
fn check(python: &Path, flavour: &str, tiff: &Path, source: &Path, tile: u32, mode: &str) -> String {
    let tile = tile.to_string();
    let args = [SCRIPT, flavour, s(tiff), s(source), &tile, mode];
    let out = Command::new(python).args(args).output().unwrap();
    let said = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "{flavour} {}: {said}", tiff.display());
    said
}

/// Splits `args` into PNG tiles (border 0, box filter) and returns the directory's files,
/// name and bytes, sorted: what two runs of the same levels must agree on.
pub(crate) fn png_tiles(source: &Path, dir: &Path, extra: &[&str]) -> Vec<(String, Vec<u8>)> {
    let mut args = vec!["split", s(source), "-o", s(dir), "--border", "0", "--codec", "png", "--filter", "box", "-q"];
    args.extend(extra);
    ok(&args);
    let mut files: Vec<(String, Vec<u8>)> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap())
        .filter(|e| e.file_name().to_string_lossy().ends_with(".png"))
        .map(|e| (e.file_name().to_string_lossy().into_owned(), std::fs::read(e.path()).unwrap()))
        .collect();
    files.sort();
    files
}

/// A lossless TIFF read back as a source by our own TIFF reader (its full resolution) cuts
/// the same tiles as the image it was made from: the file's tile index, offsets and predictor
/// hold together, in every flavour, 8 and 16 bits, alpha, Deflate, LZW and none (our reader
/// has no zstd yet; the readers below check zstd).
#[test]
fn our_reader_reads_the_full_resolution_back() {
    let dir = tempfile::tempdir().unwrap();
    let cases = [
        ("a.tif", rgb8(), 1000, 700, "deflate"),
        ("b.ome.tif", PixelLayout::new(Channels::Grey, Depth::U16), 333, 517, "deflate"),
        ("c.tiff", PixelLayout::new(Channels::Rgba, Depth::U8), 301, 77, "raw"),
        ("d.ome.tiff", PixelLayout::new(Channels::GreyAlpha, Depth::U16), 257, 129, "deflate"),
        ("e.tif", rgb8(), 1000, 700, "lzw"),
        ("f.cog.tif", PixelLayout::new(Channels::Grey, Depth::U16), 333, 517, "lzw"),
    ];
    for (k, (name, layout, w, h, codec)) in cases.into_iter().enumerate() {
        let source = input(dir.path(), &format!("src{k}"), w, h, layout);
        let tiff = dir.path().join(name);
        ok(&["split", s(&source), "-o", s(&tiff), "--codec", codec, "--filter", "box", "--tile-size", "128", "-q"]);
        let want = png_tiles(&source, &dir.path().join(format!("want{k}")), &["--tile-size", "96"]);
        let got = png_tiles(&tiff, &dir.path().join(format!("got{k}")), &["--tile-size", "96"]);
        assert!(!want.is_empty());
        assert!(want == got, "{name}: its tiles differ from the source's");
    }
}

/// A lossless TIFF's bytes are the same on every run, whatever the thread count: its tiles
/// are compressed on the encoder threads and stored in the producer's order (the pack's
/// way). Deflate and zstd with the predictor, and JPEG.
#[test]
fn a_tiff_is_the_same_on_every_run() {
    let dir = tempfile::tempdir().unwrap();
    let cases = [
        (rgb8(), "deflate", "a.tif"),
        (PixelLayout::new(Channels::Grey, Depth::U16), "zstd", "b.ome.tif"),
        (rgb8(), "jpeg", "c.tif"),
    ];
    for (k, (layout, codec, name)) in cases.into_iter().enumerate() {
        let source = input(dir.path(), &format!("src{k}"), 1000, 700, layout);
        let files: Vec<Vec<u8>> = ["1", "3", "3"]
            .iter()
            .enumerate()
            .map(|(run, threads)| {
                let tiff = dir.path().join(format!("{run}-{name}"));
                let args = ["split", s(&source), "-o", s(&tiff), "--codec", codec, "--tile-size", "128"];
                ok(&[&args[..], &["--threads", threads, "-q"]].concat());
                std::fs::read(&tiff).unwrap()
            })
            .collect();
        assert!(files[0] == files[1] && files[1] == files[2], "{name} ({codec}): the runs' files differ");
    }
}

/// `-o a.ome.tif` beside Deep Zoom and a pack in one run: every output written, the TIFF in
/// the summary and in `--json`; a TIFF in a folder that does not exist fails the run and
/// leaves nothing; a file of someone else's at the path is not replaced.
#[test]
fn a_tiff_is_one_output_among_others_and_atomic() {
    let dir = tempfile::tempdir().unwrap();
    let source = input(dir.path(), "src", 1000, 700, rgb8());
    let (tiff, web, pack) = (dir.path().join("a.ome.tif"), dir.path().join("web"), dir.path().join("a.vtpk"));
    let args = ["split", s(&source), "-o", s(&tiff), "-o", s(&web), "--layout", "dzi", "--pack", s(&pack)];
    let json = ok(&[&args[..], &["--json", "--overlap", "0", "--border", "0", "--tile-size", "256"]].concat());
    let doc: serde_json::Value = serde_json::from_str(json.trim()).unwrap();
    let outputs = doc["outputs"].as_array().unwrap();
    assert_eq!(outputs.len(), 3);
    assert_eq!(outputs[0]["layout"], "ome-tiff", "{doc}");
    let t = &outputs[0]["tiff"];
    assert_eq!(
        (t["flavour"].as_str(), t["levels"].as_u64(), t["bigtiff"].as_bool()),
        (Some("ome-tiff"), Some(3), Some(false))
    );
    assert_eq!(t["compression"], "jpeg");
    assert_eq!(t["fileBytes"].as_u64(), Some(std::fs::metadata(&tiff).unwrap().len()));
    assert!(web.join("src.dzi").is_file() && pack.is_file());
    // The summary line names it; a second run replaces our own file.
    let text = ok(&["split", s(&source), "-o", s(&tiff), "--codec", "deflate"]);
    assert!(text.contains("ome-tiff: 3 levels") && text.contains("deflate") && text.contains("classic TIFF"), "{text}");
    let big = ok(&["split", s(&source), "-o", s(&tiff), "--bigtiff", "--json"]);
    assert!(big.contains("\"bigtiff\":true"), "{big}");

    let missing = dir.path().join("nowhere/b.tif");
    fails_with(&run(&["split", s(&source), "-o", s(&missing), "-o", s(&dir.path().join("web2"))]), &["nowhere"]);
    assert!(!missing.exists() && !dir.path().join("web2").exists());
    let names: Vec<String> =
        std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    assert!(!names.iter().any(|n| n.contains("partial")), "{names:?}");

    let theirs = dir.path().join("scan.tif");
    std::fs::write(&theirs, b"II*\0\x08\0\0\0\0\0").unwrap();
    fails_with(&run(&["split", s(&source), "-o", s(&theirs)]), &["scan.tif", "another program", "--force"]);
    assert_eq!(std::fs::read(&theirs).unwrap(), b"II*\0\x08\0\0\0\0\0");
    fails_with(
        &run(&["split", s(&source), "-o", s(&tiff), "--codec", "png"]),
        &["jpeg, jxl, deflate, lzw, zstd or raw"],
    );
    let web = dir.path().join("web3");
    let lzw = ["split", s(&source), "-o", s(&tiff), "-o", s(&web), "--layout", "dzi", "--codec", "lzw"];
    fails_with(&run(&lzw), &["web3 (dzi)", "--codec lzw compresses a TIFF output's tiles"]);
    fails_with(&run(&["split", s(&source), "-o", s(&tiff), "--tile-size", "100"]), &["multiple of 16"]);
}

/// tifffile reads the OME-TIFF as one series with every level, libvips every SubIFD; lossless
/// levels equal the naive pyramid, JPEG ones are within JPEG's error of it, their tiles
/// abbreviated behind the level's shared JPEGTables.
#[test]
fn readers_open_every_level_of_an_ome_tiff() {
    let Some(python) = readers() else { return };
    let dir = tempfile::tempdir().unwrap();
    let cases = [
        (rgb8(), 1000, 700, 256, "deflate", "exact"),
        (PixelLayout::new(Channels::Grey, Depth::U16), 333, 517, 128, "zstd", "exact"),
        (rgb8(), 1000, 700, 256, "jpeg", "jpeg"),
        (PixelLayout::new(Channels::Grey, Depth::U8), 700, 301, 128, "jpeg", "jpeg"),
        (rgb8(), 1000, 700, 256, "lzw", "exact"),
    ];
    for (k, (layout, w, h, tile, codec, mode)) in cases.into_iter().enumerate() {
        let source = input(dir.path(), &format!("src{k}"), w, h, layout);
        let tiff = dir.path().join(format!("o{k}.ome.tif"));
        ok(&["split", s(&source), "-o", s(&tiff), "--codec", codec, "--tile-size", &tile.to_string(), "-q"]);
        let said = check(&python, "ome", &tiff, &source, tile, mode);
        eprintln!("{}: {said}", tiff.display());
        // JPEG levels share their tables (JPEGTables), every tile abbreviated.
        assert_eq!(said.contains("\"sharedTables\""), codec == "jpeg", "{said}");
    }
}

/// Float samples (a float32 TIFF made by tifffile, negative and fractional values) keep
/// their bits: Deflate and LZW with the floating-point predictor (3), which tifffile and
/// libvips undo; every level equals the float box oracle (means in float64, rounded once to
/// float32, as our pyramid makes them) exactly.
#[test]
fn float_samples_take_the_floating_point_predictor() {
    let Some(python) = readers() else { return };
    let dir = tempfile::tempdir().unwrap();
    let make = r#"
import sys, numpy as np, tifffile
h, w = 203, 301
y, x = np.mgrid[0:h, 0:w]
grey = (x * 0.37 - y * 1.25 + np.random.default_rng(3).normal(0, 4, (h, w))).astype(np.float32)
rgb = np.stack([grey, grey * -2.5 + 1e3, (x ^ y) / 7.0], -1).astype(np.float32)
tifffile.imwrite(sys.argv[1], grey)
tifffile.imwrite(sys.argv[2], rgb, photometric="rgb")
"#;
    let (grey, rgb) = (dir.path().join("grey.tif"), dir.path().join("rgb.tif"));
    crate::tiff_slides::python(python.as_os_str(), make, &[s(&grey), s(&rgb)]);
    for (source, flavour, out, codec) in [
        (&grey, "ome", "g.ome.tif", "deflate"),
        (&rgb, "generic", "r.tif", "lzw"),
        (&rgb, "ome", "r.ome.tif", "deflate"),
    ] {
        let tiff = dir.path().join(out);
        ok(&["split", s(source), "-o", s(&tiff), "--codec", codec, "--filter", "box", "--tile-size", "64", "-q"]);
        let said = check(&python, flavour, &tiff, source, 64, "exact");
        eprintln!("{}: {said}", tiff.display());
    }
}

/// The generic pyramid: tifffile and libvips read a page a level; OpenSlide 4 opens it as
/// generic-tiff with every level, and `read_region` gives the source.
#[test]
fn readers_open_every_level_of_a_generic_pyramid() {
    let Some(python) = readers() else { return };
    let dir = tempfile::tempdir().unwrap();
    let cases = [
        (rgb8(), 1000, 700, 256, "deflate", "exact"),
        (rgb8(), 999, 701, 128, "jpeg", "jpeg"),
        (PixelLayout::new(Channels::Rgb, Depth::U16), 301, 203, 64, "deflate", "exact"),
        (PixelLayout::new(Channels::Grey, Depth::U16), 301, 203, 64, "zstd", "exact"),
        (rgb8(), 450, 333, 256, "raw", "exact"),
        (PixelLayout::new(Channels::Rgb, Depth::U16), 301, 203, 64, "lzw", "exact"),
    ];
    for (k, (layout, w, h, tile, codec, mode)) in cases.into_iter().enumerate() {
        let source = input(dir.path(), &format!("src{k}"), w, h, layout);
        let tiff = dir.path().join(format!("g{k}.tif"));
        let tile_arg = tile.to_string();
        ok(&["split", s(&source), "-o", s(&tiff), "--codec", codec, "--filter", "box", "--tile-size", &tile_arg, "-q"]);
        let said = check(&python, "generic", &tiff, &source, tile, mode);
        eprintln!("{}: {said}", tiff.display());
        assert_eq!(said.contains("\"sharedTables\""), codec == "jpeg", "{said}");
    }
}

const COG_SCRIPT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/it/tiff_cog.py");

/// Debian's Python with GDAL (`python3-gdal`) and `gdalinfo` (`gdal-bin`): both there, or a
/// skip with a note, and a failure under CI.
fn gdal() -> bool {
    let python = Command::new("/usr/bin/python3")
        .args(["-c", "from osgeo import gdal; from osgeo_utils.samples import validate_cloud_optimized_geotiff"])
        .output()
        .is_ok_and(|o| o.status.success());
    let gdalinfo = Command::new("gdalinfo").arg("--version").output().is_ok_and(|o| o.status.success());
    if !(python && gdalinfo) {
        crate::common::skip_unless_ci("GDAL", "no gdalinfo or python3-gdal: apt-get install gdal-bin python3-gdal");
    }
    python && gdalinfo
}

/// A COG (`-o FILE.cog.tif`, `--layout cog`) as GDAL sees it: `gdalinfo -json` lists the
/// full resolution and every reduced level as its overviews; GDAL's COG validator passes,
/// with its full check of each tile's leader and trailer; each level GDAL reads equals the
/// naive pyramid (lossless) or is within JPEG's error of it. Classic and BigTIFF, 8 and 16
/// bits, Deflate with the predictor and JPEG (YCbCr).
#[test]
fn gdal_validates_a_cog_and_reads_every_level() {
    if !gdal() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let cases = [
        (rgb8(), 1000, 700, 256u32, "deflate", "exact", false),
        (PixelLayout::new(Channels::Grey, Depth::U16), 333, 517, 128, "deflate", "exact", true),
        (rgb8(), 999, 701, 128, "jpeg", "jpeg", false),
        (PixelLayout::new(Channels::Rgba, Depth::U8), 300, 200, 64, "raw", "exact", false),
        (PixelLayout::new(Channels::Grey, Depth::U16), 333, 517, 128, "lzw", "exact", false),
    ];
    for (k, (layout, w, h, tile, codec, mode, big)) in cases.into_iter().enumerate() {
        let source = input(dir.path(), &format!("src{k}"), w, h, layout);
        // The name says COG; so does --layout cog after a plain .tif name.
        let cog = dir.path().join(if k % 2 == 0 { format!("c{k}.cog.tif") } else { format!("c{k}.tif") });
        let tile_arg = tile.to_string();
        let mut args = vec!["split", s(&source), "-o", s(&cog)];
        if k % 2 == 1 {
            args.extend(["--layout", "cog"]);
        }
        args.extend(["--codec", codec, "--filter", "box", "--tile-size", &tile_arg, "--json"]);
        if big {
            args.push("--bigtiff");
        }
        let json: serde_json::Value = serde_json::from_str(ok(&args).trim()).unwrap();
        assert_eq!(json["tiff"]["flavour"], "cog", "{json}");

        let info = Command::new("gdalinfo").args(["-json", s(&cog)]).output().unwrap();
        assert!(info.status.success(), "gdalinfo: {}", String::from_utf8_lossy(&info.stderr));
        let info: serde_json::Value = serde_json::from_slice(&info.stdout).unwrap();
        assert_eq!(info["size"], serde_json::json!([w, h]), "{info}");
        assert_eq!(info["metadata"]["IMAGE_STRUCTURE"]["LAYOUT"], "COG", "{info}");
        let overviews = info["bands"][0]["overviews"].as_array().expect("overviews");
        let sizes: Vec<(u64, u64)> =
            overviews.iter().map(|o| (o["size"][0].as_u64().unwrap(), o["size"][1].as_u64().unwrap())).collect();
        // Each level ceil(size / 2^k), down to the first that fits one tile.
        let (mut want, mut lw, mut lh) = (Vec::new(), u64::from(w), u64::from(h));
        while lw.max(lh) > u64::from(tile) {
            (lw, lh) = (lw.div_ceil(2), lh.div_ceil(2));
            want.push((lw, lh));
        }
        assert_eq!(sizes, want, "{}: the overviews gdalinfo lists", cog.display());

        let out = Command::new("/usr/bin/python3").args([COG_SCRIPT, s(&cog), s(&source), &tile_arg, mode]).output();
        let out = out.unwrap();
        let said = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
        assert!(out.status.success(), "{}: {said}", cog.display());
        eprintln!("{}: {said}", cog.display());
    }
}

/// A JPEG-tiled source whose tiles fit the TIFF's (256 texels) has its interior
/// full-resolution tiles copied as they are stored, as `--json` says, and the file declares
/// the tiles' own coding for every level: YCbCr 4:2:0 from `vips tiffsave` below Q90, RGB
/// from Q90 on (as Aperio scanners store them; declared YCbCr, libvips read such tiles with a
/// mean error of 51). An explicit `--subsampling` re-encodes them. Every case reads back
/// within JPEG's error of the source.
#[test]
fn a_jpeg_tiled_source_s_tiles_are_copied_where_they_fit_the_tiff_s_tags() {
    if !crate::common::have_program("vips", "--version", "libvips-tools") {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let png = input(dir.path(), "src", 1000, 700, rgb8());
    let photometric = |tiff: &Path| {
        let mut decoder = tiff::decoder::Decoder::new(std::fs::File::open(tiff).unwrap()).unwrap();
        let mut found = vec![decoder.get_tag_u32(tiff::tags::Tag::PhotometricInterpretation).unwrap()];
        while decoder.more_images() {
            decoder.next_image().unwrap();
            found.push(decoder.get_tag_u32(tiff::tags::Tag::PhotometricInterpretation).unwrap());
        }
        found
    };
    // 3 x 2 of the 4 x 3 tiles of level 0 lie inside the image; the edge ones are encoded.
    let (ycbcr, rgb) = (6, 2);
    for (q, extra, copied, declared) in
        [("85", None, 6, ycbcr), ("95", None, 6, rgb), ("95", Some("420"), 0, ycbcr), ("85", Some("rgb"), 0, rgb)]
    {
        let tiled = dir.path().join(format!("s{q}.tif"));
        let vips = Command::new("vips")
            .args(["tiffsave", s(&png), s(&tiled), "--tile", "--tile-width", "256", "--tile-height", "256"])
            .args(["--compression", "jpeg", "--Q", q])
            .output()
            .unwrap();
        assert!(vips.status.success(), "vips: {}", String::from_utf8_lossy(&vips.stderr));
        let out = dir.path().join(format!("o{q}-{}.tif", extra.unwrap_or("as-stored")));
        let mut args = vec!["split", s(&tiled), "-o", s(&out), "--tile-size", "256", "--json"];
        args.extend(extra.map(|e| ["--subsampling", e]).iter().flatten());
        let json = ok(&args);
        let json: serde_json::Value = serde_json::from_str(json.trim()).unwrap();
        let case = format!("Q{q} --subsampling {extra:?}");
        assert_eq!(json["copied"], copied, "{case}: {json}");
        assert_eq!(json["storedTiles"]["copied"], copied, "{case}: {json}");
        assert_eq!(photometric(&out), [declared; 3], "{case}: each level's Photometric");
        if let Some(python) = readers() {
            let said = check(&python, "generic", &out, &png, 256, "jpeg");
            eprintln!("{case} {}: {said}", out.display());
        }
    }
}

/// Reads TIFF OUT (flavour FLAVOUR) against the slide SLIDE's own tiled levels: tifffile
/// reads one series of as many levels, each equal to the slide's level (the same JPEG
/// streams, decoded by the same decoder); an OME-TIFF's XML validates; OpenSlide 4 opens a
/// generic pyramid with the slide's downsamples.
const SAME_LEVELS: &str = r#"
import sys, numpy as np, tifffile, openslide, ome_types
out, slide, flavour = sys.argv[1:4]
with tifffile.TiffFile(slide) as s, tifffile.TiffFile(out) as t:
    want = [p for p in s.pages if p.is_tiled]
    levels = t.series[0].levels
    if len(levels) != len(want):
        sys.exit(f"{len(levels)} levels, the slide has {len(want)}")
    for k, (level, page) in enumerate(zip(levels, want)):
        a, b = level.asarray(), page.asarray()
        if a.shape != b.shape or not np.array_equal(a, b):
            sys.exit(f"level {k}: {a.shape} differs from the slide's {b.shape}")
    if flavour == "ome":
        ome_types.from_xml(t.ome_metadata, validate=True)
if flavour == "generic":
    ours, theirs = openslide.OpenSlide(out), openslide.OpenSlide(slide)
    if ours.level_dimensions != theirs.level_dimensions:
        sys.exit(f"OpenSlide: {ours.level_dimensions}, the slide {theirs.level_dimensions}")
    for k, size in enumerate(ours.level_dimensions):
        if not np.array_equal(np.asarray(ours.read_region((0, 0), k, size)), np.asarray(theirs.read_region((0, 0), k, size))):
            sys.exit(f"OpenSlide: level {k} differs from the slide's")
"#;

/// A slide that is a pyramid of JPEG tiles (an Aperio-like SVS as tifffile writes it, YCbCr
/// with downsamples 4 and about 16; a `vips tiffsave --pyramid` file at Q90, RGB-coded) is
/// written with its own levels, every stored tile copied, nothing encoded, in every flavour
/// (a TIFF pyramid may step down by any factor): each level read back equal to the slide's,
/// and a COG valid for GDAL. `--levels pow2` gives our pyramid, and a source with
/// no levels says nothing of them unless `--levels stored` was asked.
#[test]
fn a_slide_s_own_levels_are_copied_as_stored() {
    let Some(python) = readers() else { return };
    let dir = tempfile::tempdir().unwrap();
    let svs = dir.path().join("slide.svs");
    crate::tiff_slides::python(python.as_os_str(), crate::dicom_out::MAKE_LEVELLED_SVS, &[s(&svs)]);
    // 9 x 6, 3 x 2 and 1 tiles.
    let mut slides = vec![(svs.clone(), 61)];
    if crate::common::have_program("vips", "--version", "libvips-tools") {
        let png = input(dir.path(), "src", 1000, 700, rgb8());
        let tif = dir.path().join("vips-pyramid.tif");
        let vips = Command::new("vips")
            .args(["tiffsave", s(&png), s(&tif), "--tile", "--pyramid", "--compression", "jpeg", "--Q", "90"])
            .args(["--tile-width", "256", "--tile-height", "256"])
            .output()
            .unwrap();
        assert!(vips.status.success(), "vips: {}", String::from_utf8_lossy(&vips.stderr));
        // 4 x 3, 2 x 2 and 1 tiles.
        slides.push((tif, 17));
    }
    let flavours = [("g.tif", "generic"), ("o.ome.tif", "ome"), ("c.cog.tif", "cog")];
    for ((slide, tiles), (name, flavour)) in slides.iter().flat_map(|s| flavours.iter().map(move |f| (s, f))) {
        let out = dir.path().join(format!("{}-{name}", slide.file_stem().unwrap().to_string_lossy()));
        let json: serde_json::Value =
            serde_json::from_str(ok(&["split", s(slide), "-o", s(&out), "--json"]).trim()).unwrap();
        let case = format!("{} {flavour}", slide.display());
        assert_eq!(json["tiff"]["levelsCopied"], true, "{case}: {json}");
        assert_eq!((json["copied"].clone(), json["encoded"].clone()), ((*tiles).into(), 0.into()), "{case}: {json}");
        assert_eq!(json["tiff"]["levels"], 3, "{case}: {json}");
        let check = Command::new(&python).args(["-c", SAME_LEVELS, s(&out), s(slide), flavour]).output().unwrap();
        assert!(check.status.success(), "{case}: {}", String::from_utf8_lossy(&check.stderr));
        if *flavour == "cog" && gdal() {
            let script = "import sys; from osgeo_utils.samples import validate_cloud_optimized_geotiff as v; e, w, _ = v.validate(sys.argv[1], full_check=True); sys.exit('; '.join(e) or None)";
            let valid = Command::new("/usr/bin/python3").args(["-c", script, s(&out)]).output().unwrap();
            assert!(valid.status.success(), "{case}: {}", String::from_utf8_lossy(&valid.stderr));
        }
    }
    let pow2 = dir.path().join("pow2.tif");
    let json: serde_json::Value =
        serde_json::from_str(ok(&["split", s(&svs), "-o", s(&pow2), "--levels", "pow2", "--json"]).trim()).unwrap();
    assert_eq!((json["tiff"]["levelsCopied"].clone(), json["tiff"]["levels"].clone()), (false.into(), 5.into()));
    assert_eq!(json["tiff"]["levelsDeclined"], serde_json::Value::Null, "{json}");
    // A PNG has no levels: said only where asked.
    let png = input(dir.path(), "flat", 300, 200, rgb8());
    let flat = dir.path().join("flat.tif");
    for (extra, said) in
        [(None, serde_json::Value::Null), (Some("stored"), "the source is no slide of JPEG-tiled levels".into())]
    {
        let mut args = vec!["split", s(&png), "-o", s(&flat), "--json", "--force"];
        args.extend(extra.iter().flat_map(|e| ["--levels", e]));
        let json: serde_json::Value = serde_json::from_str(ok(&args).trim()).unwrap();
        assert_eq!(json["tiff"]["levelsDeclined"], said, "--levels {extra:?}: {json}");
    }
}

/// The associated images of an SVS (the file's pages by kind, as its descriptions name them)
/// against an output's (`generic`: named by their descriptions alone), compared by tifffile
/// sample for sample: the strips are lossless and both sides decode the slide's LZW and JPEG
/// pages with libjpeg-turbo's default IDCT, so any difference is ours. libvips reads each by
/// its `page=`, and OpenSlide still opens only the levels (the strips are not tiled).
const SAME_ASSOCIATED: &str = r#"
import sys, json, numpy as np, tifffile, pyvips, openslide
out, slide = sys.argv[1], sys.argv[2]
def associated(path, aperio):
    got = {}
    with tifffile.TiffFile(path) as t:
        for i, p in enumerate(t.pages):
            words = (p.description or "").lower().replace("\r", " ").split()
            kind = next((k for k in ("label", "macro", "thumbnail") if k in words), None)
            if kind is None and aperio and i == 1 and not p.is_tiled:
                kind = "thumbnail"
            if kind:
                got[kind] = (i, p.asarray(), int(p.compression), int(p.predictor), p.is_tiled)
    return got
want, have = associated(slide, True), associated(out, False)
assert sorted(want) == sorted(have), (sorted(want), sorted(have))
pages = {}
for kind, (_, a, _, _, _) in want.items():
    page, b, compression, predictor, tiled = have[kind]
    assert (compression, predictor, tiled) == (8, 2, False), (kind, compression, predictor, tiled)
    assert a.shape == b.shape, (kind, a.shape, b.shape)
    assert np.array_equal(a, b), (kind, int(np.abs(a.astype(int) - b).max()))
    v = pyvips.Image.new_from_file(out, page=page)
    pixels = np.ndarray(buffer=v.write_to_memory(), dtype=np.uint8, shape=[v.height, v.width, v.bands])
    assert np.array_equal(pixels, b), kind
    pages[kind] = page
# OpenSlide's generic TIFF reader takes the tiled main IFDs for levels (an OME-TIFF's
# reduced levels are SubIFDs, which it does not follow), never the strips.
s = openslide.OpenSlide(out)
assert s.level_count == int(sys.argv[3]), s.level_count
print(json.dumps(pages))
"#;

/// A slide's label, macro and thumbnail follow a generic pyramid's levels, one lossless strip
/// each (`SAME_ASSOCIATED`); `--json` and the summary list them; our own reader finds them
/// again (a DICOM series made from the TIFF carries all three). An OME-TIFF carries them
/// too, each an OME image tifffile lists as a series. `--no-associated` and a COG leave them
/// out, saying how many and why.
#[test]
fn a_slide_s_associated_images_follow_a_generic_pyramid() {
    let Some(python) = readers() else { return };
    let dir = tempfile::tempdir().unwrap();
    let svs = dir.path().join("slide.svs");
    crate::tiff_slides::python(python.as_os_str(), crate::dicom_out::MAKE_SVS_WITH_LABEL, &[s(&svs)]);
    let tif = dir.path().join("slide.tif");
    let json = json_of(&ok(&["split", s(&svs), "-o", s(&tif), "--json"]));
    let t = &json["tiff"];
    let listed: Vec<(&str, u64)> = (t["associated"].as_array().unwrap().iter())
        .map(|a| (a["kind"].as_str().unwrap(), a["page"].as_u64().unwrap()))
        .collect();
    assert_eq!(listed, [("thumbnail", 2), ("label", 3), ("overview", 4)], "{json}");
    assert_eq!(
        (t["associated"][1]["width"].clone(), t["associated"][1]["from"].clone()),
        (190.into(), "page 3".into())
    );
    assert_eq!(t["associatedLeftOut"], 0, "{json}");
    let check = Command::new(&python).args(["-c", SAME_ASSOCIATED, s(&tif), s(&svs), "2"]).output().unwrap();
    let said = String::from_utf8_lossy(&check.stdout);
    assert!(check.status.success(), "{said}{}", String::from_utf8_lossy(&check.stderr));
    assert_eq!(said.trim(), r#"{"thumbnail": 2, "label": 3, "macro": 4}"#);

    // Our reader takes them for what they are: not levels, and carried on.
    let series = dir.path().join("series");
    let json = json_of(&ok(&["split", s(&tif), "--layout", "dicom", "-o", s(&series), "--json"]));
    let kinds: Vec<&str> =
        json["dicom"]["associated"].as_array().unwrap().iter().map(|a| a["kind"].as_str().unwrap()).collect();
    assert_eq!((kinds, json["dicom"]["instances"].clone()), (vec!["thumbnail", "label", "overview"], 2.into()));

    let bare = dir.path().join("bare.tif");
    let json = json_of(&ok(&["split", s(&svs), "-o", s(&bare), "--no-associated", "--json"]));
    assert_eq!(
        (json["tiff"]["associated"].clone(), json["tiff"]["associatedLeftOut"].clone()),
        (serde_json::json!([]), 3.into())
    );
    // An OME-TIFF: the same IFDs after its pyramid's, each an OME image of its own, which
    // tifffile lists as series beside the pyramid (the OME-XML valid for ome-types).
    let ome = dir.path().join("slide.ome.tif");
    let json = json_of(&ok(&["split", s(&svs), "-o", s(&ome), "--json"]));
    assert_eq!(json["tiff"]["associated"].as_array().map(Vec::len), Some(3), "{json}");
    let check = Command::new(&python).args(["-c", SAME_ASSOCIATED, s(&ome), s(&svs), "1"]).output().unwrap();
    let said = String::from_utf8_lossy(&check.stdout);
    assert!(check.status.success(), "{said}{}", String::from_utf8_lossy(&check.stderr));
    assert_eq!(said.trim(), r#"{"thumbnail": 1, "label": 2, "macro": 3}"#, "main IFDs after level 0's");
    let series = Command::new(&python).args(["-c", OME_SERIES, s(&ome)]).output().unwrap();
    let said = String::from_utf8_lossy(&series.stdout);
    assert!(series.status.success(), "{said}{}", String::from_utf8_lossy(&series.stderr));
    assert_eq!(
        said.trim(),
        r#"[["slide", [1000, 1500, 3], 2], ["thumbnail", [125, 188, 3], 1], ["label", [230, 190, 3], 1], ["macro", [300, 820, 3], 1]]"#
    );
    let cog = dir.path().join("slide.cog.tif");
    let said = run(&["split", s(&svs), "-o", s(&cog)]);
    let line = format!("{}{}", String::from_utf8_lossy(&said.stdout), String::from_utf8_lossy(&said.stderr));
    assert!(
        said.status.success() && line.contains("3 associated image(s) left out: a generic TIFF or an OME-TIFF"),
        "{line}"
    );
    fails_with(
        &run(&["split", s(&svs), "-o", s(&dir.path().join("b.cog.tif")), "--no-associated"]),
        &["--no-associated belongs to a generic TIFF (-o FILE.tif), an OME-TIFF"],
    );
}

/// An OME-TIFF's series as tifffile lists them from its OME-XML (validated by ome-types):
/// each one's name, shape and levels.
const OME_SERIES: &str = r#"
import sys, json, tifffile, ome_types
with tifffile.TiffFile(sys.argv[1]) as t:
    assert t.is_ome
    ome_types.from_xml(t.ome_metadata, validate=True)
    print(json.dumps([[s.name, list(s.shape), len(s.levels)] for s in t.series]))
"#;

/// An associated image no output can carry (a 16-bit label) stops the run when it is
/// planned, naming the image and the way out, before any level is cut: nothing is left at
/// the TIFF's or the series' path; `--no-associated` makes both.
#[test]
fn an_associated_image_that_cannot_be_carried_is_refused_before_the_levels() {
    let Some(python) = readers() else { return };
    let dir = tempfile::tempdir().unwrap();
    let svs = dir.path().join("slide.svs");
    let sixteen_bit_label = crate::dicom_out::MAKE_SVS_WITH_LABEL
        .replace("t.write(label, compression=", "t.write(label.astype(np.uint16) * 257, compression=");
    crate::tiff_slides::python(python.as_os_str(), &sixteen_bit_label, &[s(&svs)]);
    let (tif, series) = (dir.path().join("slide.tif"), dir.path().join("series"));
    let why = ["slide.svs", "the label (page 3): rgb 16-bit texels, not 8-bit grey or RGB", "--no-associated"];
    // The library's plan refuses it, before the source's first row is read.
    {
        use vortex_tiler::formats::tiff::Flavour;
        use vortex_tiler::outputs::{Budget, Format, Output, Plan, Settings};
        let source = vortex_tiler::source::open(&svs, Budget::default()).unwrap();
        let outputs = vec![Output::new(Format::Tiff(Flavour::Generic), &tif)];
        let planned = Plan::new(outputs, &Settings::default(), &source.header(), &[svs.as_path()], Budget::default());
        let Err(refused) = planned else { panic!("a plan of a TIFF carrying a 16-bit label") };
        let refused = refused.to_string();
        assert!(why.iter().all(|w| refused.contains(w)), "{refused}");
    }
    fails_with(&run(&["split", s(&svs), "-o", s(&tif)]), &why);
    fails_with(&run(&["split", s(&svs), "--layout", "dicom", "-o", s(&series)]), &why);
    let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(left, [std::ffi::OsString::from("slide.svs")], "nothing but the slide");
    ok(&["split", s(&svs), "-o", s(&tif), "--no-associated", "-q"]);
    ok(&["split", s(&svs), "--layout", "dicom", "-o", s(&series), "--no-associated", "-q"]);
}

fn json_of(said: &str) -> serde_json::Value {
    serde_json::from_str(said.trim()).unwrap_or_else(|e| panic!("{e}: {said}"))
}

const GEO_SCRIPT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/it/tiff_geo.py");

/// Runs `tiff_geo.py` with Debian's Python (GDAL); fails with what it said.
fn geo(args: &[&str]) -> String {
    let out = Command::new("/usr/bin/python3").arg(GEO_SCRIPT).args(args).output().unwrap();
    let said = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "tiff_geo.py {args:?}: {said}");
    said
}

/// A GeoTIFF source as GDAL writes it (UTM 33N, no-data 0) keeps its georeferencing in a COG
/// and in a generic pyramid, written in one run: GDAL reads the same geotransform (the same
/// doubles), the same coordinate system (WKT), pixel-is-area or pixel-is-point and no-data
/// from the full resolution; the reduced levels hold only the no-data value, as GDAL's
/// overviews; the COG validator passes. Pixel is area (ModelPixelScale and ModelTiepoint),
/// pixel is point, and a rotated grid (ModelTransformation).
#[test]
fn a_geotiff_source_keeps_its_georeferencing() {
    if !gdal() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let png = input(dir.path(), "src", 1000, 700, rgb8());
    for kind in ["area", "point", "rotated"] {
        let source = dir.path().join(format!("{kind}.tif"));
        geo(&["make", s(&png), s(&source), kind]);
        let (cog, generic) = (dir.path().join(format!("{kind}.cog.tif")), dir.path().join(format!("{kind}-g.tif")));
        ok(&["split", s(&source), "-o", s(&cog), "-o", s(&generic), "--codec", "deflate", "--tile-size", "256", "-q"]);
        for out in [&cog, &generic] {
            let said = geo(&["check", s(&source), s(out)]);
            eprintln!("{}: {said}", out.display());
        }
    }
}

/// A GeoTIFF whose GeoKeyDirectory says more keys than it holds: a TIFF output refuses it,
/// naming the tag and the file, and leaves nothing (carried, GDAL would misplace the image or
/// drop its coordinate system without a word); a Deep Zoom output, which carries no
/// georeferencing, ignores it.
#[test]
fn a_damaged_geo_key_directory_is_refused_by_a_tiff_output_only() {
    if !gdal() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let png = input(dir.path(), "src", 300, 200, rgb8());
    let source = dir.path().join("geo.tif");
    geo(&["make", s(&png), s(&source), "area"]);
    // The directory's header (version 1, revision 1.0, 7 keys) and first key, as GDAL wrote it
    // (twice: the directory it rewrote when the geotransform was set, and the one before).
    let mut bytes = std::fs::read(&source).unwrap();
    let header: Vec<u8> = [1u16, 1, 0, 7, 1024].iter().flat_map(|v| v.to_le_bytes()).collect();
    let found: Vec<usize> = (0..bytes.len() - header.len()).filter(|&i| bytes[i..].starts_with(&header)).collect();
    assert!(!found.is_empty(), "no GeoKeyDirectory in {}", source.display());
    for at in found {
        bytes[at + 6..at + 8].copy_from_slice(&40u16.to_le_bytes());
    }
    std::fs::write(&source, bytes).unwrap();
    let cog = dir.path().join("a.cog.tif");
    fails_with(&run(&["split", s(&source), "-o", s(&cog)]), &["geo.tif", "GeoKeyDirectoryTag (34735) says 40 keys"]);
    assert!(!cog.exists());
    ok(&["split", s(&source), "-o", s(&dir.path().join("web")), "--layout", "dzi", "-q"]);
}

/// A run killed (SIGKILL) part way through a TIFF leaves nothing at the path: the file is
/// written under a temporary name (`.NAME.partial-PID`, a COG's tiles staged beside it) and
/// renamed when complete. The same command run again writes the file and removes what the
/// dead run left.
#[test]
fn a_killed_run_leaves_no_tiff_and_the_next_run_cleans_up() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("big.ppm");
    let mut bytes = b"P6\n2000 2000\n255\n".to_vec();
    bytes.extend((0..3 * 2000 * 2000u32).map(|i| (i % 251) as u8));
    std::fs::write(&input, bytes).unwrap();
    for name in ["x.tif", "x.cog.tif"] {
        let tiff = dir.path().join(name);
        let args = ["split", s(&input), "-o", s(&tiff), "--codec", "deflate", "--tile-size", "16", "-q"];
        let mut child = Command::new(crate::common::cli::BIN).args(args).spawn().unwrap();
        // The child's only sign of progress is its temporary file: a generic TIFF's grows as
        // tiles come, a COG's is written at the end (its tiles are staged in an unlinked file),
        // so it is killed once the TIFF's has 100 KB and the COG's exists, long before either
        // run could end (it has seconds of tiles to go).
        let partial = dir.path().join(format!(".{name}.partial-{}", child.id()));
        let enough = if name == "x.cog.tif" { 0 } else { 100_000 };
        let mut polls = 0;
        while !std::fs::metadata(&partial).is_ok_and(|m| m.len() >= enough) && polls < 4000 {
            assert!(child.try_wait().unwrap().is_none(), "{name}: the run ended before its temporary showed");
            std::thread::sleep(std::time::Duration::from_millis(5));
            polls += 1;
        }
        child.kill().unwrap();
        assert!(!child.wait().unwrap().success(), "{name}: killed");
        assert!(!tiff.exists(), "{name}: nothing at the destination");
        ok(&args);
        let left: Vec<String> = std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .filter(|f| f.starts_with('.'))
            .collect();
        assert!(left.is_empty(), "{name}: the dead run's temporaries remain: {left:?}");
        assert!(tiff.is_file());
    }
}
