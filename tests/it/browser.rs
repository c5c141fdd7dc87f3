//! A real browser: headless Chromium runs OpenSeadragon (npm, `tests/browser/`) on what we
//! write and serve, zoomed to known regions, and each screenshot, taken once OpenSeadragon
//! says every tile of the view is drawn, is compared with the same region of the source image
//! resized (PSNR). A blank, shifted or seamed picture fails: it must reach a floor (a blank
//! viewer is far below it) and match its region better than the region shifted by two screen
//! pixels in any direction.
//!
//! Needs `chromium`, `chromedriver` (Debian's chromium-driver) and `npm ci --prefix
//! tests/browser` (all done by `.ci/run`); outside CI a missing one skips with a note, under
//! `CI=true` it fails.

use std::path::{Path, PathBuf};
use std::time::Duration;

use image::{ImageBuffer, Rgb, RgbImage, imageops};

use crate::common::cli::{ok, s};
use crate::common::server::Server;
use crate::common::webdriver::Browser;

/// Below this the picture is wrong (a blank viewer is about 5 dB); a correct one measured 26.8
/// to 39.4 dB, OpenSeadragon's bilinear drawing against our Triangle resize (the test prints
/// each).
const MIN_PSNR_DB: f64 = 24.0;
/// The viewer's size in CSS pixels; the regions below have its aspect ratio.
const VIEW: (u32, u32) = (640, 480);

/// The regions shown, as (x, y, width, height) in image texels: the whole image (a coarse
/// level drawn smaller), a quarter at 1:1 across tile edges, and a small part enlarged 4x.
const REGIONS: [(u32, u32, u32, u32); 3] = [(8, 6, 1984, 1488), (700, 300, 640, 480), (1234, 987, 160, 120)];

/// A synthetic photograph: smooth rings, colour ramps and hard-edged discs, so that a shift or
/// a seam shows and resampling differences do not.
fn test_image() -> RgbImage {
    ImageBuffer::from_fn(2000, 1500, |x, y| {
        let (fx, fy) = (x as f64, y as f64);
        let r = ((fx - 900.0).powi(2) + (fy - 700.0).powi(2)).sqrt();
        let rings = 0.5 + 0.5 * (r / 9.0).sin();
        let disc =
            ((x / 150 + y / 150) % 2 == 0) && ((fx % 150.0 - 75.0).powi(2) + (fy % 150.0 - 75.0).powi(2)) < 40.0 * 40.0;
        let (mut red, mut green, mut blue) = (fx / 2000.0, fy / 1500.0, rings);
        if disc {
            (red, green, blue) = (1.0, 0.85, 0.2);
        }
        let g = |v: f64| (40.0 + 200.0 * v.clamp(0.0, 1.0)) as u8;
        Rgb([g(red * rings), g(green), g(blue)])
    })
}

/// The browser, its driver and OpenSeadragon, or why the test cannot run.
struct Parts {
    chromium: PathBuf,
    chromedriver: PathBuf,
    openseadragon: PathBuf,
}

fn browser_parts() -> Result<Parts, String> {
    let found = |names: &[&str]| names.iter().map(|n| Path::new("/usr/bin").join(n)).find(|p| p.is_file());
    let chromium = found(&["chromium", "chromium-browser"]).ok_or("no chromium (apt-get install chromium)")?;
    let chromedriver = found(&["chromedriver"]).ok_or("no chromedriver (apt-get install chromium-driver)")?;
    let openseadragon =
        Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/browser/node_modules/openseadragon/build/openseadragon");
    if !openseadragon.join("openseadragon.min.js").is_file() {
        return Err("no OpenSeadragon (npm ci --prefix tests/browser)".into());
    }
    Ok(Parts { chromium, chromedriver, openseadragon })
}

/// OpenSeadragon showing `region` of the tile source at `source_url`, once every tile of the
/// view is loaded and drawn.
fn screenshot(browser: &Browser, osd: &Path, dir: &Path, source_url: &str, region: (u32, u32, u32, u32)) -> RgbImage {
    let page = dir.join("view.html");
    let html = format!(
        r#"<!doctype html><html><head><style>html,body{{margin:0;background:#000;overflow:hidden}}#v{{width:{w}px;height:{h}px}}</style>
<script src="{osd}/openseadragon.min.js"></script></head><body><div id="v"></div><script>
window.viewer = OpenSeadragon({{ id: "v", tileSources: "{source_url}", drawer: "canvas", animationTime: 0, blendTime: 0,
  showNavigationControl: false, crossOriginPolicy: "Anonymous" }});
viewer.addHandler("open", () => {{
  const item = viewer.world.getItemAt(0);
  viewer.viewport.fitBounds(item.imageToViewportRectangle({x}, {y}, {rw}, {rh}), true);
  window.placed = true;
}});
</script></body></html>"#,
        w = VIEW.0,
        h = VIEW.1,
        osd = osd.display(),
        x = region.0,
        y = region.1,
        rw = region.2,
        rh = region.3,
    );
    std::fs::write(&page, html).unwrap();
    let ready = "window.placed && viewer.world.getItemAt(0).getFullyLoaded() && !viewer.world.needsDraw()";
    browser.open_and_wait(&format!("file://{}", page.display()), ready, Duration::from_secs(60));
    image::load_from_memory(&browser.screenshot("#v")).unwrap().to_rgb8()
}

/// Peak signal-to-noise ratio of `shot` against `region` of `source` resized to the view.
fn psnr(source: &RgbImage, region: (u32, u32, u32, u32), shot: &RgbImage) -> f64 {
    let part = imageops::crop_imm(source, region.0, region.1, region.2, region.3).to_image();
    let expected = imageops::resize(&part, VIEW.0, VIEW.1, imageops::FilterType::Triangle);
    assert_eq!(shot.dimensions(), VIEW, "the screenshot is not the viewer's size");
    let sum: f64 =
        expected.as_raw().iter().zip(shot.as_raw().iter()).map(|(a, b)| (*a as f64 - *b as f64).powi(2)).sum();
    let mse = sum / expected.as_raw().len() as f64;
    10.0 * (255.0f64 * 255.0 / mse.max(1e-9)).log10()
}

/// OpenSeadragon shows (a) a `--layout dzi` directory, (b) a `--layout iiif` directory and
/// (c) a pack through `serve` as Deep Zoom, each as the source image looks.
#[test]
fn openseadragon_shows_what_we_write_and_serve() {
    let parts = match browser_parts() {
        Ok(parts) => parts,
        Err(why) => {
            assert!(std::env::var("CI").map_or(true, |v| v != "true"), "CI=true and {why}");
            eprintln!("note: skipping the browser test: {why}");
            return;
        }
    };
    let dir = tempfile::tempdir().unwrap();
    let source = test_image();
    let input = dir.path().join("photo.png");
    source.save(&input).unwrap();
    let (dzi, iiif, pack) = (dir.path().join("dzi"), dir.path().join("iiif"), dir.path().join("packed.vtpk"));
    ok(&["split", s(&input), "--layout", "dzi", "-o", s(&dzi), "--quality", "95", "-q"]);
    ok(&["split", s(&input), "--layout", "iiif", "-o", s(&iiif), "--tile-size", "256", "--quality", "95", "-q"]);
    // Borders, as a GPU pack has them: served as Deep Zoom overlap, not shifted by them.
    ok(&["split", s(&input), "--pack", s(&pack), "--tile-size", "256", "--border", "4", "--quality", "95", "-q"]);
    let server = Server::start(&[&dzi, &iiif, &pack], &[]);
    let browser = Browser::start(&parts.chromedriver, &parts.chromium, VIEW);
    let sources = [
        ("dzi directory", format!("{}/dzi.dzi", server.url())),
        ("iiif directory", format!("{}/iiif/iiif/info.json", server.url())),
        ("pack as Deep Zoom", format!("{}/packed.dzi", server.url())),
    ];
    let mut failures = Vec::new();
    for (what, url) in &sources {
        for region in REGIONS {
            let shot = screenshot(&browser, &parts.openseadragon, dir.path(), url, region);
            let db = psnr(&source, region, &shot);
            // The picture must match this region better than the same region two screen pixels
            // off in any direction: a shifted picture matches a shifted region better.
            let step = (2 * region.2).div_ceil(VIEW.0).max(2);
            let off = [(step as i64, 0), (-(step as i64), 0), (0, step as i64), (0, -(step as i64))]
                .map(|(dx, dy)| {
                    psnr(
                        &source,
                        ((region.0 as i64 + dx) as u32, (region.1 as i64 + dy) as u32, region.2, region.3),
                        &shot,
                    )
                })
                .into_iter()
                .fold(f64::MIN, f64::max);
            eprintln!("{what}, region {region:?}: {db:.1} dB ({step} texels off: at best {off:.1} dB)");
            // VORTEX_BROWSER_SHOTS=DIR keeps every screenshot (the README's picture is one).
            if let Some(keep) = std::env::var_os("VORTEX_BROWSER_SHOTS") {
                std::fs::create_dir_all(&keep).unwrap();
                shot.save(Path::new(&keep).join(format!("{}-{}.png", what.replace(' ', "-"), region.0))).unwrap();
            }
            if db < MIN_PSNR_DB || db <= off {
                let keep = dir.path().join(format!("failed-{}-{}.png", what.replace(' ', "-"), region.0));
                shot.save(&keep).unwrap();
                failures.push(format!("{what}, region {region:?}: {db:.1} dB (at least {MIN_PSNR_DB} dB and more than {off:.1} dB for a shifted region)"));
            }
        }
    }
    if !failures.is_empty() {
        let kept = dir.keep();
        panic!("{} (screenshots in {})", failures.join("; "), kept.display());
    }
}
