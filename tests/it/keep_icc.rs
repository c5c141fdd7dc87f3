//! `split --keep-icc`: the kept profile written into every JPEG and PNG tile file (APP2
//! ICC_PROFILE, iCCP) as well as info.json, read back by exiftool and libvips.

use std::path::{Path, PathBuf};
use std::process::Command;

use crate::common::cli::{ok, s};
use crate::tiff_slides::{have_tools, pattern_png, tool};

const ADOBE_RGB: &str = "/usr/share/color/icc/colord/AdobeRGB1998.icc";

/// Every tile file (by extension) under `dir`.
fn tiles(dir: &Path, extension: &str) -> Vec<PathBuf> {
    let mut found = Vec::new();
    let mut stack = vec![dir.to_path_buf()];
    while let Some(d) = stack.pop() {
        for entry in std::fs::read_dir(&d).unwrap() {
            let path = entry.unwrap().path();
            if path.is_dir() {
                stack.push(path);
            } else if path.extension().is_some_and(|e| e == extension) {
                found.push(path);
            }
        }
    }
    found
}

/// The ICC profile exiftool finds in `file` (its APP2 chunks joined, or its iCCP inflated).
fn exiftool_profile(file: &Path) -> Vec<u8> {
    let out = Command::new("exiftool").args(["-b", "-ICC_Profile", s(file)]).output().unwrap();
    assert!(out.status.success(), "exiftool {}: {}", file.display(), String::from_utf8_lossy(&out.stderr));
    out.stdout
}

/// A 300x200 JPEG carrying the Adobe RGB profile as libvips writes it, in a new temporary
/// directory, and the profile's bytes; `None` (skipped) without libvips or the profile.
fn adobe_jpeg() -> Option<(tempfile::TempDir, PathBuf, Vec<u8>)> {
    if !have_tools() || !Path::new(ADOBE_RGB).is_file() {
        crate::common::skip_unless_ci(
            "the kept-profile test",
            "no colord-data's AdobeRGB1998.icc (apt-get install colord-data)",
        );
        return None;
    }
    let dir = tempfile::tempdir().unwrap();
    let png = pattern_png(dir.path(), 300, 200);
    let jpg = dir.path().join("adobe.jpg");
    tool("vips", &["jpegsave", s(&png), s(&jpg), "--profile", ADOBE_RGB]);
    let profile = std::fs::read(ADOBE_RGB).unwrap();
    Some((dir, jpg, profile))
}

/// The ICC profile libvips finds in `tile` (`vipsheader` prints it in base64).
fn vips_profile(tile: &Path) -> Vec<u8> {
    use base64::Engine;
    let header = Command::new("vipsheader").args(["-f", "icc-profile-data", s(tile)]).output().unwrap();
    let said = String::from_utf8_lossy(&header.stdout);
    base64::engine::general_purpose::STANDARD.decode(said.trim()).unwrap()
}

/// An Adobe RGB JPEG cut with --keep-icc into JPEG tiles (tile directory) and PNG tiles (Deep
/// Zoom): every tile carries the profile, byte for byte, as exiftool and libvips read it.
#[test]
fn kept_profiles_are_in_every_tile() {
    let Some((dir, jpg, profile)) = adobe_jpeg() else { return };
    let Ok(probe) = Command::new("exiftool").arg("-ver").output() else {
        crate::common::skip_unless_ci("the kept-profile test", "no exiftool (apt-get install libimage-exiftool-perl)");
        return;
    };
    assert!(probe.status.success());
    assert_eq!(exiftool_profile(&jpg), profile, "the input carries the profile");

    let out = dir.path().join("jpeg-tiles");
    ok(&["split", s(&jpg), "-o", s(&out), "--keep-icc", "--tile-size", "128", "--codec", "jpeg"]);
    let jpegs = tiles(&out, "jpg");
    assert!(jpegs.len() >= 6, "{jpegs:?}");
    for tile in &jpegs {
        assert_eq!(exiftool_profile(tile), profile, "{}", tile.display());
    }
    let dzi = dir.path().join("slide.dzi");
    ok(&["split", s(&jpg), "-o", s(&dzi), "--layout", "dzi", "--keep-icc", "--tile-size", "128", "--codec", "png"]);
    let pngs = tiles(&dzi, "png");
    assert!(pngs.len() >= 6, "{pngs:?}");
    for tile in &pngs {
        assert_eq!(exiftool_profile(tile), profile, "{}", tile.display());
    }
    // libvips reads the same profile from both kinds of tile.
    for tile in [&jpegs[0], &pngs[0]] {
        assert_eq!(vips_profile(tile), profile, "{}", tile.display());
    }
    // Without --keep-icc the texels are converted to sRGB and no tile carries a profile.
    let plain = dir.path().join("plain");
    ok(&["split", s(&jpg), "-o", s(&plain), "--tile-size", "128", "--codec", "jpeg"]);
    for tile in tiles(&plain, "jpg") {
        assert!(exiftool_profile(&tile).is_empty(), "{}", tile.display());
    }
}

/// `convert` of a pyramid a `split --keep-icc` run wrote: with --keep-icc the profile goes on
/// into the new tiles and info.json; without, the texels are converted to sRGB, the same as
/// `split` converts the original (tile for tile, byte for byte).
#[test]
fn convert_keeps_or_converts_a_kept_profile() {
    let Some((dir, jpg, profile)) = adobe_jpeg() else { return };
    let args = ["--tile-size", "128", "--codec", "png", "--border", "0"];
    let kept = dir.path().join("kept");
    ok(&[&["split", s(&jpg), "-o", s(&kept), "--keep-icc"][..], &args].concat());

    let still = dir.path().join("still-kept");
    let said = ok(&[&["convert", s(&kept), "-o", s(&still), "--keep-icc"][..], &args].concat());
    assert!(said.contains("ICC profile kept"), "{said}");
    let info = std::fs::read_to_string(still.join("info.json")).unwrap();
    assert!(info.contains("\"iccProfile\""), "{info}");
    for tile in tiles(&still, "png") {
        assert_eq!(vips_profile(&tile), profile, "{}", tile.display());
    }

    let converted = dir.path().join("converted");
    let said = ok(&[&["convert", s(&kept), "-o", s(&converted)][..], &args].concat());
    assert!(said.contains("converted to sRGB"), "{said}");
    let split = dir.path().join("split");
    ok(&[&["split", s(&jpg), "-o", s(&split)][..], &args].concat());
    let info = std::fs::read_to_string(converted.join("info.json")).unwrap();
    assert!(!info.contains("iccProfile"), "{info}");
    let lod0 = |d: &Path| {
        let mut t: Vec<PathBuf> = tiles(d, "png").into_iter().filter(|p| s(p).contains("lod00")).collect();
        t.sort();
        t.iter().map(|p| image::open(p).unwrap().to_rgb8().into_raw()).collect::<Vec<_>>()
    };
    let (ours, theirs) = (lod0(&converted), lod0(&split));
    assert_eq!(ours.len(), 6);
    assert!(ours == theirs, "convert's sRGB texels differ from split's");
}

/// A pack keeps the profile once, in its metadata (`iccProfile`, docs/pack-format.md), for PNG
/// tiles as for JPEG (its tiles carry no copy of it); `convert PACK -o DIR --keep-icc` writes it
/// into every PNG tile of the directory it makes, as `split -o` does.
#[test]
fn a_pack_keeps_the_profile_in_its_metadata() {
    let Some((dir, jpg, profile)) = adobe_jpeg() else { return };
    use base64::Engine;
    let args = ["--tile-size", "128", "--codec", "png", "--keep-icc"];
    let pack = dir.path().join("kept.vtpk");
    ok(&[&["split", s(&jpg), "--pack", s(&pack)][..], &args].concat());
    let opened = vortex_tiler::vortex_pack::Pack::open(&pack).unwrap();
    let meta: serde_json::Value = serde_json::from_slice(opened.metadata()).unwrap();
    let kept = base64::engine::general_purpose::STANDARD.decode(meta["iccProfile"].as_str().unwrap()).unwrap();
    assert_eq!(kept, profile, "the pack's metadata holds the profile");
    let out = dir.path().join("from-pack");
    ok(&[&["convert", s(&pack), "-o", s(&out)][..], &args].concat());
    let pngs = tiles(&out, "png");
    assert!(pngs.len() >= 6, "{pngs:?}");
    for tile in &pngs {
        assert_eq!(vips_profile(tile), profile, "{}", tile.display());
    }
}

/// A TIFF output keeps the profile in every level's ICC tag (34675): libvips reads it from
/// the first page and from a reduced one (`[page=1]`), and exiftool from the file; without
/// --keep-icc the file carries none.
#[test]
fn a_tiff_keeps_the_profile_in_every_level() {
    let Some((dir, jpg, profile)) = adobe_jpeg() else { return };
    let tiff = dir.path().join("kept.tif");
    ok(&["split", s(&jpg), "-o", s(&tiff), "--keep-icc", "--tile-size", "64", "--codec", "deflate"]);
    assert_eq!(vips_profile(&tiff), profile, "level 0");
    let page1 = format!("{}[page=1]", s(&tiff));
    assert_eq!(vips_profile(Path::new(&page1)), profile, "level 1");
    let plain = dir.path().join("plain.tif");
    ok(&["split", s(&jpg), "-o", s(&plain), "--tile-size", "64", "--codec", "deflate"]);
    assert!(vips_profile(&plain).is_empty(), "no profile without --keep-icc");
}
