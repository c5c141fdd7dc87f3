//! IIIF Image API 3.0 at compliance level 0, checked against the specification's own
//! requirements rather than against our names: `split --layout iiif --iiif-id URL` (the
//! directory as it would be uploaded to URL) and `serve` (a pack, the id from the request's
//! `Host`) must both answer every request a level-0 client may make: `info.json` with each
//! required field, every tile of every scale factor as the specification's implementation
//! note computes its region and size, every listed size, and `full/max`, each image of the
//! size its URL asks. `--iiif-id` must be an absolute URL.

use std::path::Path;

use image::{Rgb, RgbImage};
use serde_json::Value;

use crate::common::cli::{fails_with, ok, run, s};
use crate::common::server::Server;

/// 4411 x 301: odd sides, so that edge tiles are partial at every scale factor, and wider than
/// twice the 2048-texel bound, so that `max` is a coarser level (LOD 2, 1103 x 76).
const SIZE: (u32, u32) = (4411, 301);

/// A smooth picture (ramps and slow waves), so that a level made by our filter and the source
/// resized by another agree closely.
fn picture() -> RgbImage {
    RgbImage::from_fn(SIZE.0, SIZE.1, |x, y| {
        let (fx, fy) = (x as f64, y as f64);
        let wave = 0.5 + 0.5 * (fx / 180.0).sin() * (fy / 60.0).cos();
        Rgb([
            (fx / SIZE.0 as f64 * 230.0) as u8 + 10,
            (wave * 200.0) as u8 + 20,
            (fy / SIZE.1 as f64 * 200.0) as u8 + 30,
        ])
    })
}

/// Checks one service as a level-0 client sees it: `info` its `info.json`, `id` the id it
/// must name, `get(path)` the body of `{id}/{path}` when it answers 200. Returns the number of
/// images requested, or every failure found.
fn check_level0(info: &Value, id: &str, get: &dyn Fn(&str) -> Option<Vec<u8>>) -> Result<usize, Vec<String>> {
    let mut failures = Vec::new();
    let mut fail = |what: String| failures.push(what);
    for (field, want) in [
        ("@context", "http://iiif.io/api/image/3/context.json"),
        ("type", "ImageService3"),
        ("protocol", "http://iiif.io/api/image"),
        ("profile", "level0"),
    ] {
        if info[field] != want {
            fail(format!("{field} is {}, not {want:?}", info[field]));
        }
    }
    if info["id"] != id {
        fail(format!("id is {}, not {id:?} (the URL info.json was fetched from, without /info.json)", info["id"]));
    }
    let (w, h) = (info["width"].as_u64().unwrap_or(0) as u32, info["height"].as_u64().unwrap_or(0) as u32);
    if (w, h) != SIZE {
        fail(format!("width x height is {w} x {h}, the image {SIZE:?}"));
    }
    if info.get("maxHeight").is_some() && info.get("maxWidth").is_none() {
        fail("maxHeight without maxWidth".into());
    }
    let mut requested = 0;
    // An image request: its decoded size must be what the URL asks for.
    let mut fetch = |path: String, want: Option<(u32, u32)>, fail: &mut dyn FnMut(String)| -> Option<(u32, u32)> {
        requested += 1;
        let Some(body) = get(&path) else {
            fail(format!("{id}/{path} is missing"));
            return None;
        };
        match image::load_from_memory_with_format(&body, image::ImageFormat::Jpeg) {
            Ok(img) if want.is_none_or(|want| img.width() == want.0 && img.height() == want.1) => {
                Some((img.width(), img.height()))
            }
            Ok(img) => {
                fail(format!("{id}/{path} is {}x{}", img.width(), img.height()));
                None
            }
            Err(e) => {
                fail(format!("{id}/{path} is not a JPEG: {e}"));
                None
            }
        }
    };
    // Every tile of every scale factor, region and size as the implementation notes compute
    // them, the region written `full` where it is the whole image (its canonical form).
    let tiles = info["tiles"].as_array().cloned().unwrap_or_default();
    if tiles.is_empty() {
        fail("no tiles".into());
    }
    for t in &tiles {
        let tw = t["width"].as_u64().unwrap_or(0) as u32;
        let th = t["height"].as_u64().map_or(tw, |v| v as u32);
        let factors: Vec<u32> =
            t["scaleFactors"].as_array().into_iter().flatten().filter_map(|v| v.as_u64()).map(|v| v as u32).collect();
        if tw == 0 || factors.is_empty() {
            fail(format!("tiles entry {t} has no width or scale factors"));
            continue;
        }
        for s in factors {
            for m in 0..h.div_ceil(th * s) {
                for n in 0..w.div_ceil(tw * s) {
                    let (xr, yr) = (n * tw * s, m * th * s);
                    let (wr, hr) = ((tw * s).min(w - xr), (th * s).min(h - yr));
                    let (ws, hs) = (wr.div_ceil(s), hr.div_ceil(s));
                    let region =
                        if (xr, yr, wr, hr) == (0, 0, w, h) { "full".into() } else { format!("{xr},{yr},{wr},{hr}") };
                    fetch(format!("{region}/{ws},{hs}/0/default.jpg"), Some((ws, hs)), &mut fail);
                }
            }
        }
    }
    // Every listed size, no larger than the image (level 0 has no upscaling).
    let sizes = info["sizes"].as_array().cloned().unwrap_or_default();
    if sizes.is_empty() {
        fail("no sizes".into());
    }
    for size in &sizes {
        let (sw, sh) = (size["width"].as_u64().unwrap_or(0) as u32, size["height"].as_u64().unwrap_or(0) as u32);
        if sw == 0 || sh == 0 || sw > w || sh > h {
            fail(format!("size {size} is empty or larger than the image"));
            continue;
        }
        fetch(format!("full/{sw},{sh}/0/default.jpg"), Some((sw, sh)), &mut fail);
    }
    // `max`: the region's size unless maxWidth / maxHeight / maxArea bound it, then as large
    // as they allow with the aspect ratio kept (within a texel of rounding).
    let max_w = info["maxWidth"].as_u64().map(|v| v as u32);
    let max_h = info["maxHeight"].as_u64().map(|v| v as u32).or(max_w);
    let max_area = info["maxArea"].as_u64();
    if let Some((mw, mh)) = fetch("full/max/0/default.jpg".into(), None, &mut fail) {
        let bounded = max_w.is_some_and(|b| b < w)
            || max_h.is_some_and(|b| b < h)
            || max_area.is_some_and(|a| a < w as u64 * h as u64);
        if !bounded && (mw, mh) != (w, h) {
            fail(format!("full/max is {mw}x{mh} with no bound, not the image's {w}x{h}"));
        }
        if max_w.is_some_and(|b| mw > b)
            || max_h.is_some_and(|b| mh > b)
            || max_area.is_some_and(|a| (mw as u64 * mh as u64) > a)
        {
            fail(format!(
                "full/max is {mw}x{mh}, over maxWidth {max_w:?} / maxHeight {max_h:?} / maxArea {max_area:?}"
            ));
        }
        if bounded && !(max_w == Some(mw) || max_h == Some(mh)) {
            fail(format!("full/max is {mw}x{mh}, smaller than the bound {max_w:?} x {max_h:?} allows"));
        }
        // One scale for both sides, each rounded to a whole texel.
        let scale = |side: u32, of: u32| ((side as f64 - 1.0) / of as f64, (side as f64 + 1.0) / of as f64);
        let ((a0, a1), (b0, b1)) = (scale(mw, w), scale(mh, h));
        if a0.max(b0) > a1.min(b1) {
            fail(format!("full/max is {mw}x{mh}: not the image's aspect ratio"));
        }
        if !sizes.iter().any(|s| s["width"] == mw && s["height"] == mh) {
            fail(format!("full/max ({mw}x{mh}) is not among the sizes {sizes:?}"));
        }
    }
    if failures.is_empty() { Ok(requested) } else { Err(failures) }
}

/// PSNR of a whole-image file against the source resized to its size. Our levels are 2x2 box
/// means, the reference a Triangle resize of a smooth picture, and the file a JPEG of JPEG
/// tiles (q90): a correct image measured 40 dB; 30 dB leaves room for the resampler, while a
/// shifted or wrongly assembled image (misplaced tiles) falls far below.
fn whole_psnr(jpeg: &[u8]) -> f64 {
    let got = image::load_from_memory(jpeg).unwrap().to_rgb8();
    let want = image::imageops::resize(&picture(), got.width(), got.height(), image::imageops::FilterType::Triangle);
    let sum: f64 = want.as_raw().iter().zip(got.as_raw()).map(|(a, b)| (*a as f64 - *b as f64).powi(2)).sum();
    10.0 * (255.0f64 * 255.0 / (sum / want.as_raw().len() as f64).max(1e-9)).log10()
}

#[test]
fn static_directory_is_a_level0_service_at_its_id() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("photo.png");
    picture().save(&input).unwrap();
    let out = dir.path().join("photo");
    let id = "https://example.org/iiif/photo";
    ok(&[
        "split",
        s(&input),
        "--layout",
        "iiif",
        "-o",
        s(&out),
        "--tile-size",
        "256",
        "--quality",
        "90",
        "-q",
        "--iiif-id",
        "https://example.org/iiif/photo/",
    ]);
    let info: Value = serde_json::from_slice(&std::fs::read(out.join("info.json")).unwrap()).unwrap();
    // The bound: full/max is LOD 2 (the finest within 2048 texels), and info.json says so.
    assert_eq!((info["maxWidth"].as_u64(), info["maxHeight"].as_u64()), (Some(1103), Some(76)), "{info}");
    let get = |path: &str| std::fs::read(out.join(path)).ok();
    let requested = check_level0(&info, id, &get).unwrap_or_else(|f| panic!("{}", f.join("\n")));
    assert!(requested > 60, "{requested}");
    let db = whole_psnr(&get("full/max/0/default.jpg").unwrap());
    eprintln!("static full/max against the source resized: {db:.1} dB");
    assert!(db > 30.0, "full/max is not the picture: {db:.1} dB");

    // Without --iiif-id the directory stays what libvips writes: no full/max, no sizes.
    let plain = dir.path().join("plain");
    ok(&["split", s(&input), "--layout", "iiif", "-o", s(&plain), "--tile-size", "256", "-q"]);
    let info: Value = serde_json::from_slice(&std::fs::read(plain.join("info.json")).unwrap()).unwrap();
    assert_eq!(info["id"], ".");
    assert!(info.get("sizes").is_none() && !plain.join("full/max").exists(), "{info}");
}

#[test]
fn served_pack_is_a_level0_service_at_the_requested_host() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("photo.png");
    picture().save(&input).unwrap();
    let pack = dir.path().join("photo.vtpk");
    // Border 1 (a GPU pack's): the service's tiles are the 254-texel payloads, cut at the edge.
    ok(&["split", s(&input), "--pack", s(&pack), "--tile-size", "256", "--quality", "90", "-q"]);
    let server = Server::start(&[&pack], &[]);
    let reply = server.raw("GET /photo/iiif/info.json HTTP/1.1\r\nHost: iiif.example.test:8080");
    assert_eq!(reply.status, 200);
    let info: Value = serde_json::from_slice(&reply.body).unwrap();
    let get = |path: &str| {
        let r = server.get(&format!("/photo/iiif/{path}"), &[]);
        (r.status == 200).then_some(r.body)
    };
    let requested = check_level0(&info, "http://iiif.example.test:8080/photo/iiif", &get)
        .unwrap_or_else(|f| panic!("{}", f.join("\n")));
    assert!(requested > 60, "{requested}");
    let db = whole_psnr(&get("full/max/0/default.jpg").unwrap());
    eprintln!("served full/max against the source resized: {db:.1} dB");
    assert!(db > 30.0, "full/max is not the picture: {db:.1} dB");
    // Names that are no size of this service stay 404.
    for path in ["full/1102,76/0/default.jpg", "full/4411,301/0/default.jpg", "full/max/0/default.png"] {
        assert_eq!(server.get(&format!("/photo/iiif/{path}"), &[]).status, 404, "{path}");
    }
}

#[test]
fn iiif_id_must_be_an_absolute_url() {
    let dir = tempfile::tempdir().unwrap();
    let input = dir.path().join("p.png");
    RgbImage::from_pixel(40, 30, Rgb([9, 9, 9])).save(&input).unwrap();
    let out = dir.path().join("out");
    for (id, says) in [
        ("photo", "absolute http:// or https:// URL"),
        ("ftp://example.org/photo", "absolute http:// or https:// URL"),
        ("https://example.org/photo?x=1", "query or fragment"),
        ("https://example.org/photo#top", "query or fragment"),
        ("https:///photo", "no host"),
        ("https://example.org/", "names no image"),
        ("https://example.org//photo", "empty, '.' or '..'"),
        ("https://example.org/a b", "space"),
        // Only what a URI may hold (RFC 3986): nothing that info.json or a page would need escaped.
        ("https://example.org/a\"b", "percent-encode it (%22)"),
        ("https://example.org/<b>", "percent-encode it (%3C)"),
    ] {
        let r = run(&["split", s(&input), "--layout", "iiif", "-o", s(&out), "--iiif-id", id]);
        fails_with(&r, &["--iiif-id", says]);
        assert!(!out.exists(), "{id}: an output was left");
    }
    let r = run(&[
        "split",
        s(&input),
        "--layout",
        "iiif",
        "-o",
        s(&out),
        "--codec",
        "png",
        "--iiif-id",
        "https://example.org/p",
    ]);
    fails_with(&r, &["JPEG", "--codec jpeg"]);
    // One tile: full/max is that tile, no bound needed.
    ok(&["split", s(&input), "--layout", "iiif", "-o", s(&out), "-q", "--iiif-id", "http://example.org/p"]);
    let info: Value = serde_json::from_slice(&std::fs::read(out.join("info.json")).unwrap()).unwrap();
    assert_eq!((info["id"].as_str(), info.get("maxWidth")), (Some("http://example.org/p"), None));
    assert_eq!(info["sizes"], serde_json::json!([{"width": 40, "height": 30}]));
    assert!(Path::new(&out.join("full/max/0/default.jpg")).is_file());
}
