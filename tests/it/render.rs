//! `vortex-tiler render` as a user runs it: split the fixture into a pack, render the default
//! scene and the documented example scene, read the frames and the report; and clear errors for
//! bad packs and scenes. The GPU is lavapipe when it is installed (pinned as the GPU crate's tests
//! do); without an adapter the tests print a note and pass, except under `CI=true`.

use std::path::{Path, PathBuf};
use std::process::Output;

use crate::common::cli::{fails_with, fixture, run, s};
use crate::common::compare::{Picture, Tolerance, assert_close};

fn root(p: &str) -> PathBuf {
    Path::new(env!("CARGO_MANIFEST_DIR")).join(p)
}

/// The fixture as a pack of 136-texel tiles with a 4-texel border.
pub(crate) fn sample_pack(dir: &Path) -> PathBuf {
    let pack = dir.join("sample.vtpk");
    let r = run(&["split", s(&fixture("sample.png")), "--pack", s(&pack), "--tile-size", "136", "--border", "4"]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    pack
}

/// Whether the render failed for want of a GPU (and that is allowed here).
pub(crate) fn no_gpu(out: &Output) -> bool {
    let err = String::from_utf8_lossy(&out.stderr);
    if out.status.success() || !err.contains("no GPU adapter") {
        return false;
    }
    crate::common::skip_unless_ci("a GPU test", &format!("no GPU adapter: {err}"));
    true
}

pub(crate) fn report(path: &Path) -> serde_json::Value {
    serde_json::from_slice(&std::fs::read(path).unwrap()).unwrap()
}

#[test]
fn the_default_scene_streams_a_small_share_of_the_pack_and_converges() {
    let dir = tempfile::tempdir().unwrap();
    let pack = sample_pack(dir.path());
    let (frames, json) = (dir.path().join("frames"), dir.path().join("report.json"));
    let out =
        run(&["render", "--pack", s(&pack), "--frames", s(&frames), "--report", s(&json), "--size", "128x96", "-q"]);
    if no_gpu(&out) {
        return;
    }
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let line = String::from_utf8_lossy(&out.stdout);
    assert!(line.contains("rendered 60 frames of 128x96") && line.contains("pages touched"), "{line}");
    let r = report(&json);
    let per_frame = r["frames"].as_array().unwrap();
    assert_eq!(per_frame.len(), 60);
    for key in ["requested", "loaded", "evicted", "fallback_fraction", "lod_bias"] {
        assert!(per_frame.iter().all(|f| f[key].is_number()), "{key}");
    }
    assert_eq!(per_frame.last().unwrap()["fallback_fraction"], 0.0);
    assert!(r["frames_to_converge"].is_u64(), "{}", r["frames_to_converge"]);
    let (touched, total) = (r["pages_touched"].as_u64().unwrap(), r["pages_total"].as_u64().unwrap());
    assert!(0 < touched && touched < total, "{touched} of {total}");
    assert!(r["bytes_read"].as_u64().unwrap() > 0);
    // 60 PNG frames of the requested size, and no temporary files left.
    let names: Vec<String> =
        std::fs::read_dir(&frames).unwrap().map(|e| e.unwrap().file_name().to_string_lossy().into()).collect();
    assert_eq!(names.len(), 60, "{names:?}");
    let decoder =
        png::Decoder::new(std::io::BufReader::new(std::fs::File::open(frames.join("frame-0059.png")).unwrap()));
    let info = decoder.read_info().unwrap().info().clone();
    assert_eq!((info.width, info.height), (128, 96));
    assert!(!dir.path().read_dir().unwrap().any(|e| e.unwrap().file_name().to_string_lossy().contains(".partial")));
}

#[test]
fn anisotropy_is_asked_for_and_reported() {
    let dir = tempfile::tempdir().unwrap();
    let pack = sample_pack(dir.path());
    let json = dir.path().join("report.json");
    let bad = run(&["render", "--pack", s(&pack), "--anisotropy", "3", "-q"]);
    assert!(!bad.status.success());
    assert!(String::from_utf8_lossy(&bad.stderr).contains("must be 1 (off), 2, 4, 8 or 16"));
    let out = run(&[
        "render",
        "--pack",
        s(&pack),
        "--report",
        s(&json),
        "--size",
        "128x96",
        "--frame-count",
        "8",
        "--anisotropy",
        "8",
        "-q",
    ]);
    if no_gpu(&out) {
        return;
    }
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(report(&json)["anisotropy"], 8);
}

#[test]
fn the_documented_example_scene_renders() {
    let dir = tempfile::tempdir().unwrap();
    let pack = sample_pack(dir.path());
    // The example in docs/scenes.md is docs/scene-example.json, member for member.
    let doc = std::fs::read_to_string(root("docs/scenes.md")).unwrap();
    let block = doc.split("```json\n").nth(1).unwrap().split("```").next().unwrap();
    let file = std::fs::read_to_string(root("docs/scene-example.json")).unwrap();
    let parse = |t: &str| serde_json::from_str::<serde_json::Value>(t).unwrap();
    assert_eq!(parse(block), parse(&file), "docs/scenes.md and docs/scene-example.json differ");

    let json = dir.path().join("report.json");
    let scene = root("docs/scene-example.json");
    let out =
        run(&["render", "--pack", s(&pack), "--scene", s(&scene), "--report", s(&json), "--size", "160x120", "-q"]);
    if no_gpu(&out) {
        return;
    }
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let r = report(&json);
    assert_eq!(r["filter"], "trilinear");
    assert_eq!(r["cache_slots"], 144);
    assert_eq!(r["frames"].as_array().unwrap().len(), 48);
    assert!(r["frames"].as_array().unwrap().iter().all(|f| f["loaded"].as_u64().unwrap() <= 16));
}

#[test]
fn bad_packs_and_scenes_are_named() {
    let dir = tempfile::tempdir().unwrap();
    fails_with(&run(&["render"]), &["no texture", "--pack"]);
    let missing = dir.path().join("missing.vtpk");
    fails_with(&run(&["render", "--pack", s(&missing)]), &["missing.vtpk"]);
    let not_a_pack = dir.path().join("text.vtpk");
    std::fs::write(&not_a_pack, "hello").unwrap();
    fails_with(&run(&["render", "--pack", s(&not_a_pack)]), &["text.vtpk"]);

    let pack = sample_pack(dir.path());
    let scene = dir.path().join("scene.json");
    std::fs::write(&scene, r#"{"view": {"window": {"path": [{"frame": 0, "center": [0.5, 0.5], "width": 1}]}}, "effects": {"filter": "bicubic"}}"#).unwrap();
    fails_with(&run(&["render", "--pack", s(&pack), "--scene", s(&scene)]), &["scene.json", "bicubic"]);
    std::fs::write(
        &scene,
        r#"{"view": {"window": {"texture": 3, "path": [{"frame": 0, "center": [0.5, 0.5], "width": 1}]}}}"#,
    )
    .unwrap();
    fails_with(&run(&["render", "--pack", s(&pack), "--scene", s(&scene)]), &["texture 3"]);
    std::fs::write(&scene, r#"{"view": {"window": {"path": []}}}"#).unwrap();
    fails_with(&run(&["render", "--pack", s(&pack), "--scene", s(&scene)]), &["no keyframe"]);
}

#[test]
fn slow_reads_never_hold_up_a_real_time_frame() {
    let dir = tempfile::tempdir().unwrap();
    let pack = sample_pack(dir.path());
    let json = dir.path().join("report.json");
    let args = ["render", "--pack", s(&pack), "--io-latency", "80ms", "--threads", "4", "--size", "128x96"];
    let out = run(&[&args[..], &["--frame-count", "40", "--report", s(&json), "-q"]].concat());
    if no_gpu(&out) {
        return;
    }
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let r = report(&json);
    assert_eq!(r["pacing"], "real-time");
    let frames = r["frames"].as_array().unwrap();
    for f in frames {
        assert_eq!(f["io_wait_ms"], 0.0, "frame {} waited for pages", f["frame"]);
    }
    // Frames went on while reads were under way, drawing coarser pages meanwhile.
    assert!(
        frames.iter().any(|f| f["in_flight"].as_u64().unwrap() > 0 && f["fallback_fraction"].as_f64().unwrap() > 0.0)
    );
    // Offline, the same run waits for its pages. (How long is the machine's business: a read
    // issued before the frame begins to wait has part of its 80 ms behind it, more so on a
    // loaded machine, so only that it waited is asserted.)
    let out =
        run(&[&args[..], &["--pacing", "offline", "--frame-count", "3", "--report", s(&json), "--force", "-q"]]
            .concat());
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let waited = report(&json)["io_wait_ms_max"].as_f64().unwrap();
    assert!(waited > 0.0, "an offline frame waited {waited} ms for pages read in 80 ms");
}

#[test]
fn a_filter_that_shows_seams_is_warned_of_and_auto_avoids_it() {
    let dir = tempfile::tempdir().unwrap();
    let pack = dir.path().join("bare.vtpk");
    let split = run(&["split", s(&fixture("sample.png")), "--pack", s(&pack), "--border", "0"]);
    assert!(split.status.success(), "{}", String::from_utf8_lossy(&split.stderr));
    let json = dir.path().join("report.json");
    let base = ["render", "--pack", s(&pack), "--frame-count", "2", "--size", "64x48", "--report", s(&json), "--force"];
    let out = run(&[&base[..], &["--filter", "bilinear"]].concat());
    if no_gpu(&out) {
        return;
    }
    assert!(out.status.success());
    assert!(String::from_utf8_lossy(&out.stderr).contains("shows seams at every page edge"));
    let out = run(&base);
    assert!(out.status.success() && !String::from_utf8_lossy(&out.stderr).contains("seams"));
    assert_eq!(report(&json)["filter"], "nearest");
}

#[test]
fn a_layer_stack_renders_with_one_page_table_write_per_page() {
    let dir = tempfile::tempdir().unwrap();
    let albedo = sample_pack(dir.path());
    // A second layer on the same grid: the fixture reduced as stored values (as data is).
    let data = dir.path().join("data.vtpk");
    let source = fixture("sample.png");
    let r = run(&["split", s(&source), "--pack", s(&data), "--tile-size", "136", "--border", "4", "--filter", "box"]);
    assert!(r.status.success(), "{}", String::from_utf8_lossy(&r.stderr));
    let render = |json: &Path, extra: &[&str]| {
        let base =
            ["render", "--pack", s(&albedo), "--report", s(json), "--size", "128x96", "--frame-count", "20", "-q"];
        run(&[&base[..], extra].concat())
    };
    let (one, two) = (dir.path().join("one.json"), dir.path().join("two.json"));
    let out = render(&one, &[]);
    if no_gpu(&out) {
        return;
    }
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let layer = format!("data:{}", data.display());
    let out = render(&two, &["--layer", &layer, "--show-layer", "1"]);
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let (r1, r2) = (report(&one), report(&two));
    assert_eq!((r2["layers"].as_u64(), r2["layer"].as_u64()), (Some(2), Some(1)));
    let sum = |r: &serde_json::Value, key: &str| {
        r["frames"].as_array().unwrap().iter().map(|f| f[key].as_u64().unwrap()).sum::<u64>()
    };
    assert!(sum(&r1, "table_writes") > 0);
    assert_eq!(sum(&r2, "table_writes"), sum(&r1, "table_writes"), "the page-table writes of one layer");
    assert_eq!(sum(&r2, "loaded"), sum(&r1, "loaded"));

    let bad = dir.path().join("bad.json");
    let out = render(&bad, &["--layer", "bump:x.vtpk"]);
    let err = String::from_utf8_lossy(&out.stderr);
    assert!(!out.status.success() && err.contains("layer kind \"bump\": colour or data"), "{err}");
    fails_with(&render(&bad, &["--show-layer", "1"]), &["effects.layer 1 is not one of the 1 layers"]);
}

#[test]
fn a_view_that_comes_back_is_read_from_the_memory_tier_and_drawn_the_same() {
    let dir = tempfile::tempdir().unwrap();
    let pack = sample_pack(dir.path());
    let scene = root("bench/scenes/away-and-back.json");
    // A cache of 3² slots: the way to B evicts A's pages.
    let render = |tier: &str| {
        let (frames, json) = (dir.path().join(format!("frames-{tier}")), dir.path().join(format!("{tier}.json")));
        let args = ["render", "--pack", s(&pack), "--scene", s(&scene), "--size", "128x96", "--cache-side", "3"];
        let out =
            run(&[&args[..], &["--memory-tier", tier, "--frames", s(&frames), "--report", s(&json), "-q"]].concat());
        (out, frames, json)
    };
    let (out, on_frames, on_json) = render("64");
    if no_gpu(&out) {
        return;
    }
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let (out, off_frames, off_json) = render("0");
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    let (on, off) = (report(&on_json), report(&off_json));
    let back = |r: &serde_json::Value, key: &str| -> u64 {
        let frames = r["frames"].as_array().unwrap();
        frames.iter().filter(|f| f["frame"].as_u64().unwrap() >= 48).map(|f| f[key].as_u64().unwrap()).sum()
    };
    assert_eq!((on["memory_tier_bytes"].as_u64(), off["memory_tier_bytes"].as_u64()), (Some(64 << 20), Some(0)));
    assert!(
        back(&on, "tier_hits") > 0 && back(&off, "tier_hits") == 0,
        "{} {}",
        back(&on, "tier_hits"),
        back(&off, "tier_hits")
    );
    assert!(
        back(&on, "bytes_read") < back(&off, "bytes_read"),
        "{} {}",
        back(&on, "bytes_read"),
        back(&off, "bytes_read")
    );
    assert!(on["memory_tier_held"].as_u64().unwrap() > 0 && off["memory_tier_held"] == 0);
    let last = |dir: &Path| std::fs::read(dir.join("frame-0095.png")).unwrap();
    assert!(last(&on_frames) == last(&off_frames), "the tier changed the last frame");
}

/// Flips a byte of every stored payload of `pack`: every tile fails its checksum.
pub(crate) fn damage_every_tile(pack: &Path) {
    let entries = vortex_pack::Pack::open(pack).unwrap().ids_in_file_order();
    assert!(!entries.is_empty());
    let mut bytes = std::fs::read(pack).unwrap();
    for (_, entry) in &entries {
        bytes[entry.offset_or_value as usize] ^= 0xff;
    }
    std::fs::write(pack, bytes).unwrap();
}

#[test]
fn pages_that_fail_to_load_fail_the_run_naming_the_first() {
    let dir = tempfile::tempdir().unwrap();
    let pack = sample_pack(dir.path());
    damage_every_tile(&pack);
    let json = dir.path().join("report.json");
    let out = run(&["render", "--pack", s(&pack), "--size", "64x48", "--frame-count", "3", "--report", s(&json), "-q"]);
    if no_gpu(&out) {
        return;
    }
    fails_with(&out, &["page(s) failed to load and were drawn as a stand-in", "sample.vtpk: tile (lod"]);
    // The report is written all the same, to show which pages.
    assert!(!report(&json)["errors"].as_array().unwrap().is_empty());
}

#[test]
fn scene_numbers_out_of_range_are_refused_naming_the_member() {
    let dir = tempfile::tempdir().unwrap();
    let pack = sample_pack(dir.path());
    let scene = dir.path().join("scene.json");
    for cells in [0u64, 1025, 4294967295] {
        let json = format!(
            r#"{{"view": {{"camera": {{"path": [{{"frame": 0, "eye": [0, 1, 1], "target": [0, 0, 0]}}],
                "geometry": [{{"terrain": {{"cells": {cells}}}}}]}}}}}}"#
        );
        std::fs::write(&scene, json).unwrap();
        // Refused when the scene is read, before any GPU is needed.
        let out = run(&["render", "--pack", s(&pack), "--scene", s(&scene), "-q"]);
        fails_with(&out, &["scene.json", &format!("view.camera.geometry[0].cells {cells} must be 1..=1024")]);
    }
}

#[test]
fn a_directory_given_as_a_pack_is_named_as_one() {
    let dir = tempfile::tempdir().unwrap();
    let out = run(&["render", "--pack", s(dir.path()), "-q"]);
    fails_with(&out, &[&format!("{} is a directory, not a pack", dir.path().display())]);
    assert!(!String::from_utf8_lossy(&out.stderr).contains("os error"));
}

#[test]
fn a_report_that_cannot_be_written_is_refused_before_the_first_frame() {
    let dir = tempfile::tempdir().unwrap();
    let pack = sample_pack(dir.path());
    let frames = dir.path().join("frames");
    let mut unwritable = vec![dir.path().join("missing").join("report.json")];
    // A read-only folder holds root back from nothing: try it only where it holds.
    let read_only = dir.path().join("read-only");
    std::fs::create_dir(&read_only).unwrap();
    std::fs::set_permissions(&read_only, std::os::unix::fs::PermissionsExt::from_mode(0o555)).unwrap();
    if std::fs::write(read_only.join("probe"), b"").is_err() {
        unwritable.push(read_only.join("report.json"));
    }
    for json in &unwritable {
        let out = run(&["render", "--pack", s(&pack), "--frames", s(&frames), "--report", s(json), "-q"]);
        fails_with(&out, &[&format!("cannot write {}", json.display())]);
        // Nothing was rendered, and nothing is left behind.
        assert!(!String::from_utf8_lossy(&out.stdout).contains("rendered"));
        assert!(!frames.exists());
        let left: Vec<_> = std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name()).collect();
        assert_eq!(left.len(), 2, "{left:?}");
    }
}

/// `source` split into a PNG pack in `dir` with `split`'s options.
fn png_pack(dir: &Path, source: &image::RgbaImage, split: &[&str]) -> PathBuf {
    let input = dir.join("source.png");
    source.save(&input).unwrap();
    let pack = dir.join("source.vtpk");
    let out = run(&[&["split", s(&input), "--pack", s(&pack), "--codec", "png", "-q"], split].concat());
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    pack
}

/// `render`'s converged frame of a still window (`center`, `width`, as a scene gives them) onto
/// `pack`; `None` without a GPU.
fn render_still(pack: &Path, size: (u32, u32), center: [f64; 2], width: f64) -> Option<image::RgbaImage> {
    let dir = tempfile::tempdir().unwrap();
    let scene = dir.path().join("scene.json");
    let json = serde_json::json!({
        "size": [size.0, size.1], "frames": 8,
        "view": { "window": { "path": [{ "frame": 0, "center": center, "width": width }] } },
        "effects": { "filter": "bilinear", "cache_format": "rgba8" },
    });
    std::fs::write(&scene, json.to_string()).unwrap();
    let (frames, report_path) = (dir.path().join("frames"), dir.path().join("report.json"));
    let out =
        run(&["render", "--pack", s(pack), "--scene", s(&scene), "--frames", s(&frames), "--report", s(&report_path)]);
    if no_gpu(&out) {
        return None;
    }
    assert!(out.status.success(), "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(report(&report_path)["frames"][7]["fallback_fraction"], 0.0, "the view did not converge");
    let frame = image::open(frames.join("frame-0007.png")).unwrap().to_rgba8();
    assert_eq!(frame.dimensions(), size);
    Some(frame)
}

/// What a window (`center`, `width`, square pixels, as `Window::square_pixels` places it) of
/// `source` on a `size` frame shows, worked out in f64 here: each pixel whose centre lies on the
/// image is the texel under it, every other pixel is the background, transparent.
fn expected_still(source: &image::RgbaImage, size: (u32, u32), center: [f64; 2], width: f64) -> image::RgbaImage {
    let (iw, ih) = (f64::from(source.width()), f64::from(source.height()));
    let (fw, fh) = (f64::from(size.0), f64::from(size.1));
    let extent = [width, width * (iw / ih) / (fw / fh)];
    let (step, origin) = (
        [extent[0] * iw / fw, extent[1] * ih / fh],
        [(center[0] - extent[0] / 2.0) * iw, (center[1] - extent[1] / 2.0) * ih],
    );
    image::RgbaImage::from_fn(size.0, size.1, |x, y| {
        let (tx, ty) = (origin[0] + (f64::from(x) + 0.5) * step[0], origin[1] + (f64::from(y) + 0.5) * step[1]);
        // The windows below keep every pixel centre clear of the image's edges.
        for (t, side) in [(tx, iw), (ty, ih)] {
            assert!(
                (t - t.round()).abs() > 1e-3 || (t.round() != 0.0 && t.round() != side),
                "pixel {x}, {y} on an edge"
            );
        }
        if (0.0..iw).contains(&tx) && (0.0..ih).contains(&ty) {
            *source.get_pixel(tx as u32, ty as u32)
        } else {
            image::Rgba([0; 4])
        }
    })
}

/// Pixels of `frame` that are not the background where `expected` is, or are where it is not.
fn background_wrong(frame: &image::RgbaImage, expected: &image::RgbaImage) -> usize {
    let off = |p: &image::Rgba<u8>| p.0 == [0; 4];
    frame.pixels().zip(expected.pixels()).filter(|(a, b)| off(a) != off(b)).count()
}

/// A window that shows more than the image draws the background beyond it: the clear colour,
/// transparent, exactly, where the samples (clamped to the image's edges) would repeat its edge
/// texels (issue 41). Margins above and below (a 2:1 image whole in a square frame, as the home
/// views of `view` and the web viewer place it), left and right (a 1:2 image), and on all four
/// sides (zoomed out). At one texel per pixel with pixel centres on texel centres, each pixel on
/// the image is its texel, the first and last rows and columns included.
#[test]
fn beyond_the_image_a_window_draws_the_background() {
    // No texel is transparent black, so the background cannot pass for the image.
    let pattern = |w, h| {
        image::RgbaImage::from_fn(w, h, |x, y| {
            image::Rgba([(x * 5 + y) as u8, (y * 2 + 40) as u8, ((x ^ y) * 3) as u8, 255])
        })
    };
    let windows = [
        ("render-margins-above-and-below", pattern(200, 100), (200, 200), 1.0),
        ("render-margins-left-and-right", pattern(100, 200), (200, 200), 2.0),
        ("render-margins-all-round", pattern(200, 100), (300, 200), 1.5),
    ];
    for (name, source, size, width) in windows {
        let dir = tempfile::tempdir().unwrap();
        let split = ["--tile-size", "64", "--border", "1"];
        let pack = png_pack(dir.path(), &source, &split);
        let Some(frame) = render_still(&pack, size, [0.5, 0.5], width) else { return };
        let expected = expected_still(&source, size, [0.5, 0.5], width);
        assert_eq!(background_wrong(&frame, &expected), 0, "{name}: the background is not where it should be");
        let why = "bilinear at texel centres reads one texel, through the cache's sRGB view and into the sRGB \
                   frame: the two conversions round-trip within a code value (measured: exact on lavapipe); the \
                   background is exact";
        let (w, h) = size;
        assert_close(
            name,
            Picture::new(w, h, 4, frame.as_raw()),
            Picture::new(w, h, 4, expected.as_raw()),
            Tolerance::max(1, why),
        );
    }
}

/// An odd-sized image (3001 x 2049: its coarser levels end inside their last texels), with
/// borders 0 and 4: its first and last rows and columns are drawn, not cut by half a texel, and
/// the background begins right after them. Zoomed out to 8 texels per pixel (LOD 3), the pixel
/// centres fall on the centres of the image's first and last texels; at 1:1 on its bottom-right
/// corner, on every texel's.
#[test]
fn the_edge_texels_of_an_odd_sized_image_are_drawn() {
    // A gradient: every filter and level reproduces it, so any LOD can be checked texel by texel.
    let source = image::RgbaImage::from_fn(3001, 2049, |x, y| {
        image::Rgba([(x * 255 / 3000) as u8, (y * 255 / 2048) as u8, 128, 255])
    });
    // (frame, centre, width): 8 texels per pixel, texels 0.5 and 3000.5 across, 0.5 and 2048.5
    // down, at pixel centres; then the corner at one texel per pixel, the image in the frame's
    // top-left 32 x 32.
    let windows = [((400, 300), [0.5, 1028.5 / 2049.0], 3200.0 / 3001.0), ((64, 64), [1.0, 1.0], 64.0 / 3001.0)];
    for border in ["0", "4"] {
        let dir = tempfile::tempdir().unwrap();
        let pack = png_pack(dir.path(), &source, &["--tile-size", "128", "--border", border]);
        for (i, &(size, center, width)) in windows.iter().enumerate() {
            let name = format!("render-odd-edges-border-{border}-{i}");
            let Some(frame) = render_still(&pack, size, center, width) else { return };
            let expected = expected_still(&source, size, center, width);
            assert_eq!(background_wrong(&frame, &expected), 0, "{name}: the background is not where it should be");
            let why = "a gradient, which bilinear filtering and the pyramid's levels reproduce to a code value or two \
                       (the sRGB round trip, and the edge texels of the coarse levels clamped); the background exact";
            let (w, h) = size;
            assert_close(
                &name,
                Picture::new(w, h, 4, frame.as_raw()),
                Picture::new(w, h, 4, expected.as_raw()),
                Tolerance::max(3, why),
            );
        }
    }
}
