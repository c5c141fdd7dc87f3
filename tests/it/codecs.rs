//! Tile codecs from the command line: every codec through `split --pack`, `pack` and
//! `convert`, lossless ones exactly, lossy ones within stated bounds, and the bad combinations.

use std::path::Path;

use crate::common::cli::{fixture, ok, run, s};
use crate::common::compare::{Picture, Tolerance, assert_close};
use vortex_pack::{Pack, Tile, TileKind};

/// The error of a run that must fail.
fn fails(args: &[&str]) -> String {
    let out = run(args);
    assert_eq!(out.status.code(), Some(1), "{args:?} should fail");
    String::from_utf8_lossy(&out.stderr).into_owned()
}

/// A smooth RGB image (gradients and slow waves, the texture BC formats are made for).
fn smooth(path: &Path, width: u32, height: u32) {
    let img = image::RgbImage::from_fn(width, height, |x, y| {
        let (fx, fy) = (x as f32 / width as f32, y as f32 / height as f32);
        let wave = (fx * 7.0).sin() * (fy * 4.0).cos();
        image::Rgb([(128.0 + 100.0 * wave) as u8, (230.0 * fx) as u8, (40.0 + 200.0 * fx * fy) as u8])
    });
    img.save(path).unwrap();
}

/// Every tile of every level of a pack as RGBA8, in index order (absent tiles empty).
fn decoded(pack: &Path) -> Vec<Vec<u8>> {
    let pack = Pack::open(pack).unwrap();
    pack.ids().map(|id| pack.decode_rgba8(id).unwrap().unwrap_or_default()).collect()
}

/// PSNR in dB of `b` against `a` over the first `channels` samples of each RGBA texel.
fn psnr(a: &[Vec<u8>], b: &[Vec<u8>], channels: usize) -> f64 {
    let (mut sum, mut n) = (0f64, 0f64);
    for (ta, tb) in a.iter().zip(b) {
        assert_eq!(ta.len(), tb.len());
        for (pa, pb) in ta.chunks_exact(4).zip(tb.chunks_exact(4)) {
            for c in 0..channels {
                sum += (pa[c] as f64 - pb[c] as f64).powi(2);
                n += 1.0;
            }
        }
    }
    if sum == 0.0 { f64::INFINITY } else { 10.0 * (255f64.powi(2) * n / sum).log10() }
}

fn kinds(pack: &Path) -> serde_json::Value {
    let json: serde_json::Value = serde_json::from_str(&ok(&["info", s(pack), "--json"])).unwrap();
    json["kinds"].clone()
}

#[test]
fn every_codec_in_a_pack_decodes_losslessly_or_within_its_bound() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("smooth.png");
    smooth(&input, 150, 100);
    let split = |codec: &str, extra: &[&str]| {
        let pack = dir.path().join(format!("{codec}{}.vtpk", extra.join("")));
        let args = ["split", s(&input), "--pack", s(&pack), "--tile-size", "32", "--border", "2", "--codec", codec];
        ok(&[&args[..], extra, &["-q"]].concat());
        let report = ok(&["verify", "--decode", s(&pack)]);
        assert!(report.contains("OK: no problem found"), "{codec}: {report}");
        pack
    };
    let reference = decoded(&split("png", &[]));
    for (codec, extra) in [("raw", &[][..]), ("zstd", &[]), ("zstd", &["--zstd-level", "19"]), ("zstd-delta", &[])] {
        let pack = split(codec, extra);
        assert!(decoded(&pack) == reference, "{codec} {extra:?} is not lossless");
        let kind = if codec == "zstd-delta" { "zstd-delta" } else { codec };
        assert!(kinds(&pack)[kind]["tiles"].as_u64().unwrap() > 0, "{codec}");
    }
    // Block formats: within a bound on this smooth image (measured: BC1 43 dB, BC7 49 dB, 53 with --bc7-effort fast).
    for (codec, extra, bound) in
        [("bc1", &[][..], 35.0), ("bc7", &[][..], 42.0), ("bc7", &["--bc7-effort", "fast"][..], 42.0)]
    {
        let pack = split(codec, extra);
        let db = psnr(&reference, &decoded(&pack), 3);
        assert!(db >= bound, "{codec} {extra:?}: {db:.1} dB < {bound}");
        let blocks = (32 / 4) * (32 / 4) * if codec == "bc1" { 8 } else { 16 };
        let p = Pack::open(&pack).unwrap();
        let vortex_pack::Tile::Data(kind, bytes) = p.tile(vortex_pack::TileId::new(0, 0, 0)).unwrap() else {
            panic!("{codec}")
        };
        assert_eq!((kind.name(), bytes.len()), (codec, blocks));
    }
}

#[test]
fn lossless_pack_codecs_keep_16_bits_and_alpha_exactly() {
    // convert re-tiles LOD 0 of a pack through the split pipeline, so png tiles cut from a pack
    // equal png tiles cut from the original exactly when the pack is lossless, at 16 bits too.
    let dir = tempfile::tempdir().unwrap();
    for fixture_name in ["grey-alpha16-97x61.png", "rgba8-130x67.png"] {
        let input = fixture(fixture_name);
        let direct = dir.path().join(format!("{fixture_name}.direct"));
        ok(&["split", s(&input), "-o", s(&direct), "--tile-size", "16", "--codec", "png", "-q"]);
        for codec in ["raw", "zstd", "zstd-delta"] {
            let pack = dir.path().join(format!("{fixture_name}.{codec}.vtpk"));
            ok(&["split", s(&input), "--pack", s(&pack), "--tile-size", "16", "--codec", codec, "-q"]);
            let back = dir.path().join(format!("{fixture_name}.{codec}.back"));
            ok(&["convert", s(&pack), "-o", s(&back), "--tile-size", "16", "--codec", "png", "-q"]);
            let mut compared = 0;
            for entry in std::fs::read_dir(&direct).unwrap() {
                let name = entry.unwrap().file_name();
                if name == "info.json" {
                    continue;
                }
                compared += 1;
                let (a, b) = (std::fs::read(direct.join(&name)).unwrap(), std::fs::read(back.join(&name)).unwrap());
                assert!(a == b, "{fixture_name} through {codec}: {name:?} differs");
            }
            assert!(compared > 20, "{compared}");
        }
    }
}

#[test]
fn zstd_delta_compresses_smooth_texels_better_than_zstd() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("smooth.png");
    smooth(&input, 256, 256);
    let size = |codec: &str| {
        let pack = dir.path().join(format!("{codec}.vtpk"));
        ok(&["split", s(&input), "--pack", s(&pack), "--tile-size", "64", "--codec", codec, "-q"]);
        let json: serde_json::Value = serde_json::from_str(&ok(&["info", s(&pack), "--json"])).unwrap();
        json["payloadBytesStored"].as_u64().unwrap()
    };
    let (raw, zstd, delta) = (size("raw"), size("zstd"), size("zstd-delta"));
    assert!(delta * 2 < zstd && zstd < raw, "raw {raw}, zstd {zstd}, zstd-delta {delta}");
}

#[test]
fn jpeg_444_keeps_colour_edges_better_than_420() {
    let dir = tempfile::tempdir().unwrap();
    // Saturated stripes 3 texels wide: chroma changes at every third texel, luma barely.
    let input = dir.path().join("stripes.png");
    let colours = [[220u8, 30, 30], [30, 30, 220], [30, 170, 30]];
    image::RgbImage::from_fn(96, 64, |x, y| image::Rgb(colours[((x + y / 8) / 3) as usize % 3])).save(&input).unwrap();
    let pack = |codec: &str, extra: &[&str]| {
        let p = dir.path().join(format!("{codec}{}.vtpk", extra.join("")));
        let args = ["split", s(&input), "--pack", s(&p), "--tile-size", "32", "--codec", codec, "--quality", "90"];
        ok(&[&args[..], extra, &["-q"]].concat());
        decoded(&p)
    };
    let reference = pack("png", &[]);
    let s420 = psnr(&reference, &pack("jpeg", &[]), 3);
    let explicit420 = psnr(&reference, &pack("jpeg", &["--subsampling", "420"]), 3);
    let s444 = psnr(&reference, &pack("jpeg", &["--subsampling", "444"]), 3);
    assert_eq!(s420, explicit420, "420 is the default");
    assert!(s444 > s420 + 3.0, "4:4:4 {s444:.1} dB, 4:2:0 {s420:.1} dB");
}

#[test]
fn pack_and_convert_reencode_with_the_codec_flags() {
    let dir = tempfile::tempdir().unwrap();
    // Half one colour, so that some tiles are: re-encoding stores those as constants.
    let input = dir.path().join("half.png");
    image::RgbImage::from_fn(300, 160, |x, y| match x < 150 {
        true => image::Rgb([90, 120, 200]),
        false => image::Rgb([(x * 7 % 256) as u8, (y * 5 % 256) as u8, ((x + y) % 256) as u8]),
    })
    .save(&input)
    .unwrap();
    let tiles = dir.path().join("tiles");
    ok(&["split", s(&input), "-o", s(&tiles), "--tile-size", "64", "--codec", "png", "-q"]);
    let plain = dir.path().join("plain.vtpk");
    ok(&["pack", s(&tiles), "-o", s(&plain), "-q"]);
    // The directory's own codec: the files are stored as they are.
    let same = dir.path().join("same.vtpk");
    ok(&["pack", s(&tiles), "-o", s(&same), "--codec", "png", "-q"]);
    assert!(std::fs::read(&plain).unwrap() == std::fs::read(&same).unwrap());

    let reference = decoded(&plain);
    for codec in ["raw", "zstd", "zstd-delta", "bc1", "bc7"] {
        let pack = dir.path().join(format!("{codec}.vtpk"));
        ok(&["pack", s(&tiles), "-o", s(&pack), "--codec", codec, "-q"]);
        assert!(ok(&["verify", "--decode", s(&pack)]).contains("OK"), "{codec}");
        let got = decoded(&pack);
        if codec.starts_with("bc") {
            let db = psnr(&reference, &got, 3);
            assert!(db >= 30.0, "{codec}: {db:.1} dB");
        } else {
            assert!(got == reference, "{codec} is not lossless");
        }
        // One-colour tiles became constants; the metadata names the new codec and names.
        let kinds = kinds(&pack);
        assert!(kinds["constant"]["tiles"].as_u64().unwrap() > 0 && kinds["png"].is_null(), "{codec}: {kinds}");
        let meta: serde_json::Value = serde_json::from_slice(Pack::open(&pack).unwrap().metadata()).unwrap();
        assert_eq!(meta["codec"], codec);
        assert!(!meta["filenameFormat"].as_str().unwrap().ends_with(".png"), "{meta}");
        assert_eq!(meta["pngCompression"], serde_json::Value::Null);
    }
    let meta =
        |pack: &Path| -> serde_json::Value { serde_json::from_slice(Pack::open(pack).unwrap().metadata()).unwrap() };
    let z = dir.path().join("z9.vtpk");
    ok(&["pack", s(&tiles), "-o", s(&z), "--codec", "zstd", "--zstd-level", "9", "-q"]);
    assert_eq!(meta(&z)["zstdLevel"], 9);

    // convert takes the same flags: a BC7 pack back to files, and to another pack.
    let bc7 = dir.path().join("bc7.vtpk");
    let files = dir.path().join("from-bc7");
    ok(&["convert", s(&bc7), "-o", s(&files), "--tile-size", "64", "--codec", "png", "-q"]);
    assert!(files.join("lod00-x0000-y0000.png").is_file());
    let again = dir.path().join("again.vtpk");
    let args =
        ["convert", s(&bc7), "--pack", s(&again), "--tile-size", "64", "--codec", "bc7", "--bc7-effort", "basic"];
    ok(&[&args[..], &["-q"]].concat());
    assert_eq!(meta(&again)["bc7Effort"], "basic");
    assert_eq!(meta(&again)["tileFormat"], "rgb");
    let p = Pack::open(&again).unwrap();
    let vortex_pack::Tile::Data(TileKind::Bc7, bytes) = p.tile(vortex_pack::TileId::new(0, 3, 1)).unwrap() else {
        panic!()
    };
    let texels = Tile::Data(TileKind::Bc7, bytes).decode_texels(p.description(), 1 << 20).unwrap();
    assert_eq!(texels.len(), 64 * 64 * 3);
}

#[test]
fn bc7_ignores_colour_under_alpha_zero() {
    // Opaque smooth discs over a fully transparent background of random colour.
    let dir = tempfile::tempdir().unwrap();
    let src = dir.path().join("cutout.png");
    let mut seed = 0x9e37_79b9_7f4a_7c15u64;
    let img = image::RgbaImage::from_fn(96, 96, |x, y| {
        seed ^= seed << 13;
        seed ^= seed >> 7;
        seed ^= seed << 17;
        let inside = ((x as i32 - 48).pow(2) + (y as i32 - 48).pow(2)) < 30 * 30;
        let [a, b, c, ..] = seed.to_le_bytes();
        if inside { image::Rgba([(x * 2) as u8, (y * 2) as u8, 128, 255]) } else { image::Rgba([a, b, c, 0]) }
    });
    img.save(&src).unwrap();
    let pack = dir.path().join("cutout.vtpk");
    ok(&["split", s(&src), "--pack", s(&pack), "--tile-size", "32", "--border", "0", "--codec", "bc7", "-q"]);
    let p = Pack::open(&pack).unwrap();
    let id = vortex_pack::TileId { lod: 0, x: 1, y: 0 };
    let got = p.decode_rgba8(id).unwrap().unwrap();
    // The tile's source texels: x 32..64, y 0..32 of the image.
    let want: Vec<u8> =
        (0..32).flat_map(|y| (32..64).map(move |x| (x, y))).flat_map(|(x, y)| img.get_pixel(x, y).0).collect();
    let alpha = |t: &[u8]| t.chunks_exact(4).map(|t| t[3]).collect::<Vec<u8>>();
    // Bounds without a measurement written down: BC7's endpoints and indices are quantised.
    let why = "BC7 quantises alpha with the colour in each 4x4 block";
    let (got_alpha, want_alpha) = (alpha(&got), alpha(&want));
    assert_close(
        "bc7-alpha",
        Picture::new(32, 32, 1, &got_alpha),
        Picture::new(32, 32, 1, &want_alpha),
        Tolerance::max(8, why),
    );
    // The colour where the source is opaque; where it is transparent the encoder may put any.
    let visible = |t: &[u8]| -> Vec<u8> {
        let each = t.chunks_exact(4).zip(want.chunks_exact(4));
        each.flat_map(|(t, w)| if w[3] == 255 { [t[0], t[1], t[2]] } else { [0; 3] }).collect()
    };
    let why = "BC7 quantises the colour of the blocks the disc shares with the transparent background";
    let (got_rgb, want_rgb) = (visible(&got), visible(&want));
    assert_close(
        "bc7-visible-colour",
        Picture::new(32, 32, 3, &got_rgb),
        Picture::new(32, 32, 3, &want_rgb),
        Tolerance::max(12, why),
    );
}

#[test]
fn bad_codec_combinations_are_errors_naming_the_flag() {
    let dir = tempfile::tempdir().unwrap();
    let sample = fixture("sample.png");
    let pack = dir.path().join("p.vtpk");
    let p = s(&pack);
    for (args, expected) in [
        (vec!["--pack", p, "--codec", "bc1", "--tile-size", "130"], "--tile-size must be a multiple of 4, not 130"),
        (vec!["--pack", p, "--codec", "bc7", "--tile-size", "66"], "--codec bc7 stores 4x4-texel blocks"),
        (vec!["--pack", p, "--codec", "zstd", "--zstd-level", "23"], "zstd level 23 (--zstd-level) is outside 1..=22"),
        (vec!["--pack", p, "--codec", "zstd-delta", "--zstd-level", "0"], "(--zstd-level) is outside 1..=22"),
        (vec!["--pack", p, "--codec", "zstd", "--zstd-level", "-3"], "(--zstd-level) is outside 1..=22"),
        (vec!["--pack", p, "--codec", "bc7", "--tile-type", "unsignedShort"], "stores 8-bit samples only"),
        (vec!["-o", s(&dir.path().join("o")), "--codec", "raw"], "--codec raw writes packs only"),
        (vec!["-o", s(&dir.path().join("o")), "--codec", "zstd-delta"], "write --pack FILE instead of --output"),
        (vec!["-o", s(&dir.path().join("o")), "--codec", "bc1"], "--codec bc1 writes packs only"),
    ] {
        let err = fails(&[&["split", s(&sample)][..], &args].concat());
        assert!(err.contains(expected), "{args:?}: {err}");
    }
    let err = fails(&["split", s(&fixture("rgba8-130x67.png")), "--pack", p, "--codec", "bc1"]);
    assert!(err.contains("--codec bc1 stores opaque RGB: use --codec bc7"), "{err}");
    assert!(!pack.exists() && !dir.path().join("o").exists());

    // pack checks its codec flags against the directory's tiles.
    let tiles = dir.path().join("tiles");
    ok(&["split", s(&sample), "-o", s(&tiles), "--tile-size", "30", "-q"]);
    let err = fails(&["pack", s(&tiles), "-o", p, "--codec", "bc1"]);
    assert!(err.contains("--tile-size must be a multiple of 4, not 30"), "{err}");
    let err = fails(&["pack", s(&tiles), "-o", p, "--codec", "zstd", "--zstd-level", "40"]);
    assert!(err.contains("--zstd-level"), "{err}");

    // A pack of raw texels or blocks cannot be unpacked to files; the error says what can.
    ok(&["split", s(&sample), "--pack", p, "--codec", "zstd", "-q"]);
    let err = fails(&["unpack", p, "-o", s(&dir.path().join("u"))]);
    assert!(err.contains("zstd payloads, which are not image files") && err.contains("convert"), "{err}");
    assert!(!dir.path().join("u").exists());
}
