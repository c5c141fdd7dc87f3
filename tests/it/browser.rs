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

use std::path::Path;
use std::time::Duration;

use image::RgbImage;

use crate::common::cli::{ok, s};
use crate::common::picture::{VIEW, browser_parts, judge, test_image};
use crate::common::server::Server;
use crate::common::skip_unless_ci;
use crate::common::webdriver::Browser;

/// The regions shown, as (x, y, width, height) in image texels: the whole image (a coarse
/// level drawn smaller), a quarter at 1:1 across tile edges, and a small part enlarged 4x.
pub const REGIONS: [(u32, u32, u32, u32); 3] = [(8, 6, 1984, 1488), (700, 300, 640, 480), (1234, 987, 160, 120)];

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

/// OpenSeadragon shows (a) a `--layout dzi` directory, (b) a `--layout iiif` directory and
/// (c) a pack through `serve` as Deep Zoom, each as the source image looks.
#[test]
fn openseadragon_shows_what_we_write_and_serve() {
    let parts = match browser_parts() {
        Ok(parts) => parts,
        Err(why) => return skip_unless_ci("the browser test", &why),
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
            let verdict = judge(&source, region, &shot);
            eprintln!("{what}, region {region:?}: {}", verdict.as_ref().unwrap_or_else(|e| e));
            // VORTEX_BROWSER_SHOTS=DIR keeps every screenshot (the README's picture is one).
            if let Some(keep) = std::env::var_os("VORTEX_BROWSER_SHOTS") {
                std::fs::create_dir_all(&keep).unwrap();
                shot.save(Path::new(&keep).join(format!("{}-{}.png", what.replace(' ', "-"), region.0))).unwrap();
            }
            if let Err(why) = verdict {
                let keep = dir.path().join(format!("failed-{}-{}.png", what.replace(' ', "-"), region.0));
                shot.save(&keep).unwrap();
                failures.push(format!("{what}, region {region:?}: {why}"));
            }
        }
    }
    if !failures.is_empty() {
        let kept = dir.keep();
        panic!("{} (screenshots in {})", failures.join("; "), kept.display());
    }
}
