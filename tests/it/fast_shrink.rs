//! `--fast-shrink` (issue 45): the finest level is the stored JPEG tiles, as an exact run's is;
//! the first reduced level is made from those tiles decoded at half size by libjpeg's scaled
//! inverse DCT, which libjpeg-turbo's own `djpeg -scale 1/2` (and `cjpeg`, encoding the page)
//! is the outside oracle of.
//!
//! The JPEG TIFFs are libvips' (`vips tiffsave --tile --compression jpeg`, YCbCr 4:2:0 at Q85,
//! shared JPEGTables), as in `copy_tiles`.

use std::path::Path;

use crate::common::cli::{self, s};
use crate::common::compare::{Picture, Tolerance, assert_close};
use crate::copy_tiles::{files, have_vips, pattern_png_sized, tool};

/// A libvips JPEG TIFF of the pattern at `w x h`, in 128-texel tiles at Q85 (YCbCr 4:2:0).
fn jpeg_tiff(dir: &Path, size: (u32, u32)) -> std::path::PathBuf {
    jpeg_tiff_at(dir, size, "85")
}

/// [`jpeg_tiff`] at `quality`: YCbCr 4:2:0 below 90, RGB (an Adobe marker in the copies) from 90.
fn jpeg_tiff_at(dir: &Path, (w, h): (u32, u32), quality: &str) -> std::path::PathBuf {
    let png = pattern_png_sized(dir, w, h);
    let tiff = dir.join(format!("slide-{w}x{h}-q{quality}.tif"));
    let tiled = ["--tile", "--tile-width", "128", "--tile-height", "128", "--compression", "jpeg", "--Q", quality];
    tool("vips", &[&["tiffsave", s(&png), s(&tiff)], &tiled[..]].concat());
    tiff
}

/// Splits `tiff` into a tile directory of 128-texel pages, border 0, with `extra` flags.
fn split(tiff: &Path, out: &Path, extra: &[&str]) -> serde_json::Value {
    // Deep Zoom names its border the overlap.
    let border: &[&str] = if extra.contains(&"--layout") { &[] } else { &["--border", "0"] };
    let args = [&["split", s(tiff), "-o", s(out), "--tile-size", "128", "--json"], border, extra].concat();
    serde_json::from_str(&cli::ok(&args)).unwrap()
}

/// The tile files of level `lod` of a tile directory, by name.
fn level(all: &std::collections::BTreeMap<String, Vec<u8>>, lod: u32) -> Vec<(&String, &Vec<u8>)> {
    let prefix = format!("lod{lod:02}-");
    all.iter().filter(|(name, _)| name.starts_with(&prefix)).collect()
}

/// An RGB JPEG file's texels, as `djpeg` decodes it at `scale` (`1/1`, `1/2`): width, height and
/// samples.
fn djpeg(jpeg: &[u8], scale: &str, scratch: &Path) -> (u32, u32, Vec<u8>) {
    std::fs::write(scratch, jpeg).unwrap();
    let out = std::process::Command::new("djpeg").args(["-scale", scale, "-ppm", s(scratch)]).output().unwrap();
    assert!(out.status.success(), "djpeg: {}", String::from_utf8_lossy(&out.stderr));
    let image = image::load_from_memory(&out.stdout).unwrap().to_rgb8();
    (image.width(), image.height(), image.into_raw())
}

fn decode(jpeg: &[u8]) -> Vec<u8> {
    image::load_from_memory(jpeg).unwrap().to_rgb8().into_raw()
}

/// On a 1024x768 slide every page of LOD 0 is a stored tile: the fast run's LOD 0 is the exact
/// run's, byte for byte, and each LOD 1 page is the four tiles under it as `djpeg -scale 1/2`
/// decodes them, encoded as `cjpeg` encodes them.
#[test]
fn the_first_reduced_level_is_the_stored_tiles_at_half_size() {
    halves_as_djpeg_does("85");
}

/// The same for RGB tiles, as libvips stores them from Q90 on (no chroma subsampling, an Adobe
/// marker in the copied files).
#[test]
fn rgb_tiles_are_halved_as_djpeg_halves_them() {
    halves_as_djpeg_does("95");
}

fn halves_as_djpeg_does(quality: &str) {
    let libjpeg = ["djpeg", "cjpeg"].iter().all(|p| crate::common::have_program(p, "-version", "libjpeg-turbo-progs"));
    if !have_vips() || !libjpeg {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let tiff = jpeg_tiff_at(dir.path(), (1024, 768), quality);
    let (exact_dir, fast_dir) = (dir.path().join("exact"), dir.path().join("fast"));
    let exact = split(&tiff, &exact_dir, &[]);
    let fast = split(&tiff, &fast_dir, &["--fast-shrink"]);
    let (exact_files, fast_files) = (files(&exact_dir), files(&fast_dir));
    assert_eq!(level(&fast_files, 0), level(&exact_files, 0), "LOD 0 is the stored tiles in both runs");
    assert_eq!(level(&fast_files, 0).len(), 48);
    assert_eq!(fast["copied"], 48, "{fast}");
    assert_eq!(
        (fast["storedTiles"]["halved"].as_bool(), exact["storedTiles"]["halved"].as_bool()),
        (Some(true), Some(false))
    );
    assert_eq!(fast["tiles"], exact["tiles"]);

    let scratch = dir.path().join("tile.jpg");
    let lod0 = |x: u32, y: u32| &fast_files[&format!("lod00-x{x:04}-y{y:04}.jpg")];
    for (x, y) in (0..3).flat_map(|y| (0..4).map(move |x| (x, y))) {
        // The oracle: the four stored tiles under the page, each halved by djpeg, side by side.
        let mut want = vec![0u8; 128 * 128 * 3];
        for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
            let (w, h, half) = djpeg(lod0(2 * x + dx, 2 * y + dy), "1/2", &scratch);
            assert_eq!((w, h), (64, 64));
            for r in 0..64 {
                let at = ((dy * 64 + r) * 128 + dx * 64) as usize * 3;
                want[at..at + 64 * 3].copy_from_slice(&half[r as usize * 64 * 3..][..64 * 3]);
            }
        }
        // Encoded as the run encodes a page (libjpeg at Q85, 4:2:0: cjpeg's defaults) and
        // decoded again.
        let ppm = dir.path().join("want.ppm");
        std::fs::write(&ppm, [&b"P6\n128 128\n255\n"[..], &want].concat()).unwrap();
        let out = std::process::Command::new("cjpeg").args(["-quality", "85", s(&ppm)]).output().unwrap();
        assert!(out.status.success(), "cjpeg: {}", String::from_utf8_lossy(&out.stderr));
        let want = decode(&out.stdout);
        let got = decode(&fast_files[&format!("lod01-x{x:04}-y{y:04}.jpg")]);
        assert_close(
            &format!("fast-shrink-q{quality}-lod1-{x}-{y}"),
            Picture::new(128, 128, 3, &got),
            Picture::new(128, 128, 3, &want),
            Tolerance::max(
                0,
                "the same texels through the same libjpeg code at the same quality and \
                 subsampling (mozjpeg's fastest profile is libjpeg-turbo's, which cjpeg is): the \
                 same coefficients, the same texels; a page halved wrongly (shifted a texel, its \
                 tiles misplaced, chroma swapped) differs by dozens of levels",
            ),
        );
        // Against the exact pyramid's page: what the approximation costs, bounded loosely
        // (docs/accuracy.md measures it).
        let exact_page = decode(&exact_files[&format!("lod01-x{x:04}-y{y:04}.jpg")]);
        assert_close(
            &format!("fast-shrink-q{quality}-vs-exact-lod1-{x}-{y}"),
            Picture::new(128, 128, 3, &got),
            Picture::new(128, 128, 3, &exact_page),
            Tolerance::mean(
                4.0,
                "the scaled inverse DCT is a low-pass close to the 2x2 box the exact run averages \
                 with, on the pattern's noise and its x^y edges; a wrong level is far off",
            ),
        );
    }
}

/// Where a page cannot be copied (the padded edge pages of a tile directory, an edge page Deep
/// Zoom crops off the JPEG block grid) it is cut from its stored tile decoded whole: the same
/// page, encoded alike, as the exact run's.
#[test]
fn pages_it_cannot_copy_are_cut_from_the_decoded_tile() {
    if !have_vips() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let tiff = jpeg_tiff(dir.path(), (1000, 700));
    for (name, extra) in [
        ("edge", &[][..]),
        ("colour", &["--background", "#ff8000"][..]),
        ("dzi", &["--layout", "dzi", "--overlap", "0"][..]),
    ] {
        let (exact_dir, fast_dir) = (dir.path().join(format!("exact-{name}")), dir.path().join(format!("fast-{name}")));
        split(&tiff, &exact_dir, extra);
        let fast = split(&tiff, &fast_dir, &[extra, &["--fast-shrink"]].concat());
        let (exact_files, fast_files) = (files(&exact_dir), files(&fast_dir));
        let finest = |all: &std::collections::BTreeMap<String, Vec<u8>>| -> Vec<(String, Vec<u8>)> {
            match name {
                // Deep Zoom's finest level is the highest-numbered folder: 10 for 1000 texels.
                "dzi" => {
                    all.iter().filter(|(n, _)| n.contains("_files/10/")).map(|(n, b)| (n.clone(), b.clone())).collect()
                }
                _ => level(all, 0).into_iter().map(|(n, b)| (n.clone(), b.clone())).collect(),
            }
        };
        let (exact_finest, fast_finest) = (finest(&exact_files), finest(&fast_files));
        assert_eq!(exact_finest.len(), 48, "{name}");
        assert!(fast_finest == exact_finest, "{name}: the finest level differs from the exact run's");
        assert!(fast["encoded"].as_u64().unwrap() > 0, "{name}: {fast}");
        // Every level is written: the same files, named alike.
        let names = |all: &std::collections::BTreeMap<String, Vec<u8>>| all.keys().cloned().collect::<Vec<_>>();
        assert_eq!(names(&fast_files), names(&exact_files), "{name}");
    }
}

/// What it cannot do is refused before anything is written, saying why.
#[test]
fn runs_that_cannot_copy_the_finest_level_are_refused() {
    if !have_vips() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let tiff = jpeg_tiff(dir.path(), (400, 300));
    let png = dir.path().join("pattern-1000x700.png");
    let png = if png.exists() { png } else { pattern_png_sized(dir.path(), 1000, 700) };
    let out = dir.path().join("out");
    let base =
        |input: &Path| vec!["split".to_string(), s(input).into(), "-o".into(), s(&out).into(), "--fast-shrink".into()];
    for (input, extra, says) in [
        (&png, &[][..], &["--fast-shrink: the source stores no JPEG tiles", "JPEG-tiled TIFFs"][..]),
        (&tiff, &["--tile-size", "128", "--border", "2"][..], &["does not copy them", "border"][..]),
        (&tiff, &["--tile-size", "256", "--border", "0"][..], &["does not copy them", "256-texel pages"][..]),
        (&tiff, &["--tile-size", "128", "--border", "0", "--codec", "png"][..], &["does not copy them"][..]),
        (
            &tiff,
            &["--tile-size", "128", "--border", "0", "--quality", "70"][..],
            &["does not copy them", "--quality"][..],
        ),
    ] {
        let mut args = base(input);
        args.extend(extra.iter().map(|a| a.to_string()));
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        cli::fails_with(&cli::run(&args), says);
        assert!(!out.exists(), "{args:?} left an output");
    }
}

/// A pack (the ordered sink, which stores the finest pages first here): its finest level, unpacked,
/// is the exact run's; every other level is there.
#[test]
fn a_pack_holds_the_stored_tiles_and_every_level() {
    if !have_vips() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let tiff = jpeg_tiff(dir.path(), (1000, 700));
    let mut unpacked = Vec::new();
    for (name, extra) in [("exact", &[][..]), ("fast", &["--fast-shrink"][..])] {
        let pack = dir.path().join(format!("{name}.vtpk"));
        let args =
            [&["split", s(&tiff), "--pack", s(&pack), "--tile-size", "128", "--border", "0", "-q"], extra].concat();
        cli::ok(&args);
        let out = dir.path().join(format!("{name}-unpacked"));
        cli::ok(&["unpack", s(&pack), "-o", s(&out), "-q"]);
        unpacked.push(files(&out));
    }
    let names = |all: &std::collections::BTreeMap<String, Vec<u8>>| all.keys().cloned().collect::<Vec<_>>();
    assert_eq!(names(&unpacked[1]), names(&unpacked[0]), "the same tiles");
    assert_eq!(level(&unpacked[1], 0), level(&unpacked[0], 0), "LOD 0 is the exact run's");
    assert_eq!(level(&unpacked[1], 0).len(), 48);
}

/// A copied page of one colour is a pack's constant, as in a run that encodes every page (the
/// oracle: it finds constants in the texels it cut): a run whose finest level needs no texel
/// must still look at them where a sink stores such pages as their colour.
#[test]
fn a_copied_page_of_one_colour_is_still_a_packs_constant() {
    if !have_vips() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let png = pattern_png_sized(dir.path(), 640, 384);
    let (black, flat, both) = (dir.path().join("black.v"), dir.path().join("flat.v"), dir.path().join("both.v"));
    tool("vips", &["black", s(&black), "256", "256", "--bands", "3"]);
    tool("vips", &["linear", s(&black), s(&flat), "1", "240", "--uchar"]);
    tool("vips", &["insert", s(&png), s(&flat), s(&both), "128", "128"]);
    let tiff = dir.path().join("flat.tif");
    let tiled = ["--tile", "--tile-width", "128", "--tile-height", "128", "--compression", "jpeg", "--Q", "90"];
    tool("vips", &[&["tiffsave", s(&both), s(&tiff)], &tiled[..]].concat());
    let pack = |name: &str, extra: &[&str]| -> serde_json::Value {
        let out = dir.path().join(name);
        let args =
            [&["split", s(&tiff), "--pack", s(&out), "--tile-size", "128", "--border", "0", "--json"], extra].concat();
        serde_json::from_str(&cli::ok(&args)).unwrap()
    };
    let copied = pack("copied.vtpk", &[]);
    let encoded = pack("encoded.vtpk", &["--quality", "90"]);
    assert!(copied["copied"].as_u64() > Some(0), "{copied}");
    assert!(encoded["pack"]["constant"].as_u64() >= Some(4), "the flat 256² block's 4 pages: {encoded}");
    assert_eq!(copied["pack"]["constant"], encoded["pack"]["constant"], "{copied}\n{encoded}");
}
