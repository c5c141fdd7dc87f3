//! One file on a static host, no server of ours: nginx (Debian's, a plain static server with
//! `Range`, as S3 or GitHub Pages) serves a `.vtpk` pack, and Chromium shows it in
//! OpenSeadragon through `web/vtpk/vtpk.js`, which reads it by byte ranges. Each screenshot is
//! judged against the source region as in `browser.rs` (PSNR, and better than the region
//! shifted: a blank, shifted or seamed picture fails). A pack with a damaged tile must have that
//! tile reported and not drawn, and a pack of tiles a browser cannot decode must be refused.
//!
//! Needs nginx (nginx-light), chromium, chromedriver and `npm ci --prefix tests/browser` (all
//! done by `.ci/run`); outside CI a missing one skips with a note, under `CI=true` it fails.

use std::path::Path;
use std::time::Duration;

use image::RgbImage;
use serde_json::Value;

use crate::browser::REGIONS;
use crate::common::cli::{ok, s};
use crate::common::nginx::{Nginx, nginx_binary};
use crate::common::picture::{VIEW, browser_parts, judge, test_image};
use crate::common::skip_unless_ci;
use crate::common::webdriver::Browser;

/// The page: OpenSeadragon from a classic script, our module beside it, both from the host.
const PAGE: &str = r#"<!doctype html><html><head><style>html,body{margin:0;background:#000;overflow:hidden}#v{width:640px;height:480px}</style>
<script src="/osd/openseadragon.min.js"></script></head><body><div id="v"></div>
<script type="module">
import { VtpkTileSource } from "/web/vtpk/vtpk.js";
const q = new URLSearchParams(location.search);
const [x, y, w, h] = q.get("region").split(",").map(Number);
window.loaded = []; window.failed = [];
// OpenSeadragon 6 opens only the image formats it lists: JPEG XL is added, as docs/jxl.md says.
OpenSeadragon.setImageFormatsSupported({ jxl: true });
try {
  // ?dzi=URL shows a Deep Zoom directory instead, for the measurement against it.
  const source = q.get("dzi") || await VtpkTileSource.open(q.get("pack"), { wholeIndexUpTo: Number(q.get("whole")) });
  if (!q.get("dzi")) window.source = source;
  window.viewer = OpenSeadragon({ id: "v", tileSources: source, drawer: "canvas", animationTime: 0, blendTime: 0,
    showNavigationControl: false, maxTilesPerFrame: Number(q.get("perFrame") || 1) });
  const lod = (t) => t.tiledImage.source.maxLevel - t.level;
  viewer.addHandler("tile-loaded", (e) => loaded.push([lod(e.tile), e.tile.x, e.tile.y]));
  viewer.addHandler("tile-load-failed", (e) => failed.push([lod(e.tile), e.tile.x, e.tile.y, e.message]));
  viewer.addHandler("open", () => {
    const item = viewer.world.getItemAt(0);
    viewer.viewport.fitBounds(item.imageToViewportRectangle(x, y, w, h), true);
    window.placed = true;
  });
} catch (e) { window.openError = String(e && e.message); }
</script></body></html>"#;

/// Waits for the view to be complete (or the open to fail) and returns what the page knows.
const READY: &str =
    "window.openError || (window.placed && viewer.world.getItemAt(0).getFullyLoaded() && !viewer.world.needsDraw())";
const STATE: &str = "return { openError: window.openError || null, errors: window.source ? source.errors : [], \
    loaded: window.loaded, failed: window.failed, stats: window.source ? source.vtpk.stats : null };";

struct Site {
    nginx: Nginx,
    browser: Browser,
    dir: tempfile::TempDir,
}

impl Site {
    /// nginx serving a fresh temp dir (with the page), the repository's `web/` and
    /// OpenSeadragon; Chromium to look at it. `None` (after a note) where a part is missing.
    fn start(test: &str) -> Option<Site> {
        let parts = browser_parts().and_then(|p| nginx_binary().map(|n| (p, n)));
        let (parts, nginx) = match parts {
            Ok(found) => found,
            Err(why) => {
                skip_unless_ci(test, &why);
                return None;
            }
        };
        let dir = tempfile::tempdir().unwrap();
        std::fs::write(dir.path().join("view.html"), PAGE).unwrap();
        let web = Path::new(env!("CARGO_MANIFEST_DIR")).join("web");
        let nginx = Nginx::start(&nginx, dir.path(), &[("web", &web), ("osd", &parts.openseadragon)]);
        let browser = Browser::start(&parts.chromedriver, &parts.chromium, VIEW);
        Some(Site { nginx, browser, dir })
    }

    /// Shows `region` of the pack `name` (in the site dir); the screenshot and the page's state.
    fn show(&self, name: &str, region: (u32, u32, u32, u32), whole_index_up_to: u64) -> (RgbImage, Value) {
        self.show_query(&format!("pack={name}&whole={whole_index_up_to}"), region)
    }

    /// Shows `region` of what `query` names (`pack=NAME&whole=N`, or `dzi=URL`, a tile source
    /// OpenSeadragon opens itself); the screenshot and the page's state.
    fn show_query(&self, query: &str, region: (u32, u32, u32, u32)) -> (RgbImage, Value) {
        self.show_until(query, region, READY)
    }

    /// As [`Site::show_query`], ready when the script `ready` is true.
    fn show_until(&self, query: &str, region: (u32, u32, u32, u32), ready: &str) -> (RgbImage, Value) {
        let (x, y, w, h) = region;
        let url = format!("{}/view.html?{query}&region={x},{y},{w},{h}", self.nginx.url());
        self.browser.open_and_wait(&url, ready, Duration::from_secs(60));
        let state = self.browser.execute(STATE);
        let shot = image::load_from_memory(&self.browser.screenshot("#v")).unwrap().to_rgb8();
        (shot, state)
    }
}

/// The photograph split into `name` in the site dir with `args`.
fn pack(site: &Site, input: &Path, name: &str, args: &[&str]) {
    let out = site.dir.path().join(name);
    let mut all = vec!["split", s(input), "--pack", s(&out), "-q"];
    all.extend_from_slice(args);
    ok(&all);
}

/// A JPEG pack with 256-texel tiles and border 4 (its index read whole) and a PNG pack with
/// 128-texel tiles and the default border 1 (its index read in blocks), each shown at the three
/// regions of `browser.rs` from nginx.
#[test]
fn vtpk_source_shows_packs_from_a_static_host() {
    let Some(site) = Site::start("the static-host browser test") else { return };
    let source = test_image();
    let input = site.dir.path().join("photo.png");
    source.save(&input).unwrap();
    pack(&site, &input, "bordered.vtpk", &["--tile-size", "256", "--border", "4", "--quality", "95"]);
    pack(&site, &input, "png.vtpk", &["--tile-size", "128", "--codec", "png"]);
    let mut failures = Vec::new();
    for (name, whole) in [("bordered.vtpk", 1 << 18), ("png.vtpk", 0)] {
        for region in REGIONS {
            let (shot, state) = site.show(name, region, whole);
            assert_eq!(state["openError"], Value::Null, "{name}: {state}");
            assert_eq!(state["errors"], serde_json::json!([]), "{name}: {state}");
            let verdict = judge(&source, region, &shot);
            eprintln!(
                "{name}, region {region:?}: {} ({} requests, {} bytes)",
                verdict.as_ref().unwrap_or_else(|e| e),
                state["stats"]["requests"],
                state["stats"]["bytes"]
            );
            // VORTEX_BROWSER_SHOTS=DIR keeps every screenshot, as in browser.rs.
            if let Some(keep) = std::env::var_os("VORTEX_BROWSER_SHOTS") {
                std::fs::create_dir_all(&keep).unwrap();
                shot.save(Path::new(&keep).join(format!("{name}-{}.png", region.0))).unwrap();
            }
            if let Err(why) = verdict {
                shot.save(site.dir.path().join(format!("failed-{name}-{}.png", region.0))).unwrap();
                failures.push(format!("{name}, region {region:?}: {why}"));
            }
        }
    }
    if !failures.is_empty() {
        let kept = site.dir.keep();
        panic!("{} (screenshots in {})", failures.join("; "), kept.display());
    }
    // Every read went to nginx as a Range request of the pack and was answered 206.
    let requests = site.nginx.requests();
    let pack_reads: Vec<_> = requests.iter().filter(|r| r.2.contains(".vtpk HTTP/")).collect();
    assert!(!pack_reads.is_empty());
    assert!(pack_reads.iter().all(|r| r.0 == 206 && r.3.starts_with("bytes=")), "{pack_reads:?}");
}

/// JPEG XL (issue 46), from the same static host: a pack of JXL tiles through `vtpk.js` (which
/// hands them to the browser's own decoder) and a `--layout dzi` directory of `.jxl` tiles that
/// OpenSeadragon opens itself, each at the three regions and the same picture threshold as the
/// JPEG ones; nginx served every `.jxl` tile.
#[test]
fn openseadragon_shows_jpeg_xl_packs_and_deep_zoom_from_a_static_host() {
    let Some(site) = Site::start("the static-host JPEG XL browser test") else { return };
    let source = test_image();
    let input = site.dir.path().join("photo.png");
    source.save(&input).unwrap();
    // Quality 90 is JPEG XL's "visually lossless" distance 1.0, as Q95 is for the JPEG tests.
    let jxl = ["--codec", "jxl", "--quality", "90", "--jxl-effort", "3"];
    pack(&site, &input, "jxl.vtpk", &[&["--tile-size", "256", "--border", "4"][..], &jxl].concat());
    let dzi = site.dir.path().join("dzi-jxl");
    ok(&[&["split", s(&input), "--layout", "dzi", "-o", s(&dzi), "-q"][..], &jxl].concat());
    let dzi_url = format!("{}/dzi-jxl/photo.dzi", site.nginx.url());
    let mut failures = Vec::new();
    for (what, query) in
        [("jxl.vtpk", "pack=jxl.vtpk&whole=262144".to_string()), ("jxl Deep Zoom", format!("dzi={dzi_url}"))]
    {
        for region in REGIONS {
            let (shot, state) = site.show_query(&query, region);
            assert_eq!(state["openError"], Value::Null, "{what}: {state}");
            assert_eq!(state["errors"], serde_json::json!([]), "{what}: {state}");
            assert_eq!(state["failed"], serde_json::json!([]), "{what}: tiles failed to load: {state}");
            let verdict = judge(&source, region, &shot);
            eprintln!("{what}, region {region:?}: {}", verdict.as_ref().unwrap_or_else(|e| e));
            if let Err(why) = verdict {
                shot.save(site.dir.path().join(format!("failed-{}-{}.png", what.replace(' ', "-"), region.0))).unwrap();
                failures.push(format!("{what}, region {region:?}: {why}"));
            }
        }
    }
    if !failures.is_empty() {
        let kept = site.dir.keep();
        panic!("{} (screenshots in {})", failures.join("; "), kept.display());
    }
    let requests = site.nginx.requests();
    let tiles: Vec<_> = requests.iter().filter(|r| r.2.contains("/dzi-jxl/photo_files/")).collect();
    assert!(tiles.len() > 3 && tiles.iter().all(|r| r.0 == 200 && r.2.contains(".jxl ")), "{tiles:?}");
}

/// A tile whose payload was changed after writing is reported by the JS source (with its
/// position and CRC) and never handed to OpenSeadragon; the rest of the view is drawn. So is a
/// damaged index entry. A pack of zstd tiles is refused at open with a message naming the codec
/// and the way out.
#[test]
fn vtpk_source_reports_a_damaged_tile_and_refuses_undecodable_packs() {
    let Some(site) = Site::start("the static-host browser test") else { return };
    let input = site.dir.path().join("photo.png");
    test_image().save(&input).unwrap();
    pack(&site, &input, "good.vtpk", &["--tile-size", "256", "--quality", "90"]);
    let home = REGIONS[0];
    let (_, state) = site.show("good.vtpk", home, 1 << 18);
    assert_eq!(state["errors"], serde_json::json!([]), "{state}");
    // Damage the finest tile the home view loaded, in the middle of its payload.
    let loaded = state["loaded"].as_array().unwrap();
    let finest = loaded.iter().map(|t| t[0].as_u64().unwrap()).min().unwrap();
    let victim = loaded.iter().find(|t| t[0] == finest).unwrap();
    let (lod, x, y) =
        (victim[0].as_u64().unwrap() as u32, victim[1].as_u64().unwrap() as u32, victim[2].as_u64().unwrap() as u32);
    let good = site.dir.path().join("good.vtpk");
    let mut bytes = std::fs::read(&good).unwrap();
    let p = vortex_pack::Pack::open(&good).unwrap();
    let entry = p.entry(p.position(vortex_pack::TileId { lod, x, y }).unwrap());
    assert!(entry.len > 16, "tile ({lod}, {x}, {y}) has no payload to damage");
    bytes[(entry.offset_or_value + entry.len as u64 / 2) as usize] ^= 0x10;
    std::fs::write(site.dir.path().join("damaged.vtpk"), &bytes).unwrap();

    let (_, state) = site.show("damaged.vtpk", home, 1 << 18);
    let errors = state["errors"].as_array().unwrap();
    let expected = format!("tile (lod {lod}, x {x}, y {y})");
    assert!(
        errors.len() == 1
            && errors[0].as_str().unwrap().contains(&expected)
            && errors[0].as_str().unwrap().contains("CRC-32C"),
        "the damaged {expected} is not reported alone: {state}"
    );
    let is_victim = |t: &Value| t[0] == lod && t[1] == x && t[2] == y;
    assert!(!state["loaded"].as_array().unwrap().iter().any(is_victim), "the damaged tile was drawn: {state}");
    assert!(state["failed"].as_array().unwrap().iter().any(is_victim), "OpenSeadragon was not told: {state}");
    assert!(state["loaded"].as_array().unwrap().len() >= loaded.len() - 1, "the rest was not drawn: {state}");

    // The same tile's index entry made constant: caught by the index CRC when the index is read
    // whole, by the entry's own fields (length and CRC set) when it is read in blocks.
    let mut bytes = std::fs::read(&good).unwrap();
    let position = p.position(vortex_pack::TileId { lod, x, y }).unwrap();
    bytes[(p.header().index_offset + 24 * position + 16) as usize] = 1;
    std::fs::write(site.dir.path().join("bad-index.vtpk"), &bytes).unwrap();
    let (_, state) = site.show("bad-index.vtpk", home, 1 << 18);
    let message = state["openError"].as_str().unwrap_or_else(|| panic!("a damaged index was used: {state}"));
    assert!(message.contains("index is damaged"), "{message}");
    // Read in blocks, the view never completes: once every block is here the CRC fails and
    // every later entry is refused (docs/pack-format.md), so the page is ready when the damaged
    // entry is reported.
    let reported = format!(
        "window.openError || (window.source && source.errors.some((e) => e.includes({:?}) && e.includes('index is damaged')))",
        expected
    );
    let (_, state) = site.show_until("pack=bad-index.vtpk&whole=0", home, &reported);
    let errors = state["errors"].as_array().unwrap();
    assert!(
        errors
            .iter()
            .any(|e| e.as_str().unwrap().contains(&expected) && e.as_str().unwrap().contains("index is damaged")),
        "the damaged entry of {expected} is not reported: {state}"
    );
    assert!(!state["loaded"].as_array().unwrap().iter().any(is_victim), "the damaged entry was drawn: {state}");

    pack(&site, &input, "zstd.vtpk", &["--tile-size", "256", "--codec", "zstd"]);
    let (_, state) = site.show("zstd.vtpk", home, 1 << 18);
    let message = state["openError"].as_str().unwrap_or_else(|| panic!("a zstd pack was opened: {state}"));
    assert!(message.contains("zstd") && message.contains("--codec jpeg"), "{message}");
}

/// (c) A IIIF directory written with an absolute id (`--iiif-id`), uploaded to that id's URL on
/// a plain static host, opens in OpenSeadragon from its `info.json` alone and shows the three
/// regions; every request nginx answered was for a file the directory holds.
#[test]
fn openseadragon_shows_a_static_iiif_service_at_its_id() {
    let Some(site) = Site::start("the static IIIF browser test") else { return };
    let source = test_image();
    let input = site.dir.path().join("photo.png");
    source.save(&input).unwrap();
    let id = format!("{}/iiif/photo", site.nginx.url());
    let out = site.dir.path().join("iiif/photo");
    let split = ["split", s(&input), "--layout", "iiif", "-o", s(&out), "--tile-size", "256", "--quality", "95"];
    ok(&[&split[..], &["-q", "--iiif-id", &id]].concat());
    let mut failures = Vec::new();
    for region in REGIONS {
        let (shot, state) = site.show_query(&format!("dzi={id}/info.json"), region);
        assert_eq!(state["openError"], Value::Null, "{state}");
        assert_eq!(state["failed"], serde_json::json!([]), "tiles failed to load: {state}");
        let verdict = judge(&source, region, &shot);
        eprintln!("static IIIF, region {region:?}: {}", verdict.as_ref().unwrap_or_else(|e| e));
        if let Err(why) = verdict {
            shot.save(site.dir.path().join(format!("failed-iiif-{}.png", region.0))).unwrap();
            failures.push(format!("region {region:?}: {why}"));
        }
    }
    if !failures.is_empty() {
        let kept = site.dir.keep();
        panic!("{} (screenshots in {})", failures.join("; "), kept.display());
    }
    let requests = site.nginx.requests();
    let iiif: Vec<_> = requests.iter().filter(|r| r.2.contains(" /iiif/photo/")).collect();
    assert!(iiif.iter().any(|r| r.2.contains("/info.json ")), "{requests:?}");
    assert!(iiif.len() > 3 && iiif.iter().all(|r| r.0 == 200), "{iiif:?}");
}

/// Requests and bytes fetched from the host for a first view and a deep zoom: the JS source on
/// a pack against OpenSeadragon's own Deep Zoom reader on a `--layout dzi` directory of the same
/// pyramid (254-texel payloads, 1 texel of overlap or border, JPEG q85), counted in nginx's
/// access log. Not a test: run it by hand (docs/web.md has the numbers and the command),
/// `VORTEX_WEB_MEASURE=SIZE_OR_IMAGE` (default 4096; the docs used 16384).
#[test]
#[ignore]
fn measure_requests_against_dzi() {
    let Some(site) = Site::start("the static-host measurement") else { return };
    let spec = std::env::var("VORTEX_WEB_MEASURE").unwrap_or_else(|_| "4096".into());
    let input = match spec.parse::<u32>() {
        Ok(side) => {
            let input = site.dir.path().join("photo.tif");
            let generator = Path::new(env!("CARGO_MANIFEST_DIR")).join("target/debug/gen_image");
            let status = std::process::Command::new(&generator)
                .args([&side.to_string(), &side.to_string(), s(&input)])
                .status()
                .unwrap_or_else(|e| {
                    panic!("{}: {e} (cargo build -p vortex-bench --bin gen_image)", generator.display())
                });
            assert!(status.success());
            input
        }
        Err(_) => Path::new(&spec).to_path_buf(),
    };
    let tiles = ["--tile-size", "256", "--border", "1", "--quality", "85"];
    pack(&site, &input, "photo.vtpk", &tiles);
    ok(&["split", s(&input), "--layout", "dzi", "-o", s(&site.dir.path().join("dzi")), "--quality", "85", "-q"]);
    let dzi = std::fs::read_dir(site.dir.path().join("dzi"))
        .unwrap()
        .map(|e| e.unwrap().file_name().into_string().unwrap())
        .find(|n| n.ends_with(".dzi"))
        .unwrap();
    // The upload-cost stand-in: files and bytes of each.
    let (mut files, mut bytes, mut stack) = (0u64, 0u64, vec![site.dir.path().join("dzi")]);
    while let Some(dir) = stack.pop() {
        for e in std::fs::read_dir(dir).unwrap().map(|e| e.unwrap()) {
            if e.file_type().unwrap().is_dir() {
                stack.push(e.path());
            } else {
                (files, bytes) = (files + 1, bytes + e.metadata().unwrap().len());
            }
        }
    }
    let pack_len = std::fs::metadata(site.dir.path().join("photo.vtpk")).unwrap().len();
    println!("upload: DZI {files} files, {bytes} bytes; pack 1 file, {pack_len} bytes\n");
    let d = *vortex_pack::Pack::open(site.dir.path().join("photo.vtpk")).unwrap().description();
    let (w, h) = (d.width, d.height);
    let views = [("first view", (0, 0, w, h)), ("deep zoom 1:1", (w / 2, h / 2, VIEW.0, VIEW.1))];
    println!(
        "| view | maxTilesPerFrame | index | DZI requests | DZI bytes | pack requests | pack bytes | requests ratio | bytes ratio |"
    );
    println!("|---|---:|---|---:|---:|---:|---:|---:|---:|");
    for (what, region) in views {
        for (per_frame, whole) in [(1, 1 << 18), (16, 1 << 18), (1, 0), (16, 0)] {
            let fetched = |query: &str| {
                site.nginx.clear_requests();
                let (x, y, rw, rh) = region;
                let url = format!(
                    "{}/view.html?{query}&region={x},{y},{rw},{rh}&whole={whole}&perFrame={per_frame}",
                    site.nginx.url()
                );
                site.browser.open_and_wait(&url, READY, Duration::from_secs(120));
                let state = site.browser.execute(STATE);
                assert_eq!(state["openError"], Value::Null, "{state}");
                let counted: Vec<_> = site
                    .nginx
                    .requests()
                    .into_iter()
                    .filter(|r| r.2.contains(".vtpk HTTP/") || r.2.contains("/dzi/"))
                    .collect();
                // VORTEX_WEB_REQUESTS=1 lists them: where the bytes go.
                if std::env::var_os("VORTEX_WEB_REQUESTS").is_some() {
                    counted.iter().for_each(|r| println!("    {} {} {} {}", r.0, r.1, r.2, r.3));
                }
                (counted.len(), counted.iter().map(|r| r.1).sum::<u64>())
            };
            let (dr, db) = fetched(&format!("dzi=/dzi/{dzi}"));
            let (pr, pb) = fetched("pack=photo.vtpk");
            println!(
                "| {what} | {per_frame} | {} | {dr} | {db} | {pr} | {pb} | {:.2} | {:.2} |",
                if whole > 0 { "whole" } else { "blocks" },
                pr as f64 / dr as f64,
                pb as f64 / db as f64
            );
        }
    }
}

/// One-colour tiles are drawn from the index without a request, and tiles that share a payload
/// (stored once) fetch it once: an image whose left part is flat (constant tiles) and whose
/// right part repeats a pattern every payload width (identical tiles, borders included), shown
/// at 1:1 across both, must look right and read exactly one payload per distinct offset.
#[test]
fn vtpk_source_draws_constants_without_a_request_and_fetches_shared_tiles_once() {
    let Some(site) = Site::start("the static-host browser test") else { return };
    // Payload 126 (128-texel tiles, border 1); the pattern repeats every 126 texels from x = 252,
    // so the interior tiles right of it are the same tile.
    let period = 126u32;
    let source = RgbImage::from_fn(1260, 756, |x, y| {
        if x < 2 * period {
            return image::Rgb([200, 60, 40]);
        }
        let (u, v) = ((x % period) as f64 - 63.0, (y % period) as f64 - 63.0);
        let ring = 0.5 + 0.5 * ((u * u + v * v).sqrt() / 5.0).sin();
        image::Rgb([(40.0 + 200.0 * ring) as u8, (x % period * 2) as u8, (y % period * 2) as u8])
    });
    let input = site.dir.path().join("tiles.png");
    source.save(&input).unwrap();
    pack(&site, &input, "shared.vtpk", &["--tile-size", "128", "--border", "1", "--codec", "png"]);
    let region = (60, 100, 640, 480);
    let (shot, state) = site.show("shared.vtpk", region, 1 << 18);
    assert_eq!(state["errors"], serde_json::json!([]), "{state}");
    let verdict = judge(&source, region, &shot);
    eprintln!("shared.vtpk, region {region:?}: {}", verdict.as_ref().unwrap_or_else(|e| e));
    verdict.unwrap();
    // What the page loaded, against the pack's index and nginx's log: constant tiles come from
    // the index (no payload to read), and each distinct payload the view needed reached the
    // host in exactly one request, however many tiles share it.
    let p = vortex_pack::Pack::open(site.dir.path().join("shared.vtpk")).unwrap();
    let (mut constants, mut with_payload, mut payloads) = (0, 0, std::collections::BTreeSet::new());
    for t in state["loaded"].as_array().unwrap() {
        let id = vortex_pack::TileId {
            lod: t[0].as_u64().unwrap() as u32,
            x: t[1].as_u64().unwrap() as u32,
            y: t[2].as_u64().unwrap() as u32,
        };
        let e = p.entry(p.position(id).unwrap());
        match e.kind {
            1 => constants += 1,
            _ => {
                with_payload += 1;
                payloads.insert((e.offset_or_value, e.len as u64));
            }
        }
    }
    eprintln!(
        "{constants} constant tiles, {with_payload} with a payload, {} distinct: {}",
        payloads.len(),
        state["stats"]
    );
    assert!(constants > 0 && payloads.len() < with_payload, "the view has no constant or shared tiles: {state}");
    assert!(
        state["stats"]["constants"].as_u64().unwrap() >= constants,
        "constant tiles not drawn from the index: {state}"
    );
    let ranges: Vec<(u64, u64)> = site
        .nginx
        .requests()
        .iter()
        .filter(|r| r.2.contains("shared.vtpk HTTP/"))
        .filter_map(|r| {
            let (a, b) = r.3.strip_prefix("bytes=")?.split_once('-')?;
            Some((a.parse().ok()?, b.parse().ok()?))
        })
        .collect();
    for (offset, len) in payloads {
        let covering = ranges.iter().filter(|(a, b)| *a <= offset && offset + len - 1 <= *b).count();
        assert_eq!(covering, 1, "the payload at {offset} ({len} bytes) was fetched {covering} times: {ranges:?}");
    }
}
