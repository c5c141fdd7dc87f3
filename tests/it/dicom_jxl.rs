//! DICOM whole-slide images of JPEG XL frames (`--layout dicom --codec jxl`, issue 46;
//! docs/dicom.md, "JPEG XL frames"): lossless frames (1.2.840.10008.1.2.4.110) that wsidicom
//! reads exactly as the box pyramid, lossy ones (.112) within JPEG's error of it, a JPEG-tiled
//! source's stored tiles recompressed losslessly (.111 where every frame of an instance is
//! one) that `djxl` turns back into the JPEG frames a JPEG series copies, byte for byte; our
//! own reader reads every series back. dciodvfy (dicom3tools of 2022) predates Supplement
//! 232: its only complaints are those its not knowing the transfer syntax brings
//! ([`UNKNOWN_TRANSFER_SYNTAX`], [`UNKNOWN_METHOD`]). The Python checks are `dicom_out.py jxl`; each reader is
//! skipped with a note where missing outside CI, and a failure under CI.

use std::path::Path;
use std::process::Command;

use vortex_tiler::pixel::{Channels, Depth, PixelLayout};

use crate::common::cli::{fails_with, ok, run, s};
use crate::common::compare::{Picture, Tolerance, assert_close};
use crate::dicom_out::{ACCEPTED_WARNINGS, SCRIPT, json_of, readers, vips_jpeg_tiff};
use crate::ome_zarr::input;

const LOSSLESS: &str = "1.2.840.10008.1.2.4.110";
const RECOMPRESSION: &str = "1.2.840.10008.1.2.4.111";
const LOSSY: &str = "1.2.840.10008.1.2.4.112";

/// What dciodvfy of dicom3tools 1.00~20220618 says of every JPEG XL instance because it
/// predates Supplement 232 (2024) and knows neither its transfer syntaxes nor its defined
/// term: it takes the unknown transfer syntax for a native one, so the encapsulated Pixel
/// Data's undefined length is "illegal" to it, it stops reading there and then misses the
/// Pixel Data; and `ISO_18181_1` is no method it knows. Every other check passes as for
/// JPEG frames. A dciodvfy that knows the syntaxes says none of them.
const UNKNOWN_TRANSFER_SYNTAX: &[&str] = &[
    "Error - Undefined value length of other byte/word element is illegal in non-encapsulated transfer syntax",
    "Error - Dicom dataset read failed",
    "Error - Missing attribute Type 1C Conditional Element=<PixelData> Module=<ImagePixel>",
];

/// Its warnings on the lossy history, which it checks against the transfer syntax: of a
/// series whose own JPEG XL coding was lossy, a method it does not know; of a JPEG source's
/// step, JPEG's method, which it finds inconsistent with a transfer syntax it does not know
/// to hold JPEG XL (of recompressed JPEGs, even): a native series of the same source, whose
/// syntax it knows, passes with the same step.
const UNKNOWN_METHOD: &[&str] = &[
    "Warning - Unrecognized defined term <ISO_18181_1> for value",
    "Warning - method inconsistent with Transfer Syntax - attribute <LossyImageCompressionMethod> = <ISO_10918_1>",
];

/// dciodvfy on every instance of `dir` (skipped with a note where dicom3tools is missing
/// outside CI): each level's JPEG XL instance says all of [`UNKNOWN_TRANSFER_SYNTAX`] or none
/// of it, perhaps some of [`UNKNOWN_METHOD`], and nothing else but `dicom_out`'s accepted warnings;
/// the associated images' JPEG baseline instances pass as in every series.
fn dciodvfy(dir: &Path) {
    if !crate::common::have_program("dciodvfy", "-help", "dicom3tools") {
        return;
    }
    let mut instances: Vec<std::path::PathBuf> = std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().path()).collect();
    instances.sort();
    assert!(!instances.is_empty());
    for dcm in instances {
        let out = Command::new("dciodvfy").arg(&dcm).output().unwrap();
        let said = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
        let jxl = dcm.file_name().unwrap().to_string_lossy().starts_with("level-");
        let complaints: Vec<&str> = (said.lines())
            .filter(|l| l.starts_with("Error") || l.starts_with("Warning"))
            .filter(|l| !ACCEPTED_WARNINGS.iter().any(|(w, _)| l.contains(w)))
            .collect();
        let unknown: Vec<&str> = complaints.iter().copied().filter(|l| UNKNOWN_TRANSFER_SYNTAX.contains(l)).collect();
        let others: Vec<&str> = (complaints.iter().copied())
            .filter(|l| {
                let method = jxl && UNKNOWN_METHOD.iter().any(|m| l.starts_with(m));
                !(UNKNOWN_TRANSFER_SYNTAX.contains(l) || method)
            })
            .collect();
        assert!(others.is_empty(), "dciodvfy {}: {others:?}\n{said}", dcm.display());
        let all_or_none = unknown.is_empty() || UNKNOWN_TRANSFER_SYNTAX.iter().all(|u| unknown.contains(u));
        assert!(all_or_none && (jxl || unknown.is_empty()), "dciodvfy {}: {said}", dcm.display());
    }
}

/// `dicom_out.py jxl` on the series `dir` made from `source`: its JSON.
fn check(
    python: &Path,
    dir: &Path,
    source: &Path,
    tile: u32,
    mode: &str,
    jpeg_dir: Option<&Path>,
) -> serde_json::Value {
    let tile = tile.to_string();
    let mut args = vec![SCRIPT, "jxl", s(dir), s(source), &tile, mode];
    args.extend(jpeg_dir.map(s));
    let out = Command::new(python).args(&args).output().unwrap();
    let said = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "{}: {said}", dir.display());
    eprintln!("{}: {said}", dir.display());
    json_of(&String::from_utf8_lossy(&out.stdout))
}

/// Each level's instance's transfer syntax and photometric interpretation, as `--json` says.
fn level_frames(json: &serde_json::Value) -> Vec<(String, String)> {
    let levels = json["dicom"]["levelFrames"].as_array().unwrap_or_else(|| panic!("no levelFrames: {json}"));
    (levels.iter())
        .map(|l| {
            let text = |key: &str| l[key].as_str().unwrap().to_string();
            (text("transferSyntax"), text("photometricInterpretation"))
        })
        .collect()
}

/// The full-resolution PNG tiles our reader cuts from `input` (256 texels, no border, box
/// filter; named `lod00-xX-yY.png`), decoded.
fn level_0_tiles(input: &Path, dir: &Path) -> Vec<(String, image::DynamicImage)> {
    let tiles = crate::tiff_out::png_tiles(input, dir, &["--tile-size", "256"]);
    let lod_0: Vec<(String, image::DynamicImage)> = (tiles.into_iter())
        .filter(|(name, _)| name.starts_with("lod00-"))
        .map(|(name, bytes)| (name, image::load_from_memory(&bytes).unwrap()))
        .collect();
    lod_0
}

/// Lossless frames (`--lossless`): JPEG XL Lossless instances of MONOCHROME2 or RGB frames,
/// Lossy Image Compression `00` for a PNG; wsidicom reads every level equal to the box
/// pyramid, exactly (the frames are the pyramid's samples, and the box pyramid is exact); our
/// reader reads the series back to the very PNG tiles of the image it was made from.
#[test]
fn lossless_frames_are_the_pyramid_s_samples_exactly() {
    let dir = tempfile::tempdir().unwrap();
    let grey = PixelLayout::new(Channels::Grey, Depth::U8);
    for (name, layout, w, h) in
        [("rgb", PixelLayout::new(Channels::Rgb, Depth::U8), 1000, 700), ("grey", grey, 600, 300)]
    {
        let png = input(dir.path(), name, w, h, layout);
        let out = dir.path().join(format!("{name}-series"));
        let args = ["split", s(&png), "--layout", "dicom", "-o", s(&out), "--pixel-size", "0.5um"];
        let lossless = ["--codec", "jxl", "--lossless", "--jxl-effort", "1", "--filter", "box", "--json"];
        let json = json_of(&ok(&[&args[..], &lossless].concat()));
        let dicom = &json["dicom"];
        let photometric = if layout.channels == Channels::Grey { "MONOCHROME2" } else { "RGB" };
        assert_eq!(dicom["transferSyntax"], LOSSLESS, "{json}");
        assert_eq!(dicom["frameCoding"], "JPEG XL lossless", "{json}");
        assert_eq!(dicom["photometricInterpretation"], photometric, "{json}");
        let levels = level_frames(&json);
        assert!(levels.iter().all(|(t, p)| t == LOSSLESS && p == photometric), "{json}");
        dciodvfy(&out);
        if let Some(python) = readers() {
            let measured = check(&python, &out, &png, 256, "exact", None);
            assert_eq!(measured["lossy"], serde_json::json!(vec!["00"; levels.len()]), "{measured}");
        }
        // Our reader takes the series' level 0: the same pyramid as from the image.
        let from_png = crate::tiff_out::png_tiles(&png, &dir.path().join(format!("{name}-from-png")), &[]);
        let from_dicom = crate::tiff_out::png_tiles(&out, &dir.path().join(format!("{name}-from-dicom")), &[]);
        assert!(!from_png.is_empty() && from_png == from_dicom, "{name}: the series reads back otherwise");
    }
}

/// Lossy frames (the default quality 90, Butteraugli distance 1.0): JPEG XL instances of RGB
/// frames (they decode to RGB: the XYB transform is the codestream's own), each stating its
/// lossy step as `ISO_18181_1`; wsidicom reads every level within JPEG's error of the box
/// pyramid (30 dB, as the JPEG series: JPEG XL at distance 1.0 measures 36.8 dB on
/// photographs, docs/jxl.md, and 35.1 dB on this image's level 0; a reader taking its RGB for
/// YCbCr falls under 20), and so does
/// our reader, whose full-resolution tiles are within JPEG XL's error of the image's.
#[test]
fn lossy_frames_are_within_jpeg_s_error_and_say_so() {
    let dir = tempfile::tempdir().unwrap();
    let png = input(dir.path(), "rgb", 1000, 700, PixelLayout::new(Channels::Rgb, Depth::U8));
    let out = dir.path().join("series");
    let args = ["split", s(&png), "--layout", "dicom", "-o", s(&out), "--pixel-size", "0.5um"];
    let json =
        json_of(&ok(&[&args[..], &["--codec", "jxl", "--jxl-effort", "3", "--filter", "box", "--json"]].concat()));
    let dicom = &json["dicom"];
    assert_eq!((dicom["transferSyntax"].as_str(), dicom["frameCoding"].as_str()), (Some(LOSSY), Some("JPEG XL")));
    assert!(level_frames(&json).iter().all(|(t, p)| t == LOSSY && p == "RGB"), "{json}");
    dciodvfy(&out);
    if let Some(python) = readers() {
        let measured = check(&python, &out, &png, 256, "jpeg", None);
        for (k, methods) in measured["methods"].as_array().unwrap().iter().enumerate() {
            assert_eq!(measured["lossy"][k], "01", "{measured}");
            assert_eq!(methods, &serde_json::json!(["ISO_18181_1"]), "level {k}: {measured}");
        }
    }
    let theirs = level_0_tiles(&png, &dir.path().join("from-png"));
    let ours = level_0_tiles(&out, &dir.path().join("from-dicom"));
    assert!(!theirs.is_empty() && theirs.len() == ours.len(), "{} tiles, {} read back", theirs.len(), ours.len());
    for ((name, want), (_, got)) in theirs.iter().zip(&ours) {
        let (want, got) = (want.to_rgb8(), got.to_rgb8());
        assert_close(
            &format!("dicom-jxl-lossy-{name}"),
            Picture::new(got.width(), got.height(), 3, got.as_raw()),
            Picture::new(want.width(), want.height(), 3, want.as_raw()),
            Tolerance::mean(
                4.0,
                "JPEG XL at distance 1.0 keeps the mean error within a few levels (36.8 dB on photographs); a frame misplaced or read in the wrong colours is tens of levels off",
            ),
        );
    }
}

/// A JPEG-tiled source (a `vips tiffsave` JPEG TIFF, Q85: YCbCr 4:2:0) with `--codec jxl`:
/// its stored tiles that fill a level-0 frame are recompressed losslessly, counted in
/// `storedTiles.recompressed`; where they are every frame of level 0 (1024 x 768: 4 x 3
/// whole tiles) its instance is JPEG XL JPEG Recompression and states YBR_FULL_422, what the
/// JPEG baseline instance rebuilt from it states, and adds no lossy step to the source's;
/// the reduced levels, coded here, are JPEG XL of RGB frames, a step of their own. Where some
/// frames are coded here (1000 x 700: the edge tiles lie past the image), level 0 is JPEG XL
/// RGB. Every recompressed frame `djxl` turns back into the JPEG series' frame, byte for byte;
/// wsidicom and our reader read each series within JPEG's error of the source.
#[test]
fn a_jpeg_tiled_source_s_tiles_become_jpeg_xl_jpeg_recompression_frames() {
    if !crate::common::have_program("vips", "--version", "libvips-tools")
        || !crate::common::have_program("djxl", "--version", "libjxl-tools")
    {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    for (w, h, recompressed, level_0) in
        [(1024, 768, 12, (RECOMPRESSION, "YBR_FULL_422")), (1000, 700, 6, (LOSSY, "RGB"))]
    {
        let tiled = vips_jpeg_tiff(dir.path(), w, h, 85);
        let jpeg = dir.path().join(format!("jpeg-{w}"));
        ok(&["split", s(&tiled), "--layout", "dicom", "-o", s(&jpeg), "--pixel-size", "0.5um", "-q"]);
        let out = dir.path().join(format!("jxl-{w}"));
        let args = ["split", s(&tiled), "--layout", "dicom", "-o", s(&out), "--pixel-size", "0.5um"];
        let json = json_of(&ok(&[&args[..], &["--codec", "jxl", "--jxl-effort", "3", "--json"]].concat()));
        let stored = &json["storedTiles"]["recompressed"];
        assert_eq!((stored["tiles"].as_u64(), stored["refused"].as_u64()), (Some(recompressed), Some(0)), "{json}");
        assert_eq!(json["copied"], recompressed, "{json}");
        let levels = level_frames(&json);
        assert_eq!((levels[0].0.as_str(), levels[0].1.as_str()), level_0, "{json}");
        assert!(levels[1..].iter().all(|(t, p)| t == LOSSY && p == "RGB"), "{json}");
        assert_eq!(json["dicom"]["levelFrames"][0]["storedFrames"], recompressed, "{json}");
        dciodvfy(&out);
        if let Some(python) = readers() {
            let measured = check(&python, &out, &tiled, 256, "jpeg", Some(&jpeg));
            let rebuilt = measured["rebuiltFrames"].as_array().unwrap().len() as u64;
            assert_eq!(rebuilt, recompressed, "{measured}");
            let source = serde_json::json!("ISO_10918_1");
            let ours = serde_json::json!("ISO_18181_1");
            let level_0_methods = match recompressed {
                12 => serde_json::json!([source]),
                _ => serde_json::json!([source, ours]),
            };
            assert_eq!(measured["methods"][0], level_0_methods, "{measured}");
            assert_eq!(measured["methods"][1], serde_json::json!([source, ours]), "{measured}");
        }
        // Our reader reads the series back as it reads the JPEG series: the same frames,
        // decoded by libjxl rather than libjpeg-turbo.
        let theirs = level_0_tiles(&jpeg, &dir.path().join(format!("jpeg-{w}-back")));
        let ours = level_0_tiles(&out, &dir.path().join(format!("jxl-{w}-back")));
        assert!(!theirs.is_empty() && theirs.len() == ours.len());
        for ((name, want), (_, got)) in theirs.iter().zip(&ours).take(4) {
            let (want, got) = (want.to_rgb8(), got.to_rgb8());
            assert_close(
                &format!("dicom-jxl-recompressed-{w}-{name}"),
                Picture::new(got.width(), got.height(), 3, got.as_raw()),
                Picture::new(want.width(), want.height(), 3, want.as_raw()),
                Tolerance::mean(
                    4.0,
                    "a recompressed JPEG decodes through libjxl a few levels from libjpeg-turbo's decoding (50.8 dB, docs/jxl.md), and a frame coded here within JPEG XL's error; a misplaced or miscoloured frame is tens of levels off",
                ),
            );
        }
    }
}

/// A slide's own JPEG levels (`--levels stored`, a `vips tiffsave --pyramid` JPEG TIFF of
/// 2300 x 1500 in 256-texel tiles: 78 tiles over 5 levels) with `--codec jxl`: nothing
/// decoded, every tile recompressed losslessly, every instance JPEG XL JPEG Recompression
/// stating YBR_FULL_422 and the slide's lossy step alone; `djxl` turns every frame back into
/// the frame a JPEG series of the slide's own levels copies, byte for byte; wsidicom reads
/// every level within JPEG's error of the box pyramid of level 0 (the slide's reduced levels
/// are libvips' own, JPEG-coded again).
#[test]
fn a_slide_s_own_levels_are_recompressed_into_jpeg_xl_jpeg_recompression_instances() {
    if !crate::common::have_program("vips", "--version", "libvips-tools")
        || !crate::common::have_program("djxl", "--version", "libjxl-tools")
    {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let tif = crate::dicom_out::vips_pyramid(dir.path());
    let jpeg = dir.path().join("jpeg");
    ok(&["split", s(&tif), "--layout", "dicom", "-o", s(&jpeg), "--pixel-size", "0.5um", "-q"]);
    let out = dir.path().join("jxl");
    let args = ["split", s(&tif), "--layout", "dicom", "-o", s(&out), "--pixel-size", "0.5um"];
    let json = json_of(&ok(&[&args[..], &["--codec", "jxl", "--jxl-effort", "3", "--json"]].concat()));
    let dicom = &json["dicom"];
    assert_eq!((dicom["levels"].as_str(), dicom["levelsDeclined"].as_str()), (Some("stored"), None), "{json}");
    assert_eq!((json["copied"].as_u64(), json["encoded"].as_u64()), (Some(78), Some(0)), "{json}");
    let recompressed = &json["storedTiles"]["recompressed"];
    assert_eq!((recompressed["tiles"].as_u64(), recompressed["refused"].as_u64()), (Some(78), Some(0)), "{json}");
    assert!(recompressed["savedBytes"].as_i64().unwrap() > 0, "{json}");
    assert_eq!(dicom["transferSyntax"], RECOMPRESSION, "{json}");
    assert!(level_frames(&json).iter().all(|(t, p)| t == RECOMPRESSION && p == "YBR_FULL_422"), "{json}");
    dciodvfy(&out);
    if let Some(python) = readers() {
        let measured = check(&python, &out, &tif, 256, "jpeg", Some(&jpeg));
        assert_eq!(measured["rebuilt"], serde_json::json!([54, 15, 6, 2, 1]), "{measured}");
        assert!(measured["methods"].as_array().unwrap().iter().all(|m| m == &serde_json::json!(["ISO_10918_1"])));
    }
    // Our reader reads level 0 back as from the JPEG series, within libjxl's decoding of it.
    let theirs = level_0_tiles(&jpeg, &dir.path().join("jpeg-back"));
    let ours = level_0_tiles(&out, &dir.path().join("jxl-back"));
    assert!(!theirs.is_empty() && theirs.len() == ours.len());
    for ((name, want), (_, got)) in theirs.iter().zip(&ours).take(4) {
        let (want, got) = (want.to_rgb8(), got.to_rgb8());
        assert_close(
            &format!("dicom-jxl-levels-{name}"),
            Picture::new(got.width(), got.height(), 3, got.as_raw()),
            Picture::new(want.width(), want.height(), 3, want.as_raw()),
            Tolerance::mean(
                2.0,
                "a recompressed JPEG decodes through libjxl a few levels from libjpeg-turbo's decoding of it (50.8 dB, docs/jxl.md); a misplaced or miscoloured frame is tens of levels off",
            ),
        );
    }
}

/// Our reader refuses a damaged JPEG XL frame naming the file and the frame: one whose
/// signature is gone (no JPEG XL codestream), one whose header is damaged.
#[test]
fn a_damaged_jpeg_xl_frame_is_an_error_naming_it() {
    let dir = tempfile::tempdir().unwrap();
    let png = input(dir.path(), "rgb", 600, 300, PixelLayout::new(Channels::Rgb, Depth::U8));
    let out = dir.path().join("series");
    let args = ["split", s(&png), "--layout", "dicom", "-o", s(&out), "--pixel-size", "0.5um"];
    ok(&[&args[..], &["--codec", "jxl", "--lossless", "--jxl-effort", "1", "-q"]].concat());
    let level = out.join("level-0.dcm");
    let bytes = std::fs::read(&level).unwrap();
    // The Pixel Data element (7FE0,0010, OB, undefined length), then the Basic Offset
    // Table's item, then frame 0's item: its bytes 8 on.
    let pixel_data = (0..bytes.len() - 4).find(|&i| bytes[i..i + 4] == [0xE0, 0x7F, 0x10, 0x00]).unwrap();
    let table = pixel_data + 12;
    assert_eq!(bytes[table..table + 4], [0xFE, 0xFF, 0x00, 0xE0]);
    let length = u32::from_le_bytes(bytes[table + 4..table + 8].try_into().unwrap()) as usize;
    let frame = table + 8 + length + 8;
    assert_eq!(bytes[frame..frame + 2], [0xFF, 0x0A], "frame 0 is a bare codestream");
    for (name, at, damage, want) in
        [("unsigned", frame, &[0u8, 0][..], "no JPEG XL codestream"), ("header", frame + 2, &[0xFF; 8][..], "JPEG XL")]
    {
        let mut damaged = bytes.clone();
        damaged[at..at + damage.len()].copy_from_slice(damage);
        let series = dir.path().join(name);
        std::fs::create_dir(&series).unwrap();
        std::fs::write(series.join("level-0.dcm"), &damaged).unwrap();
        let back = dir.path().join(format!("{name}-back"));
        fails_with(&run(&["split", s(&series), "-o", s(&back), "--codec", "png"]), &["level-0.dcm", "frame 0", want]);
    }
}

/// What JPEG XL frames cannot hold is refused before anything is written, naming what to
/// change: alpha without `--flatten`, JPEG's subsampling, a 32-bit float image.
#[test]
fn jpeg_xl_refusals() {
    let dir = tempfile::tempdir().unwrap();
    let png = input(dir.path(), "in", 300, 200, PixelLayout::new(Channels::Rgb, Depth::U8));
    let alpha = input(dir.path(), "alpha", 300, 200, PixelLayout::new(Channels::Rgba, Depth::U8));
    let out = dir.path().join("series");
    let jxl = ["--layout", "dicom", "-o", s(&out), "--pixel-size", "1um", "--codec", "jxl"];
    for (input, extra, want) in [
        (&alpha, &[][..], &["alpha", "--flatten"][..]),
        (&png, &["--subsampling", "444"][..], &["--subsampling"][..]),
        (&png, &["--lossless", "--quality", "80"][..], &["--lossless", "--quality"][..]),
    ] {
        fails_with(&run(&[&["split", s(input)][..], &jxl, extra].concat()), want);
        assert!(!out.exists());
    }
}
