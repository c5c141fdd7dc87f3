//! convert: re-tiling an already-tiled input gives what splitting the original image gives.

use std::path::Path;
use std::process::Command;

use crate::common::cli::{BIN, wait_or_kill};
use crate::common::{Image, MemSink, layouts, png_options};
use proptest::prelude::*;
use vortex_tiler::background::Background;
use vortex_tiler::formats::tiles::filename::FilenameFormat;
use vortex_tiler::formats::tiles::info::InfoFile;
use vortex_tiler::formats::tiles::{NamedDir, SplitOutput};
use vortex_tiler::limits::Budget;
use vortex_tiler::output::{self, Product};
use vortex_tiler::settings::describe;
use vortex_tiler::sink::DirSink;
use vortex_tiler::source::tiled::{TileGrid, TiledSource};
use vortex_tiler::split::split;

/// Every tile's PNG bytes by (lod, x, y).
type Tiles = std::collections::BTreeMap<(u32, u32, u32), Vec<u8>>;

fn split_to_memory(source: Box<dyn vortex_tiler::source::RowSource>, tile: u32, border: u32) -> Tiles {
    let sink = MemSink::default();
    split(source, &sink, &png_options(tile, border, Background::Edge), &()).unwrap();
    sink.tiles.into_inner().unwrap()
}

fn split_to_dir(image: &Image, dir: &Path, tile: u32, border: u32) {
    let opts = png_options(tile, border, Background::Edge);
    let names = FilenameFormat::parse("lod%1$02s-x%2$04s-y%3$04s.png", 3).unwrap();
    let claim = output::claim(dir, Product::TileDir, &[], false).unwrap();
    let sink = DirSink::create(&claim, names.clone()).unwrap();
    let summary = split(image.source(), &sink, &opts, &()).unwrap();
    let info: InfoFile = describe(&summary.layout, summary.stored, &opts, &names);
    sink.finish(&info).unwrap();
}

fn converted(grid: Box<dyn TileGrid>, tile: u32, border: u32) -> Tiles {
    split_to_memory(Box::new(TiledSource::new(grid, vec![0; 8], true)), tile, border)
}

proptest! {
    #![proptest_config(ProptestConfig { cases: 24, .. ProptestConfig::default() })]

    #[test]
    fn convert_of_split_equals_split(
        w in 1u32..90, h in 1u32..90, layout_idx in 0usize..8,
        a in 8u32..40, ab in 0u32..3, b in 8u32..40, bb in 0u32..3, seed in any::<u64>(),
    ) {
        prop_assume!(a >= 2 * ab + 4 && b >= 2 * bb + 4);
        let image = Image::random(w, h, layouts()[layout_idx], seed);
        let dir = tempfile::tempdir().unwrap();
        let first = dir.path().join("first");
        split_to_dir(&image, &first, a, ab);
        let got = converted(Box::new(SplitOutput::open(&first).unwrap()), b, bb);
        let want = split_to_memory(image.source(), b, bb);
        prop_assert!(got == want, "{w}x{h} {}: {a}/{ab} -> {b}/{bb}", image.layout);
    }
}

/// Writes `image` as tiles of `tw x th` named by `pattern` (x, y), edge tiles smaller.
fn write_named(image: &image::RgbImage, dir: &Path, pattern: &str, tw: u32, th: u32) {
    let f = FilenameFormat::parse(pattern, 2).unwrap();
    for ty in 0..image.height().div_ceil(th) {
        for tx in 0..image.width().div_ceil(tw) {
            let (x0, y0) = (tx * tw, ty * th);
            let sub = image::imageops::crop_imm(image, x0, y0, tw.min(image.width() - x0), th.min(image.height() - y0))
                .to_image();
            let path = dir.join(f.format(&[tx, ty]));
            std::fs::create_dir_all(path.parent().unwrap()).unwrap();
            sub.save(&path).unwrap();
        }
    }
}

fn test_image(w: u32, h: u32) -> image::RgbImage {
    image::RgbImage::from_fn(w, h, |x, y| image::Rgb([(x * 7 + y) as u8, (y * 5) as u8, (x ^ y) as u8]))
}

#[test]
fn named_tiles_that_do_not_divide_the_new_size() {
    let dir = tempfile::tempdir().unwrap();
    let img = test_image(250, 170);
    let tiles = dir.path().join("tiles");
    write_named(&img, &tiles, "x%02s-y%02s.png", 100, 100);
    let original = dir.path().join("orig.png");
    img.save(&original).unwrap();
    let got = converted(Box::new(NamedDir::open(&tiles, "x%02s-y%02s.png").unwrap()), 128, 4);
    let want = split_to_memory(vortex_tiler::source::open(&original, Budget::new(1 << 30)).unwrap(), 128, 4);
    assert!(got == want);
}

fn convert_err(args: &[&str]) -> String {
    let out = Command::new(BIN).arg("convert").args(args).output().unwrap();
    assert_eq!(out.status.code(), Some(1), "{}", String::from_utf8_lossy(&out.stderr));
    String::from_utf8_lossy(&out.stderr).into_owned()
}

#[test]
fn bad_tiled_inputs_name_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let tiles = dir.path().join("tiles");
    write_named(&test_image(60, 40), &tiles, "x%02s-y%02s.png", 32, 32);
    let t = tiles.to_str().unwrap();
    let out = dir.path().join("out");
    let o = out.to_str().unwrap();
    let ff = ["--tiled", "--ff", "x%02s-y%02s.png"];

    std::fs::write(tiles.join("notes.txt"), "x").unwrap();
    let e = convert_err(&[&[t, "-o", o][..], &ff].concat());
    assert!(e.contains("notes.txt") && e.contains("does not match"), "{e}");
    std::fs::remove_file(tiles.join("notes.txt")).unwrap();

    std::fs::copy(tiles.join("x01-y00.png"), tiles.join("x1-y0.png")).unwrap();
    let e = convert_err(&[&[t, "-o", o][..], &ff].concat());
    assert!(e.contains("x1-y0.png") && e.contains("same coordinates"), "{e}");
    std::fs::remove_file(tiles.join("x1-y0.png")).unwrap();

    image::RgbImage::new(20, 20).save(tiles.join("x00-y00.png")).unwrap();
    let e = convert_err(&[&[t, "-o", o][..], &ff].concat());
    assert!(e.contains("x00-y00.png") || e.contains("x01-y00.png"), "{e}");
    write_named(&test_image(60, 40), &tiles, "x%02s-y%02s.png", 32, 32);

    image::GrayImage::new(32, 32).save(tiles.join("x01-y00.png")).unwrap();
    let e = convert_err(&[&[t, "-o", o][..], &ff].concat());
    assert!(e.contains("x01-y00.png") && e.contains("luminance"), "{e}");

    std::fs::write(tiles.join("x01-y00.png"), b"\x89PNG\r\n\x1a\nbroken").unwrap();
    let e = convert_err(&[&[t, "-o", o][..], &ff].concat());
    assert!(e.contains("x01-y00.png"), "{e}");

    let empty = dir.path().join("empty");
    std::fs::create_dir(&empty).unwrap();
    let e = convert_err(&[&[empty.to_str().unwrap(), "-o", o][..], &ff].concat());
    assert!(e.contains("empty") && e.contains("no tiles"), "{e}");
    assert!(!out.exists());
}

#[test]
fn missing_tiles_are_filled_with_a_warning_or_refused_with_strict() {
    let dir = tempfile::tempdir().unwrap();
    let tiles = dir.path().join("tiles");
    write_named(&test_image(90, 70), &tiles, "%s_%s.png", 32, 32);
    std::fs::remove_file(tiles.join("1_1.png")).unwrap();
    let out = dir.path().join("out");
    let args =
        [tiles.to_str().unwrap(), "-o", out.to_str().unwrap(), "--ff", "%s_%s.png", "--background", "#ff0000", "-q"];
    let r = Command::new(BIN).arg("convert").args(args).output().unwrap();
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let warning = String::from_utf8_lossy(&r.stderr);
    assert!(warning.contains("1 input tile(s) missing") && warning.contains("#ff0000"), "{warning}");
    let e = convert_err(&[&args[..], &["--strict"]].concat());
    assert!(e.contains("missing") && e.contains("--strict"), "{e}");
}

/// Every file under `dir` (relative path, bytes), sorted.
fn files(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut out: Vec<(String, Vec<u8>)> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap().path())
        .map(|p| (p.file_name().unwrap().to_string_lossy().into_owned(), std::fs::read(&p).unwrap()))
        .collect();
    out.sort();
    out
}

fn run_ok(args: &[&str]) {
    let out = Command::new(BIN).args(args).output().unwrap();
    assert!(out.status.success(), "{args:?}: {}", String::from_utf8_lossy(&out.stderr));
}

/// Each kind of input, from the command line, gives the files `split` of the original gives.
#[test]
fn every_input_kind_converts_like_splitting_the_original() {
    let dir = tempfile::tempdir().unwrap();
    let d = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    let img = test_image(150, 97);
    img.save(d("orig.png")).unwrap();
    let target = ["--tile-size", "64", "--border", "2", "--codec", "png", "-q"];
    run_ok(&[&["split", &d("orig.png"), "-o", &d("want")][..], &target].concat());
    let want = files(Path::new(&d("want")));

    // A pack (lossless tiles).
    run_ok(&[
        "split",
        &d("orig.png"),
        "--pack",
        &d("in.vtpk"),
        "--tile-size",
        "32",
        "--border",
        "1",
        "--codec",
        "png",
        "-q",
    ]);
    run_ok(&[&["convert", &d("in.vtpk"), "-o", &d("from-pack")][..], &target].concat());
    assert!(files(Path::new(&d("from-pack"))) == want, "from a pack");

    // Deep Zoom with overlap 1 and odd edge tiles: level 8 holds the 150x97 image.
    let (ts, overlap) = (40u32, 1u32);
    let level = dir.path().join("slide_files/8");
    std::fs::create_dir_all(&level).unwrap();
    for r in 0..img.height().div_ceil(ts) {
        for c in 0..img.width().div_ceil(ts) {
            let x0 = (c * ts).saturating_sub(if c > 0 { overlap } else { 0 });
            let y0 = (r * ts).saturating_sub(if r > 0 { overlap } else { 0 });
            let x1 = ((c + 1) * ts + overlap).min(img.width());
            let y1 = ((r + 1) * ts + overlap).min(img.height());
            image::imageops::crop_imm(&img, x0, y0, x1 - x0, y1 - y0)
                .to_image()
                .save(level.join(format!("{c}_{r}.png")))
                .unwrap();
        }
    }
    std::fs::write(
        d("slide.dzi"),
        format!(r#"<?xml version="1.0"?><Image xmlns="http://schemas.microsoft.com/deepzoom/2008" Format="png" Overlap="{overlap}" TileSize="{ts}"><Size Height="97" Width="150"/></Image>"#),
    )
    .unwrap();
    run_ok(&[&["convert", &d("slide.dzi"), "-o", &d("from-dzi")][..], &target].concat());
    assert!(files(Path::new(&d("from-dzi"))) == want, "from Deep Zoom");

    // Google z/y/x with 50-texel tiles covering 150x100: crop the original to that box first.
    let xyz = dir.path().join("xyz");
    let padded = image::RgbImage::from_fn(150, 100, |x, y| *img.get_pixel(x, y.min(96)));
    for y in 0..2u32 {
        for x in 0..3u32 {
            let p = xyz.join(format!("5/{}/{}.png", 7 + y, 11 + x));
            std::fs::create_dir_all(p.parent().unwrap()).unwrap();
            image::imageops::crop_imm(&padded, x * 50, y * 50, 50, 50).to_image().save(p).unwrap();
        }
    }
    padded.save(d("padded.png")).unwrap();
    run_ok(&[&["split", &d("padded.png"), "-o", &d("want-xyz")][..], &target].concat());
    run_ok(&[&["convert", &d("xyz"), "--input-layout", "google", "-o", &d("from-xyz")][..], &target].concat());
    assert!(files(Path::new(&d("from-xyz"))) == files(Path::new(&d("want-xyz"))), "from z/y/x");
}

#[test]
fn an_info_json_beside_named_tiles_gives_the_image_size() {
    let dir = tempfile::tempdir().unwrap();
    let img = test_image(128, 128);
    let tiles = dir.path().join("tiles");
    write_named(&img, &tiles, "x%s-y%s.png", 64, 64);
    std::fs::write(tiles.join("info.json"), r#"{"width": 100, "height": 90}"#).unwrap();
    let cropped = image::imageops::crop_imm(&img, 0, 0, 100, 90).to_image();
    cropped.save(dir.path().join("c.png")).unwrap();
    let got = converted(Box::new(NamedDir::open(&tiles, "x%s-y%s.png").unwrap()), 32, 1);
    let want =
        split_to_memory(vortex_tiler::source::open(&dir.path().join("c.png"), Budget::new(1 << 30)).unwrap(), 32, 1);
    assert!(got == want);
}

/// Directories and packs written before per-axis grids (format version 1: a square
/// power-of-two grid of `tileCount` pages per side, padding pages included) still read.
#[test]
fn square_grids_of_older_versions_still_read() {
    let dir = tempfile::tempdir().unwrap();
    let d = |name: &str| dir.path().join(name).to_str().unwrap().to_string();
    test_image(150, 97).save(d("orig.png")).unwrap();
    let target = ["--tile-size", "64", "--border", "2", "--codec", "png", "-q"];
    run_ok(&[&["split", &d("orig.png"), "-o", &d("want")][..], &target].concat());
    run_ok(&["split", &d("orig.png"), "-o", &d("tight"), "--tile-size", "32", "--border", "1", "--codec", "png", "-q"]);

    // 150 x 97 in 30-texel payloads: 5 x 4 pages, which version 1 kept in an 8 x 8 square.
    let old = dir.path().join("old");
    std::fs::create_dir(&old).unwrap();
    let mut info: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("tight/info.json")).unwrap()).unwrap();
    assert_eq!((&info["tileColumns"], &info["tileRows"], &info["lodCount"]), (&5.into(), &4.into(), &4.into()));
    let map = info.as_object_mut().unwrap();
    map.remove("tileColumns");
    map.remove("tileRows");
    map.insert("formatVersion".into(), 1.into());
    map.insert("tileCount".into(), 8.into());
    std::fs::write(old.join("info.json"), serde_json::to_vec_pretty(&info).unwrap()).unwrap();
    let padding = std::fs::read(dir.path().join("tight/lod03-x0000-y0000.png")).unwrap();
    for lod in 0..4u32 {
        for y in 0..8 >> lod {
            for x in 0..8 >> lod {
                let name = format!("lod{lod:02}-x{x:04}-y{y:04}.png");
                let tile = std::fs::read(dir.path().join("tight").join(&name)).unwrap_or_else(|_| padding.clone());
                std::fs::write(old.join(name), tile).unwrap();
            }
        }
    }

    run_ok(&[&["convert", &d("old"), "-o", &d("from-old")][..], &target].concat());
    assert!(files(Path::new(&d("from-old"))) == files(Path::new(&d("want"))), "from a version 1 directory");
    // `pack` keeps the square grid it was given, and `unpack` gives the files back.
    run_ok(&["pack", &d("old"), "-o", &d("old.vtpk"), "-q"]);
    let pack = vortex_pack::Pack::open(Path::new(&d("old.vtpk"))).unwrap();
    let grids: Vec<(u32, u32)> = pack.levels().iter().map(|l| (l.tiles_w, l.tiles_h)).collect();
    assert_eq!(grids, [(8, 8), (4, 4), (2, 2), (1, 1)]);
    run_ok(&["unpack", &d("old.vtpk"), "-o", &d("unpacked"), "-q"]);
    // The tiles come back as they were; info.json is completed (formatVersion 2, same grid).
    let tiles = |dir: &Path| files(dir).into_iter().filter(|(name, _)| name != "info.json").collect::<Vec<_>>();
    assert!(tiles(Path::new(&d("unpacked"))) == tiles(&old), "unpack(pack(version 1))");
    let back: serde_json::Value =
        serde_json::from_slice(&std::fs::read(dir.path().join("unpacked/info.json")).unwrap()).unwrap();
    assert_eq!((&back["tileCount"], back.get("tileColumns")), (&8.into(), None));
    run_ok(&[&["convert", &d("old.vtpk"), "-o", &d("from-old-pack")][..], &target].concat());
    assert!(files(Path::new(&d("from-old-pack"))) == files(Path::new(&d("want"))), "from a square pack");
}

/// Whether `vips` (libvips-tools) is on PATH; without it the vips tests print a note and pass,
/// except under `CI=true` (.ci/run installs it), where they fail.
fn have_vips() -> bool {
    crate::common::have_program("vips", "--version", "libvips-tools")
}

fn run_vips(args: &[&str]) {
    let out = Command::new("vips").args(args).output().unwrap();
    assert!(out.status.success(), "vips {args:?}: {}", String::from_utf8_lossy(&out.stderr));
}

/// Converts `input` (plus `extra` flags) to 64-texel PNG pages and checks them against
/// splitting `original`: the same LOD 0 texels, so the same files at every LOD.
fn converts_like(input: &Path, extra: &[&str], original: &Path, out: &Path, what: &str) {
    let target = ["--tile-size", "64", "--border", "2", "--codec", "png", "-q"];
    let want = out.with_extension("want");
    if !want.exists() {
        run_ok(&[&["split", original.to_str().unwrap(), "-o", want.to_str().unwrap()][..], &target].concat());
    }
    let args = [&["convert", input.to_str().unwrap(), "-o", out.to_str().unwrap()][..], extra, &target].concat();
    run_ok(&args);
    assert!(files(out) == files(&want), "{what}: {args:?}");
}

/// What `vips dzsave` writes (IIIF 2 and 3 directories, Deep Zoom and Google zip archives,
/// stored and deflated), converted, gives what splitting the original gives.
#[test]
fn vips_dzsave_layouts_convert_like_the_original() {
    if !have_vips() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let d = |name: &str| dir.path().join(name);
    // 300x200 in 128-texel tiles: 3x2 tiles, the last column 44 and the last row 72 wide.
    let img = test_image(300, 200);
    img.save(d("orig.png")).unwrap();
    let orig = d("orig.png");
    let o = orig.to_str().unwrap();
    let png = ["--suffix", ".png", "--tile-size", "128"];
    let cases: [(&str, &[&str], &str); 6] = [
        ("iiif2", &["--layout", "iiif"], "iiif2"),
        ("iiif3", &["--layout", "iiif3"], "iiif3"),
        ("dz.zip", &[], "dz.zip"),
        ("dzdeflated.zip", &["--compression", "6"], "dzdeflated.zip"),
        ("iiif3.zip", &["--layout", "iiif3"], "iiif3.zip"),
        ("dir/slide", &[], "dir/slide.dzi"),
    ];
    std::fs::create_dir(d("dir")).unwrap();
    for (name, flags, input) in cases {
        run_vips(&[&["dzsave", o, d(name).to_str().unwrap()][..], &png, flags].concat());
        converts_like(&d(input), &[], &orig, &d(&format!("out-{}", name.replace('/', "-"))), name);
    }
    // The info.json itself names a IIIF directory too.
    converts_like(&d("iiif3/info.json"), &[], &orig, &d("out-info"), "iiif3/info.json");

    // Google tiles are padded to whole tiles: an image of whole tiles compares exactly.
    let whole = test_image(256, 128);
    whole.save(d("whole.png")).unwrap();
    let w = d("whole.png");
    for (name, flags) in [("google.zip", &["--compression", "6"][..]), ("google", &[][..])] {
        run_vips(
            &[&["dzsave", w.to_str().unwrap(), d(name).to_str().unwrap(), "--layout", "google"][..], &png, flags]
                .concat(),
        );
        let extra: &[&str] = if name.ends_with(".zip") { &[] } else { &["--input-layout", "google"] };
        converts_like(&d(name), extra, &w, &d(&format!("out-{name}")), name);
    }
}

/// vips 8.14 writes an image that fits in one IIIF tile with `scaleFactors: []`.
#[test]
fn vips_one_tile_iiif_images_convert() {
    if !have_vips() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let d = |name: &str| dir.path().join(name);
    test_image(90, 60).save(d("small.png")).unwrap();
    for layout in ["iiif", "iiif3"] {
        let out = d(layout);
        run_vips(&[
            "dzsave",
            d("small.png").to_str().unwrap(),
            out.to_str().unwrap(),
            "--layout",
            layout,
            "--suffix",
            ".png",
        ]);
        converts_like(&out, &[], &d("small.png"), &d(&format!("out-{layout}")), layout);
    }
}

/// libvips 8.18 (pyvips) writes a Deep Zoom zip without the top folder and a one-tile IIIF
/// image as `full/{w},{h}/0/default.png`. Runs where `VORTEX_PYVIPS` names a Python with
/// pyvips (`.ci/run` makes one: `python3 -m venv V && V/bin/pip install pyvips pyvips-binary`).
#[test]
fn pyvips_layouts_convert_like_the_original() {
    let Some(python) = std::env::var_os("VORTEX_PYVIPS") else {
        crate::common::skip_unless_ci("the pyvips test", "VORTEX_PYVIPS unset: set it to a Python with pyvips");
        return;
    };
    let dir = tempfile::tempdir().unwrap();
    let d = |name: &str| dir.path().join(name);
    test_image(300, 200).save(d("orig.png")).unwrap();
    test_image(90, 60).save(d("small.png")).unwrap();
    let script = r#"
import sys, pyvips
big, small, out = (pyvips.Image.new_from_file(sys.argv[1]), pyvips.Image.new_from_file(sys.argv[2]), sys.argv[3])
for name, image, layout in [("dz.zip", big, "dz"), ("g3.zip", big, "iiif3"), ("i2", big, "iiif"),
                            ("s3", small, "iiif3"), ("s2", small, "iiif")]:
    image.dzsave(out + "/" + name, layout=layout, suffix=".png", tile_size=128)
"#;
    let out =
        Command::new(python).args(["-c", script]).args([d("orig.png"), d("small.png"), dir.path().into()]).output();
    let out = out.unwrap();
    assert!(out.status.success(), "pyvips: {}", String::from_utf8_lossy(&out.stderr));
    for name in ["dz.zip", "g3.zip", "i2"] {
        converts_like(&d(name), &[], &d("orig.png"), &d(&format!("out-{name}")), name);
    }
    for name in ["s3", "s2"] {
        converts_like(&d(name), &[], &d("small.png"), &d(&format!("out-{name}")), name);
    }
}

/// Bad IIIF and zip inputs fail naming the file and the member or entry.
#[test]
fn bad_iiif_and_zip_inputs_name_the_file() {
    let dir = tempfile::tempdir().unwrap();
    let d = |name: &str| dir.path().join(name);
    let out = d("out");
    let o = out.to_str().unwrap();
    std::fs::create_dir(d("iiif")).unwrap();
    let info = r#"{"@context": "http://iiif.io/api/image/3/context.json", "id": "x", "type": "ImageService3",
                   "width": 300, "height": 200, "tiles": [{"width": 128, "scaleFactors": [2, 4]}]}"#;
    std::fs::write(d("iiif/info.json"), info).unwrap();
    let e = convert_err(&[d("iiif").to_str().unwrap(), "-o", o]);
    assert!(e.contains("iiif/info.json: tiles[0].scaleFactors") && e.contains("lacks 1"), "{e}");
    std::fs::write(d("iiif/info.json"), info.replace("[2, 4]", "[1]")).unwrap();
    let e = convert_err(&[d("iiif").to_str().unwrap(), "-o", o]);
    assert!(e.contains("holds no full-size tile") && e.contains("0,0,128,128/128,128/0/default.jpg"), "{e}");

    std::fs::write(d("bad.zip"), b"PK\x03\x04 truncated").unwrap();
    let e = convert_err(&[d("bad.zip").to_str().unwrap(), "-o", o]);
    assert!(e.contains("bad.zip") && e.contains("zip"), "{e}");

    std::fs::create_dir(d("plain")).unwrap();
    let e = convert_err(&[d("plain").to_str().unwrap(), "-o", o]);
    assert!(e.contains("--input-layout google") && e.contains("--input-layout xyz"), "{e}");
    assert!(!out.exists());
}

/// `image` as PNG bytes.
fn png_bytes(image: &image::RgbImage) -> Vec<u8> {
    let mut out = Vec::new();
    image.write_to(&mut std::io::Cursor::new(&mut out), image::ImageFormat::Png).unwrap();
    out
}

/// A tile whose zip entry inflates far past any tile is refused from its declared size, naming
/// the entry, instead of being inflated (up to 256 MiB per thread) under --max-memory 64M.
#[test]
fn a_zip_bomb_tile_is_refused_naming_the_entry() {
    use std::io::Write;
    let dir = tempfile::tempdir().unwrap();
    let zip = dir.path().join("bomb.zip");
    let out = dir.path().join("out");
    let image = test_image(128, 64);
    let mut w = zip::ZipWriter::new(std::fs::File::create(&zip).unwrap());
    let deflated = zip::write::SimpleFileOptions::default().compression_method(zip::CompressionMethod::Deflated);
    w.start_file("dz.dzi", deflated).unwrap();
    w.write_all(br#"<Image TileSize="64" Overlap="0" Format="png"><Size Width="128" Height="64"/></Image>"#).unwrap();
    w.start_file("dz_files/7/0_0.png", deflated).unwrap();
    w.write_all(&png_bytes(&image::imageops::crop_imm(&image, 0, 0, 64, 64).to_image())).unwrap();
    w.start_file("dz_files/7/1_0.png", deflated).unwrap();
    w.write_all(&vec![0u8; 32 << 20]).unwrap();
    w.finish().unwrap();
    assert!(std::fs::metadata(&zip).unwrap().len() < 100_000);
    let e = convert_err(&[zip.to_str().unwrap(), "-o", out.to_str().unwrap(), "--max-memory", "64M"]);
    assert!(e.contains("bomb.zip:dz_files/7/1_0.png") && e.contains("32.0 MiB, more than"), "{e}");
    assert!(!out.exists());
}

/// A FIFO among the tiles is refused, naming it, instead of blocking the run for good.
#[cfg(unix)]
#[test]
fn a_fifo_among_the_tiles_is_refused_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let tiles = dir.path().join("tiles");
    write_named(&test_image(60, 40), &tiles, "x%02s-y%02s.png", 32, 32);
    let fifo = tiles.join("x01-y00.png");
    std::fs::remove_file(&fifo).unwrap();
    assert!(Command::new("mkfifo").arg(&fifo).status().unwrap().success());
    let out = dir.path().join("out.vtpk");
    let child = Command::new(BIN)
        .args(["convert", tiles.to_str().unwrap(), "--ff", "x%02s-y%02s.png", "--pack", out.to_str().unwrap()])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let result = wait_or_kill(child.id(), "convert of tiles holding a FIFO", || child.wait_with_output().unwrap());
    let e = String::from_utf8_lossy(&result.stderr);
    assert_eq!(result.status.code(), Some(1), "{e}");
    assert!(e.contains("x01-y00.png") && e.contains("not a regular file"), "{e}");
    let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(left, ["tiles"], "nothing written, no temporary left");
}

/// A second signal ends the run at once (the first asks it to stop between tiles, which a
/// blocked read would never reach), and removes the temporary output on the way.
#[cfg(unix)]
#[test]
fn a_second_signal_removes_the_temporary_output() {
    let dir = tempfile::tempdir().unwrap();
    let d = |name: &str| dir.path().join(name);
    // Noise, slow to compress at best: the run is stopped long before it ends.
    let side = 2000u32;
    let mut state = 0x2545_F491_4F6C_DD1Du64;
    let noise = image::RgbImage::from_fn(side, side, |_, _| {
        state ^= state << 13;
        state ^= state >> 7;
        state ^= state << 17;
        image::Rgb([state as u8, (state >> 8) as u8, (state >> 16) as u8])
    });
    noise.save(d("noise.png")).unwrap();
    run_ok(&["split", d("noise.png").to_str().unwrap(), "-o", d("tiles").to_str().unwrap(), "-q", "--codec", "png"]);
    let child = Command::new(BIN)
        .args(["convert", d("tiles").to_str().unwrap(), "--pack", d("out.vtpk").to_str().unwrap(), "-q"])
        .args(["--codec", "png", "--png-compression", "best"])
        .stdout(std::process::Stdio::null())
        .stderr(std::process::Stdio::piped())
        .spawn()
        .unwrap();
    let pid = child.id().to_string();
    let temporary = || {
        std::fs::read_dir(dir.path())
            .unwrap()
            .map(|e| e.unwrap().file_name().to_string_lossy().into_owned())
            .any(|n| n.starts_with(".out.vtpk.tmp-"))
    };
    // Until the run has its temporary (a fail-safe deadline, not a timing).
    let deadline = std::time::Instant::now() + std::time::Duration::from_secs(120);
    while !temporary() && std::time::Instant::now() < deadline {
        std::thread::sleep(std::time::Duration::from_millis(5));
    }
    // Stopped, the run takes both signals at once when it goes on: the second finds the first
    // not yet acted on.
    let kill = |signal: &str| assert!(Command::new("kill").args([signal, &pid]).status().unwrap().success());
    kill("-STOP");
    assert!(temporary(), "the run wrote no temporary, or finished before it was stopped");
    kill("-TERM");
    kill("-INT");
    kill("-CONT");
    let result = wait_or_kill(child.id(), "convert after two signals", || child.wait_with_output().unwrap());
    let e = String::from_utf8_lossy(&result.stderr);
    assert!(matches!(result.status.code(), Some(130 | 143)), "{:?}: {e}", result.status);
    assert!(!e.contains("panicked"), "{e}");
    assert!(!temporary() && !d("out.vtpk").exists(), "{e}");
}

/// A descriptor declaring far more tiles than are there is refused up front (a .dzi claiming
/// 300000² over one tile would be filled for minutes), unless --allow-missing-tiles.
#[test]
fn a_descriptor_over_mostly_missing_tiles_is_refused() {
    let dir = tempfile::tempdir().unwrap();
    let d = |name: &str| dir.path().join(name);
    let o = d("out");
    let o = o.to_str().unwrap();
    let dzi = |w: u32, h: u32| {
        format!(r#"<Image TileSize="254" Overlap="1" Format="png"><Size Width="{w}" Height="{h}"/></Image>"#)
    };
    std::fs::create_dir_all(d("big_files/19")).unwrap();
    std::fs::write(d("big.dzi"), dzi(300_000, 300_000)).unwrap();
    test_image(255, 255).save(d("big_files/19/0_0.png")).unwrap();
    let e = convert_err(&[d("big.dzi").to_str().unwrap(), "-o", o]);
    assert!(e.contains("big.dzi") && e.contains("only 1 of its 1397124 tiles"), "{e}");
    assert!(e.contains("--allow-missing-tiles"), "{e}");

    // 500x300 in 254-texel tiles: 2x2, one there.
    std::fs::create_dir_all(d("small_files/9")).unwrap();
    std::fs::write(d("small.dzi"), dzi(500, 300)).unwrap();
    test_image(255, 255).save(d("small_files/9/0_0.png")).unwrap();
    let e = convert_err(&[d("small.dzi").to_str().unwrap(), "-o", o]);
    assert!(e.contains("only 1 of its 4 tiles"), "{e}");
    let r = Command::new(BIN)
        .args(["convert", d("small.dzi").to_str().unwrap(), "-o", o, "-q", "--allow-missing-tiles"])
        .output()
        .unwrap();
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    assert!(String::from_utf8_lossy(&r.stderr).contains("3 input tile(s) missing"));
    // Half there is not most missing.
    test_image(247, 255).save(d("small_files/9/1_0.png")).unwrap();
    run_ok(&["convert", d("small.dzi").to_str().unwrap(), "-o", d("out2").to_str().unwrap(), "-q"]);

    // IIIF: 300000² in 512-texel tiles, one region there.
    std::fs::create_dir_all(d("iiif/0,0,512,512/512,512/0")).unwrap();
    let info = r#"{"@context": "http://iiif.io/api/image/3/context.json", "id": "x", "type": "ImageService3",
                   "width": 300000, "height": 300000, "tiles": [{"width": 512, "scaleFactors": [1]}]}"#;
    std::fs::write(d("iiif/info.json"), info).unwrap();
    test_image(512, 512).save(d("iiif/0,0,512,512/512,512/0/default.png")).unwrap();
    let e = convert_err(&[d("iiif").to_str().unwrap(), "-o", d("out3").to_str().unwrap()]);
    assert!(e.contains("IIIF") && e.contains("only 1 of its 343396 tiles"), "{e}");
}
