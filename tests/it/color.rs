//! Orientation and colour: EXIF orientation applied as viewers show the image, ICC profiles
//! converted to sRGB, CMYK JPEG. Inputs are made here and tagged with the tools people use
//! (exiftool, libvips); the pixels are compared with libvips (`vips autorot`, `vips
//! icc_transform`) and with a naive oracle written here.

use std::path::{Path, PathBuf};
use std::process::Command;

use vortex_tiler::pixel::{Channels, Depth, PixelLayout};
use vortex_tiler::source::orient::{self, Orientation};
use vortex_tiler::source::{self, OpenOptions, RowSource};

use crate::common::Image;
use crate::common::cli::{fails_with, ok, run, s};
use crate::common::compare::{Picture, Tolerance, assert_close};
use crate::common::decode_png_sized;
use vortex_tiler::limits::Budget;

const COLORD: &str = "/usr/share/color/icc/colord";

/// Whether `tool` runs; outside CI a missing one skips the test with a note.
fn have(tool: &str, version: &str, package: &str) -> bool {
    crate::common::have_program(tool, version, package)
}

fn have_tools() -> bool {
    have("vips", "--version", "libvips-tools")
        && have("exiftool", "-ver", "libimage-exiftool-perl")
        && Path::new(COLORD).is_dir()
}

fn tool(program: &str, args: &[&str]) {
    let out = Command::new(program).args(args).output().expect("tool runs");
    assert!(out.status.success(), "{program} {args:?}: {}", String::from_utf8_lossy(&out.stderr));
}

/// Sets a file's EXIF Orientation as a camera would (`exiftool -Orientation=N -n`).
fn tag_orientation(path: &Path, value: u16) {
    tool("exiftool", &["-q", "-overwrite_original", &format!("-Orientation={value}"), "-n", s(path)]);
}

/// Embeds the ICC profile `icc` in `path` without touching its pixels.
fn tag_profile(path: &Path, icc: &Path) {
    tool("exiftool", &["-q", "-overwrite_original", &format!("-icc_profile<={}", s(icc)), s(path)]);
}

/// Every row of `source`, widened to u16 samples.
fn read_all(mut source: Box<dyn RowSource>) -> (u32, u32, PixelLayout, Vec<u16>) {
    let (w, h, layout) = (source.width(), source.height(), source.layout());
    let mut row = vec![0u8; w as usize * layout.bytes_per_pixel()];
    let mut all = Vec::new();
    for _ in 0..h {
        source.read_row(&mut row).unwrap();
        match layout.depth {
            Depth::U8 => all.extend(row.iter().map(|&v| v as u16)),
            // These sources are 8- or 16-bit.
            _ => all.extend(row.chunks_exact(2).map(|b| u16::from_ne_bytes([b[0], b[1]]))),
        }
    }
    (w, h, layout, all)
}

fn shown(path: &Path) -> (u32, u32, PixelLayout, Vec<u16>) {
    read_all(source::open_with(path, OpenOptions::shown(Budget::new(1 << 30))).unwrap().source)
}

fn png_of(path: &Path) -> (u32, u32, Vec<u16>) {
    decode_png_sized(&std::fs::read(path).unwrap())
}

/// An asymmetric picture (no mirror or rotation of it equals another): gradients plus a block
/// in one corner.
fn picture(width: u32, height: u32, layout: PixelLayout) -> Vec<u8> {
    let mut v = Vec::new();
    for y in 0..height {
        for x in 0..width {
            let corner = x < width / 4 && y < height / 5;
            let rgb = [(x * 255 / width) as u16, (y * 255 / height) as u16, if corner { 250 } else { 40 }];
            // Grey takes the first sample, alpha the next (or 200 after RGB).
            for &value in rgb.iter().chain(&[200]).take(layout.channels.count()) {
                match layout.depth {
                    Depth::U8 => v.push(value as u8),
                    // Low bits that 8-bit sources lack.
                    _ => v.extend_from_slice(&(value * 257).saturating_add(x as u16).to_be_bytes()),
                }
            }
        }
    }
    v
}

fn write_png(path: &Path, width: u32, height: u32, layout: PixelLayout) {
    let file = std::fs::File::create(path).unwrap();
    let mut encoder = png::Encoder::new(std::io::BufWriter::new(file), width, height);
    encoder.set_color(match layout.channels {
        Channels::Grey => png::ColorType::Grayscale,
        Channels::GreyAlpha => png::ColorType::GrayscaleAlpha,
        Channels::Rgb => png::ColorType::Rgb,
        Channels::Rgba => png::ColorType::Rgba,
    });
    encoder.set_depth(if layout.depth == Depth::U8 { png::BitDepth::Eight } else { png::BitDepth::Sixteen });
    encoder.write_header().unwrap().write_image_data(&picture(width, height, layout)).unwrap();
}

const RGB8: PixelLayout = PixelLayout { channels: Channels::Rgb, depth: Depth::U8 };

/// The oracle: each orientation as the operations its EXIF definition names, on a whole image.
fn naive(image: &Image, orientation: u16) -> (u32, u32, Vec<u16>) {
    let (w, h, c) = (image.width as usize, image.height as usize, image.channels());
    let at = |x: usize, y: usize| &image.samples[(y * w + x) * c..][..c];
    // (shown width, shown height, stored texel for shown (x, y))
    let (sw, sh): (usize, usize) = if orientation >= 5 { (h, w) } else { (w, h) };
    let mut out = Vec::new();
    for y in 0..sh {
        for x in 0..sw {
            let texel = match orientation {
                1 => at(x, y),
                2 => at(w - 1 - x, y),         // mirror left-right
                3 => at(w - 1 - x, h - 1 - y), // rotate 180
                4 => at(x, h - 1 - y),         // mirror top-bottom
                5 => at(y, x),                 // transpose
                6 => at(y, h - 1 - x),         // rotate 90 clockwise
                7 => at(w - 1 - y, h - 1 - x), // transverse
                8 => at(w - 1 - y, x),         // rotate 90 anticlockwise
                _ => unreachable!(),
            };
            out.extend_from_slice(texel);
        }
    }
    (sw as u32, sh as u32, out)
}

#[test]
fn every_orientation_matches_a_naive_oracle_whole_and_in_passes() {
    for (w, h, layout) in [(7, 5, RGB8), (1, 9, RGB8), (13, 2, PixelLayout::new(Channels::GreyAlpha, Depth::U16))] {
        let image = Image::random(w, h, layout, 7);
        let bytes = (w.max(h) * w.max(h)) as u64 * layout.bytes_per_pixel() as u64;
        for orientation in 1..=8u16 {
            let want = naive(&image, orientation);
            // The whole image in one band; a third of it per band (7x5: three passes, each a
            // rewind of the source).
            for max_memory in [1 << 20, bytes / 3] {
                let o = Orientation::from_tag(orientation);
                let shown = orient::apply(Path::new("mem"), image.source(), o, max_memory).unwrap();
                let (sw, sh, _, got) = read_all(shown);
                assert_eq!((sw, sh, &got), (want.0, want.1, &want.2), "{w}x{h} orientation {orientation}");
            }
            // And read twice, as a striped run does.
            let mut shown =
                orient::apply(Path::new("mem"), image.source(), Orientation::from_tag(orientation), bytes / 3).unwrap();
            let mut row = vec![0u8; shown.width() as usize * layout.bytes_per_pixel()];
            shown.read_row(&mut row).unwrap();
            shown.rewind().unwrap();
            assert_eq!(read_all(shown).3, want.2, "rewound, orientation {orientation}");
        }
    }
    // Too little memory for a few passes: refused, naming the flag that keeps the stored order.
    let image = Image::random(64, 64, RGB8, 1);
    let err = orient::apply(Path::new("big.jpg"), image.source(), Orientation::from_tag(6), 64 * 3 * 2)
        .err()
        .unwrap()
        .to_string();
    assert!(err.contains("big.jpg") && err.contains("--no-autorotate") && err.contains("--max-memory"), "{err}");
    // A mirror streams within any memory.
    assert!(orient::apply(Path::new("m"), image.source(), Orientation::from_tag(2), 1).is_ok());
}

#[test]
fn jpeg_tiff_and_png_orientations_match_vips_autorot() {
    if !have_tools() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("base.png");
    write_png(&png, 60, 40, RGB8);
    let inputs: Vec<(PathBuf, &str)> = vec![
        (dir.path().join("base.jpg"), "base.png[0]"),
        (dir.path().join("base.tif"), "tiled"),
        (dir.path().join("strips.tif"), "strips"),
        (png.clone(), "png"),
    ];
    tool("vips", &["copy", s(&png), &format!("{}[Q=95]", s(&inputs[0].0))]);
    tool("vips", &["tiffsave", s(&png), s(&inputs[1].0), "--tile", "--tile-width", "16", "--tile-height", "16"]);
    tool("vips", &["tiffsave", s(&png), s(&inputs[2].0)]);
    for (base, _) in &inputs {
        let ext = base.extension().unwrap().to_str().unwrap();
        for orientation in 1..=8u16 {
            let path = dir.path().join(format!("{}-{orientation}.{ext}", base.file_stem().unwrap().to_str().unwrap()));
            std::fs::copy(base, &path).unwrap();
            tag_orientation(&path, orientation);
            let theirs = dir.path().join("vips.png");
            tool("vips", &["autorot", s(&path), s(&theirs)]);
            let (tw, th, want) = png_of(&theirs);
            let (w, h, _, got) = shown(&path);
            assert_eq!((w, h), (tw, th), "{} orientation {orientation}", path.display());
            // Both decode with libjpeg-turbo's accurate IDCT and fancy upsampling; the
            // decoders' versions may still round a sample differently, by one.
            let why = "libjpeg-turbo's accurate IDCT on both sides; their versions may round a sample by one";
            let (name, c) = (format!("autorot-{ext}-{orientation}"), got.len() / (w * h) as usize);
            assert_close(&name, Picture::new(w, h, c, &got), Picture::new(w, h, c, &want), Tolerance::max(1, why));
            // The stored order when asked.
            let options = OpenOptions { autorotate: false, ..OpenOptions::shown(Budget::new(1 << 30)) };
            let source = source::open_with(&path, options).unwrap().source;
            assert_eq!((source.width(), source.height()), (60, 40));
            if orientation != 1 {
                assert!(source.describe().contains("not applied (--no-autorotate)"), "{}", source.describe());
            }
        }
    }
}

/// Our conversion of `path` against `vips icc_transform --embedded` to sRGB.
fn compare_with_vips_icc(path: &Path, depth16: bool, tolerance: Tolerance) {
    let theirs = path.with_extension("vips.png");
    let mut args = vec!["icc_transform", s(path), s(&theirs), "srgb", "--embedded", "--intent", "relative"];
    if depth16 {
        args.extend(["--depth", "16"]);
    }
    tool("vips", &args);
    let (tw, th, want) = png_of(&theirs);
    let (w, h, layout, got) = shown(path);
    assert_eq!((w, h), (tw, th));
    // vips makes three bands of a grey image: compare its first.
    let want: Vec<u16> = if layout.channels == Channels::Grey && want.len() == got.len() * 3 {
        want.chunks_exact(3).map(|c| c[0]).collect()
    } else {
        want
    };
    let channels = got.len() / (w as usize * h as usize);
    let name = format!("vips-icc-{}", path.file_name().unwrap().to_string_lossy());
    assert_close(&name, Picture::new(w, h, channels, &got), Picture::new(w, h, channels, &want), tolerance);
}

#[test]
fn icc_profiles_are_converted_to_srgb_as_vips_does() {
    if !have_tools() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    // Both are LittleCMS (vips 8.14 uses it too) with the same intent; the differences left
    // are 8-bit rounding of the two pipelines (vips goes through 16-bit or float Lab) and
    // JPEG decoding: one level for 8-bit, 1/256 of the range (257 + a few) for 16-bit.
    for (profile, name) in [("AdobeRGB1998.icc", "adobe"), ("ProPhotoRGB.icc", "prophoto")] {
        let icc = Path::new(COLORD).join(profile);
        let png = dir.path().join(format!("{name}.png"));
        write_png(&png, 48, 32, RGB8);
        let jpg = png.with_extension("jpg");
        let tif = png.with_extension("tif");
        tool("vips", &["copy", s(&png), &format!("{}[Q=95,strip]", s(&jpg))]);
        tool("vips", &["tiffsave", s(&png), s(&tif), "--tile", "--tile-width", "16", "--tile-height", "16"]);
        // A JPEG-compressed TIFF has a source of its own (`tiff/jpeg.rs`): its profile too.
        let jpeg_tif = dir.path().join(format!("{name}-jpeg.tif"));
        let tiled = ["--tile", "--tile-width", "16", "--tile-height", "16", "--compression", "jpeg", "--Q", "95"];
        tool("vips", &[&["tiffsave", s(&png), s(&jpeg_tif)][..], &tiled].concat());
        for path in [&png, &jpg, &tif, &jpeg_tif] {
            tag_profile(path, &icc);
            assert!(source::open(path, Budget::new(1 << 30)).unwrap().embedded().icc.is_some(), "{}", path.display());
            let why = "LittleCMS on both sides; 8-bit rounding of the two pipelines and JPEG decoding";
            compare_with_vips_icc(path, false, Tolerance::max_and_mean(2, 0.5, why));
            let source = source::open_with(path, OpenOptions::shown(Budget::new(1 << 30))).unwrap().source;
            assert!(source.describe().contains("converted to sRGB"), "{}", source.describe());
        }
        // A PNG as libvips writes one with a profile (`vips copy x.png y.png[profile=..]`: its
        // iCCP named "icc", before pHYs), not as exiftool retags one.
        let vips_png = dir.path().join(format!("{name}-vips.png"));
        tool("vips", &["copy", s(&png), &format!("{}[profile={}]", s(&vips_png), s(&icc))]);
        let why = "LittleCMS on both sides; 8-bit rounding of the two pipelines";
        compare_with_vips_icc(&vips_png, false, Tolerance::max_and_mean(2, 0.5, why));
        // 16 bits stay 16 bits.
        let deep = dir.path().join(format!("{name}-16.png"));
        write_png(&deep, 48, 32, PixelLayout::new(Channels::Rgba, Depth::U16));
        tag_profile(&deep, &icc);
        let source = source::open_with(&deep, OpenOptions::shown(Budget::new(1 << 30))).unwrap().source;
        assert_eq!(source.layout(), PixelLayout::new(Channels::Rgba, Depth::U16));
        let why = "LittleCMS on both sides; vips' 16-bit or float Lab rounds to 1/256 of the range (257 + a few)";
        compare_with_vips_icc(&deep, true, Tolerance::max_and_mean(300, 40.0, why));
    }
    // sRGB itself is left alone.
    let png = dir.path().join("srgb.png");
    write_png(&png, 48, 32, RGB8);
    let plain = read_all(source::open(&png, Budget::new(1 << 30)).unwrap()).3;
    tag_profile(&png, &Path::new(COLORD).join("sRGB.icc"));
    let source = source::open_with(&png, OpenOptions::shown(Budget::new(1 << 30))).unwrap().source;
    assert!(source.describe().contains("is sRGB: left as is"), "{}", source.describe());
    assert_eq!(read_all(source).3, plain);
}

#[test]
fn grey_profiles_are_converted_too() {
    if !have_tools() {
        return;
    }
    // A grey profile with a gamma-1.0 (linear) curve, made with LittleCMS; vips converts it
    // through the same library.
    let dir = tempfile::tempdir().unwrap();
    let d50 = lcms2::CIExyY { x: 0.3457, y: 0.3585, Y: 1.0 };
    let linear = lcms2::Profile::new_gray(&d50, &lcms2::ToneCurve::new(1.0)).unwrap().icc().unwrap();
    let icc = dir.path().join("linear-grey.icc");
    std::fs::write(&icc, linear).unwrap();
    let png = dir.path().join("grey.png");
    write_png(&png, 40, 30, PixelLayout::new(Channels::Grey, Depth::U8));
    tag_profile(&png, &icc);
    let source = source::open_with(&png, OpenOptions::shown(Budget::new(1 << 30))).unwrap().source;
    assert_eq!(source.layout().channels, Channels::Grey);
    let why = "a linear grey profile through LittleCMS on both sides: 8-bit rounding";
    compare_with_vips_icc(&png, false, Tolerance::max_and_mean(2, 0.6, why));
}

/// A JPEG with an APP2 ICC_PROFILE segment holding `body`, spliced in after SOI.
fn jpeg_with_icc(dir: &Path, body: &[u8]) -> PathBuf {
    let path = dir.join("damaged-icc.jpg");
    let encoder = jpeg_encoder::Encoder::new_file(&path, 90).unwrap();
    encoder.encode(&picture(16, 16, RGB8), 16, 16, jpeg_encoder::ColorType::Rgb).unwrap();
    let bytes = std::fs::read(&path).unwrap();
    let mut segment = b"ICC_PROFILE\0\x01\x01".to_vec();
    segment.extend_from_slice(body);
    let mut out = bytes[..2].to_vec();
    out.extend_from_slice(&[0xFF, 0xE2]);
    out.extend_from_slice(&((segment.len() + 2) as u16).to_be_bytes());
    out.extend_from_slice(&segment);
    out.extend_from_slice(&bytes[2..]);
    std::fs::write(&path, out).unwrap();
    path
}

#[test]
fn a_damaged_profile_is_a_clear_error_and_keep_icc_takes_it_as_it_is() {
    let dir = tempfile::tempdir().unwrap();
    // Not a profile at all, then a real profile cut short.
    let srgb = lcms2::Profile::new_srgb().icc().unwrap();
    for body in [b"this is not an ICC profile".to_vec(), srgb[..srgb.len() / 2].to_vec()] {
        let path = jpeg_with_icc(dir.path(), &body);
        let err = source::open_with(&path, OpenOptions::shown(Budget::new(1 << 30))).err().unwrap().to_string();
        assert!(err.contains("damaged-icc.jpg") && err.contains("ICC profile") && err.contains("--keep-icc"), "{err}");
        let out = run(&["split", s(&path), "-o", s(&dir.path().join("out"))]);
        fails_with(&out, &["damaged-icc.jpg", "ICC profile"]);
        // --keep-icc keeps the pixels and the bytes as they are.
        let keep = OpenOptions { keep_icc: true, ..OpenOptions::shown(Budget::new(1 << 30)) };
        let source::Opened { source, icc: kept, .. } = source::open_with(&path, keep).unwrap();
        assert_eq!(kept.as_deref(), Some(&body[..]));
        assert_eq!(read_all(source).3, read_all(source::open(&path, Budget::new(1 << 30)).unwrap()).3);
    }
}

#[test]
fn cmyk_jpeg_is_converted_through_its_profile_or_the_default_one() {
    let default = Path::new(source::icc::DEFAULT_CMYK_PROFILE);
    if !have_tools() || !default.is_file() {
        crate::common::skip_unless_ci(
            "the CMYK test",
            &format!("no {} (apt-get install ghostscript)", default.display()),
        );
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("rgb.png");
    write_png(&png, 48, 32, RGB8);
    // vips writes CMYK JPEG as Photoshop does: Adobe APP14, inverted samples, the profile in APP2.
    let tagged = dir.path().join("cmyk.jpg");
    tool("vips", &["icc_export", s(&png), &format!("{}[Q=95]", s(&tagged)), "--output-profile", s(default)]);
    let bytes = std::fs::read(&tagged).unwrap();
    assert!(bytes.windows(7).any(|w| w == b"\xff\xeeA\0\x0eAd" || w.starts_with(b"Adobe")), "no APP14");
    let source = source::open_with(&tagged, OpenOptions::shown(Budget::new(1 << 30))).unwrap().source;
    assert!(source.describe().contains("CMYK, Adobe-inverted") && source.describe().contains("embedded ICC"));
    assert_eq!(source.layout(), RGB8);
    // LittleCMS on both sides, through a CLUT profile: rounding of the two pipelines plus
    // JPEG decoding of four channels.
    let why = "LittleCMS on both sides through a CLUT profile, and JPEG decoding of four channels";
    compare_with_vips_icc(&tagged, false, Tolerance::max_and_mean(3, 0.6, why));

    // Without a profile: the default one, as vips is told to use it.
    let bare = dir.path().join("bare.jpg");
    tool("vips", &["copy", s(&tagged), &format!("{}[Q=95,strip]", s(&bare))]);
    assert!(source::open(&bare, Budget::new(1 << 30)).unwrap().embedded().icc.is_none());
    let theirs = dir.path().join("bare.vips.png");
    tool(
        "vips",
        &["icc_transform", s(&bare), s(&theirs), "srgb", "--input-profile", s(default), "--intent", "relative"],
    );
    let source = source::open_with(&bare, OpenOptions::shown(Budget::new(1 << 30))).unwrap().source;
    assert!(source.describe().contains("no profile embedded"), "{}", source.describe());
    let (w, h, _, ours) = read_all(source);
    let why = "LittleCMS on both sides through the default CMYK profile, and JPEG decoding of four channels";
    let theirs = png_of(&theirs).2;
    assert_close(
        "cmyk-default",
        Picture::new(w, h, 3, &ours),
        Picture::new(w, h, 3, &theirs),
        Tolerance::max_and_mean(3, 0.6, why),
    );
}

#[test]
fn split_says_what_it_did_and_keeps_the_profile_when_asked() {
    if !have_tools() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("photo.png");
    write_png(&png, 300, 200, RGB8);
    let jpg = dir.path().join("photo.jpg");
    tool("vips", &["copy", s(&png), s(&jpg)]);
    tag_orientation(&jpg, 6);
    let icc = Path::new(COLORD).join("AdobeRGB1998.icc");
    tag_profile(&jpg, &icc);

    let out = dir.path().join("out");
    let line = ok(&["split", s(&jpg), "-o", s(&out), "--codec", "png"]);
    assert!(line.contains("rotated 90° clockwise (EXIF orientation 6") && line.contains("converted to sRGB"), "{line}");
    let info: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("info.json")).unwrap()).unwrap();
    assert_eq!((info["width"].as_u64(), info["height"].as_u64()), (Some(200), Some(300)));
    assert!(info.get("iccProfile").is_none());

    let out = dir.path().join("kept");
    let json = ok(&["split", s(&jpg), "-o", s(&out), "--codec", "png", "--no-autorotate", "--keep-icc", "--json"]);
    let doc: serde_json::Value = serde_json::from_str(json.trim()).unwrap();
    let said = doc["source"].as_str().unwrap();
    assert!(said.contains("--no-autorotate") && said.contains("--keep-icc"), "{said}");
    let info: serde_json::Value =
        serde_json::from_str(&std::fs::read_to_string(out.join("info.json")).unwrap()).unwrap();
    assert_eq!((info["width"].as_u64(), info["height"].as_u64()), (Some(300), Some(200)));
    use base64::Engine;
    let kept = base64::engine::general_purpose::STANDARD.decode(info["iccProfile"].as_str().unwrap()).unwrap();
    assert_eq!(kept, std::fs::read(&icc).unwrap());
    // A viewer layout keeps it in its tiles (tests/it/keep_icc.rs).
}

#[test]
fn a_rotated_tiff_larger_than_max_memory_is_read_in_passes() {
    if !have_tools() {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    let png = dir.path().join("big.png");
    write_png(&png, 96, 64, RGB8);
    let tif = dir.path().join("big.tif");
    tool("vips", &["tiffsave", s(&png), s(&tif), "--tile", "--tile-width", "16", "--tile-height", "16"]);
    // 96x64 RGB is 18 KiB; 7 KiB of --max-memory holds a third of it.
    let max_memory = 7 * 1024;
    for (orientation, passes) in [(6u16, "3 passes"), (3, "3 passes"), (2, "streamed")] {
        let path = dir.path().join(format!("big-{orientation}.tif"));
        std::fs::copy(&tif, &path).unwrap();
        tag_orientation(&path, orientation);
        let source = source::open_with(&path, OpenOptions::shown(Budget::new(max_memory))).unwrap().source;
        assert!(source.describe().contains(passes), "{}", source.describe());
        let theirs = dir.path().join("vips.png");
        tool("vips", &["autorot", s(&path), s(&theirs)]);
        let (tw, th, want) = png_of(&theirs);
        let (w, h, _, got) = read_all(source);
        // Lossless on both sides: the same texels.
        assert_eq!((w, h, got), (tw, th, want), "orientation {orientation}");
    }
}
