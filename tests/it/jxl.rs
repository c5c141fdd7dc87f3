//! JPEG XL tiles (`--codec jxl`, issue 46), checked with Debian's `djxl` (libjxl-tools) as the
//! outside decoder: every tile decodes to its size, lossless tiles hold exactly the texels of
//! the PNG tiles of the same run, a copied JPEG tile recompressed into JPEG XL gives the stored
//! JPEG back byte for byte, `convert` reads a JXL directory back, and what cannot hold JXL says
//! so. Outside CI a missing `djxl` (or `vips`, which makes the JPEG-tiled TIFF) skips with a note.

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::common::cli::{self, fixture, s};
use crate::common::server::Server;

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

/// sample.png as libvips writes a JPEG-tiled TIFF (128-texel tiles, Q85, shared tables, and
/// `extra` flags) in `dir`; `None` (after a note, or a failure under CI) without djxl or vips.
fn vips_jpeg_tiff(dir: &Path, extra: &[&str]) -> Option<PathBuf> {
    if !have_djxl() || !crate::common::have_program("vips", "--version", "libvips-tools") {
        return None;
    }
    let slide = dir.join("slide.tif");
    let out = Command::new("vips")
        .args(["tiffsave", s(&fixture("sample.png")), s(&slide), "--tile", "--tile-width", "128"])
        .args(["--tile-height", "128", "--compression", "jpeg", "--Q", "85"])
        .args(extra)
        .output()
        .unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    Some(slide)
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
    let tmp = tempfile::tempdir().unwrap();
    let Some(slide) = vips_jpeg_tiff(tmp.path(), &[]) else { return };
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

/// The fixture `input` split twice with `grid` (`flag`: `-o` or `--pack`): into `jxl` as
/// lossless JPEG XL (effort 1) and into `other` with `--codec codec`, the same pyramid.
fn lossless_and(input: &str, flag: &str, (jxl, other): (&Path, &Path), grid: &[&str], codec: &str) {
    let run =
        |out: &Path, how: &[&str]| cli::ok(&[&["split", s(&fixture(input)), flag, s(out)][..], grid, how].concat());
    run(jxl, &["--codec", "jxl", "--lossless", "--jxl-effort", "1"]);
    run(other, &["--codec", codec]);
}

/// Every tile of `pack` as RGBA8 (`vortex_pack`'s decoders: jxl-oxide for JPEG XL tiles),
/// with its id, absent tiles left out.
fn pack_tiles(pack: &Path) -> Vec<(vortex_pack::TileId, Vec<u8>)> {
    let pack = vortex_pack::Pack::open(pack).unwrap();
    let mut out = Vec::new();
    for (lod, level) in pack.levels().iter().enumerate() {
        for y in 0..level.tiles_h {
            for x in 0..level.tiles_w {
                let id = vortex_pack::TileId::new(lod as u32, x, y);
                if let Some(rgba) = pack.decode_rgba8(id).unwrap() {
                    out.push((id, rgba));
                }
            }
        }
    }
    out
}

#[test]
fn a_jxl_pack_holds_lossless_tiles_and_recompressed_stored_jpegs() {
    let tmp = tempfile::tempdir().unwrap();
    // Lossless: the pack's JPEG XL tiles decode (by jxl-oxide, the runtimes' decoder) to the
    // PNG pack's texels, and libjxl (`convert`) reads them back as the PNG pack's pyramid.
    for input in ["sample.png", "rgba8-130x67.png", "grey-alpha16-97x61.png"] {
        let (jxl, png) = (tmp.path().join(format!("{input}.jxl.vtpk")), tmp.path().join(format!("{input}.png.vtpk")));
        let tiles = ["--tile-size", "64", "--border", "2"];
        lossless_and(input, "--pack", (&jxl, &png), &tiles, "png");
        let p = vortex_pack::Pack::open(&jxl).unwrap();
        assert_eq!(p.header().required_features & vortex_pack::format::REQUIRED_JXL, vortex_pack::format::REQUIRED_JXL);
        let (ours, theirs) = (pack_tiles(&jxl), pack_tiles(&png));
        assert!(ours.len() > 2 && ours.len() == theirs.len(), "{input}");
        for ((id, a), (_, b)) in ours.iter().zip(&theirs) {
            assert!(a == b, "{input} {id:?}: the JPEG XL tile differs from the PNG tile");
        }
        let verified = cli::ok(&["verify", s(&jxl), "--decode"]);
        assert!(verified.contains("jxl"), "{verified}");
        // `unpack` writes the tiles out as .jxl files and `pack` stores them again, as they were.
        let (files_dir, again) =
            (tmp.path().join(format!("{input}-files")), tmp.path().join(format!("{input}-again.vtpk")));
        cli::ok(&["unpack", s(&jxl), "-o", s(&files_dir)]);
        assert!(!files(&files_dir, "jxl").is_empty());
        cli::ok(&["pack", s(&files_dir), "-o", s(&again)]);
        let a = vortex_pack::Pack::open(&jxl).unwrap();
        let b = vortex_pack::Pack::open(&again).unwrap();
        assert!(
            a.ids().all(|id| a.tile(id).unwrap() == b.tile(id).unwrap()),
            "{input}: pack -> unpack -> pack changed a tile"
        );
        let (a, b) = (tmp.path().join(format!("{input}-a")), tmp.path().join(format!("{input}-b")));
        cli::ok(&["convert", s(&jxl), "-o", s(&a), "--codec", "png"]);
        cli::ok(&["convert", s(&png), "-o", s(&b), "--codec", "png"]);
        for name in files(&b, "png") {
            let (x, y) = (image::open(a.join(&name)).unwrap(), image::open(b.join(&name)).unwrap());
            assert!(x.as_bytes() == y.as_bytes(), "{input} {name:?}: converted back through libjxl, it differs");
        }
    }

    // A JPEG-tiled TIFF's stored tiles: the JPEG pack copies them, the JPEG XL pack holds each
    // recompressed, from which djxl gives the same JPEG back.
    let Some(slide) = vips_jpeg_tiff(tmp.path(), &[]) else { return };
    let (jpeg, jxl) = (tmp.path().join("slide.jpeg.vtpk"), tmp.path().join("slide.jxl.vtpk"));
    let grid = ["--border", "0", "--tile-size", "128", "--json"];
    cli::ok(&[&["split", s(&slide), "--pack", s(&jpeg)][..], &grid].concat());
    let report: serde_json::Value = serde_json::from_str(&cli::ok(
        &[&["split", s(&slide), "--pack", s(&jxl)][..], &grid, &["--codec", "jxl"]].concat(),
    ))
    .unwrap();
    let recompressed = &report["storedTiles"]["recompressed"];
    assert!(recompressed["tiles"].as_u64().unwrap() > 0, "{report}");
    let (jpeg, jxl) = (vortex_pack::Pack::open(&jpeg).unwrap(), vortex_pack::Pack::open(&jxl).unwrap());
    let mut rebuilt = 0;
    for (x, y) in (0..jxl.levels()[0].tiles_w).flat_map(|x| (0..jxl.levels()[0].tiles_h).map(move |y| (x, y))) {
        let id = vortex_pack::TileId::new(0, x, y);
        let vortex_pack::Tile::Data(vortex_pack::TileKind::Jxl, bytes) = jxl.tile(id).unwrap() else {
            panic!("{id:?}")
        };
        if !bytes.windows(4).any(|w| w == b"jbrd") {
            continue;
        }
        let (tile, back) = (tmp.path().join("tile.jxl"), tmp.path().join("tile.jpg"));
        std::fs::write(&tile, bytes).unwrap();
        let _ = std::fs::remove_file(&back);
        djxl(&tile, &back).unwrap();
        let vortex_pack::Tile::Data(vortex_pack::TileKind::Jpeg, original) = jpeg.tile(id).unwrap() else { panic!() };
        assert!(std::fs::read(&back).unwrap() == original, "{id:?}: djxl's JPEG is not the stored one");
        rebuilt += 1;
    }
    assert_eq!(Some(rebuilt), recompressed["tiles"].as_u64(), "{report}");
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

#[test]
fn serve_hands_out_a_jxl_pack_s_tiles_as_jpeg_xl() {
    let tmp = tempfile::tempdir().unwrap();
    // sample.png (700 x 500) in 64-texel pages with a border of 1: Deep Zoom tiles of 62, the
    // edge ones cropped, the levels below the last LOD halved (tests/it/serve.rs has the grid).
    let (jxl, png) = (tmp.path().join("world.vtpk"), tmp.path().join("png").join("world.vtpk"));
    std::fs::create_dir(tmp.path().join("png")).unwrap();
    let grid = ["--tile-size", "64", "--border", "1", "-q"];
    lossless_and("sample.png", "--pack", (&jxl, &png), &grid, "png");
    let (server, png_server) = (Server::start(&[&jxl], &[]), Server::start(&[&png], &[]));

    let dzi = server.get("/world.dzi", &[]).text();
    assert!(dzi.contains(r#"Format="jxl" Overlap="1" TileSize="62""#), "{dzi}");
    // An interior page is sent as stored.
    let pack = vortex_pack::Pack::open(&jxl).unwrap();
    let vortex_pack::Tile::Data(vortex_pack::TileKind::Jxl, stored) =
        pack.tile(vortex_pack::TileId::new(0, 3, 2)).unwrap()
    else {
        panic!("a JPEG XL page")
    };
    let tile = server.get("/world_files/10/3_2.jxl", &[]);
    assert_eq!((tile.status, tile.header("content-type")), (200, Some("image/jxl")));
    assert!(tile.body == stored, "the interior tile is not the stored payload");
    // Cropped edge tiles and halved levels are encoded again, losslessly as the pack was: the
    // texels of the PNG pack's served tiles.
    for (path, size) in [("10/11_8", (19, 5)), ("10/0_0", (63, 63)), ("5/0_0", (22, 16)), ("0/0_0", (1, 1))] {
        let reply = server.get(&format!("/world_files/{path}.jxl"), &[]);
        assert_eq!((reply.status, reply.header("content-type")), (200, Some("image/jxl")), "{path}");
        let ours = vortex_jxl::decode(&reply.body, (64, 64)).unwrap();
        assert_eq!((ours.header.width, ours.header.height), size, "{path}");
        let expected = image::load_from_memory(&png_server.get(&format!("/world_files/{path}.png"), &[]).body).unwrap();
        let vortex_jxl::Samples::U8(texels) = ours.samples else { panic!("8-bit") };
        assert!(texels == expected.as_bytes(), "{path}: the served JPEG XL tile differs from the PNG one");
    }
    // IIIF and XYZ name their tiles .jxl; the other extensions are not there.
    assert_eq!(server.get("/world/iiif/full/44,32/0/default.jxl", &[]).status, 200);
    assert_eq!(server.get("/world/xyz/0/0/0.jxl", &[]).status, 200);
    assert_eq!(server.get("/world_files/10/3_2.jpeg", &[]).status, 404);
}

/// tifffile (with imagecodecs' libjxl) reads every level of the TIFF named and prints, per
/// level, its compression and its samples' digest; with `tiles`, it also writes level 0's raw
/// tiles to `DIR/x_y.jxl`.
const TIFF_PAGES: &str = r#"
import hashlib, json, sys, tifffile
path, tiles = sys.argv[1], sys.argv[2] if len(sys.argv) > 2 else None
with tifffile.TiffFile(path) as t:
    # An OME-TIFF's levels are SubIFDs of its first page: the series' levels find both kinds.
    levels = t.series[0].levels if len(t.series[0].levels) > 1 else t.pages
    for level in levels:
        a = level.asarray()
        print(json.dumps({"compression": int(level.keyframe.compression), "shape": list(a.shape),
                          "dtype": str(a.dtype), "sha": hashlib.sha256(a.tobytes()).hexdigest()}))
    if tiles:
        page = t.pages[0]
        across = -(-page.imagewidth // page.tilewidth)
        for i, (at, n) in enumerate(zip(page.dataoffsets, page.databytecounts)):
            t.filehandle.seek(at)
            with open(f"{tiles}/{i % across}_{i // across}.jxl", "wb") as f:
                f.write(t.filehandle.read(n))
"#;

/// What [`TIFF_PAGES`] says of `tiff`, a JSON object a page.
fn tiff_pages(python: &Path, tiff: &Path, tiles: Option<&Path>) -> Vec<serde_json::Value> {
    let mut args = vec!["-c", TIFF_PAGES, s(tiff)];
    args.extend(tiles.map(s));
    let out = Command::new(python).args(&args).output().unwrap();
    assert!(out.status.success(), "{}: {}", tiff.display(), String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stdout).lines().map(|l| serde_json::from_str(l).unwrap()).collect()
}

#[test]
fn a_jxl_tiff_is_what_tifffile_reads_and_holds_the_stored_jpegs_recompressed() {
    let Some(python) =
        crate::common::python_with("tifffile, imagecodecs", "the JPEG XL TIFF test", "tifffile and imagecodecs")
    else {
        return;
    };
    let tmp = tempfile::tempdir().unwrap();
    // Lossless JPEG XL levels (compression 50002, as tifffile and libvips write it) hold the
    // samples of the Deflate file of the same pyramid, page for page: RGB, RGBA, 16-bit grey
    // with alpha; generic and OME-TIFF.
    for (input, ext) in [("sample.png", "tif"), ("rgba8-130x67.png", "tif"), ("grey-alpha16-97x61.png", "ome.tif")] {
        let (jxl, deflate) =
            (tmp.path().join(format!("{input}.jxl.{ext}")), tmp.path().join(format!("{input}.deflate.{ext}")));
        let grid = ["--tile-size", "64", "-q"];
        lossless_and(input, "-o", (&jxl, &deflate), &grid, "deflate");
        let (ours, theirs) = (tiff_pages(&python, &jxl, None), tiff_pages(&python, &deflate, None));
        assert!(ours.len() > 1 && ours.len() == theirs.len(), "{input}: {ours:?}");
        for (a, b) in ours.iter().zip(&theirs) {
            assert_eq!(a["compression"], 50002, "{input}");
            assert_eq!(
                (&a["shape"], &a["dtype"], &a["sha"]),
                (&b["shape"], &b["dtype"], &b["sha"]),
                "{input}: a level differs"
            );
        }
    }

    // A JPEG-tiled TIFF's stored tiles: each tile of the JPEG XL file's full resolution that
    // carries libjxl's reconstruction data gives back, through djxl, the JPEG the JPEG pack
    // copies; the slide's reduced levels are not copied (they are JPEG), the summary says why.
    let Some(slide) = vips_jpeg_tiff(tmp.path(), &["--pyramid"]) else { return };
    let (tiff, pack) = (tmp.path().join("slide.jxl.tif"), tmp.path().join("slide.jpeg.vtpk"));
    let said = cli::ok(&["split", s(&slide), "-o", s(&tiff), "--tile-size", "128", "--codec", "jxl"]);
    assert!(said.contains("JPEG XL tiles asked") && said.contains("recompressed losslessly"), "{said}");
    cli::ok(&["split", s(&slide), "--pack", s(&pack), "--tile-size", "128", "--border", "0", "-q"]);
    let tiles = tmp.path().join("tiles");
    std::fs::create_dir(&tiles).unwrap();
    assert!(tiff_pages(&python, &tiff, Some(&tiles)).iter().all(|p| p["compression"] == 50002));
    let pack = vortex_pack::Pack::open(&pack).unwrap();
    let mut rebuilt = 0;
    for name in files(&tiles, "jxl") {
        let tile = tiles.join(&name);
        if !std::fs::read(&tile).unwrap().windows(4).any(|w| w == b"jbrd") {
            continue;
        }
        let (x, y) = name.to_str().unwrap().trim_end_matches(".jxl").split_once('_').unwrap();
        let id = vortex_pack::TileId::new(0, x.parse().unwrap(), y.parse().unwrap());
        let vortex_pack::Tile::Data(vortex_pack::TileKind::Jpeg, original) = pack.tile(id).unwrap() else {
            panic!("{id:?}")
        };
        let back = tmp.path().join("back.jpg");
        let _ = std::fs::remove_file(&back);
        djxl(&tile, &back).unwrap();
        assert!(std::fs::read(&back).unwrap() == original, "{id:?}: djxl's JPEG is not the stored one");
        rebuilt += 1;
    }
    assert!(rebuilt >= 6, "{rebuilt} tiles rebuilt: {said}");
}

/// An RGB slide as libvips 8.18 (and Aperio's scanners) store it, `Q=90`: `Photometric` RGB,
/// shared `JPEGTables` holding a chroma table no component uses. libjxl 0.7 refuses such a
/// JPEG ("Non-trivial unused quant table"); the tiles are recompressed without that table, and
/// djxl's JPEG is the stored one less that table, decoding to the same texels.
#[test]
fn an_rgb_slide_s_tiles_are_recompressed_without_their_unused_table() {
    let Some(python) = crate::common::python_with("pyvips", "the RGB slide recompression test", "pyvips") else {
        return;
    };
    if !have_djxl() {
        return;
    }
    let tmp = tempfile::tempdir().unwrap();
    let slide = tmp.path().join("rgb-slide.tif");
    let save = "import pyvips, sys; pyvips.Image.new_from_file(sys.argv[1]).tiffsave(sys.argv[2], tile=True, \
                tile_width=128, tile_height=128, compression='jpeg', Q=90)";
    let out = Command::new(&python).args(["-c", save, s(&fixture("sample.png")), s(&slide)]).output().unwrap();
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let (jpeg, jxl) = (tmp.path().join("jpeg"), tmp.path().join("jxl"));
    let grid = ["--layout", "dzi", "--overlap", "0", "--tile-size", "128", "--json", "-q"];
    split(&slide, &jpeg, &grid);
    let report: serde_json::Value =
        serde_json::from_str(&split(&slide, &jxl, &[&grid[..], &["--codec", "jxl"]].concat())).unwrap();
    let recompressed = &report["storedTiles"]["recompressed"];
    assert_eq!(recompressed["refused"], 0, "{report}");
    assert_eq!(recompressed["tiles"], report["storedTiles"]["copied"], "{report}");
    let level = "rgb-slide_files/10";
    let (mut rebuilt, mut stripped) = (0, 0);
    for name in files(&jxl.join(level), "jxl") {
        let tile = jxl.join(level).join(&name);
        if !std::fs::read(&tile).unwrap().windows(4).any(|w| w == b"jbrd") {
            continue;
        }
        let back = tmp.path().join("back.jpg");
        let _ = std::fs::remove_file(&back);
        djxl(&tile, &back).unwrap();
        let (ours, stored) =
            (std::fs::read(&back).unwrap(), std::fs::read(jpeg.join(level).join(name.with_extension("jpeg"))).unwrap());
        // One 8-bit table less (its id and 64 values), and its DQT segment's marker and length
        // where it was alone in one, as libtiff writes them; none less for an edge tile, which
        // the lossless crop rewrote with the tables it uses.
        let less = stored.len() - ours.len();
        assert!(matches!(less, 0 | 65 | 69), "{name:?}: {less} bytes less");
        stripped += usize::from(less > 0);
        let decode = |b: &[u8]| image::load_from_memory(b).unwrap().to_rgb8().into_raw();
        assert!(decode(&ours) == decode(&stored), "{name:?}: djxl's JPEG decodes to other texels");
        rebuilt += 1;
    }
    assert!(rebuilt > 0 && Some(rebuilt) == recompressed["tiles"].as_u64(), "{rebuilt}: {report}");
    assert!(stripped > 0, "no stored tile had an unused table: the test no longer tests it");
}
