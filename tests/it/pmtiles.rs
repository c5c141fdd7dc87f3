//! `split --pmtiles`: one PMTiles v3 archive of the web-map pyramid. The independent reader is
//! the `pmtiles` package from PyPI (the format's reference Python code, in the venv that
//! `VORTEX_PYVIPS` names): it must read every tile back byte for byte equal to the file our
//! `--layout xyz` writes for the same run, and find the header and metadata we promise.
//! Outside CI a missing reader skips with a note; under `CI=true` it fails.

use std::path::{Path, PathBuf};
use std::process::Command;

use image::{ImageBuffer, Rgb, RgbImage};
use serde_json::Value;

use crate::common::cli::{fails_with, ok, run, s};

/// The Python with the `pmtiles` package, or `None` after a note (a failure under CI).
fn python() -> Option<PathBuf> {
    let Some(python) = std::env::var_os("VORTEX_PYVIPS") else {
        crate::common::skip_unless_ci(
            "the PMTiles reader check",
            "VORTEX_PYVIPS unset: set it to a Python with pmtiles",
        );
        return None;
    };
    Some(PathBuf::from(python))
}

/// Reads `archive` with the reference reader: header, metadata, every tile through
/// `all_tiles` (which walks the directories) and again through `Reader.get` (which searches
/// them, run lengths included; every `step`th tile, as each call inflates its directories
/// again), each compared with `xyz/{z}/{x}/{y}.EXT`.
const CHECK: &str = r#"
import json, os, sys
from pmtiles.reader import Reader, MmapSource, all_tiles
archive, xyz, ext, step = sys.argv[1:5]
with open(archive, "rb") as f:
    r = Reader(MmapSource(f))
    h = r.header()
    seen = set()
    for i, ((z, x, y), data) in enumerate(all_tiles(r.get_bytes)):
        with open(os.path.join(xyz, str(z), str(x), f"{y}.{ext}"), "rb") as t:
            assert t.read() == data, (z, x, y)
        if i % int(step) == 0:
            assert r.get(z, x, y) == data, (z, x, y)
        seen.add((z, x, y))
    files = set()
    for root, _, names in os.walk(xyz):
        for n in names:
            if n.endswith("." + ext):
                z, x = os.path.relpath(root, xyz).split(os.sep)
                files.add((int(z), int(x), int(n.split(".")[0])))
    assert seen == files, (len(seen), len(files))
    print(json.dumps({"header": {k: (v.value if hasattr(v, "value") else v) for k, v in h.items()},
                      "metadata": r.metadata(), "tiles": len(seen)}))
"#;

fn check_with_reader(python: &Path, archive: &Path, xyz: &Path, ext: &str, step: u32) -> Value {
    let out =
        Command::new(python).args(["-c", CHECK]).args([archive, xyz]).args([ext, &step.to_string()]).output().unwrap();
    assert!(out.status.success(), "pmtiles reader: {}", String::from_utf8_lossy(&out.stderr));
    serde_json::from_slice(&out.stdout).unwrap()
}

/// A picture with a flat grey block (identical tiles: shared payloads and runs) beside
/// gradients (distinct tiles), not square and not a multiple of the tile size.
fn picture(width: u32, height: u32) -> RgbImage {
    ImageBuffer::from_fn(width, height, |x, y| {
        if x < width / 2 && y < height / 2 {
            Rgb([128, 128, 128])
        } else {
            Rgb([(x * 7 % 256) as u8, (y * 5 % 256) as u8, ((x ^ y) % 256) as u8])
        }
    })
}

/// Splits `input` into `NAME.pmtiles` and `NAME-xyz/` with the same `args`; the `--json`
/// summary of the archive.
fn split_both(dir: &Path, input: &Path, name: &str, args: &[&str]) -> Value {
    let archive = dir.join(format!("{name}.pmtiles"));
    let xyz = dir.join(format!("{name}-xyz"));
    let mut a = vec!["split", s(input), "--pmtiles", s(&archive), "--json"];
    a.extend_from_slice(args);
    let summary: Value = serde_json::from_str(ok(&a).trim()).unwrap();
    let mut a = vec!["split", s(input), "--layout", "xyz", "-o", s(&xyz), "-q"];
    a.extend_from_slice(args);
    ok(&a);
    summary
}

/// JPEG, PNG and JPEG XL archives read back by the reference reader: every tile equals our XYZ tile,
/// the header says what the archive holds and where the image lies, the metadata names the
/// image's size, and identical tiles share one payload.
#[test]
fn the_reference_reader_reads_every_tile_back() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in.png");
    picture(1000, 700).save(&input).unwrap();
    let Some(python) = python() else {
        // The archive is still written and described without the reader.
        split_both(dir.path(), &input, "jpeg", &["--tile-size", "128"]);
        return;
    };
    // JPEG XL has no tile type of its own: 0, "Unknown/Other", with the metadata's format.
    let cases = [
        ("jpeg", "jpg", 128u32, 3, &["--tile-size", "128"][..]),
        ("png", "png", 64, 2, &["--tile-size", "64", "--codec", "png"][..]),
        ("jxl", "jxl", 64, 0, &["--tile-size", "64", "--codec", "jxl"][..]),
    ];
    for (name, ext, tile, tile_type, args) in cases {
        let summary = split_both(dir.path(), &input, name, args);
        let read = check_with_reader(
            &python,
            &dir.path().join(format!("{name}.pmtiles")),
            &dir.path().join(format!("{name}-xyz")),
            ext,
            1,
        );
        let h = &read["header"];
        // Zoom z holds the image in 2^z tiles per side at most: 1000 px needs 8 of 128, 16 of 64.
        let max_zoom = if tile == 128 { 3 } else { 4 };
        assert_eq!((h["version"].as_u64(), h["clustered"].as_bool()), (Some(3), Some(true)), "{h}");
        assert_eq!((h["min_zoom"].as_u64(), h["max_zoom"].as_u64()), (Some(0), Some(max_zoom)), "{h}");
        assert_eq!(h["tile_type"].as_u64(), Some(tile_type), "{h}");
        assert_eq!(h["internal_compression"].as_u64(), Some(2), "{h}");
        assert_eq!(h["addressed_tiles_count"].as_u64(), read["tiles"].as_u64(), "{h}");
        // The flat block makes identical tiles: fewer payloads than tiles.
        assert!(h["tile_contents_count"].as_u64() < h["addressed_tiles_count"].as_u64(), "{h}");
        // Bounds: the image's part of the web-mercator square from its top-left corner.
        let side = f64::from(tile << max_zoom);
        let max_lon = -180.0 + 360.0 * 1000.0 / side;
        assert_eq!(h["min_lon_e7"].as_i64(), Some(-1_800_000_000), "{h}");
        assert!((h["max_lon_e7"].as_i64().unwrap() as f64 / 1e7 - max_lon).abs() < 1e-6, "{h}");
        assert_eq!(h["max_lat_e7"].as_i64(), Some(850_511_288), "{h}");
        let m = &read["metadata"];
        assert_eq!((m["vortex"]["width"].as_u64(), m["vortex"]["height"].as_u64()), (Some(1000), Some(700)), "{m}");
        assert_eq!(m["vortex"]["tileSize"].as_u64(), Some(tile.into()), "{m}");
        assert_eq!(m["format"].as_str(), Some(ext), "{m}");
        let p = &summary["pmtiles"];
        assert_eq!(p["tiles"], h["addressed_tiles_count"], "{summary}");
        assert_eq!(p["contents"], h["tile_contents_count"], "{summary}");
        let len = std::fs::metadata(dir.path().join(format!("{name}.pmtiles"))).unwrap().len();
        assert_eq!(p["fileBytes"].as_u64(), Some(len), "{summary}");
    }
}

/// Enough tiles that the root directory cannot hold them all within the first 16 KiB: leaf
/// directories, which the reference reader follows to every tile.
#[test]
fn a_large_pyramid_gets_leaf_directories() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in.png");
    // 16-texel tiles of noise-like content: 32,600 tiles of varied lengths, whose root alone
    // would take about 25 KiB (12,500 such entries measured 9.8 KiB).
    ImageBuffer::from_fn(2600, 2400, |x, y| {
        let v = x.wrapping_mul(2654435761) ^ y.wrapping_mul(40503) ^ (x * y);
        Rgb([v as u8, (v >> 8) as u8, (v >> 16) as u8])
    })
    .save(&input)
    .unwrap();
    let summary = split_both(dir.path(), &input, "many", &["--tile-size", "16", "--quality", "60"]);
    assert!(summary["pmtiles"]["leafDirectories"].as_u64() > Some(1), "{summary}");
    let archive = dir.path().join("many.pmtiles");
    let bytes = std::fs::read(&archive).unwrap();
    let root_end =
        u64::from_le_bytes(bytes[8..16].try_into().unwrap()) + u64::from_le_bytes(bytes[16..24].try_into().unwrap());
    assert!(root_end <= 16384, "the root directory ends at {root_end}");
    if let Some(python) = python() {
        let read = check_with_reader(&python, &archive, &dir.path().join("many-xyz"), "jpg", 101);
        assert_eq!(read["tiles"], summary["pmtiles"]["tiles"]);
    }
}

/// The output rules: a PMTiles archive is replaced, another file only with --force, and a
/// failed run leaves nothing (no archive, no temporaries). Options that cannot make an
/// archive are refused naming the flag.
#[test]
fn pmtiles_output_follows_the_output_rules() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("in.png");
    picture(300, 200).save(&input).unwrap();
    let archive = dir.path().join("out.pmtiles");
    ok(&["split", s(&input), "--pmtiles", s(&archive), "-q"]);
    ok(&["split", s(&input), "--pmtiles", s(&archive), "-q", "--quality", "50"]);
    let notes = dir.path().join("notes.txt");
    std::fs::write(&notes, "mine").unwrap();
    fails_with(&run(&["split", s(&input), "--pmtiles", s(&notes)]), &["notes.txt", "--force"]);
    assert_eq!(std::fs::read(&notes).unwrap(), b"mine");
    ok(&["split", s(&input), "--pmtiles", s(&notes), "-q", "--force"]);
    assert_eq!(&std::fs::read(&notes).unwrap()[..8], b"PMTiles\x03");

    fails_with(
        &run(&["split", s(&input), "--pmtiles", s(&archive), "--layout", "dzi"]),
        &["--pmtiles", "--layout dzi", "xyz"],
    );
    fails_with(&run(&["split", s(&input), "--pmtiles", s(&archive), "--codec", "zstd"]), &["zstd"]);
    // With a pack beside it: two outputs of one run (tests/it/outputs.rs).
    let pack = dir.path().join("x.vtpk");
    ok(&["split", s(&input), "--pmtiles", s(&archive), "--pack", s(&pack), "-q"]);
    assert!(pack.is_file());
    std::fs::remove_file(&pack).unwrap();

    // A PNG cut short fails part-way through: nothing is left beside the previous archive.
    let before = std::fs::read(&archive).unwrap();
    let png = std::fs::read(&input).unwrap();
    let broken = dir.path().join("broken.png");
    std::fs::write(&broken, &png[..png.len() * 2 / 3]).unwrap();
    let out = run(&["split", s(&broken), "--pmtiles", s(&archive)]);
    assert_eq!(out.status.code(), Some(1), "{}", String::from_utf8_lossy(&out.stderr));
    assert_eq!(std::fs::read(&archive).unwrap(), before, "the previous archive was touched");
    let mut left: Vec<_> =
        std::fs::read_dir(dir.path()).unwrap().map(|e| e.unwrap().file_name().into_string().unwrap()).collect();
    left.sort();
    assert_eq!(left, ["broken.png", "in.png", "notes.txt", "out.pmtiles"]);
}

/// Leaflet on a pixel map (`L.CRS.Simple`, no geography) showing an archive through the npm
/// `pmtiles` package's `leafletRasterLayer`: map units are image texels over 2^maxzoom, the
/// image's size and tile size come from our metadata. `?archive=URL&region=x,y,w,h`.
const LEAFLET_PAGE: &str = r#"<!doctype html><html><head><link rel="stylesheet" href="/leaflet/leaflet.css">
<style>html,body{margin:0;background:#000;overflow:hidden}#v{width:640px;height:480px;background:#000}</style>
<script src="/leaflet/leaflet.js"></script><script src="/pmtiles/pmtiles.js"></script></head><body><div id="v"></div>
<script>
const q = new URLSearchParams(location.search);
const [x, y, w, h] = q.get("region").split(",").map(Number);
window.errors = [];
(async () => { try {
  const archive = new pmtiles.PMTiles(q.get("archive"));
  const header = await archive.getHeader(), meta = await archive.getMetadata();
  const Z = header.maxZoom, size = meta.vortex.tileSize, u = (v) => v / 2 ** Z;
  const map = L.map("v", { crs: L.CRS.Simple, zoomSnap: 0, zoomAnimation: false, fadeAnimation: false,
    attributionControl: false, zoomControl: false, minZoom: -8, maxZoom: Z + 8 });
  map.fitBounds(L.latLngBounds([-u(y + h), u(x)], [-u(y), u(x + w)]), { animate: false });
  const layer = pmtiles.leafletRasterLayer(archive, { tileSize: size, minZoom: 0, maxNativeZoom: Z, maxZoom: Z + 8,
    bounds: L.latLngBounds([-u(meta.vortex.height), 0], [0, u(meta.vortex.width)]), noWrap: true });
  layer.on("tileerror", (e) => errors.push(String(e.error)));
  layer.on("load", () => { window.done = true; });
  layer.addTo(map);
} catch (e) { window.openError = String(e && e.message || e); } })();
</script></body></html>"#;

/// nginx (a plain static host with `Range`) serves an archive of JPEG tiles and one of JPEG XL
/// tiles, and Leaflet with the npm `pmtiles` package shows each in Chromium at the three
/// regions of `browser.rs`; each screenshot is judged against the source region (PSNR, and
/// better than the region shifted), the same threshold for both codecs.
#[test]
fn leaflet_shows_an_archive_from_a_static_host() {
    use crate::browser::REGIONS;
    use crate::common::nginx::{Nginx, nginx_binary};
    use crate::common::picture::{VIEW, browser_parts, judge, test_image};
    use crate::common::skip_unless_ci;
    use crate::common::webdriver::Browser;

    let test = "the Leaflet PMTiles test";
    let modules = Path::new(env!("CARGO_MANIFEST_DIR")).join("tests/browser/node_modules");
    let (parts, nginx) = match browser_parts().and_then(|p| nginx_binary().map(|n| (p, n))) {
        Ok(found) => found,
        Err(why) => return skip_unless_ci(test, &why),
    };
    if !modules.join("pmtiles/dist/pmtiles.js").is_file() || !modules.join("leaflet/dist/leaflet.js").is_file() {
        return skip_unless_ci(test, "no leaflet or pmtiles (npm ci --prefix tests/browser)");
    }
    let dir = tempfile::tempdir().unwrap();
    std::fs::write(dir.path().join("map.html"), LEAFLET_PAGE).unwrap();
    let source = test_image();
    let input = dir.path().join("photo.png");
    source.save(&input).unwrap();
    // JPEG, and JPEG XL in an archive of tile type 0 ("Unknown/Other"): the package hands its
    // tiles to an <img> untyped and Chromium recognises JPEG XL by its signature.
    let archives = [("photo.pmtiles", "jpeg"), ("photo-jxl.pmtiles", "jxl")];
    for (name, codec) in archives {
        let archive = dir.path().join(name);
        ok(&["split", s(&input), "--pmtiles", s(&archive), "-q", "--codec", codec, "--quality", "95"]);
    }
    let server = Nginx::start(
        &nginx,
        dir.path(),
        &[("leaflet", &modules.join("leaflet/dist")), ("pmtiles", &modules.join("pmtiles/dist"))],
    );
    let browser = Browser::start(&parts.chromedriver, &parts.chromium, VIEW);
    let mut failures = Vec::new();
    for ((name, codec), region) in archives.into_iter().flat_map(|a| REGIONS.map(|r| (a, r))) {
        let (x, y, w, h) = region;
        let url = format!("{}/map.html?archive={name}&region={x},{y},{w},{h}", server.url());
        browser.open_and_wait(&url, "window.openError || window.done", std::time::Duration::from_secs(60));
        let state = browser.execute("return { openError: window.openError || null, errors: window.errors };");
        assert_eq!(state["openError"], Value::Null, "{codec}: {state}");
        assert_eq!(state["errors"], serde_json::json!([]), "{codec}: {state}");
        let shot = image::load_from_memory(&browser.screenshot("#v")).unwrap().to_rgb8();
        let verdict = judge(&source, region, &shot);
        eprintln!("leaflet, {codec}, region {region:?}: {}", verdict.as_ref().unwrap_or_else(|e| e));
        if let Err(why) = verdict {
            shot.save(dir.path().join(format!("failed-{codec}-{x}.png"))).unwrap();
            failures.push(format!("{codec}, region {region:?}: {why}"));
        }
    }
    if !failures.is_empty() {
        let kept = dir.keep();
        panic!("{} (screenshots in {})", failures.join("; "), kept.display());
    }
    // The archive was read by byte ranges from the plain static host.
    let reads: Vec<_> = server.requests().into_iter().filter(|r| r.2.contains(".pmtiles HTTP/")).collect();
    assert!(!reads.is_empty() && reads.iter().all(|r| r.0 == 206 && r.3.starts_with("bytes=")), "{reads:?}");
}
