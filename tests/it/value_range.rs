//! `split --range MIN:MAX`: 32-bit integer and float samples mapped linearly onto 8 or 16 bits
//! for PNG and JPEG tiles, values outside clamped and counted (docs/sources.md).

use std::path::{Path, PathBuf};

use crate::common::cli::{ok, run, s};
use tiff::encoder::{TiffEncoder, colortype};

/// The finest level's texels of a tile directory whose one tile covers the image (`width` x
/// `height`), decoded from its PNG as 16-bit samples (8-bit PNGs widened by 257) or 8-bit.
fn finest_png(dir: &Path, width: u32, height: u32) -> image::DynamicImage {
    for entry in std::fs::read_dir(dir).unwrap() {
        let path = entry.unwrap().path();
        if path.extension().is_some_and(|e| e == "png") {
            let img = image::open(&path).unwrap();
            if img.width() >= width && img.height() >= height && path.to_string_lossy().contains("lod00") {
                return img;
            }
        }
    }
    panic!("no finest PNG tile in {}", dir.display());
}

/// `values` (32 of them) as an 8x4 grey float TIFF `f.tif` in `dir`.
fn float_tif(dir: &Path, values: &[f32]) -> PathBuf {
    let tif = dir.join("f.tif");
    let mut encoder = TiffEncoder::new(std::fs::File::create(&tif).unwrap()).unwrap();
    encoder.write_image::<colortype::Gray32Float>(8, 4, values).unwrap();
    tif
}

/// A float image into 8-bit PNG through --range 0:1: each value's code is round(v * 255)
/// (halves away from zero), those outside 0..1 and NaN clamped, and the summary counts them.
#[test]
fn floats_map_onto_8_bits_exactly_and_clamped_ones_are_counted() {
    let dir = tempfile::tempdir().unwrap();
    // (value, expected code, outside the range)
    let cases: [(f32, u8, bool); 8] = [
        (0.0, 0, false),
        (1.0, 255, false),
        (0.5, 128, false), // 127.5: halves away from zero
        (0.25, 64, false), // 63.75
        (0.1, 26, false),  // 25.5
        (-0.5, 0, true),
        (7.0, 255, true),
        (f32::NAN, 0, true),
    ];
    let values: Vec<f32> = (0..4).flat_map(|_| cases.map(|c| c.0)).collect();
    let tif = float_tif(dir.path(), &values);
    let out = dir.path().join("out");
    let args = ["split", s(&tif), "-o", s(&out), "--codec", "png", "--tile-size", "8", "--border", "0"];
    let said = ok(&[&args[..], &["--range", "0:1", "--filter", "box", "--json"]].concat());
    assert!(said.contains("12 samples outside --range clamped to it"), "{said}");
    assert!(said.contains("mapped from float to 8 bits (--range 0:1)"), "{said}");
    let img = finest_png(&out, 8, 4).to_luma8();
    for y in 0..4 {
        for (x, (value, code, _)) in cases.iter().enumerate() {
            assert_eq!(img.get_pixel(x as u32, y).0[0], *code, "{value} at ({x}, {y})");
        }
    }
    // Without --range the PNG codec refuses, naming it.
    let out2 = dir.path().join("refused");
    let refused = run(&["split", s(&tif), "-o", s(&out2), "--codec", "png"]);
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(!refused.status.success() && err.contains("--range MIN:MAX"), "{err}");
}

/// 32-bit integers onto 16 bits (--tile-type unsignedShort): code = round((v - MIN) * 65535 /
/// (MAX - MIN)); none outside; an 8-bit source and a 32-bit tile type with --range are refused.
#[test]
fn integers_map_onto_16_bits_exactly() {
    let dir = tempfile::tempdir().unwrap();
    let tif = dir.path().join("u.tif");
    let values: Vec<u32> = (0..32).map(|i| 1000 + i * 100).collect(); // 1000 ..= 4100
    let mut encoder = TiffEncoder::new(std::fs::File::create(&tif).unwrap()).unwrap();
    encoder.write_image::<colortype::Gray32>(8, 4, &values).unwrap();
    let out = dir.path().join("out");
    let said = ok(&[
        "split",
        s(&tif),
        "-o",
        s(&out),
        "--codec",
        "png",
        "--tile-size",
        "8",
        "--border",
        "0",
        "--range",
        "1000:4100",
        "--tile-type",
        "unsignedShort",
        "--filter",
        "box",
    ]);
    assert!(said.contains("no sample outside --range"), "{said}");
    let img = finest_png(&out, 8, 4).to_luma16();
    for (i, v) in values.iter().enumerate() {
        let want = ((*v as f64 - 1000.0) * 65535.0 / 3100.0).round() as u16;
        assert_eq!(img.get_pixel(i as u32 % 8, i as u32 / 8).0[0], want, "{v}");
    }
    let refused = |extra: &[&str], needle: &str| {
        let out = run(&[&["split", s(&tif), "-o", s(&dir.path().join("r"))][..], extra].concat());
        let err = String::from_utf8_lossy(&out.stderr);
        assert!(!out.status.success() && err.contains(needle), "{needle:?} missing from: {err}");
    };
    refused(&["--range", "0:1", "--codec", "raw", "--tile-type", "unsignedInt"], "leave --range out");
    refused(&["--range", "2:1"], "MIN must be below MAX");
    let png = dir.path().join("eight.png");
    image::GrayImage::new(4, 4).save(&png).unwrap();
    let out = run(&["split", s(&png), "-o", s(&dir.path().join("r8")), "--range", "0:1"]);
    assert!(String::from_utf8_lossy(&out.stderr).contains("8-bit"), "{:?}", out);
}

/// `convert --range`: a float pack (raw tiles, kept as float) re-tiled into 8-bit PNG maps as
/// split's --range does, code for code; without --range the PNG codec refuses, naming the flag.
#[test]
fn convert_maps_a_float_pack_as_split_does() {
    let dir = tempfile::tempdir().unwrap();
    let values: Vec<f32> = (0..32).map(|i| i as f32 / 20.0 - 0.2).collect(); // -0.2 ..= 1.35
    let tif = float_tif(dir.path(), &values);
    let pack = dir.path().join("f.vtpk");
    let tiles = ["--tile-size", "8", "--border", "0", "--filter", "box"];
    ok(&[&["split", s(&tif), "--pack", s(&pack), "--codec", "raw"][..], &tiles].concat());
    let out = dir.path().join("out");
    let said = ok(&[&["convert", s(&pack), "-o", s(&out), "--codec", "png", "--range", "0:1"][..], &tiles].concat());
    let outside = values.iter().filter(|v| !(0.0..=1.0).contains(*v)).count();
    assert!(said.contains(&format!("{outside} samples outside --range clamped to it")), "{said}");
    let img = finest_png(&out, 8, 4).to_luma8();
    for (i, v) in values.iter().enumerate() {
        let want = (*v as f64 * 255.0).clamp(0.0, 255.0).round() as u8;
        assert_eq!(img.get_pixel(i as u32 % 8, i as u32 / 8).0[0], want, "{v}");
    }
    let refused = run(&["convert", s(&pack), "-o", s(&dir.path().join("refused")), "--codec", "png"]);
    let err = String::from_utf8_lossy(&refused.stderr);
    assert!(!refused.status.success() && err.contains("--range MIN:MAX"), "{err}");
}

/// A negative MIN written as the help writes it, `--range -0.5:1.5` (two arguments, no `=`):
/// the parser takes it as the flag's value, not as an unknown flag, for split and convert.
#[test]
fn a_negative_min_is_taken_without_an_equals_sign() {
    let dir = tempfile::tempdir().unwrap();
    let values: Vec<f32> = (0..32).map(|i| i as f32 / 16.0 - 0.5).collect(); // -0.5 ..= 1.4375
    let tif = float_tif(dir.path(), &values);
    let tiles = ["--tile-size", "8", "--border", "0", "--filter", "box"];
    let out = dir.path().join("split");
    let said = ok(&[&["split", s(&tif), "-o", s(&out), "--codec", "png", "--range", "-0.5:1.5"][..], &tiles].concat());
    assert!(said.contains("(--range -0.5:1.5)"), "{said}");
    let img = finest_png(&out, 8, 4).to_luma8();
    for (i, v) in values.iter().enumerate() {
        let want = ((*v as f64 + 0.5) * 255.0 / 2.0).round() as u8;
        assert_eq!(img.get_pixel(i as u32 % 8, i as u32 / 8).0[0], want, "{v}");
    }
    let pack = dir.path().join("f.vtpk");
    ok(&[&["split", s(&tif), "--pack", s(&pack), "--codec", "raw"][..], &tiles].concat());
    let converted = dir.path().join("convert");
    let args = ["convert", s(&pack), "-o", s(&converted), "--codec", "png", "--range", "-0.5:1.5"];
    ok(&[&args[..], &tiles].concat());
    assert!(finest_png(&converted, 8, 4).to_luma8() == img, "convert maps as split does");
    // A flag where the value should be is still refused, naming what was expected.
    let out = run(&["split", s(&tif), "-o", s(&dir.path().join("r")), "--range", "--json"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("MIN:MAX"), "{err}");
}
