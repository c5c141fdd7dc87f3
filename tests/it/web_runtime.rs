//! The runtime in the browser: the viewer page (`scripts/build-web.sh`, `web/viewer/`) served
//! by nginx with a pack beside it, opened by headless Chromium on WebGPU (SwiftShader), draws the
//! home view until it converges; the screenshot is compared with `render`'s frame of the same
//! view on lavapipe. A second load holds the tile reads back and takes a frame meanwhile: the
//! root page stands in, magnified, with no hole and no stand-in tile. The canvas is wider than
//! the image's aspect, so the home view has the background (black) left and right of the image,
//! never the image's edge columns stretched over it.
//!
//! The page is built once per checkout into target/web-viewer (or taken from `VORTEX_WEB_DIR`,
//! which CI sets after building it once). Missing wasm tools, Chromium or nginx skip the test
//! with a note outside CI and fail it under `CI=true`.

use std::path::{Path, PathBuf};
use std::process::Command;
use std::time::Duration;

use image::RgbImage;
use serde_json::Value;

use crate::common::cli::{run, s};
use crate::common::compare::{Picture, Tolerance, assert_close, differences};
use crate::common::nginx::{Nginx, nginx_binary};
use crate::common::picture::test_image;
use crate::common::skip_unless_ci;
use crate::common::webdriver::Browser;
use crate::render::no_gpu;

/// The canvas, in device pixels (headless Chromium's pixel ratio is 1): 16:10, wider than the
/// 4:3 test image, so that its home view has the background beside the image.
const SIZE: (u32, u32) = (640, 400);

/// The home view of an `image`-sized image on the canvas (the viewer's `home`: the whole image,
/// fit and centred): the share of the image's width across the canvas, and the canvas columns
/// that show the image, those whose centre samples a LOD-0 texel `origin + (x + 0.5) * step`
/// inside it (for 2000 x 1500: 1.2 widths, columns 53 to 586).
fn home_columns(image: (u32, u32)) -> (f64, std::ops::RangeInclusive<u32>) {
    let (iw, ih) = (f64::from(image.0), f64::from(image.1));
    let width = (f64::from(SIZE.0) / f64::from(SIZE.1) / (iw / ih)).max(1.0);
    let (step, origin) = (width * iw / f64::from(SIZE.0), (0.5 - width / 2.0) * iw);
    let texel = |x: u32| origin + (f64::from(x) + 0.5) * step;
    // No pixel centre so close to an edge that f32 arithmetic could put it on either side.
    assert!((0..SIZE.0).all(|x| texel(x).abs() > 0.01 && (texel(x) - iw).abs() > 0.01), "a pixel on an edge");
    let on: Vec<u32> = (0..SIZE.0).filter(|&x| (0.0..iw).contains(&texel(x))).collect();
    (width, on[0]..=on[on.len() - 1])
}

/// Chromium's WebGPU on SwiftShader, headless, with the canvas in screenshots
/// (/work/shared/tech-notes.md).
const WEBGPU_FLAGS: [&str; 8] = [
    "--enable-unsafe-webgpu",
    "--enable-features=Vulkan",
    "--use-vulkan=swiftshader",
    "--use-webgpu-adapter=swiftshader",
    "--enable-unsafe-swiftshader",
    "--use-gl=angle",
    "--use-angle=swiftshader",
    "--force-device-scale-factor=1",
];

/// Convergence on SwiftShader takes a few dozen frames; the page is polled every 100 ms.
const CONVERGE: Duration = Duration::from_secs(120);

/// The tolerance against `render`'s frame, per channel of 8 bits. SwiftShader and lavapipe both
/// filter in fixed point but round the bilinear weights, the sRGB conversions and the trilinear
/// blend each their own way: measured, a mean of 0.21 and no channel off by more than 1. The
/// bounds leave room for a pixel whose LOD lies on a mip boundary to take the other mip on one
/// of them; a wrong page, a shifted view or a missing LOD differs by tens over whole tiles.
const MAX_MEAN_DIFF: f64 = 0.5;
const MAX_PIXEL_DIFF: u8 = 8;

/// The built page's directory, or why there is none.
fn page_dir() -> Result<PathBuf, String> {
    if let Some(dir) = std::env::var_os("VORTEX_WEB_DIR") {
        let dir = PathBuf::from(dir);
        return if dir.join("vortex_web_bg.wasm").is_file() {
            Ok(dir)
        } else {
            Err(format!("VORTEX_WEB_DIR={} holds no built page", dir.display()))
        };
    }
    let root = Path::new(env!("CARGO_MANIFEST_DIR"));
    let targets = Command::new("rustup").args(["target", "list", "--installed"]).output();
    if !targets.is_ok_and(|o| String::from_utf8_lossy(&o.stdout).contains("wasm32-unknown-unknown")) {
        return Err("no wasm32-unknown-unknown target (rustup target add wasm32-unknown-unknown)".into());
    }
    if !root.join("target/wasm-tools/bin/wasm-bindgen").is_file() {
        return Err("no wasm-bindgen CLI in target/wasm-tools (scripts/build-web.sh installs it)".into());
    }
    let dir = root.join("target/web-viewer");
    let out = Command::new(root.join("scripts/build-web.sh")).arg(&dir).output().map_err(|e| e.to_string())?;
    assert!(out.status.success(), "scripts/build-web.sh failed: {}", String::from_utf8_lossy(&out.stderr));
    Ok(dir)
}

/// Everything the test needs from outside, or `None` after the skip note.
fn parts(test: &str) -> Option<(PathBuf, PathBuf, PathBuf, PathBuf)> {
    let found = |names: &[&str]| names.iter().map(|n| Path::new("/usr/bin").join(n)).find(|p| p.is_file());
    let all = || -> Result<_, String> {
        let chromium = found(&["chromium", "chromium-browser"]).ok_or("no chromium (apt-get install chromium)")?;
        let driver = found(&["chromedriver"]).ok_or("no chromedriver (apt-get install chromium-driver)")?;
        Ok((chromium, driver, nginx_binary()?, page_dir()?))
    };
    all().map_err(|why| skip_unless_ci(test, &why)).ok()
}

/// The page's state. Not under `error`: the WebDriver client takes a reply with that key for
/// its own error.
fn state(browser: &Browser) -> Value {
    browser.execute(
        "return { failure: vortex.error, frames: vortex.frames, counters: vortex.counters, view: vortex.view };",
    )
}

/// The canvas alone: the panel and the counters, which lie over it, hidden first.
fn screenshot(browser: &Browser) -> RgbImage {
    browser.execute("for (const id of ['panel', 'counters']) document.getElementById(id).style.display = 'none';");
    image::load_from_memory(&browser.screenshot("#view")).unwrap().to_rgb8()
}

/// `render`'s frame of the window `view` (the page's `{center, width}`) of `pack`, offline
/// (each frame waits for its pages) until it has converged, exact texels.
fn rendered(pack: &Path, view: &Value, dir: &Path) -> Option<RgbImage> {
    let scene = serde_json::json!({
        "size": [SIZE.0, SIZE.1],
        "frames": 16,
        "view": { "window": { "path": [{ "frame": 0, "center": view["center"], "width": view["width"] }] } },
        "effects": { "cache_format": "rgba8" },
    });
    let (scene_path, frames) = (dir.join("scene.json"), dir.join("frames"));
    std::fs::write(&scene_path, scene.to_string()).unwrap();
    let out = run(&["render", "--pack", s(pack), "--scene", s(&scene_path), "--frames", s(&frames), "-q"]);
    if no_gpu(&out) {
        return None;
    }
    assert!(out.status.success(), "render: {}", String::from_utf8_lossy(&out.stderr));
    Some(image::open(frames.join("frame-0015.png")).unwrap().to_rgb8())
}

/// Milliseconds per decode of `pack`'s root tile to RGBA8 natively, over `rounds`.
fn native_decode_ms(pack: &Path, rounds: u32) -> f64 {
    let pack = vortex_pack::Pack::open(pack).unwrap();
    let root = pack.description().level_count - 1;
    let started = std::time::Instant::now();
    for _ in 0..rounds {
        pack.decode_rgba8(vortex_pack::TileId { lod: root, x: 0, y: 0 }).unwrap();
    }
    started.elapsed().as_secs_f64() * 1000.0 / f64::from(rounds)
}

/// Where a failing picture goes: target/web-runtime/NAME.png.
fn keep(name: &str, picture: &RgbImage) -> PathBuf {
    let dir = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/web-runtime");
    std::fs::create_dir_all(&dir).unwrap();
    let path = dir.join(format!("{name}.png"));
    picture.save(&path).unwrap();
    path
}

#[test]
fn the_browser_draws_a_pack_as_render_does_and_falls_back_while_pages_are_in_flight() {
    let Some((chromium, driver, nginx, page)) = parts("the web runtime test") else { return };
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("photo.png");
    test_image().save(&input).unwrap();
    let pack = dir.path().join("photo.vtpk");
    // JPEG tiles of 256 texels with a border of 4: trilinear, decoded by the same Rust decoder
    // on both sides.
    let out =
        run(&["split", s(&input), "--pack", s(&pack), "--tile-size", "256", "--border", "4", "--codec", "jpeg", "-q"]);
    assert!(out.status.success(), "split: {}", String::from_utf8_lossy(&out.stderr));
    let data = dir.path().join("data");
    std::fs::create_dir(&data).unwrap();
    std::fs::copy(&pack, data.join("photo.vtpk")).unwrap();
    let server = Nginx::start(&nginx, &page, &[("data", &data)]);
    let browser = Browser::start_with(&driver, &chromium, SIZE, &WEBGPU_FLAGS);
    let url = format!("{}/index.html?pack=/data/photo.vtpk&size={}x{}", server.url(), SIZE.0, SIZE.1);

    // Pages held back: the frames draw the root page (fetched at open), magnified.
    browser.open(&format!("{url}&hold"));
    // Once the feedback has asked for pages, they stay in flight: the frames draw the root.
    browser
        .wait_js("window.vortex && (vortex.error || (vortex.frames >= 8 && vortex.counters.in_flight > 0))", CONVERGE);
    let held = state(&browser);
    assert_eq!(held["failure"], "", "{held}");
    let fallback = screenshot(&browser);
    let image = test_image().dimensions();
    let (home_width, columns) = home_columns(image);
    assert_eq!(held["view"]["center"], serde_json::json!([0.5, 0.5]), "not the home view: {held}");
    let shown = held["view"]["width"].as_f64().unwrap();
    assert!((shown - home_width).abs() < 1e-9, "not the home view: a width of {shown}, not {home_width}");
    assert!(held["counters"]["in_flight"].as_u64().unwrap() > 0, "nothing in flight while held: {held}");
    assert_eq!(held["counters"]["load_errors"], 0, "{held}");
    // The home view shows the whole 2000 x 1500 image across the canvas's height: every pixel
    // of it is the image, whose darkest value is 40, and none is the stand-in's magenta; every
    // pixel beside it is the background, black.
    let on_image = |x: u32| columns.contains(&x);
    let holes = fallback.enumerate_pixels().filter(|(x, _, p)| on_image(*x) && p.0.iter().all(|&v| v < 20)).count();
    let stand_ins = fallback.pixels().filter(|p| p.0 == [255, 0, 255]).count();
    let stretched = fallback.enumerate_pixels().filter(|(x, _, p)| !on_image(*x) && p.0 != [0, 0, 0]).count();
    if (holes, stand_ins, stretched) != (0, 0, 0) {
        let kept = keep("held", &fallback);
        panic!(
            "{holes} black and {stand_ins} stand-in pixels on the image, {stretched} not black beside it, while pages \
             were in flight (see {kept:?}): {held}"
        );
    }

    // Let the reads go: the view converges.
    browser.execute("vortex.release(); return null;");
    browser.wait_js("vortex.error || vortex.converged", CONVERGE);
    let done = state(&browser);
    assert_eq!(done["failure"], "", "{done}");
    assert_eq!(done["counters"]["load_errors"], 0, "{done}");
    let shot = screenshot(&browser);
    // Beside the image, the background exactly: not the image's edge columns stretched.
    let stretched = shot.enumerate_pixels().filter(|(x, _, p)| !columns.contains(x) && p.0 != [0, 0, 0]).count();
    if stretched > 0 {
        let kept = keep("beside-the-image", &shot);
        panic!("{stretched} pixels beside the image are not the black background (see {kept:?}): {done}");
    }
    let Some(expected) = rendered(&pack, &done["view"], dir.path()) else { return };
    let (worst, mean) = differences(shot.as_raw(), expected.as_raw());
    let (_, fallback_mean) = differences(fallback.as_raw(), expected.as_raw());
    // The root tile (a 256-texel JPEG) decoded by the runtime's Rust decoder in wasm, by the
    // browser's createImageBitmap (read back through a canvas), and natively: printed, not judged.
    browser.execute("vortex.measureDecode(50); return null;");
    browser.wait_js("vortex.error || vortex.decode", CONVERGE);
    let decode = browser.execute("return vortex.decode;");
    eprintln!(
        "web runtime: a 256-texel JPEG tile decodes in {} ms in wasm, {} ms by createImageBitmap, {:.3} ms natively",
        decode["wasm"],
        decode["bitmap"],
        native_decode_ms(&pack, 50)
    );
    let timing = browser.execute(
        "const c = [...vortex.cpuMs].sort((a, b) => a - b); \
         return { first: vortex.firstPictureMs, p50: c[Math.floor(c.length / 2)], p99: c[Math.floor(c.length * 0.99)] };",
    );
    eprintln!(
        "web runtime: first picture {:.0} ms after the page's start; frame CPU p50 {} ms, p99 {} ms",
        timing["first"].as_f64().unwrap_or(0.0),
        timing["p50"],
        timing["p99"]
    );
    eprintln!(
        "web runtime: {} frames to converge, {} requests, {} bytes; against render: mean {mean:.3}, worst {worst}; \
         the held frame's mean {fallback_mean:.2}",
        done["frames"], done["counters"]["requests"], done["counters"]["bytes_fetched"]
    );
    let (w, h) = shot.dimensions();
    let why =
        "SwiftShader and lavapipe round the bilinear weights, sRGB and trilinear blend their own way (MAX_MEAN_DIFF)";
    let tolerance = Tolerance::max_and_mean(MAX_PIXEL_DIFF.into(), MAX_MEAN_DIFF, why);
    let (shown, rendered) = (Picture::new(w, h, 3, shot.as_raw()), Picture::new(w, h, 3, expected.as_raw()));
    assert_close("web-runtime-home", shown, rendered, tolerance);
    // The held frame was the coarse fallback, visibly not the converged picture.
    assert!(
        fallback_mean > 2.0 * mean.max(0.5),
        "the held frame is as sharp as the converged one ({fallback_mean:.2})"
    );
    // The README's picture of the viewer.
    shot.save(Path::new(env!("CARGO_MANIFEST_DIR")).join("target/web-runtime-home.png")).unwrap();
}
