//! DICOM whole-slide images out (`--layout dicom -o DIR`; docs/dicom.md): every instance
//! checked by dciodvfy (Debian's dicom3tools), and the series read back by pydicom, highdicom,
//! wsidicom and OpenSlide 4 through the Python named by VORTEX_PYVIPS (`dicom_out.py`), each
//! skipped with a note where missing outside CI and a failure under CI. Every level read back
//! must be within JPEG's error of a naive box pyramid of the source (tiff_oracle.py: 30 dB,
//! between the 35 dB JPEG Q85 measures on these images and the under 20 dB of a reader that
//! takes YCbCr for RGB).

use std::path::{Path, PathBuf};
use std::process::Command;

use vortex_tiler::pixel::{Channels, Depth, PixelLayout};

use crate::common::cli::{fails_with, ok, run, s};
use crate::ome_zarr::input;

pub(crate) const SCRIPT: &str = concat!(env!("CARGO_MANIFEST_DIR"), "/tests/it/dicom_out.py");

fn rgb8() -> PixelLayout {
    PixelLayout::new(Channels::Rgb, Depth::U8)
}

/// The Python with pydicom, highdicom, wsidicom and OpenSlide 4, or a skip with a note (a
/// failure under CI).
pub(crate) fn readers() -> Option<PathBuf> {
    crate::common::python_with(
        "pydicom, highdicom, wsidicom, openslide, pyvips, tifffile, numpy",
        "the DICOM readers",
        "pydicom, highdicom, wsidicom, openslide-python and openslide-bin",
    )
}

/// Runs `dicom_out.py` on the series in `dir`; fails with what it said; returns its JSON.
fn check(python: &Path, dir: &Path, source: &Path, tile: u32, copied_from: Option<&Path>) -> serde_json::Value {
    let tile = tile.to_string();
    let mut args = vec![SCRIPT, s(dir), s(source), &tile];
    args.extend(copied_from.map(s));
    let out = Command::new(python).args(&args).output().unwrap();
    let said = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
    assert!(out.status.success(), "{}: {said}", dir.display());
    eprintln!("{}: {said}", dir.display());
    let line = String::from_utf8_lossy(&out.stdout);
    serde_json::from_str(line.trim().lines().last().unwrap_or("{}")).unwrap()
}

/// The warnings dciodvfy is allowed to give, each with why it stands (docs/dicom.md); an
/// error is never allowed.
pub(crate) const ACCEPTED_WARNINGS: &[(&str, &str)] = &[(
    "Missing attribute or value that would be needed to build DICOMDIR",
    "Patient ID, Study Date, Study Time and Study ID are type 2, left empty unless --dicom-meta \
     gives them (never invented); only a DICOMDIR, which we do not write, would need them",
)];

/// dciodvfy on every instance of `dir`: no error; every warning one of [`ACCEPTED_WARNINGS`].
/// Skipped with a note where dicom3tools is missing outside CI.
fn dciodvfy(dir: &Path) {
    if !crate::common::have_program("dciodvfy", "-help", "dicom3tools") {
        return;
    }
    let mut instances: Vec<PathBuf> = std::fs::read_dir(dir).unwrap().map(|e| e.unwrap().path()).collect();
    instances.sort();
    assert!(!instances.is_empty());
    for dcm in instances {
        let out = Command::new("dciodvfy").arg(&dcm).output().unwrap();
        let said = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
        let errors: Vec<&str> = said.lines().filter(|l| l.starts_with("Error")).collect();
        assert!(errors.is_empty(), "dciodvfy {}: {}", dcm.display(), said);
        for warning in said.lines().filter(|l| l.starts_with("Warning")) {
            let known = ACCEPTED_WARNINGS.iter().any(|(w, _)| warning.contains(w));
            assert!(known, "dciodvfy {}: an unexplained warning: {warning}\n{said}", dcm.display());
        }
    }
}

fn files(dir: &Path) -> Vec<(String, Vec<u8>)> {
    let mut out: Vec<(String, Vec<u8>)> = std::fs::read_dir(dir)
        .unwrap()
        .map(|e| e.unwrap())
        .map(|e| (e.file_name().to_string_lossy().into_owned(), std::fs::read(e.path()).unwrap()))
        .collect();
    out.sort();
    out
}

/// An RGB image encoded (no JPEG-tiled source): one valid instance a level, read back by
/// every reader within JPEG's error of the exact pyramid; the same bytes on a second run
/// (the UIDs are a hash of the input and options); other UIDs with another root.
#[test]
fn a_series_is_valid_read_back_by_every_reader_and_the_same_on_every_run() {
    let dir = tempfile::tempdir().unwrap();
    let png = input(dir.path(), "slide", 1000, 700, rgb8());
    let out = dir.path().join("series");
    let json = ok(&["split", s(&png), "--layout", "dicom", "-o", s(&out), "--pixel-size", "0.5um", "--json"]);
    let json: serde_json::Value = serde_json::from_str(json.trim()).unwrap();
    assert_eq!(json["dicom"]["instances"], 3, "{json}");
    assert_eq!(json["dicom"]["photometricInterpretation"], "YBR_FULL_422", "{json}");
    let names: Vec<String> = files(&out).into_iter().map(|(n, _)| n).collect();
    assert_eq!(names, ["level-0.dcm", "level-1.dcm", "level-2.dcm"]);
    dciodvfy(&out);
    if let Some(python) = readers() {
        check(&python, &out, &png, 256, None);
    }

    let again = dir.path().join("again");
    ok(&["split", s(&png), "--layout", "dicom", "-o", s(&again), "--pixel-size", "0.5um", "-q"]);
    assert!(files(&out) == files(&again), "a second run wrote other bytes");
    // A re-run replaces the series it wrote.
    ok(&["split", s(&png), "--layout", "dicom", "-o", s(&again), "--pixel-size", "0.5um", "-q"]);

    let rooted = dir.path().join("rooted");
    let root = "1.2.826.0.1.3680043.10.999";
    let json = ok(&[
        "split",
        s(&png),
        "--layout",
        "dicom",
        "-o",
        s(&rooted),
        "--pixel-size",
        "0.5um",
        "--dicom-uid-root",
        root,
        "--json",
    ]);
    let json: serde_json::Value = serde_json::from_str(json.trim()).unwrap();
    let series = json["dicom"]["seriesInstanceUID"].as_str().unwrap().to_string();
    assert!(series.starts_with(&format!("{root}.")) && series.len() <= 64, "{series}");
}

/// A grey image, and the user's attributes (`--dicom-meta`): MONOCHROME2 frames, valid; the
/// attributes given are in every instance, never invented where not.
#[test]
fn grey_frames_and_the_users_attributes() {
    let dir = tempfile::tempdir().unwrap();
    let png = input(dir.path(), "grey", 600, 300, PixelLayout::new(Channels::Grey, Depth::U8));
    let meta = dir.path().join("meta.json");
    std::fs::write(&meta, r#"{"PatientName": "Doe^Jane", "PatientID": "P-17", "AccessionNumber": "A42"}"#).unwrap();
    let out = dir.path().join("series");
    let json = ok(&[
        "split",
        s(&png),
        "--layout",
        "dicom",
        "-o",
        s(&out),
        "--pixel-size",
        "250nm",
        "--dicom-meta",
        s(&meta),
        "--json",
    ]);
    assert!(json.contains("MONOCHROME2"), "{json}");
    dciodvfy(&out);
    let level0 = std::fs::read(out.join("level-0.dcm")).unwrap();
    for given in ["Doe^Jane", "P-17", "A42"] {
        assert!(level0.windows(given.len()).any(|w| w == given.as_bytes()), "{given} missing");
    }
    if let Some(python) = readers() {
        check(&python, &out, &png, 256, None);
    }
}

/// A `W x H` gradient-with-noise image saved by `vips tiffsave` as a JPEG TIFF of 256-texel tiles
/// at Q85 (YCbCr 4:2:0, as libvips writes below Q90): `DIR/s85.tif`.
pub(crate) fn vips_jpeg_tiff(dir: &Path, w: u32, h: u32, quality: u8) -> PathBuf {
    let png = input(dir, "src", w, h, rgb8());
    let tiled = dir.join(format!("s{quality}.tif"));
    let vips = Command::new("vips")
        .args(["tiffsave", s(&png), s(&tiled), "--tile", "--tile-width", "256", "--tile-height", "256"])
        .args(["--compression", "jpeg", "--Q", &quality.to_string()])
        .output()
        .unwrap();
    assert!(vips.status.success(), "vips: {}", String::from_utf8_lossy(&vips.stderr));
    tiled
}

/// A JPEG-tiled source whose tiles fit the frames (256 texels) has its interior
/// full-resolution tiles copied byte for byte (their entropy-coded data equal to the source's
/// stored tiles), as `--json` says, whether they are YCbCr 4:2:0 (`vips tiffsave` below Q90:
/// YBR_FULL_422) or RGB (from Q90 on, as Aperio scanners store them: the series says RGB);
/// the edge tiles, which lie past the image, and the reduced levels are encoded alike. Read
/// back within JPEG's error of the source as libvips decodes it.
#[test]
fn a_jpeg_tiled_source_s_tiles_are_copied_byte_for_byte() {
    if !crate::common::have_program("vips", "--version", "libvips-tools") {
        return;
    }
    let dir = tempfile::tempdir().unwrap();
    for (quality, photometric) in [(85, "YBR_FULL_422"), (95, "RGB")] {
        let tiled = vips_jpeg_tiff(dir.path(), 1000, 700, quality);
        let out = dir.path().join(format!("series{quality}"));
        let json = ok(&["split", s(&tiled), "--layout", "dicom", "-o", s(&out), "--pixel-size", "0.5um", "--json"]);
        let json: serde_json::Value = serde_json::from_str(json.trim()).unwrap();
        // 3 x 2 of the 4 x 3 tiles of level 0 lie inside the image.
        assert_eq!(json["copied"], 6, "Q{quality}: {json}");
        dciodvfy(&out);
        if let Some(python) = readers() {
            let measured = check(&python, &out, &tiled, 256, Some(&tiled));
            assert_eq!(measured["copied"], 6, "Q{quality}: {measured}");
            assert_eq!(measured["copiedFrames"], serde_json::json!([0, 1, 2, 4, 5, 6]), "Q{quality}: {measured}");
            assert_eq!(measured["photometric"], photometric, "Q{quality}: {measured}");
        }
    }
}

/// What a DICOM series cannot hold is refused before anything is written, naming what to
/// change; a failing run leaves no partial series.
#[test]
fn refusals_and_no_partial_series() {
    let dir = tempfile::tempdir().unwrap();
    let png = input(dir.path(), "in", 300, 200, rgb8());
    let deep = input(dir.path(), "deep", 300, 200, PixelLayout::new(Channels::Rgb, Depth::U16));
    let alpha = input(dir.path(), "alpha", 300, 200, PixelLayout::new(Channels::Rgba, Depth::U8));
    let out = dir.path().join("series");
    let o = s(&out);
    let a_file = dir.path().join("a-file");
    std::fs::write(&a_file, b"not a directory").unwrap();
    let bad_meta = dir.path().join("bad.json");
    std::fs::write(&bad_meta, r#"{"PatientAge": "040Y"}"#).unwrap();
    for (args, want) in [
        (vec!["split", s(&png), "--layout", "dicom", "-o", o], &["--pixel-size"][..]),
        (vec!["split", s(&deep), "--layout", "dicom", "-o", o, "--pixel-size", "1um"], &["8-bit", "lossless"][..]),
        (vec!["split", s(&alpha), "--layout", "dicom", "-o", o, "--pixel-size", "1um"], &["--flatten"][..]),
        (
            vec!["split", s(&png), "--layout", "dicom", "-o", o, "--pixel-size", "1um", "--codec", "png"],
            &["JPEG baseline"][..],
        ),
        (
            vec!["split", s(&png), "--layout", "dicom", "-o", s(&a_file), "--pixel-size", "1um"],
            &["a-file", "a file"][..],
        ),
        (
            vec!["split", s(&png), "--layout", "dicom", "-o", o, "--pixel-size", "1um", "--dicom-meta", s(&bad_meta)],
            &["bad.json", "unknown keyword \"PatientAge\""][..],
        ),
        (
            vec!["split", s(&png), "--layout", "dicom", "-o", o, "--pixel-size", "1um", "--dicom-uid-root", "1.02"],
            &["leading zero"][..],
        ),
        (
            vec!["split", s(&png), "-o", o, "--dicom-uid-root", "1.2"],
            &["--dicom-uid-root belongs to --layout dicom"][..],
        ),
        (
            vec!["split", s(&png), "--layout", "dicom", "-o", o, "--pixel-size", "1um", "--overlap", "1"],
            &["--overlap"][..],
        ),
        (
            vec!["split", s(&png), "--layout", "dicom", "-o", o, "--pixel-size", "1um", "--subsampling", "444"],
            &["--subsampling 444", "YBR_FULL", "may not state"][..],
        ),
    ] {
        fails_with(&run(&args), want);
        assert!(!out.exists(), "{args:?} left {}", out.display());
    }
    assert_eq!(std::fs::read(&a_file).unwrap(), b"not a directory");
    // A truncated source fails mid-run: nothing is left, the staging directory neither.
    let bytes = std::fs::read(&png).unwrap();
    let cut = dir.path().join("cut.png");
    std::fs::write(&cut, &bytes[..bytes.len() / 2]).unwrap();
    let result = run(&["split", s(&cut), "--layout", "dicom", "-o", o, "--pixel-size", "1um"]);
    assert!(!result.status.success());
    let left: Vec<String> =
        std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    assert!(left.iter().all(|n| !n.contains("series")), "left behind: {left:?}");
}

/// A DICOM series is one output among others of one run: Deep Zoom beside it shares the
/// pyramid's encoding.
#[test]
fn a_series_beside_deep_zoom() {
    let dir = tempfile::tempdir().unwrap();
    let png = input(dir.path(), "slide", 700, 500, rgb8());
    let (dcm, web) = (dir.path().join("dcm"), dir.path().join("web"));
    let said = ok(&[
        "split",
        s(&png),
        "--layout",
        "dicom",
        "-o",
        s(&dcm),
        "-o",
        s(&web),
        "--layout",
        "dzi",
        "--overlap",
        "0",
        "--tile-size",
        "256",
        "--pixel-size",
        "0.5um",
    ]);
    assert!(said.contains("2 outputs") && said.contains("1 pyramid"), "{said}");
    assert!(dcm.join("level-0.dcm").is_file() && web.join("slide.dzi").is_file());
    dciodvfy(&dcm);
}

/// An Aperio-like SVS as tifffile writes it: 256-texel JPEG tiles in YCbCr 4:2:0, a thumbnail.
const MAKE_SVS: &str = r#"
import sys, numpy as np, tifffile
h, w = 600, 900
y, x = np.mgrid[0:h, 0:w]
img = np.stack([x * 255 // w, y * 255 // h, (x // 3 + y // 5) & 255], -1).astype(np.int32)
img += np.random.default_rng(7).integers(0, 16, img.shape)
img = np.clip(img, 0, 255).astype(np.uint8)
head = "Aperio Image Library v12.0.15 \r\n%dx%d" % (w, h)
with tifffile.TiffWriter(sys.argv[1]) as t:
    t.write(img, tile=(256, 256), compression="jpeg", compressionargs={"level": 80}, photometric="ycbcr", subsampling=(2, 2), description=head + " [0,0 %dx%d] (256x256) JPEG/YCC Q=80|AppMag = 20|MPP = 0.5" % (w, h), metadata=None)
    t.write(img[::8, ::8].copy(), compression="jpeg", photometric="rgb", description=head + " -> 112x75", metadata=None)
"#;

/// An SVS's interior full-resolution tiles are copied byte for byte; OpenSlide reads the
/// region they cover from the series exactly as from the slide (the same JPEG data, the same
/// decoder); every level is within JPEG's error of the slide as libvips decodes it.
#[test]
fn an_svs_s_tiles_are_copied_and_read_as_the_slide_s() {
    let Some(python) = readers() else { return };
    let dir = tempfile::tempdir().unwrap();
    let svs = dir.path().join("slide.svs");
    crate::tiff_slides::python(python.as_os_str(), MAKE_SVS, &[s(&svs)]);
    let out = dir.path().join("series");
    let json = ok(&["split", s(&svs), "--layout", "dicom", "-o", s(&out), "--pixel-size", "0.5um", "--json"]);
    let json: serde_json::Value = serde_json::from_str(json.trim()).unwrap();
    // 3 x 2 of the 4 x 3 tiles of level 0 lie inside the image.
    assert_eq!(json["copied"], 6, "{json}");
    dciodvfy(&out);
    let measured = check(&python, &out, &svs, 256, Some(&svs));
    assert_eq!(measured["copiedFrames"], serde_json::json!([0, 1, 2, 4, 5, 6]), "{measured}");
}

/// An Aperio-like SVS with reduced levels (downsamples 4 and about 16), as tifffile writes
/// it: 256-texel JPEG tiles in YCbCr 4:2:0, a thumbnail in strips between the levels. With
/// `zlib` as the second argument its first reduced level is Deflate-compressed instead.
pub(crate) const MAKE_LEVELLED_SVS: &str = r#"
import sys, numpy as np, tifffile
h, w = 1500, 2300
y, x = np.mgrid[0:h, 0:w]
img = np.stack([x * 255 // w, y * 255 // h, (x // 3 + y // 5) & 255], -1).astype(np.int32)
img += np.random.default_rng(7).integers(0, 16, img.shape)
img = np.clip(img, 0, 255).astype(np.uint8)
head = "Aperio Image Library v12.0.15 \r\n%dx%d" % (w, h)
kw = dict(compression="jpeg", compressionargs={"level": 80}, photometric="ycbcr", subsampling=(2, 2), metadata=None)
reduced = dict(kw, compression="zlib", compressionargs={}, photometric="rgb", subsampling=None) if sys.argv[2:] == ["zlib"] else kw
with tifffile.TiffWriter(sys.argv[1]) as t:
    t.write(img, tile=(256, 256), description=head + " [0,0 %dx%d] (256x256) JPEG/YCC Q=80|AppMag = 20|MPP = 0.5" % (w, h), **kw)
    t.write(img[::8, ::8].copy(), compression="jpeg", photometric="rgb", description=head + " -> thumbnail", metadata=None)
    t.write(img[::4, ::4].copy(), tile=(256, 256), description=head + " -> 575x375", **reduced)
    t.write(img[::16, ::16].copy(), tile=(256, 256), description=head + " -> 144x94", **kw)
"#;

pub(crate) fn json_of(said: &str) -> serde_json::Value {
    serde_json::from_str(said.trim()).unwrap()
}

/// A slide that is a pyramid of JPEG tiles (an Aperio-like SVS, a `vips tiffsave --pyramid`
/// JPEG TIFF) has every level written as an instance, every stored tile copied as a frame
/// (edge tiles too: TILED_FULL frames may reach past the image), nothing encoded: valid for
/// dciodvfy, the frames the source's stored tiles made complete (wsidicom), and every level
/// read by OpenSlide exactly as it reads the slide's. `--levels pow2` gives our pyramid.
#[test]
fn a_slide_s_own_levels_are_copied_as_stored() {
    let Some(python) = readers() else { return };
    let dir = tempfile::tempdir().unwrap();
    let svs = dir.path().join("slide.svs");
    crate::tiff_slides::python(python.as_os_str(), MAKE_LEVELLED_SVS, &[s(&svs)]);
    let mut slides = vec![(svs.clone(), 61)];
    if crate::common::have_program("vips", "--version", "libvips-tools") {
        let tif = vips_pyramid(dir.path());
        // 9 x 6, 5 x 3, 3 x 2, 2 x 1 and 1 tiles.
        slides.push((tif, 78));
    }
    for (slide, frames) in slides {
        let out = dir.path().join(format!("{}-series", slide.file_stem().unwrap().to_string_lossy()));
        let json = ok(&["split", s(&slide), "--layout", "dicom", "-o", s(&out), "--pixel-size", "0.5um", "--json"]);
        let json = json_of(&json);
        assert_eq!(json["dicom"]["levels"], "stored", "{json}");
        assert_eq!(json["dicom"]["levelsDeclined"], serde_json::Value::Null, "{json}");
        assert_eq!(json["dicom"]["frames"], frames, "{json}");
        assert_eq!((json["copied"].clone(), json["encoded"].clone()), (frames.into(), 0.into()), "{json}");
        assert_eq!(json["dicom"]["photometricInterpretation"], "YBR_FULL_422", "{json}");
        dciodvfy(&out);
        let script = Command::new(&python).args([SCRIPT, "levels", s(&out), s(&slide)]).output().unwrap();
        let said = format!("{}{}", String::from_utf8_lossy(&script.stdout), String::from_utf8_lossy(&script.stderr));
        assert!(script.status.success(), "{}: {said}", out.display());
        assert!(said.contains(&format!("\"framesEqual\": {frames}")), "{said}");
    }
    // Our exact pyramid instead: 2300 x 1500 in 256-texel frames, down to one frame.
    let pow2 = dir.path().join("pow2");
    let json = ok(&[
        "split",
        s(&svs),
        "--layout",
        "dicom",
        "-o",
        s(&pow2),
        "--pixel-size",
        "0.5um",
        "--levels",
        "pow2",
        "--json",
    ]);
    let json = json_of(&json);
    assert_eq!(json["dicom"]["levels"], "pow2", "{json}");
    assert_eq!(json["dicom"]["levelsAsked"], "pow2", "{json}");
    assert_eq!(json["dicom"]["instances"], 5, "{json}");
    // 8 x 5 of the 9 x 6 tiles of level 0 lie inside the image.
    assert_eq!(json["copied"], 40, "{json}");
    dciodvfy(&pow2);
}

/// An Aperio SVS of JPEG 2000 tiles as tifffile writes it with imagecodecs' OpenJPEG: three
/// levels of 128-texel tiles (1024 x 704, 256 x 176, 64 x 44: 48, 4 and 1 tiles; downsamples
/// of 4 and 16 as wsidicom needs them, within 1% of a power of two) and a JPEG
/// thumbnail between the first two, as Aperio orders them. The second argument picks the
/// coding: `rct` (33005, the reversible wavelet through the codestream's colour transform),
/// `ict` (33005, irreversible, through the transform), `rgb` (33005, reversible, no transform)
/// or `ycbcr` (33003: Y, Cb, Cr components, reversible, no transform: `YBR_FULL`, which no
/// whole-slide image may state).
const MAKE_J2K_LEVELLED_SVS: &str = r#"
import sys, numpy as np, tifffile, imagecodecs
kind = sys.argv[2]
h, w, t = 704, 1024, 128
y, x = np.mgrid[0:h, 0:w]
img = np.stack([x * 255 // w, y * 255 // h, (x // 3 + y // 5) & 255], -1).astype(np.int32)
img += np.random.default_rng(7).integers(0, 16, img.shape)
img = np.clip(img, 0, 255).astype(np.uint8)
def ycc(a):
    f = a.astype(np.float64)
    c = np.stack([0.299 * f[..., 0] + 0.587 * f[..., 1] + 0.114 * f[..., 2],
                  128 - 0.168736 * f[..., 0] - 0.331264 * f[..., 1] + 0.5 * f[..., 2],
                  128 + 0.5 * f[..., 0] - 0.418688 * f[..., 1] - 0.081312 * f[..., 2]], -1)
    return np.clip(np.round(c), 0, 255).astype(np.uint8)
code = 33003 if kind == "ycbcr" else 33005
def tiles(a):
    a = ycc(a) if kind == "ycbcr" else a
    for ty in range(0, a.shape[0], t):
        for tx in range(0, a.shape[1], t):
            tile = np.zeros((t, t, 3), np.uint8)
            part = a[ty:ty + t, tx:tx + t]
            tile[:part.shape[0], :part.shape[1]] = part
            if kind == "ict":
                yield imagecodecs.jpeg2k_encode(tile, level=40, codecformat="J2K", mct=True, reversible=False)
            else:
                yield imagecodecs.jpeg2k_encode(tile, level=0, codecformat="J2K", mct=kind == "rct", reversible=True)
head = "Aperio Image Library v12.0.15 \r\n%dx%d" % (w, h)
with tifffile.TiffWriter(sys.argv[1]) as tw:
    def level(a, description):
        tw.write(tiles(a), shape=a.shape, dtype="uint8", tile=(t, t), compression=code, photometric="rgb", description=description, metadata=None)
    level(img, head + " [0,0 %dx%d] (%dx%d) J2K/KDU Q=70|AppMag = 20|MPP = 0.5" % (w, h, t, t))
    tw.write(img[::8, ::8].copy(), compression="jpeg", photometric="rgb", description=head + " -> thumbnail", metadata=None)
    level(img[::4, ::4].copy(), head + " -> 256x176")
    level(img[::16, ::16].copy(), head + " -> 64x44")
"#;

/// An Aperio JPEG 2000 slide's levels are copied as JPEG 2000 frames, nothing decoded: each
/// codestream byte for byte (pydicom's frames, wsidicom's encoded tiles), the transfer syntax
/// lossless only (.90) for reversible codestreams, .91 for irreversible ones, the photometric
/// interpretation what the codestream and the TIFF say (PS3.5 8.2.4), valid for dciodvfy and
/// read by OpenSlide 4 exactly as it reads the slide; the thumbnail stays a JPEG baseline
/// instance. The irreversible slide's instances state its JPEG 2000 step and no coding of
/// their own. Aperio's YCbCr (33003) tiles would be `YBR_FULL` frames, which the IOD forbids:
/// that slide makes our JPEG pyramid, saying why, as `--levels pow2` does.
#[test]
fn an_aperio_jpeg_2000_slide_s_levels_are_copied_as_jpeg_2000_frames() {
    let Some(python) = readers() else { return };
    let dir = tempfile::tempdir().unwrap();
    let (lossless, lossy) = ("1.2.840.10008.1.2.4.90", "1.2.840.10008.1.2.4.91");
    for (kind, photometric, transfer) in
        [("rct", "YBR_RCT", lossless), ("ict", "YBR_ICT", lossy), ("rgb", "RGB", lossless)]
    {
        let svs = dir.path().join(format!("{kind}.svs"));
        crate::tiff_slides::python(python.as_os_str(), MAKE_J2K_LEVELLED_SVS, &[s(&svs), kind]);
        let out = dir.path().join(format!("{kind}-series"));
        let json = ok(&["split", s(&svs), "--layout", "dicom", "-o", s(&out), "--pixel-size", "0.5um", "--json"]);
        let json = json_of(&json);
        let d = &json["dicom"];
        assert_eq!(
            (d["levels"].clone(), d["levelsDeclined"].clone()),
            ("stored".into(), serde_json::Value::Null),
            "{json}"
        );
        assert_eq!((json["copied"].clone(), json["encoded"].clone()), (53.into(), 0.into()), "{kind}: {json}");
        assert_eq!(
            (d["photometricInterpretation"].as_str(), d["transferSyntax"].as_str()),
            (Some(photometric), Some(transfer))
        );
        dciodvfy(&out);
        let script =
            Command::new(&python).args([SCRIPT, "j2k", s(&out), s(&svs), photometric, transfer]).output().unwrap();
        let said = format!("{}{}", String::from_utf8_lossy(&script.stdout), String::from_utf8_lossy(&script.stderr));
        assert!(script.status.success(), "{kind}: {said}");
        assert!(said.contains("\"framesEqual\": 53") && said.contains("\"openslideLevelsEqual\": 3"), "{said}");
        // Each level's lossy history: the slide's JPEG 2000 step where it was irreversible,
        // nothing of the series' own.
        let history = Command::new(&python).args([SCRIPT, "lossy", s(&out)]).output().unwrap();
        let history = json_of(&String::from_utf8_lossy(&history.stdout));
        let want: &[&str] = if kind == "ict" { &["ISO_15444_1"] } else { &[] };
        for level in ["level-0.dcm", "level-1.dcm", "level-2.dcm"] {
            assert_eq!(history[level]["methods"], serde_json::json!(want), "{kind} {level}: {history}");
        }
    }
    // Our JPEG pyramid instead: asked for, or where the tiles are YCbCr; every frame encoded.
    let ycbcr = dir.path().join("ycbcr.svs");
    crate::tiff_slides::python(python.as_os_str(), MAKE_J2K_LEVELLED_SVS, &[s(&ycbcr), "ycbcr"]);
    for (slide, extra, declined) in [("rct.svs", &["--levels", "pow2"][..], false), ("ycbcr.svs", &[][..], true)] {
        let (slide, out) = (dir.path().join(slide), dir.path().join(format!("{slide}-pow2")));
        let args = ["split", s(&slide), "--layout", "dicom", "-o", s(&out), "--pixel-size", "0.5um"];
        let json = json_of(&ok(&[&args[..], extra, &["--json"]].concat()));
        let d = &json["dicom"];
        assert_eq!((d["transferSyntax"].as_str(), json["copied"].as_u64()), (Some("1.2.840.10008.1.2.4.50"), Some(0)));
        assert_eq!(d["photometricInterpretation"], "YBR_FULL_422", "{json}");
        let why = d["levelsDeclined"].as_str().unwrap_or_default();
        assert_eq!(why.contains("Compression 33003: YBR_FULL, which"), declined, "{json}");
        dciodvfy(&out);
    }
}

/// DICOM of the slide's own levels beside Deep Zoom in one run: Deep Zoom's pyramid is cut,
/// the series copies the levels.
#[test]
fn copied_levels_beside_deep_zoom() {
    let Some(python) = readers() else { return };
    let dir = tempfile::tempdir().unwrap();
    let svs = dir.path().join("slide.svs");
    crate::tiff_slides::python(python.as_os_str(), MAKE_LEVELLED_SVS, &[s(&svs)]);
    let (dcm, web) = (dir.path().join("dcm"), dir.path().join("web"));
    let args = ["split", s(&svs), "--layout", "dicom", "-o", s(&dcm), "-o", s(&web), "--layout", "dzi"];
    let json = json_of(&ok(&[&args[..], &["--pixel-size", "0.5um", "--json"]].concat()));
    let outputs = json["outputs"].as_array().unwrap();
    assert_eq!(json["pyramids"], 1, "{json}");
    assert_eq!(outputs[0]["dicom"]["levels"], "stored", "{json}");
    assert_eq!(outputs[0]["pyramid"], serde_json::Value::Null, "{json}");
    assert_eq!(outputs[1]["pyramid"], 0, "{json}");
    assert!(web.join("slide.dzi").is_file());
    // The three levels and the slide's thumbnail.
    assert_eq!(std::fs::read_dir(&dcm).unwrap().count(), 4);
    dciodvfy(&dcm);
}

/// Levels DICOM cannot hold as stored (here a Deflate-compressed reduced level) make our
/// pyramid, the summary saying why; a source that is no pyramid of JPEG tiles too. The
/// output is then what `--levels pow2` writes, byte for byte.
#[test]
fn levels_not_copyable_fall_back_to_our_pyramid_saying_why() {
    let Some(python) = readers() else { return };
    let dir = tempfile::tempdir().unwrap();
    let svs = dir.path().join("deflate-level.svs");
    crate::tiff_slides::python(python.as_os_str(), MAKE_LEVELLED_SVS, &[s(&svs), "zlib"]);
    let png = input(dir.path(), "flat", 600, 400, rgb8());
    // A source without levels says why only where they were asked for.
    let asked: &[&str] = &["--levels", "stored"];
    for (source, why, extra) in
        [(&svs, "level 1 (page 2) is not JPEG-compressed", &[][..]), (&png, "no slide of JPEG-tiled levels", asked)]
    {
        let out = dir.path().join("series");
        let args = ["split", s(source), "--layout", "dicom", "-o", s(&out), "--pixel-size", "1um"];
        let json = json_of(&ok(&[&args[..], extra, &["--json"]].concat()));
        assert_eq!(json["dicom"]["levels"], "pow2", "{json}");
        assert!(json["dicom"]["levelsDeclined"].as_str().unwrap().contains(why), "{json}");
        let said = ok(&[&args[..], extra].concat());
        assert!(said.contains(why), "{said}");
        let pow2 = dir.path().join("pow2");
        ok(&["split", s(source), "--layout", "dicom", "-o", s(&pow2), "--pixel-size", "1um", "--levels", "pow2", "-q"]);
        assert!(files(&out) == files(&pow2), "the fallback is not --levels pow2's series");
        std::fs::remove_dir_all(&out).unwrap();
        std::fs::remove_dir_all(&pow2).unwrap();
    }
    // Encoded frames asked: our pyramid, saying so.
    let levelled = dir.path().join("levelled.svs");
    crate::tiff_slides::python(python.as_os_str(), MAKE_LEVELLED_SVS, &[s(&levelled)]);
    let out = dir.path().join("q70");
    let json = json_of(&ok(&[
        "split",
        s(&levelled),
        "--layout",
        "dicom",
        "-o",
        s(&out),
        "--pixel-size",
        "1um",
        "--quality",
        "70",
        "--json",
    ]));
    assert_eq!(json["dicom"]["levels"], "pow2", "{json}");
    assert!(json["dicom"]["levelsDeclined"].as_str().unwrap().contains("--quality"), "{json}");
    fails_with(
        &run(&["split", s(&png), "-o", s(&dir.path().join("web")), "--levels", "pow2"]),
        &["--levels belongs to a TIFF output", "or --layout dicom"],
    );
}

/// A reduced level whose tiles lie past the end of the file (a truncated slide) fails the
/// run with an error naming the file, the level and the tile, and leaves no series.
#[test]
fn a_truncated_level_fails_naming_it_and_leaves_no_series() {
    let Some(python) = readers() else { return };
    let dir = tempfile::tempdir().unwrap();
    let svs = dir.path().join("cut.svs");
    crate::tiff_slides::python(python.as_os_str(), MAKE_LEVELLED_SVS, &[s(&svs)]);
    // The last tile of level 1 (page 2) moved past the end of the file.
    let damage = r#"
import sys, tifffile
with tifffile.TiffFile(sys.argv[1], mode="r+b") as t:
    tag = t.pages[2].tags["TileOffsets"]
    offsets = list(tag.value)
    offsets[-1] = 1 << 30
    tag.overwrite(offsets)
"#;
    crate::tiff_slides::python(python.as_os_str(), damage, &[s(&svs)]);
    let out = dir.path().join("series");
    let result = run(&["split", s(&svs), "--layout", "dicom", "-o", s(&out), "--pixel-size", "0.5um"]);
    fails_with(&result, &["cut.svs", "level 1 (page 2)", "column 2, row 1", "past the end of the file"]);
    let left: Vec<String> =
        std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into_owned()).collect();
    assert!(left.iter().all(|n| !n.contains("series")), "left behind: {left:?}");
}

/// An Aperio-like SVS with a reduced level and every associated image, in Aperio's order:
/// the full resolution, the thumbnail (JPEG strips), a reduced level, the label (LZW strips)
/// and the macro (JPEG strips).
pub(crate) const MAKE_SVS_WITH_LABEL: &str = r#"
import sys, numpy as np, tifffile
def picture(h, w, seed):
    y, x = np.mgrid[0:h, 0:w]
    img = np.stack([x * 255 // w, y * 255 // h, (x // 3 + y // 5) & 255], -1).astype(np.int32)
    img += np.random.default_rng(seed).integers(0, 16, img.shape)
    return np.clip(img, 0, 255).astype(np.uint8)
h, w = 1000, 1500
img = picture(h, w, 7)
head = "Aperio Image Library v12.0.15 \r\n%dx%d" % (w, h)
kw = dict(compression="jpeg", compressionargs={"level": 80}, photometric="ycbcr", subsampling=(2, 2), metadata=None)
label = picture(230, 190, 8)
label[40:60, 20:170] = 0
macro = picture(300, 820, 9)
with tifffile.TiffWriter(sys.argv[1]) as t:
    t.write(img, tile=(256, 256), description=head + " [0,0 %dx%d] (256x256) JPEG/YCC Q=80|AppMag = 20|MPP = 0.5" % (w, h), **kw)
    t.write(img[::8, ::8].copy(), compression="jpeg", photometric="rgb", description=head + " -> thumbnail", metadata=None)
    t.write(img[::4, ::4].copy(), tile=(256, 256), description=head + " -> 375x250", **kw)
    t.write(label, compression="lzw", photometric="rgb", rowsperstrip=16, description="Aperio Image Library v12.0.15\r\nlabel 190x230", metadata=None)
    t.write(macro, compression="jpeg", photometric="rgb", rowsperstrip=32, description="Aperio Image Library v12.0.15\r\nmacro 820x300", metadata=None)
"#;

/// A slide's label, overview (macro) and thumbnail are carried into the series as their own
/// instances (LABEL, OVERVIEW, THUMBNAIL, in the levels' series), valid for dciodvfy, read by
/// pydicom, highdicom, wsidicom and OpenSlide 4 (its `label`, `macro`, `thumbnail`) within
/// JPEG's error of the slide's pages (they are decoded and encoded again: 30 dB, as every
/// encoded frame); `--json` lists them; `--no-associated` leaves them out, saying how many.
#[test]
fn a_slide_s_associated_images_are_instances_of_the_series() {
    let Some(python) = readers() else { return };
    let dir = tempfile::tempdir().unwrap();
    let svs = dir.path().join("slide.svs");
    crate::tiff_slides::python(python.as_os_str(), MAKE_SVS_WITH_LABEL, &[s(&svs)]);
    let out = dir.path().join("series");
    let json = json_of(&ok(&["split", s(&svs), "--layout", "dicom", "-o", s(&out), "--json"]));
    let dicom = &json["dicom"];
    assert_eq!(dicom["levels"], "stored", "{json}");
    assert_eq!(dicom["instances"], 2, "{json}");
    let kinds: Vec<&str> =
        dicom["associated"].as_array().unwrap().iter().map(|a| a["kind"].as_str().unwrap()).collect();
    assert_eq!(kinds, ["thumbnail", "label", "overview"], "{json}");
    assert_eq!(dicom["associated"][1]["width"], 190, "{json}");
    assert_eq!(dicom["associated"][1]["from"], "page 3", "{json}");
    assert_eq!(dicom["associatedLeftOut"], 0, "{json}");
    let names: Vec<String> = files(&out).into_iter().map(|(n, _)| n).collect();
    assert_eq!(names, ["label.dcm", "level-0.dcm", "level-1.dcm", "overview.dcm", "thumbnail.dcm"]);
    dciodvfy(&out);
    let script = Command::new(&python).args([SCRIPT, "associated", s(&out), s(&svs)]).output().unwrap();
    let said = format!("{}{}", String::from_utf8_lossy(&script.stdout), String::from_utf8_lossy(&script.stderr));
    assert!(script.status.success(), "{}: {said}", out.display());
    eprintln!("{said}");

    let bare = dir.path().join("bare");
    let said = ok(&["split", s(&svs), "--layout", "dicom", "-o", s(&bare), "--no-associated", "--json"]);
    let json = json_of(&said);
    assert_eq!(json["dicom"]["associated"], serde_json::json!([]), "{json}");
    assert_eq!(json["dicom"]["associatedLeftOut"], 3, "{json}");
    let names: Vec<String> = files(&bare).into_iter().map(|(n, _)| n).collect();
    assert_eq!(names, ["level-0.dcm", "level-1.dcm"]);
    let said = run(&["split", s(&svs), "--layout", "dicom", "-o", s(&bare)]);
    let line = format!("{}{}", String::from_utf8_lossy(&said.stdout), String::from_utf8_lossy(&said.stderr));
    assert!(line.contains("label 190x230 (page 3)"), "{line}");
    let web = dir.path().join("web");
    fails_with(
        &run(&["split", s(&svs), "--layout", "dzi", "-o", s(&web), "--no-associated"]),
        &["--no-associated belongs to", "--layout dicom"],
    );

    // A damaged associated image (the macro's JPEG strip zeroed) fails the run naming the
    // file and the image, and leaves no series; --no-associated converts the slide.
    let damaged = dir.path().join("damaged.svs");
    let mut bytes = std::fs::read(&svs).unwrap();
    let macro_strip = r#"
import sys, tifffile
with tifffile.TiffFile(sys.argv[1]) as t:
    p = t.pages[4]
    print(p.dataoffsets[0], p.databytecounts[0])
"#;
    let out_py = Command::new(&python).args(["-c", macro_strip, s(&svs)]).output().unwrap();
    let said = String::from_utf8_lossy(&out_py.stdout).into_owned();
    let [at, len]: [usize; 2] =
        said.split_whitespace().map(|v| v.parse().unwrap()).collect::<Vec<_>>().try_into().unwrap();
    bytes[at..at + len].fill(0);
    std::fs::write(&damaged, &bytes).unwrap();
    let series = dir.path().join("damaged-series");
    fails_with(
        &run(&["split", s(&damaged), "--layout", "dicom", "-o", s(&series)]),
        &["damaged.svs", "the overview (page 4)", "--no-associated"],
    );
    assert!(!series.exists());
    ok(&["split", s(&damaged), "--layout", "dicom", "-o", s(&series), "--no-associated", "-q"]);
}

/// Native frames (`--codec raw`, explicit VR little endian): 8-bit RGB, 16-bit grey and
/// 16-bit RGB, each valid for dciodvfy; pydicom reads every frame equal to the naive box
/// pyramid's tile (tiff_oracle.py; the edge frames padded with the edge repeated), exactly:
/// the frames are the pyramid's samples as they are, and the box pyramid is exact; wsidicom
/// reads every level equal to it (grey and 8-bit: it reads no 16-bit RGB), OpenSlide 4 the
/// 8-bit RGB series' (it reads no grey or 16-bit DICOM slide). Our own DICOM reader reads
/// the 8-bit series back to the same tiles as the image it was made from.
#[test]
fn native_frames_are_the_pyramid_s_samples_exactly() {
    let dir = tempfile::tempdir().unwrap();
    let grey16 = PixelLayout::new(Channels::Grey, Depth::U16);
    let rgb16 = PixelLayout::new(Channels::Rgb, Depth::U16);
    // Sizes whose levels halve exactly where wsidicom checks the scale (1024 x 640 by 96,
    // edges padded); 1000 x 700 and 301 x 203 round at every level.
    for (name, layout, w, h, tile, bits) in
        [("rgb8", rgb8(), 1000, 700, 256, 8), ("grey16", grey16, 1024, 640, 96, 16), ("rgb16", rgb16, 301, 203, 64, 16)]
    {
        let png = input(dir.path(), name, w, h, layout);
        let out = dir.path().join(format!("{name}-series"));
        let tile_arg = tile.to_string();
        let args = ["split", s(&png), "--layout", "dicom", "-o", s(&out), "--pixel-size", "0.5um"];
        let json =
            json_of(&ok(
                &[&args[..], &["--codec", "raw", "--filter", "box", "--tile-size", &tile_arg, "--json"]].concat()
            ));
        let dicom = &json["dicom"];
        assert_eq!(dicom["transferSyntax"], "1.2.840.10008.1.2.1", "{json}");
        assert_eq!(dicom["frameCoding"], format!("native {bits}-bit"), "{json}");
        let photometric = if layout.channels == Channels::Grey { "MONOCHROME2" } else { "RGB" };
        assert_eq!(dicom["photometricInterpretation"], photometric, "{json}");
        assert_eq!(dicom["extendedOffsetTables"], 0, "{json}");
        assert_eq!(json["copied"], 0, "{json}");
        dciodvfy(&out);
        if let Some(python) = readers() {
            let script = Command::new(&python).args([SCRIPT, "native", s(&out), s(&png), &tile_arg]).output().unwrap();
            let said =
                format!("{}{}", String::from_utf8_lossy(&script.stdout), String::from_utf8_lossy(&script.stderr));
            assert!(script.status.success(), "{}: {said}", out.display());
            eprintln!("{name}: {said}");
        }
        if bits == 8 {
            // Our reader takes the series' level 0: the same pyramid as from the image.
            let from_png = crate::tiff_out::png_tiles(&png, &dir.path().join("from-png"), &[]);
            let from_dicom = crate::tiff_out::png_tiles(&out, &dir.path().join("from-dicom"), &[]);
            assert!(!from_png.is_empty() && from_png == from_dicom, "the series reads back otherwise");
        }
    }
}

/// A JPEG-tiled slide with `--codec raw`: nothing is copied (a JPEG tile is no native
/// frame), the summary says why the slide's own levels were not; the associated images are
/// native too, valid, their samples those decoded from the slide.
#[test]
fn native_frames_of_a_jpeg_slide_copy_nothing_and_say_why() {
    let Some(python) = readers() else { return };
    let dir = tempfile::tempdir().unwrap();
    let svs = dir.path().join("slide.svs");
    crate::tiff_slides::python(python.as_os_str(), MAKE_SVS_WITH_LABEL, &[s(&svs)]);
    let out = dir.path().join("series");
    let json = json_of(&ok(&["split", s(&svs), "--layout", "dicom", "-o", s(&out), "--codec", "raw", "--json"]));
    let dicom = &json["dicom"];
    assert_eq!(dicom["levels"], "pow2", "{json}");
    assert!(dicom["levelsDeclined"].as_str().unwrap().contains("raw"), "{json}");
    assert_eq!((json["copied"].clone(), dicom["transferSyntax"].clone()), (0.into(), "1.2.840.10008.1.2.1".into()));
    assert_eq!(dicom["associated"].as_array().unwrap().len(), 3, "{json}");
    dciodvfy(&out);
    let script = Command::new(&python).args([SCRIPT, "associated", s(&out), s(&svs), "native"]).output().unwrap();
    let said = format!("{}{}", String::from_utf8_lossy(&script.stdout), String::from_utf8_lossy(&script.stderr));
    assert!(script.status.success(), "{}: {said}", out.display());
    eprintln!("{said}");
}

/// What native frames cannot hold is refused before anything is written, naming the flag to
/// change: float samples (DICOM whole-slide images have none), alpha without `--flatten`,
/// JPEG's own flags, another codec.
#[test]
fn native_refusals() {
    let dir = tempfile::tempdir().unwrap();
    let png = input(dir.path(), "in", 300, 200, rgb8());
    let alpha = input(dir.path(), "alpha", 300, 200, PixelLayout::new(Channels::Rgba, Depth::U8));
    let tiff = dir.path().join("float.tif");
    let floats: Vec<f32> = (0..64 * 48).map(|i| i as f32 / 100.0).collect();
    let mut tif = tiff::encoder::TiffEncoder::new(std::fs::File::create(&tiff).unwrap()).unwrap();
    tif.write_image::<tiff::encoder::colortype::Gray32Float>(64, 48, &floats).unwrap();
    let out = dir.path().join("series");
    let o = s(&out);
    let native = ["--layout", "dicom", "-o", o, "--pixel-size", "1um", "--codec", "raw"];
    for (input, extra, want) in [
        (&tiff, &[][..], &["series", "32-bit float", "8- or 16-bit unsigned", "--range"][..]),
        (&alpha, &[][..], &["alpha", "--flatten"][..]),
        (&png, &["--quality", "90"][..], &["--quality is JPEG's"][..]),
    ] {
        fails_with(&run(&[&["split", s(input)][..], &native, extra].concat()), want);
        assert!(!out.exists());
    }
    let args = ["split", s(&png), "--layout", "dicom", "-o", o, "--pixel-size", "1um", "--codec", "deflate"];
    fails_with(&run(&args), &["jpeg", "raw", "Deflated transfer syntax is not written"]);
    // With --flatten, alpha is composited away: RGB frames.
    ok(&[&["split", s(&alpha)][..], &native, &["--flatten", "-q"]].concat());
    dciodvfy(&out);
}

/// Every instance states the pixels' lossy history (PS3.3 C.7.6.1.1.5), read by pydicom:
/// the source's JPEG coding (its texels' bytes over its tiles' bytes, as tifffile lists
/// them), then the series' own JPEG coding where it coded frames; a PNG's native frames
/// were never lossy (`00`). A copied level adds no step; a level made by the pyramid does.
#[test]
fn each_instance_states_the_lossy_history_of_its_pixels() {
    let Some(python) = readers() else { return };
    let dir = tempfile::tempdir().unwrap();
    let history = |series: &Path, slide: Option<&Path>| {
        let mut args = vec![SCRIPT, "lossy", s(series)];
        args.extend(slide.map(s));
        let out = Command::new(&python).args(&args).output().unwrap();
        let said = format!("{}{}", String::from_utf8_lossy(&out.stdout), String::from_utf8_lossy(&out.stderr));
        assert!(out.status.success(), "{}: {said}", series.display());
        json_of(&String::from_utf8_lossy(&out.stdout))
    };
    let methods = |said: &serde_json::Value, file: &str| -> Vec<String> {
        said[file]["methods"].as_array().unwrap().iter().map(|m| m.as_str().unwrap().to_string()).collect()
    };
    let jpeg = || "ISO_10918_1".to_string();
    // A PNG: native frames never lossy, JPEG frames one step, ours.
    let png = input(dir.path(), "src", 600, 400, rgb8());
    for (codec, flag, steps) in [("raw", "00", 0), ("jpeg", "01", 1)] {
        let out = dir.path().join(format!("png-{codec}"));
        ok(&["split", s(&png), "--layout", "dicom", "-o", s(&out), "--pixel-size", "0.5um", "--codec", codec]);
        let said = history(&out, None);
        for file in ["level-0.dcm", "level-1.dcm"] {
            assert_eq!(said[file]["flag"], flag, "{codec}: {said}");
            assert_eq!(methods(&said, file), vec![jpeg(); steps], "{codec}: {said}");
        }
    }
    // A JPEG-tiled slide: its coding is every instance's first step.
    let svs = dir.path().join("slide.svs");
    crate::tiff_slides::python(python.as_os_str(), MAKE_LEVELLED_SVS, &[s(&svs)]);
    let runs: [(&str, &[&str], [usize; 2]); 3] = [
        // Its own levels, every frame copied: the slide's step alone.
        ("stored", &[], [1, 1]),
        // Level 0's inner tiles copied, its edge frames and the other levels coded here.
        ("pow2", &["--levels", "pow2"], [2, 2]),
        // Native frames: the slide's step, no more.
        ("raw", &["--codec", "raw"], [1, 1]),
    ];
    for (name, extra, steps) in runs {
        let out = dir.path().join(format!("svs-{name}"));
        let args = ["split", s(&svs), "--layout", "dicom", "-o", s(&out), "--pixel-size", "0.5um"];
        ok(&[&args[..], extra].concat());
        let said = history(&out, Some(&svs));
        let source = said["sourceRatio"].as_f64().unwrap();
        for (file, steps) in ["level-0.dcm", "level-1.dcm"].into_iter().zip(steps) {
            assert_eq!(said[file]["flag"], "01", "{name}: {said}");
            assert_eq!(methods(&said, file), vec![jpeg(); steps], "{name}: {said}");
            let ratios = said[file]["ratios"].as_array().unwrap();
            assert_eq!(ratios.len(), steps, "{name}: {said}");
            // The slide's step is its level 0's ratio, in DS's 16 characters.
            let first = ratios[0].as_f64().unwrap();
            assert!((first - source).abs() <= source * 1e-9, "{name}: {first} is not the slide's {source}: {said}");
        }
        if name == "pow2" {
            dciodvfy(&out);
        }
    }
}

/// A 2300 x 1500 RGB image as `vips tiffsave --tile --pyramid` writes it (JPEG Q85, 256-texel
/// tiles, its own reduced levels), at `dir/vips-pyramid.tif`: a slide of another writer.
pub(crate) fn vips_pyramid(dir: &Path) -> PathBuf {
    let png = input(dir, "src", 2300, 1500, rgb8());
    let tif = dir.join("vips-pyramid.tif");
    let vips = Command::new("vips")
        .args(["tiffsave", s(&png), s(&tif), "--tile", "--pyramid", "--compression", "jpeg", "--Q", "85"])
        .args(["--tile-width", "256", "--tile-height", "256"])
        .output()
        .unwrap();
    assert!(vips.status.success(), "vips: {}", String::from_utf8_lossy(&vips.stderr));
    tif
}
