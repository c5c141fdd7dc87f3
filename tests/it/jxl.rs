//! JPEG XL tiles (`--codec jxl`, issue 46), checked with Debian's `djxl` (libjxl-tools) as the
//! outside decoder: every tile decodes to its size, lossless tiles hold exactly the texels of
//! the PNG tiles of the same run, a copied JPEG tile recompressed into JPEG XL gives the stored
//! JPEG back byte for byte, `convert` reads a JXL directory back, and what cannot hold JXL says
//! so. Outside CI a missing `djxl` (or `vips`, which makes the JPEG-tiled TIFF) skips with a note.

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::common::cli::{self, fixture, s};

fn have_djxl() -> bool {
    crate::common::have_program("djxl", "--version", "libjxl-tools")
}

/// Every file under `dir` ending `.ext`, sorted, as paths relative to `dir`.
fn files(dir: &Path, ext: &str) -> Vec<PathBuf> {
    fn walk(root: &Path, at: &Path, ext: &str, out: &mut Vec<PathBuf>) {
        for entry in std::fs::read_dir(at).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                walk(root, &path, ext, out);
            } else if path.extension().is_some_and(|e| e == ext) {
                out.push(path.strip_prefix(root).unwrap().to_path_buf());
            }
        }
    }
    let mut out = Vec::new();
    walk(dir, dir, ext, &mut out);
    out.sort();
    out
}

/// `djxl jxl out`: `Ok` if it wrote `out`, `Err` with its message if it refused.
fn djxl(jxl: &Path, out: &Path) -> Result<(), String> {
    let run = Command::new("djxl").arg(jxl).arg(out).output().unwrap();
    match run.status.success() && out.is_file() {
        true => Ok(()),
        false => Err(format!("{}: {}", jxl.display(), String::from_utf8_lossy(&run.stderr))),
    }
}

/// `jxl` decoded by `djxl` into a PNG, read back.
fn djxl_image(jxl: &Path, scratch: &Path) -> image::DynamicImage {
    let png = scratch.join("djxl-out.png");
    djxl(jxl, &png).unwrap();
    image::open(&png).unwrap()
}

/// A split of `input` with `args`, into `out`.
fn split(input: &Path, out: &Path, args: &[&str]) -> String {
    let mut all = vec!["split", s(input), "-o", s(out)];
    all.extend_from_slice(args);
    cli::ok(&all)
}

#[test]
fn every_tile_decodes_with_djxl_to_the_size_of_the_png_runs_tile() {
    if !have_djxl() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let input = fixture("sample.png");
    let layouts = [
        ("dir", &["--tile-size", "128"][..]),
        ("dzi", &["--layout", "dzi"][..]),
        ("iiif", &["--layout", "iiif", "--tile-size", "256"][..]),
        ("xyz", &["--layout", "xyz"][..]),
    ];
    for (name, layout) in layouts {
        let (jxl, png) = (tmp.path().join(format!("{name}-jxl")), tmp.path().join(format!("{name}-png")));
        split(&input, &jxl, &[layout, &["--codec", "jxl", "--quality", "80", "--jxl-effort", "3"]].concat());
        split(&input, &png, &[layout, &["--codec", "png"]].concat());
        let (tiles, pngs) = (files(&jxl, "jxl"), files(&png, "png"));
        assert_eq!(tiles.len(), pngs.len(), "{name}: one JXL tile for every PNG tile");
        assert!(tiles.len() > 4, "{name}: {} tiles", tiles.len());
        for (tile, png_tile) in tiles.iter().zip(&pngs) {
            assert_eq!(tile.with_extension("png"), *png_tile, "{name}: the same names");
            let theirs = djxl_image(&jxl.join(tile), tmp.path());
            let expected = image::open(png.join(png_tile)).unwrap();
            assert_eq!((theirs.width(), theirs.height()), (expected.width(), expected.height()), "{name}: {tile:?}");
            // Our own reader agrees on the size.
            let ours = vortex_jxl::decode(&std::fs::read(jxl.join(tile)).unwrap(), (4096, 4096)).unwrap();
            assert_eq!((ours.header.width, ours.header.height), (expected.width(), expected.height()));
        }
    }
    let dzi = std::fs::read_to_string(tmp.path().join("dzi-jxl/sample.dzi")).unwrap();
    assert!(dzi.contains(r#"Format="jxl""#), "{dzi}");
    let iiif: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(tmp.path().join("iiif-jxl/info.json")).unwrap()).unwrap();
    assert_eq!(
        (&iiif["preferredFormats"], &iiif["extraFormats"]),
        (&serde_json::json!(["jxl"]), &serde_json::json!(["jxl"]))
    );
    let tilejson = std::fs::read_to_string(tmp.path().join("xyz-jxl/tilejson.json")).unwrap();
    assert!(tilejson.contains("{z}/{x}/{y}.jxl"), "{tilejson}");
    let info = std::fs::read_to_string(tmp.path().join("dir-jxl/info.json")).unwrap();
    for member in [r#""codec": "jxl""#, r#""quality": 80"#, r#""jxlEffort": 3"#, ".jxl\""] {
        assert!(info.contains(member), "info.json lacks {member}: {info}");
    }
}

#[test]
fn lossless_tiles_hold_exactly_the_png_tiles_texels() {
    if !have_djxl() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    // RGB 8-bit, RGBA 8-bit and grey + alpha 16-bit: every layout JPEG XL keeps losslessly.
    for input in ["sample.png", "rgba8-130x67.png", "grey-alpha16-97x61.png"] {
        let (jxl, png) = (tmp.path().join(format!("{input}-jxl")), tmp.path().join(format!("{input}-png")));
        let tiles = ["--tile-size", "64", "--border", "2"];
        split(&fixture(input), &jxl, &[&tiles[..], &["--codec", "jxl", "--lossless"]].concat());
        split(&fixture(input), &png, &[&tiles[..], &["--codec", "png"]].concat());
        let names = files(&png, "png");
        assert!(!names.is_empty());
        for name in names {
            let jxl_tile = jxl.join(name.with_extension("jxl"));
            let expected = image::open(png.join(&name)).unwrap();
            let theirs = djxl_image(&jxl_tile, tmp.path());
            assert_eq!(theirs.color(), expected.color(), "{input} {name:?}: djxl's layout");
            assert!(theirs.as_bytes() == expected.as_bytes(), "{input} {name:?}: djxl's texels differ from the PNG's");
            // Our reader gives the same samples (native-endian 16-bit ones for 16-bit tiles).
            let ours = vortex_jxl::decode(&std::fs::read(&jxl_tile).unwrap(), (64, 64)).unwrap();
            let ours: Vec<u8> = match ours.samples {
                vortex_jxl::Samples::U8(v) => v,
                vortex_jxl::Samples::U16(v) => v.iter().flat_map(|x| x.to_ne_bytes()).collect(),
            };
            assert!(ours == expected.as_bytes(), "{input} {name:?}: our reader's texels differ from the PNG's");
        }
        let info = std::fs::read_to_string(jxl.join("info.json")).unwrap();
        assert!(info.contains(r#""lossless": true"#) && !info.contains("quality"), "{info}");
    }
}

#[test]
fn convert_reads_a_jxl_directory_back_texel_for_texel() {
    let tmp = tempfile::tempdir().unwrap();
    let (jxl, png, back) = (tmp.path().join("jxl"), tmp.path().join("png"), tmp.path().join("back"));
    let tiles = ["--tile-size", "64", "--border", "1", "--filter", "box"];
    split(&fixture("sample.png"), &jxl, &[&tiles[..], &["--codec", "jxl", "--lossless", "--jxl-effort", "1"]].concat());
    split(&fixture("sample.png"), &png, &[&tiles[..], &["--codec", "png"]].concat());
    cli::ok(&[&["convert", s(&jxl), "-o", s(&back), "--codec", "png"][..], &tiles[..]].concat());
    let names = files(&png, "png");
    assert_eq!(names, files(&back, "png"));
    for name in names {
        let (a, b) = (image::open(png.join(&name)).unwrap(), image::open(back.join(&name)).unwrap());
        assert!(a.as_bytes() == b.as_bytes(), "{name:?}: the converted lossless JXL pyramid differs");
    }
}

#[test]
fn recompressed_stored_jpeg_tiles_give_back_the_stored_jpeg_byte_for_byte() {
    if !have_djxl() || !crate::common::have_program("vips", "--version", "libvips-tools") {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let slide = tmp.path().join("slide.tif");
    let out = Command::new("vips")
        .args(["tiffsave", s(&fixture("sample.png")), s(&slide), "--tile", "--tile-width", "128"])
        .args(["--tile-height", "128", "--compression", "jpeg", "--Q", "85"])
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let (jpeg, jxl) = (tmp.path().join("jpeg"), tmp.path().join("jxl"));
    let grid = ["--layout", "dzi", "--overlap", "0", "--tile-size", "128", "--json"];
    // The JPEG run copies the stored tiles byte for byte (tests/it/copy_tiles.rs checks that).
    let copied: serde_json::Value = serde_json::from_str(&split(&slide, &jpeg, &grid)).unwrap();
    let report: serde_json::Value =
        serde_json::from_str(&split(&slide, &jxl, &[&grid[..], &["--codec", "jxl"]].concat())).unwrap();
    let stored = &report["storedTiles"];
    let recompressed = &stored["recompressed"];
    assert_eq!(stored["copied"], copied["storedTiles"]["copied"], "{report}");
    assert_eq!(recompressed["tiles"], stored["copied"], "{report}");
    assert_eq!(recompressed["refused"], 0, "{report}");
    let level = "slide_files/10";
    let (mut rebuilt, mut jpeg_bytes, mut jxl_bytes) = (0, 0, 0);
    for name in files(&jxl.join(level), "jxl") {
        let tile = jxl.join(level).join(&name);
        let back = tmp.path().join("back.jpg");
        let _ = std::fs::remove_file(&back);
        // A page encoded from texels has no JPEG to rebuild (djxl would encode its pixels as a
        // new JPEG); a recompressed one carries libjxl's reconstruction data, the `jbrd` box.
        let bytes = std::fs::read(&tile).unwrap();
        if !bytes.windows(4).any(|w| w == b"jbrd") {
            continue;
        }
        djxl(&tile, &back).unwrap();
        let original = std::fs::read(jpeg.join(level).join(name.with_extension("jpeg"))).unwrap();
        assert!(std::fs::read(&back).unwrap() == original, "{name:?}: djxl's JPEG is not the stored one");
        (rebuilt, jpeg_bytes, jxl_bytes) =
            (rebuilt + 1, jpeg_bytes + original.len(), jxl_bytes + tile.metadata().unwrap().len());
    }
    assert!(rebuilt > 0 && rebuilt == recompressed["tiles"].as_u64().unwrap(), "{rebuilt} rebuilt: {report}");
    assert_eq!(recompressed["jpegBytes"].as_u64(), Some(jpeg_bytes as u64));
    assert_eq!(recompressed["jxlBytes"].as_u64(), Some(jxl_bytes));
    assert!(jxl_bytes < jpeg_bytes as u64, "recompression saved nothing: {jxl_bytes} >= {jpeg_bytes}");
    let line = split(
        &slide,
        &tmp.path().join("line"),
        &["--layout", "dzi", "--overlap", "0", "--tile-size", "128", "--codec", "jxl"],
    );
    assert!(line.contains("recompressed losslessly into JPEG XL") && line.contains("saved"), "{line}");
}

#[test]
fn what_cannot_hold_jxl_and_flags_that_do_not_fit_are_clear_errors() {
    let tmp = tempfile::tempdir().unwrap();
    let input = fixture("sample.png");
    let out = |name: &str| tmp.path().join(name);
    let run = |args: &[&str]| cli::run(&[&["split", s(&input)], args].concat());
    let cases: Vec<(Vec<String>, Vec<&str>)> = vec![
        (vec!["-o".into(), s(&out("a")).into(), "--lossless".into()], vec!["--lossless is JPEG XL's", "--codec jxl"]),
        (
            vec!["-o".into(), s(&out("b")).into(), "--codec".into(), "png".into(), "--jxl-effort".into(), "3".into()],
            vec!["--jxl-effort is JPEG XL's", "lossless already"],
        ),
        (
            vec![
                "-o".into(),
                s(&out("c")).into(),
                "--codec".into(),
                "jxl".into(),
                "--lossless".into(),
                "--quality".into(),
                "80".into(),
            ],
            vec!["--lossless", "--quality"],
        ),
        (
            vec!["-o".into(), s(&out("d")).into(), "--codec".into(), "jxl".into(), "--jxl-effort".into(), "12".into()],
            vec!["effort 12", "1..=9", "--jxl-effort"],
        ),
        (
            vec![
                "-o".into(),
                s(&out("e")).into(),
                "--codec".into(),
                "jxl".into(),
                "--subsampling".into(),
                "444".into(),
            ],
            vec!["--subsampling is JPEG's"],
        ),
        (
            vec![
                "-o".into(),
                s(&out("f")).into(),
                "--layout".into(),
                "iiif".into(),
                "--codec".into(),
                "jxl".into(),
                "--iiif-id".into(),
                "https://example.org/iiif/x".into(),
            ],
            vec!["--iiif-id", "required format is JPEG"],
        ),
        (
            vec!["--pmtiles".into(), s(&out("g.pmtiles")).into(), "--codec".into(), "jxl".into()],
            vec!["PMTiles archive cannot declare JPEG XL", "--layout dzi, iiif or xyz"],
        ),
        (
            vec!["--pack".into(), s(&out("h.vtpk")).into(), "--codec".into(), "jxl".into()],
            vec!["packs do not hold JPEG XL tiles yet"],
        ),
        (
            vec!["-o".into(), s(&out("i.tif")).into(), "--codec".into(), "jxl".into()],
            vec!["--codec jxl", "TIFF tiles are"],
        ),
    ];
    for (args, needles) in cases {
        let args: Vec<&str> = args.iter().map(String::as_str).collect();
        cli::fails_with(&run(&args), &needles);
    }
    // Nothing was left behind by the refused runs.
    assert_eq!(std::fs::read_dir(tmp.path()).unwrap().count(), 0);
}

#[test]
fn a_corrupt_or_truncated_jxl_tile_is_an_error_naming_it() {
    let tmp = tempfile::tempdir().unwrap();
    let dir = tmp.path().join("jxl");
    split(&fixture("sample.png"), &dir, &["--tile-size", "64", "--codec", "jxl", "--lossless", "--jxl-effort", "1"]);
    let tile = dir.join("lod00-x0001-y0002.jxl");
    let whole = std::fs::read(&tile).unwrap();
    let mut garbage = whole.clone();
    for b in garbage.iter_mut().skip(16) {
        *b = b.wrapping_mul(31).wrapping_add(7);
    }
    for (what, bytes) in [("truncated", whole[..whole.len() / 3].to_vec()), ("corrupt", garbage)] {
        std::fs::write(&tile, &bytes).unwrap();
        let out = cli::run(&["convert", s(&dir), "-o", s(&tmp.path().join(format!("out-{what}"))), "--codec", "png"]);
        // Debian's libjxl 0.7 prints its own trace of the failure (`./lib/jxl/decode.cc:...`)
        // to standard error first; our message is the line that starts with `error: `.
        let err = String::from_utf8_lossy(&out.stderr);
        assert_eq!(out.status.code(), Some(1), "{what}: {err}");
        assert!(!err.contains("panicked"), "{what}: {err}");
        let line = err.lines().find(|l| l.starts_with("error: ")).unwrap_or_else(|| panic!("{what}: {err}"));
        assert!(line.contains("lod00-x0001-y0002.jxl") && line.contains("JPEG XL"), "{what}: {line}");
    }
}
