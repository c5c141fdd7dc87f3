//! The command line as a user meets it: good runs, and one clear line plus exit code 1 for
//! every kind of bad input.

use std::path::{Path, PathBuf};

use crate::common::cli::{fails_with, fixture, ok, run, s};

/// A small PPM with the given header and `body` bytes of pixels.
fn ppm(dir: &Path, name: &str, header: &str, body: usize) -> PathBuf {
    let p = dir.join(name);
    let mut bytes = header.as_bytes().to_vec();
    bytes.resize(bytes.len() + body, 77);
    std::fs::write(&p, bytes).unwrap();
    p
}

#[test]
fn splits_the_fixture_with_both_spellings() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let r = run(&["split", s(&fixture("sample.png")), "-o", s(&out), "--tile-size", "64", "--border", "2"]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let line = String::from_utf8_lossy(&r.stdout);
    // 700 x 500 in 60-texel payloads: 12 x 9, 6 x 5, 3 x 3, 2 x 2 and 1 x 1 pages.
    assert!(line.contains("wrote 152 tiles") && line.contains("Mpx/s"), "{line}");
    let info: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join("info.json")).unwrap()).unwrap();
    assert_eq!(info["tileSize"], 64);
    assert_eq!((&info["tileColumns"], &info["tileRows"], &info["lodCount"]), (&12.into(), &9.into(), &5.into()));
    // Not a square power-of-two grid: no thesis tileCount.
    assert!(info.get("tileCount").is_none(), "{info}");
    assert!(out.join("lod04-x0000-y0000.jpg").is_file());
    assert!(out.join("lod00-x0011-y0008.jpg").is_file());
    assert!(!out.join("lod00-x0012-y0000.jpg").exists() && !out.join("lod00-x0000-y0009.jpg").exists());
    assert_eq!(std::fs::read_dir(&out).unwrap().count(), 152 + 1);

    let out2 = dir.path().join("out2");
    let r = run(&["split", &format!("--input={}", s(&fixture("sample.png"))), &format!("--output={}", s(&out2)), "-q"]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    assert!(r.stdout.is_empty());
    assert!(out2.join("info.json").is_file());
}

#[test]
fn json_summary_says_where_the_time_went() {
    let dir = tempfile::tempdir().unwrap();
    let pack = dir.path().join("t.vtpk");
    let r = run(&["split", s(&fixture("sample.png")), "--pack", s(&pack), "--json"]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let json: serde_json::Value = serde_json::from_slice(&r.stdout).unwrap();
    let stage = |name: &str| json["stages"][name].as_f64().unwrap_or_else(|| panic!("stages.{name}: {json}"));
    let (seconds, read, pyramid, encode) =
        (json["seconds"].as_f64().unwrap(), stage("readSeconds"), stage("pyramidSeconds"), stage("encodeSeconds"));
    assert!(read > 0.0 && pyramid > 0.0 && encode > 0.0, "{json}");
    // Each thread's stages happen in its own run, none longer than the whole: the reader's
    // reading; the producer's waits for rows and sums; the cutter's cutting and its waits for
    // the encoders; the encoders' idle and busy time; the writer's storing. (Threads overlap:
    // stages of different threads do not add up to the wall time.)
    let within = |parts: &[&str]| parts.iter().map(|p| stage(p)).sum::<f64>() <= seconds;
    assert!(within(&["readSeconds"]), "{json}");
    assert!(within(&["readWaitSeconds", "pyramidSeconds"]), "{json}");
    assert!(within(&["cutSeconds", "producerBlockedSeconds"]), "{json}");
    assert!(within(&["encodersIdleSeconds", "encodeSeconds"]), "{json}");
    assert!(within(&["storeSeconds"]), "{json}");
}

#[test]
fn existing_info_json_sets_the_output_and_flags_override_it() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    std::fs::create_dir(&out).unwrap();
    std::fs::write(out.join("info.json"), r#"{"tileSize":256,"filenameFormat":"t/%1$d/%2$d_%3$d.png"}"#).unwrap();
    let r = run(&["split", s(&fixture("sample.png")), "-o", s(&out), "-q"]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    assert!(out.join("t/0/2_1.png").is_file(), "the PNG names and 256 tiles from info.json were used");
    let info: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join("info.json")).unwrap()).unwrap();
    assert_eq!((info["tileSize"].as_u64(), info["codec"].as_str()), (Some(256), Some("png")));

    // A flag overrides; the rewritten info.json is now the configuration. A tile the old
    // pattern names is part of the previous output, replaced with it.
    std::fs::write(out.join("t/0/99_99.png"), "from an older run").unwrap();
    let r = run(&["split", s(&fixture("sample.png")), "-o", s(&out), "-q", "--tile-size", "128"]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let info: serde_json::Value = serde_json::from_slice(&std::fs::read(out.join("info.json")).unwrap()).unwrap();
    assert_eq!(info["tileSize"], 128);
    assert!(out.join("t/3/0_0.png").is_file(), "128-texel tiles make 4 LODs");
    assert!(!out.join("t/0/99_99.png").exists(), "the previous pyramid was replaced, not mixed in");
}

#[test]
fn border_defaults_to_one_texel_and_zero_is_still_there() {
    // The runtime filters trilinearly by default, which reads one texel across a page edge:
    // without --border, tiles carry that texel of their neighbours (docs/gpu-sampling.md).
    let dir = tempfile::tempdir().unwrap();
    let sample = fixture("sample.png");
    let source = image::open(&sample).unwrap().to_rgb8();
    let info = |d: &Path| -> serde_json::Value {
        serde_json::from_slice(&std::fs::read(d.join("info.json")).unwrap()).unwrap()
    };
    let pack_json = |p: &Path| -> serde_json::Value { serde_json::from_str(&ok(&["info", s(p), "--json"])).unwrap() };
    // Column 0 of page (1, 0) at LOD 0, and the source column it must repeat.
    let left_edge = |d: &Path| {
        let tile = image::open(d.join("lod00-x0001-y0000.png")).unwrap().to_rgb8();
        (0..tile.height()).map(|y| *tile.get_pixel(0, y)).collect::<Vec<_>>()
    };
    let column = |x: u32, rows: std::ops::Range<u32>| rows.map(|y| *source.get_pixel(x, y)).collect::<Vec<_>>();

    let files = dir.path().join("files");
    ok(&["split", s(&sample), "-o", s(&files), "--codec", "png", "-q"]);
    assert_eq!((&info(&files)["border"], &info(&files)["tileSize"]), (&1.into(), &128.into()));
    // 126-texel payloads: page (1, 0) starts at source column 126, its border at 125; its top
    // border row repeats the image's first row.
    let want: Vec<_> = column(125, 0..1).into_iter().chain(column(125, 0..127)).collect();
    assert_eq!(left_edge(&files), want);
    let pack = dir.path().join("default.vtpk");
    ok(&["split", s(&sample), "--pack", s(&pack), "-q"]);
    let json = pack_json(&pack);
    assert_eq!((&json["border"], &json["metadata"]["border"]), (&1.into(), &1.into()));

    // --border 0 as before: pages meet without shared texels.
    let flat = dir.path().join("flat");
    ok(&["split", s(&sample), "-o", s(&flat), "--codec", "png", "--border", "0", "-q"]);
    assert_eq!(info(&flat)["border"], 0);
    assert_eq!(left_edge(&flat), column(128, 0..128));
    let flat_pack = dir.path().join("flat.vtpk");
    ok(&["split", s(&sample), "--pack", s(&flat_pack), "--border", "0", "-q"]);
    let json = pack_json(&flat_pack);
    assert_eq!((&json["border"], &json["metadata"]["border"]), (&0.into(), &0.into()));

    // convert re-tiles with the same default, whatever the input's border.
    let conv = dir.path().join("conv.vtpk");
    ok(&["convert", s(&flat_pack), "--pack", s(&conv), "-q"]);
    assert_eq!(pack_json(&conv)["border"], 1);

    // An existing info.json without border is a thesis file's: its tiles have none.
    let thesis = dir.path().join("thesis");
    std::fs::create_dir(&thesis).unwrap();
    std::fs::write(thesis.join("info.json"), r#"{"tileSize":128,"tileCount":8,"lodCount":4}"#).unwrap();
    let r = run(&["split", s(&sample), "-o", s(&thesis)]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    assert_eq!(info(&thesis)["border"], 0);
    let said = String::from_utf8_lossy(&r.stderr);
    assert!(said.contains("settings from") && said.contains("border 0"), "{said}");

    // --help says why.
    let help =
        String::from_utf8_lossy(&run(&["split", "--help"]).stdout).split_whitespace().collect::<Vec<_>>().join(" ");
    assert!(help.contains("bilinear and trilinear filtering without seams") && help.contains("[default: 1;"), "{help}");
}

#[test]
fn help_lists_options_with_defaults() {
    let r = run(&["split", "--help"]);
    let help = String::from_utf8_lossy(&r.stdout);
    for needle in [
        "--tile-size",
        "[default: 128]",
        "--border",
        "--codec",
        "--quality",
        "[default: 85]",
        "--background",
        "--max-memory",
        "[default: 1G]",
        "--filename-format",
        "--ff",
    ] {
        assert!(help.contains(needle), "--help lacks {needle}");
    }
}

#[test]
fn missing_and_unreadable_inputs() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    fails_with(&run(&["split", "/no/such/image.png", "-o", s(&out)]), &["/no/such/image.png", "No such file"]);
    fails_with(&run(&["split", s(dir.path()), "-o", s(&out)]), &[s(dir.path()), "directory"]);
    let empty = ppm(dir.path(), "empty.ppm", "", 0);
    fails_with(&run(&["split", s(&empty), "-o", s(&out)]), &["empty.ppm", "empty"]);
    let text = dir.path().join("notes.txt");
    std::fs::write(&text, "hello, not an image").unwrap();
    fails_with(&run(&["split", s(&text), "-o", s(&out)]), &["notes.txt", "not an image format"]);
    assert!(!out.exists());
}

#[test]
fn truncated_and_corrupt_images() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let png = std::fs::read(fixture("sample.png")).unwrap();
    let cut = dir.path().join("cut.png");
    std::fs::write(&cut, &png[..png.len() / 2]).unwrap();
    fails_with(&run(&["split", s(&cut), "-o", s(&out)]), &["cut.png", "row "]);
    assert!(!out.exists(), "a failed run leaves no output");
    let leftovers: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
    assert_eq!(leftovers.len(), 1, "the staging directory was removed: {leftovers:?}");

    let mut bad = png.clone();
    for b in &mut bad[200..400] {
        *b ^= 0x5a;
    }
    let bad_path = dir.path().join("bad.png");
    std::fs::write(&bad_path, &bad).unwrap();
    fails_with(&run(&["split", s(&bad_path), "-o", s(&out)]), &["bad.png"]);

    let header_only = dir.path().join("header.png");
    std::fs::write(&header_only, &png[..8]).unwrap();
    fails_with(&run(&["split", s(&header_only), "-o", s(&out)]), &["header.png", "PNG"]);
}

#[test]
fn headers_that_lie_or_are_absurd() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let lying = ppm(dir.path(), "lying.ppm", "P6\n1000 1000\n255\n", 3 * 1000 * 10);
    fails_with(&run(&["split", s(&lying), "-o", s(&out)]), &["lying.ppm", "truncated", "1000x1000"]);
    let zero = ppm(dir.path(), "zero.ppm", "P6\n0 10\n255\n", 0);
    fails_with(&run(&["split", s(&zero), "-o", s(&out)]), &["zero.ppm", "no pixels"]);
    let huge = ppm(dir.path(), "huge.ppm", "P5\n40000000 1\n255\n", 40_000_000);
    fails_with(&run(&["split", s(&huge), "-o", s(&out)]), &["40000000x1", "not supported"]);
    let bad_field = ppm(dir.path(), "field.ppm", "P6\n10 ten\n255\n", 300);
    fails_with(&run(&["split", s(&bad_field), "-o", s(&out)]), &["field.ppm", "height"]);
}

#[test]
fn unwritable_or_foreign_output() {
    let dir = tempfile::tempdir().unwrap();
    let file = dir.path().join("a-file");
    std::fs::write(&file, "x").unwrap();
    let under_file = file.join("out");
    fails_with(&run(&["split", s(&fixture("sample.png")), "-o", s(&under_file)]), &["a-file"]);
    fails_with(
        &run(&["split", s(&fixture("sample.png")), "-o", s(&file)]),
        &["a-file", "is a file where a tile directory goes"],
    );
    let foreign = dir.path().join("photos");
    std::fs::create_dir(&foreign).unwrap();
    std::fs::write(foreign.join("holiday.jpg"), "precious").unwrap();
    fails_with(&run(&["split", s(&fixture("sample.png")), "-o", s(&foreign)]), &["photos", "no info.json"]);
    assert_eq!(std::fs::read(foreign.join("holiday.jpg")).unwrap(), b"precious");
}

#[test]
fn contradictory_settings() {
    let dir = tempfile::tempdir().unwrap();
    let out = dir.path().join("out");
    let rgba = dir.path().join("rgba.png");
    image::RgbaImage::from_pixel(40, 30, image::Rgba([1, 2, 3, 4])).save(&rgba).unwrap();
    fails_with(&run(&["split", s(&rgba), "-o", s(&out), "--codec", "jpeg"]), &["alpha", "--flatten"]);
    let r = run(&["split", s(&rgba), "-o", s(&out), "--codec", "jpeg", "--flatten", "-q"]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));

    fails_with(
        &run(&[
            "split",
            s(&rgba),
            "-o",
            s(&dir.path().join("o2")),
            "--codec",
            "jpeg",
            "--ff",
            "%s-%s-%s.png",
            "--flatten",
        ]),
        &[".png", "jpeg"],
    );
    fails_with(
        &run(&["split", s(&rgba), "-o", s(&dir.path().join("o3")), "--ff", "x%s-y%s.png"]),
        &["never uses argument 3"],
    );
    let sample = fixture("sample.png");
    fails_with(
        &run(&["split", s(&sample), "-o", s(&dir.path().join("o4")), "--ff", "%1$s%2$s%3$s.png", "--tile-size", "16"]),
        &["two tiles one name"],
    );
    fails_with(&run(&["split", s(&rgba), "-o", s(&dir.path().join("o5")), "--border", "70"]), &["border 70"]);

    let conf = dir.path().join("conf");
    std::fs::create_dir(&conf).unwrap();
    std::fs::write(conf.join("info.json"), r#"{"tileSize":128,"tileCount":512,"lodCount":10}"#).unwrap();
    fails_with(&run(&["split", s(&rgba), "-o", s(&conf)]), &["info.json", "tileCount", "512"]);
    std::fs::write(conf.join("info.json"), r#"{"tileFormat":"luminance"}"#).unwrap();
    fails_with(&run(&["split", s(&rgba), "-o", s(&conf)]), &["info.json", "tileFormat"]);
    std::fs::write(conf.join("info.json"), r#"{"tileSize": "big"}"#).unwrap();
    fails_with(&run(&["split", s(&rgba), "-o", s(&conf)]), &["info.json", "line 1"]);
}

#[test]
fn filter_flag_is_checked_recorded_and_read_back() {
    let dir = tempfile::tempdir().unwrap();
    let rgba = dir.path().join("rgba.png");
    image::RgbaImage::from_fn(70, 50, |x, y| image::Rgba([x as u8, y as u8, 7, if x < 30 { 255 } else { 0 }]))
        .save(&rgba)
        .unwrap();
    let info = |dir: &Path| -> serde_json::Value {
        serde_json::from_slice(&std::fs::read(dir.join("info.json")).unwrap()).unwrap()
    };

    // A bad value is refused by the parser, which lists the good ones.
    let r = run(&["split", s(&rgba), "-o", s(&dir.path().join("bad")), "--filter", "gaussian"]);
    let err = String::from_utf8_lossy(&r.stderr);
    assert_eq!(r.status.code(), Some(2), "{err}");
    for needle in ["gaussian", "--filter", "box", "linear-premultiplied", "lanczos3", "mitchell"] {
        assert!(err.contains(needle), "stderr lacks {needle}: {err}");
    }
    assert!(!dir.path().join("bad").exists());

    // Recorded in info.json; linear-premultiplied when not given.
    let out = dir.path().join("out");
    let r = run(&["split", s(&rgba), "-o", s(&out), "--tile-size", "16", "--filter", "premultiplied", "-q"]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    assert_eq!(info(&out)["filter"], "premultiplied");
    let plain = dir.path().join("plain");
    assert!(run(&["split", s(&rgba), "-o", s(&plain), "--tile-size", "16", "-q"]).status.success());
    assert_eq!(info(&plain)["filter"], "linear-premultiplied");

    // An existing info.json's filter is this run's default, and the flag overrides it.
    assert!(run(&["split", s(&rgba), "-o", s(&out), "-q"]).status.success());
    assert_eq!(info(&out)["filter"], "premultiplied");
    assert!(run(&["split", s(&rgba), "-o", s(&out), "--filter", "lanczos3", "-q"]).status.success());
    assert_eq!(info(&out)["filter"], "lanczos3");
    let conf = dir.path().join("conf");
    std::fs::create_dir(&conf).unwrap();
    std::fs::write(conf.join("info.json"), r#"{"filter":"gaussian"}"#).unwrap();
    fails_with(&run(&["split", s(&rgba), "-o", s(&conf)]), &["info.json", "filter", "gaussian"]);

    // convert takes it too; a pack's metadata records it, and pack keeps what the files were made with.
    let conv = dir.path().join("conv");
    let r = run(&["convert", s(&out), "-o", s(&conv), "--tile-size", "32", "--filter", "linear", "-q"]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    assert_eq!(info(&conv)["filter"], "linear");
    let pack = dir.path().join("conv.vtpk");
    assert!(run(&["pack", s(&conv), "-o", s(&pack), "-q"]).status.success());
    let r = run(&["info", s(&pack), "--json"]);
    let json: serde_json::Value = serde_json::from_slice(&r.stdout).unwrap();
    assert_eq!(json["metadata"]["filter"], "linear");
    let direct = dir.path().join("direct.vtpk");
    assert!(run(&["split", s(&rgba), "--pack", s(&direct), "--filter", "mitchell", "-q"]).status.success());
    let json: serde_json::Value = serde_json::from_slice(&run(&["info", s(&direct), "--json"]).stdout).unwrap();
    assert_eq!(json["metadata"]["filter"], "mitchell");
}
