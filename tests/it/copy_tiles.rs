//! Copy instead of re-encode (issue 30): the finest level's tiles of a JPEG-tiled TIFF whose
//! grid lines up with the output's pages are the stored tiles, byte for byte, as complete
//! JPEG files; everything else is what a `--reencode` run makes.
//!
//! The TIFFs are made by libvips (`vips tiffsave --tile --compression jpeg`: shared
//! JPEGTables; YCbCr 4:2:0 below Q90, RGB from Q90 on, grey) and tifffile (each tile a complete
//! JPEG). The stored streams are read from the TIFF with the `tiff` crate and compared segment
//! by segment; the pixels are compared with Debian's libvips decoding the source tile (through
//! libtiff) and the copied file (through its JPEG loader): both libjpeg-turbo, so they must be
//! equal (tolerance 0).

use std::collections::BTreeMap;
use std::path::{Path, PathBuf};
use std::process::Command;

use crate::common::cli::{self, s};

/// Whether `vips` runs; outside CI a missing one skips the test with a note.
pub(crate) fn have_vips() -> bool {
    crate::common::have_program("vips", "--version", "libvips-tools")
}

pub(crate) fn tool(name: &str, args: &[&str]) {
    let out = Command::new(name).args(args).output().unwrap();
    assert!(out.status.success(), "{name} {args:?}: {}", String::from_utf8_lossy(&out.stderr));
}

/// An RGB image with ramps, edges and noise, 400x300: 3x2 whole 128-texel tiles and a partial
/// column and row.
fn pattern_png(dir: &Path) -> PathBuf {
    pattern_png_sized(dir, 400, 300)
}

/// The pattern at `w x h`.
pub(crate) fn pattern_png_sized(dir: &Path, w: u32, h: u32) -> PathBuf {
    let mut state = 0x2545_F491u32;
    let img = image::RgbImage::from_fn(w, h, |x, y| {
        state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
        let noise = (state >> 24) % 40;
        image::Rgb([(x * 255 / w + noise).min(255) as u8, (y * 255 / h) as u8, ((x ^ y) & 255) as u8])
    });
    let path = dir.join(format!("pattern-{w}x{h}.png"));
    img.save(&path).unwrap();
    path
}

/// A JPEG stream split at its first scan: its marker segments before it (marker, body), and
/// the scan onwards.
fn segments(stream: &[u8]) -> (Vec<(u8, Vec<u8>)>, Vec<u8>) {
    assert_eq!(&stream[..2], [0xFF, 0xD8], "no SOI");
    let (mut at, mut list) = (2, Vec::new());
    while stream[at + 1] != 0xDA {
        assert_eq!(stream[at], 0xFF, "a marker at {at}");
        let len = u16::from_be_bytes([stream[at + 2], stream[at + 3]]) as usize;
        list.push((stream[at + 1], stream[at + 4..at + 2 + len].to_vec()));
        at += 2 + len;
    }
    (list, stream[at..].to_vec())
}

/// The TIFF's tile `index` as a complete stream: its JPEGTables (without SOI and EOI) spliced
/// in after the tile's SOI, as TIFF Technical Note 2 says a reader does.
fn stored_stream(tiff: &Path, index: usize) -> Vec<u8> {
    let mut decoder = tiff::decoder::Decoder::new(std::fs::File::open(tiff).unwrap()).unwrap();
    let offsets = decoder.get_tag_u64_vec(tiff::tags::Tag::TileOffsets).unwrap();
    let counts = decoder.get_tag_u64_vec(tiff::tags::Tag::TileByteCounts).unwrap();
    let tables = decoder.get_tag_u8_vec(tiff::tags::Tag::JPEGTables).ok();
    let bytes = std::fs::read(tiff).unwrap();
    let tile = &bytes[offsets[index] as usize..][..counts[index] as usize];
    let mut stream = tile[..2].to_vec();
    if let Some(tables) = tables {
        stream.extend_from_slice(&tables[2..tables.len() - 2]);
    }
    stream.extend_from_slice(&tile[2..]);
    stream
}

/// What marks a copied file's colour space: a JFIF APP0 (YCbCr, grey) or an Adobe APP14 with
/// transform 0 (RGB as it is).
#[derive(Clone, Copy, Debug, PartialEq)]
enum Marker {
    Jfif,
    AdobeRgb,
}

/// The copied file is the stored stream with one marker added after SOI: every other segment
/// and the entropy-coded data the same bytes.
fn assert_copied(file: &[u8], stored: &[u8], marker: Option<Marker>, what: &str) {
    let (mut ours, our_scan) = segments(file);
    let (theirs, their_scan) = segments(stored);
    assert!(our_scan == their_scan, "{what}: the entropy-coded data differs");
    if let Some(marker) = marker {
        let (code, body) = ours.remove(0);
        match marker {
            Marker::Jfif => assert!(code == 0xE0 && body.starts_with(b"JFIF\0"), "{what}: no JFIF APP0 first"),
            Marker::AdobeRgb => {
                assert!(code == 0xEE && body.starts_with(b"Adobe") && body[11] == 0, "{what}: no Adobe APP14 (RGB)")
            }
        }
    }
    assert!(ours == theirs, "{what}: the marker segments differ");
}

/// Texels libvips decodes from `path` (a region of it with `crop`: x, y, width, height), as raw
/// bytes.
fn vips_texels(path: &Path, crop: Option<(u32, u32, u32, u32)>, scratch: &Path) -> Vec<u8> {
    let raw = scratch.with_extension("raw");
    match crop {
        None => tool("vips", &["rawsave", s(path), s(&raw)]),
        Some((x, y, w, h)) => {
            let cut = scratch.with_extension("v");
            let (x, y, w, h) = (x.to_string(), y.to_string(), w.to_string(), h.to_string());
            tool("vips", &["crop", s(path), s(&cut), &x, &y, &w, &h]);
            tool("vips", &["rawsave", s(&cut), s(&raw)]);
        }
    }
    std::fs::read(raw).unwrap()
}

/// Every file under `dir`, by its path below it.
pub(crate) fn files(dir: &Path) -> BTreeMap<String, Vec<u8>> {
    let mut all = BTreeMap::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(d).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else {
                all.insert(
                    path.strip_prefix(dir).unwrap().to_string_lossy().into_owned(),
                    std::fs::read(&path).unwrap(),
                );
            }
        }
    }
    all
}

fn json(args: &[&str]) -> serde_json::Value {
    let mut args = args.to_vec();
    args.push("--json");
    serde_json::from_str(&cli::ok(&args)).unwrap()
}

/// Whether a JPEG stream's chroma is subsampled (a component's sampling factors below another's).
fn subsampled(stream: &[u8]) -> bool {
    let (list, _) = segments(stream);
    let (_, sof) = list.iter().find(|(m, _)| matches!(m, 0xC0..=0xC2)).expect("no SOF");
    let factors: Vec<u8> = sof[6..].chunks_exact(3).map(|c| c[1]).collect();
    factors.iter().any(|&f| f != factors[0])
}

/// One JPEG TIFF of a 4x3-page image through `split --layout dzi --overlap 0`: the 3x2 whole
/// tiles copied (the stored bytes, decoding to the source tile's texels); the edge pages, where
/// `crops`, the stored tiles cropped losslessly (one baseline scan, decoding to the source's
/// texels there, exactly), else what `--reencode` makes, byte for byte, as every coarser tile.
fn check_dzi_copies(tiff: &Path, marker: Option<Marker>, quality: u8, crops: bool) {
    let dir = tiff.parent().unwrap();
    let stem = tiff.file_stem().unwrap().to_string_lossy().into_owned();
    let (copy, again) = (dir.join(format!("{stem}-copy")), dir.join(format!("{stem}-again")));
    let dzi = ["split", s(tiff), "--layout", "dzi", "--tile-size", "128", "--overlap", "0"];
    let done = json(&[&dzi[..], &["-o", s(&copy)]].concat());
    let cropped = if crops { 6 } else { 0 };
    assert_eq!((&done["copied"], &done["cropped"]), (&(6 + cropped).into(), &cropped.into()), "{stem}: {done}");
    assert_eq!(done["storedTiles"]["cropped"], cropped, "{stem}: {done}");
    assert_eq!(done["storedTiles"]["quality"], quality, "{stem}: {done}");
    assert_eq!(done["storedTiles"]["qualityExact"], true, "{stem}: {done}");
    let redone = json(&[&dzi[..], &["-o", s(&again), "--reencode"]].concat());
    assert_eq!(redone["copied"], 0, "{stem}: {redone}");
    assert_eq!(redone["storedTiles"]["declined"], "--reencode asked", "{stem}: {redone}");
    assert_eq!(done["tiles"], redone["tiles"]);

    let (width, height) = (done["width"].as_u64().unwrap() as u32, done["height"].as_u64().unwrap() as u32);
    let (ours, reencoded) = (files(&copy), files(&again));
    assert_eq!(ours.keys().collect::<Vec<_>>(), reencoded.keys().collect::<Vec<_>>());
    let finest = format!("{stem}_files/9/"); // 400 texels wide or so: Deep Zoom level ceil(log2 400)
    let (mut copied, mut edges) = (0, 0);
    for (name, bytes) in &ours {
        let page = name.strip_prefix(&finest).and_then(|t| t.strip_suffix(".jpeg")).and_then(|t| {
            let (x, y) = t.split_once('_')?;
            Some((x.parse::<u32>().ok()?, y.parse::<u32>().ok()?))
        });
        let edge = page.is_some_and(|(x, y)| x == 3 || y == 2);
        let Some((x, y)) = page.filter(|_| !edge || crops) else {
            assert!(bytes == &reencoded[name], "{stem}: {name} differs from the --reencode run's");
            continue;
        };
        let what = format!("{stem}: tile {x},{y}");
        let stored = stored_stream(tiff, (y * 4 + x) as usize);
        let (w, h) = ((width - x * 128).min(128), (height - y * 128).min(128));
        if edge {
            edges += 1;
            let (list, _) = segments(bytes);
            assert!(list.iter().any(|(m, _)| *m == 0xC0), "{what}: the crop is not baseline");
            let sof = list.iter().find(|(m, _)| *m == 0xC0).unwrap();
            assert_eq!(sof.1[1..5], [(h >> 8) as u8, h as u8, (w >> 8) as u8, w as u8], "{what}: its size");
            let tables = |l: &[(u8, Vec<u8>)]| {
                l.iter().filter(|(m, _)| *m == 0xDB).flat_map(|(_, b)| b.clone()).collect::<Vec<u8>>()
            };
            assert_eq!(tables(&list), tables(&segments(&stored).0), "{what}: other quantisation tables");
        } else {
            copied += 1;
            assert_copied(bytes, &stored, marker, &what);
        }
        assert!(bytes != &reencoded[name], "{what}: the copy is the re-encoded tile");
        let scratch = dir.join(format!("{stem}-{x}-{y}"));
        let source = vips_texels(tiff, Some((x * 128, y * 128, w, h)), &scratch.with_extension("src"));
        let shown = vips_texels(&copy.join(name), None, &scratch.with_extension("copy"));
        assert!(source == shown, "{what}: libvips decodes other texels from the copy");
    }
    assert_eq!((copied, edges), (6, cropped), "{stem}");
}

/// libvips's JPEG TIFFs (shared tables; YCbCr 4:2:0, RGB and grey) and tifffile's (complete
/// tiles, JFIF or not as imagecodecs writes them): the whole tiles copied, the rest re-encoded.
#[test]
fn whole_tiles_are_copied_as_stored() {
    if !have_vips() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let d = |name: &str| dir.path().join(name);
    let png = pattern_png(dir.path());
    let grey = d("grey.v");
    tool("vips", &["colourspace", s(&png), s(&grey), "b-w"]);
    let tiled = ["--tile", "--tile-width", "128", "--tile-height", "128", "--compression", "jpeg"];
    for (name, input, extra, marker, quality, crops) in [
        // 4:2:0: the edge pages are 16 and 44 texels: even, so chroma upsampling at their new
        // edge would differ (`crop::exact`); they are encoded. At 405x301 (21 and 45) they are cropped.
        ("ycbcr", &png, &["--Q", "75"][..], Marker::Jfif, 75, false),
        ("ycbcr-odd", &pattern_png_sized(dir.path(), 405, 301), &["--Q", "75"][..], Marker::Jfif, 75, true),
        // At Q >= 90 libvips writes RGB (PhotometricInterpretation 2), chroma whole.
        ("rgb", &png, &["--Q", "90"][..], Marker::AdobeRgb, 90, true),
        ("grey", &grey, &["--Q", "85"][..], Marker::Jfif, 85, true),
    ] {
        let tiff = d(&format!("{name}.tif"));
        tool("vips", &[&["tiffsave", s(input), s(&tiff)], &tiled[..], extra].concat());
        check_dzi_copies(&tiff, Some(marker), quality, crops);
    }
    let Some(py) = std::env::var_os("VORTEX_PYVIPS") else {
        crate::common::skip_unless_ci(
            "tifffile's JPEG TIFF",
            "VORTEX_PYVIPS unset: set it to a Python with tifffile and imagecodecs",
        );
        return;
    };
    let tiff = d("tifffile.tif");
    let script = "import sys, numpy, tifffile, PIL.Image\nimg = numpy.asarray(PIL.Image.open(sys.argv[1]))\ntifffile.imwrite(sys.argv[2], img, tile=(128, 128), compression='jpeg', compressionargs={'level': 80}, photometric='rgb', metadata=None)";
    let out = Command::new(py).args(["-c", script, s(&png), s(&tiff)]).output().unwrap();
    assert!(out.status.success(), "tifffile: {}", String::from_utf8_lossy(&out.stderr));
    // Each tile is a complete JPEG; a JFIF marker of its own is kept, not added twice.
    let has_jfif = stored_stream(&tiff, 0).windows(5).any(|w| w == b"JFIF\0");
    let crops = !subsampled(&stored_stream(&tiff, 0));
    check_dzi_copies(&tiff, (!has_jfif).then_some(Marker::Jfif), 80, crops);
}

/// Packs (border 0), IIIF and XYZ copy the same whole tiles; a grid that does not line up, a
/// border, an overlap or an explicit quality re-encode them and say why.
#[test]
fn other_layouts_copy_and_misfits_say_why() {
    if !have_vips() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let d = |name: &str| dir.path().join(name);
    let png = pattern_png(dir.path());
    let tiff = d("slide.tif");
    // At Q90 libvips writes RGB: the copies carry an Adobe marker.
    let tiled = ["--tile", "--tile-width", "128", "--tile-height", "128", "--compression", "jpeg", "--Q", "90"];
    tool("vips", &[&["tiffsave", s(&png), s(&tiff)], &tiled[..]].concat());

    let pack = d("slide.vtpk");
    let done = json(&["split", s(&tiff), "--pack", s(&pack), "--tile-size", "128", "--border", "0"]);
    assert_eq!(done["copied"], 6, "{done}");
    let p = vortex_pack::Pack::open(&pack).unwrap();
    for (x, y) in [(0, 0), (2, 1)] {
        let vortex_pack::Tile::Data(vortex_pack::TileKind::Jpeg, bytes) =
            p.tile(vortex_pack::TileId::new(0, x, y)).unwrap()
        else {
            panic!()
        };
        assert_copied(bytes, &stored_stream(&tiff, (y * 4 + x) as usize), Some(Marker::AdobeRgb), "pack");
    }
    // IIIF crops its edge tiles (RGB: cropped copies); XYZ pads them, as a pack does: encoded.
    for (layout, copied, cropped) in [("iiif", 12, 6), ("xyz", 6, 0)] {
        let out = d(layout);
        let done = json(&["split", s(&tiff), "-o", s(&out), "--layout", layout, "--tile-size", "128"]);
        assert_eq!((&done["copied"], &done["cropped"]), (&copied.into(), &cropped.into()), "{layout}: {done}");
    }

    let tiff240 = d("slide240.tif");
    let tiled240 = ["--tile", "--tile-width", "240", "--tile-height", "240", "--compression", "jpeg"];
    tool("vips", &[&["tiffsave", s(&png), s(&tiff240)], &tiled240[..]].concat());
    let misfits: [(&Path, &[&str], &str); 4] = [
        (&tiff240, &["--layout", "dzi", "--tile-size", "256", "--overlap", "0"], "not on the grid of 256-texel pages"),
        (&tiff, &["--layout", "dzi", "--tile-size", "128"], "a border (overlap) of 1"),
        (&tiff, &["--layout", "dzi", "--tile-size", "128", "--overlap", "0", "--quality", "80"], "--quality asked"),
        (&tiff, &["--layout", "xyz", "--tile-size", "128", "--codec", "png"], "the tiles are png"),
    ];
    for (i, (input, flags, why)) in misfits.into_iter().enumerate() {
        let out = d(&format!("misfit{i}"));
        let line = cli::ok(&[&["split", s(input), "-o", s(&out)], flags].concat());
        let said = line.split_once("re-encoded, not copied: ").map(|(_, said)| said);
        assert!(said.is_some_and(|said| said.contains(why)), "{flags:?}: {line}");
        let done = json(&[&["split", s(input), "-o", s(&out)], flags].concat());
        assert_eq!(done["copied"], 0, "{flags:?}: {done}");
        assert!(done["encoded"].as_u64().unwrap() > 0, "{flags:?}: {done}");
    }
}

/// Outputs of one pyramid that store other codecs: with `--filter box`, a pack (border 0) and
/// an OME-Zarr share the pyramid of a JPEG-tiled TIFF; the pack gets the stored tiles copied,
/// the OME-Zarr the same pages decoded, in zstd chunks, and each says what it got.
#[test]
fn copies_go_only_to_the_outputs_that_store_jpeg() {
    if !have_vips() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let d = |name: &str| dir.path().join(name);
    let png = pattern_png(dir.path());
    let tiff = d("slide.tif");
    let tiled = ["--tile", "--tile-width", "128", "--tile-height", "128", "--compression", "jpeg", "--Q", "90"];
    tool("vips", &[&["tiffsave", s(&png), s(&tiff)], &tiled[..]].concat());
    let (pack, zarr) = (d("slide.vtpk"), d("slide.ome.zarr"));
    let flags = ["--tile-size", "128", "--filter", "box", "--border", "0"];
    let done = json(&[&["split", s(&tiff), "--pack", s(&pack), "-o", s(&zarr)], &flags[..]].concat());
    assert_eq!(done["pyramids"], 1, "{done}");
    let output = |layout: &str| done["outputs"].as_array().unwrap().iter().find(|o| o["layout"] == layout).unwrap();
    let (p, z) = (output("pack"), output("ome-zarr"));
    assert_eq!((&p["copied"], &z["copied"]), (&6.into(), &0.into()), "{done}");
    assert_eq!(z["storedTiles"]["declined"], "the tiles are raw", "{done}");
    let p = vortex_pack::Pack::open(&pack).unwrap();
    let vortex_pack::Tile::Data(vortex_pack::TileKind::Jpeg, bytes) =
        p.tile(vortex_pack::TileId::new(0, 2, 1)).unwrap()
    else {
        panic!()
    };
    assert_copied(bytes, &stored_stream(&tiff, 6), Some(Marker::AdobeRgb), "pack");
    // The OME-Zarr alone is the same: its chunks are the decoded pages either way.
    let alone = d("alone.ome.zarr");
    cli::ok(&[&["split", s(&tiff), "-o", s(&alone)], &flags[..4]].concat());
    assert_eq!(files(&zarr), files(&alone));
}

/// `convert` copies too: the JPEG tiles of a Deep Zoom pyramid without overlap (vips dzsave's)
/// go into a pack of the same grid as the files they are; with overlap there is nothing to copy.
#[test]
fn convert_copies_jpeg_cells() {
    if !have_vips() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let d = |name: &str| dir.path().join(name);
    let png = pattern_png(dir.path());
    let dzi = |overlap: &str| {
        let base = d(&format!("dz{overlap}"));
        let flags = ["--tile-size", "128", "--overlap", overlap, "--suffix", ".jpeg[Q=80]"];
        tool("vips", &[&["dzsave", s(&png), s(&base)], &flags[..]].concat());
        base.with_extension("dzi")
    };
    let pack = d("from-dzi.vtpk");
    let done = json(&["convert", s(&dzi("0")), "--pack", s(&pack), "--tile-size", "128", "--border", "0"]);
    assert_eq!(done["copied"], 6, "{done}");
    assert_eq!(done["storedTiles"]["quality"], 80, "{done}");
    let p = vortex_pack::Pack::open(&pack).unwrap();
    for (x, y) in [(0, 0), (1, 1), (2, 0)] {
        let vortex_pack::Tile::Data(vortex_pack::TileKind::Jpeg, bytes) =
            p.tile(vortex_pack::TileId::new(0, x, y)).unwrap()
        else {
            panic!()
        };
        let file = std::fs::read(d(&format!("dz0_files/9/{x}_{y}.jpeg"))).unwrap();
        assert!(bytes == file, "tile {x},{y} is not vips's file");
    }
    let pack1 = d("from-dzi1.vtpk");
    let done = json(&["convert", s(&dzi("1")), "--pack", s(&pack1), "--tile-size", "128", "--border", "0"]);
    assert_eq!(done["copied"], 0, "{done}");
    assert!(done.get("storedTiles").is_none(), "{done}");
}

/// The next row of tiles decoded on the pool while this one's rows are read (issue 45) changes
/// no byte: a JPEG-tiled TIFF of 8 tile rows (RGB and YCbCr 4:2:0; the finest level copied,
/// the others made from the decoded tiles) makes the same pack with one pool thread and with three, and the same tile
/// directory as a run under a budget that leaves no room for a second row of tiles (and so cuts
/// it in stripes: a pack's order would differ, its tiles not).
#[test]
fn decoding_ahead_changes_no_byte() {
    if !have_vips() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let png = pattern_png_sized(dir.path(), 1000, 900);
    let tiled = ["--tile", "--tile-width", "128", "--tile-height", "128", "--compression", "jpeg"];
    for (name, quality) in [("rgb", "90"), ("ycbcr", "75")] {
        let tiff = dir.path().join(format!("{name}.tif"));
        tool("vips", &[&["tiffsave", s(&png), s(&tiff)], &tiled[..], &["--Q", quality]].concat());
        let mut outputs = Vec::new();
        // 2 MiB: a row of tiles is 375 KiB, two more than a quarter of it.
        let runs = [
            ("--pack", "--threads", "1"),
            ("--pack", "--threads", "3"),
            ("-o", "--threads", "2"),
            ("-o", "--max-memory", "2M"),
        ];
        for (run, (to, flag, value)) in runs.into_iter().enumerate() {
            let out = dir.path().join(format!("{name}-{run}"));
            let args = ["split", s(&tiff), to, s(&out), "--tile-size", "128", "--border", "0", flag, value];
            let doc = json(&args);
            let what = format!("{name} with {to} {flag} {value}: {doc}");
            let ahead = doc["source"].as_str().unwrap().contains("decoded ahead");
            assert_eq!(ahead, flag == "--threads", "{what}");
            assert!(doc["copied"].as_u64().unwrap() > 0 && doc["encoded"].as_u64().unwrap() > 0, "{what}");
            // The tiles are decoded on the pool, ahead or not: the `decode` stage.
            assert!(doc["stages"]["decodeSeconds"].as_f64().unwrap() > 0.0, "{what}");
            outputs.push(match to {
                "--pack" => BTreeMap::from([(String::new(), std::fs::read(&out).unwrap())]),
                _ => files(&out),
            });
        }
        assert!(outputs[0] == outputs[1], "{name}: the packs differ");
        assert!(outputs[2] == outputs[3], "{name}: the tile directories differ");
    }
}
