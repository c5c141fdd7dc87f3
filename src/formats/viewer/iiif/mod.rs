//! IIIF Image API 3.0 at compliance level 0: static tiles a plain web server can serve, named
//! by the request that fetches them, as libvips 8.18 writes them (`dzsave layout="iiif3"`).
//!
//! Our LOD k is scale factor 2^k. Page (x, y) at LOD k is the region
//! `x * P * 2^k, y * P * 2^k` of the full image, `P * 2^k` on a side and cropped to the image,
//! delivered at `ceil(region / 2^k)` texels: `{rx},{ry},{rw},{rh}/{w},{h}/0/default.{ext}`. The
//! coarsest LOD (one page) is the whole image, which viewers ask for as `full/{w},{h}`; when
//! that is the full resolution too, OpenSeadragon asks for `full/max`, so that name is written
//! as well (libvips does not).
//!
//! With an absolute id (`--iiif-id`, [`Service`]) the directory is a conformant level-0
//! service once uploaded there: level 0 also requires `full/max`, and every size `info.json`
//! lists in `sizes`, as files. `max` of a gigapixel image would be the whole image at full
//! resolution, which no client wants in one file, so `max` is bounded by `maxWidth` and
//! `maxHeight`: it is the finest LOD whose long side is at most `MAX_WHOLE_SIDE` (2048), and `sizes`
//! lists it and every coarser LOD. Those whole-image files are made from the LOD's tiles
//! (`whole`).

mod read;
pub(crate) mod whole;

pub use read::Iiif;
pub(crate) use read::looks_like_iiif;

use serde_json::json;

use super::Crop;
use crate::codec::Codec;
use crate::layout::Layout;

/// libvips' default tile size for IIIF.
pub(crate) const DEFAULT_TILE_SIZE: u32 = 512;
/// The image's `id` when none is given: relative, resolved by a viewer against the page it
/// runs in (see docs/viewers.md); `serve` rewrites it to its own URL.
pub(crate) const DEFAULT_ID: &str = ".";

/// The longest side `full/max` may have: 2048 texels fill a 4K screen's height twice over,
/// yet take at most 16 MiB to assemble (RGBA, 8-bit) and about a megabyte as a JPEG.
pub(crate) const MAX_WHOLE_SIDE: u32 = 2048;

/// A conformant IIIF service: its absolute id, and the codec its whole-image files (`full/max`,
/// the `sizes`) are encoded with, the tiles' own.
#[derive(Clone, Debug, PartialEq)]
pub struct Service {
    /// The service's absolute URL (`--iiif-id`), what `info.json`'s `id` says.
    pub id: String,
    /// The codec of the whole-image files.
    pub codec: Codec,
}

/// `--iiif-id`'s URL as the `id` of `info.json`: an absolute `http` or `https` URL with a host
/// and no query or fragment (the id is the base every request is built on, and a viewer
/// appends `/info.json` and `/region/size/...` to it); a trailing slash is dropped, since the
/// id names the image, not a directory of it. IIIF takes the id as a URI (RFC 3986), so every
/// character must be one a URI may hold as it is: letters, digits, `-._~`, `!$&'()*+,;=`,
/// `:`, `@`, `/` and `%` starting a two-digit hex escape. Anything else (a space, `"`, `<`,
/// `>`, `\`, `^`, a backtick, `{|}`, a non-ASCII letter) is refused, naming the character and
/// its percent-encoding.
pub(crate) fn absolute_id(url: &str) -> Result<String, String> {
    let why = |what: &str| format!("--iiif-id {url:?} {what}");
    let rest = url
        .strip_prefix("https://")
        .or_else(|| url.strip_prefix("http://"))
        .ok_or_else(|| why("must be an absolute http:// or https:// URL, the address the directory is uploaded to"))?;
    if url.contains(['?', '#']) {
        return Err(why("has a query or fragment; a IIIF id is a plain path that requests are appended to"));
    }
    if let Some((at, c)) = url.char_indices().find(|&(at, c)| !uri_char(url, at, c)) {
        let encoded: String = c.encode_utf8(&mut [0; 4]).bytes().map(|b| format!("%{b:02X}")).collect();
        let what = match c {
            '%' => "has a '%' that starts no two-digit hex escape; write a '%' itself as %25".to_string(),
            c if c.is_whitespace() || c.is_control() => {
                format!("has a space or control character ({c:?}); percent-encode it ({encoded})")
            }
            c => format!(
                "has {c:?}, which a URI (RFC 3986), and so a IIIF id, may not hold as it is; percent-encode it ({encoded})"
            ),
        };
        return Err(why(&format!("{what} (at byte {at})")));
    }
    let (host, path) = rest.split_once('/').unwrap_or((rest, ""));
    if host.is_empty() || host.starts_with(':') || host.contains('@') {
        return Err(why("has no host name (or one with a user name, which viewers would send in clear)"));
    }
    let path = path.strip_suffix('/').unwrap_or(path);
    if path.is_empty() {
        return Err(why("names no image: add its path, e.g. https://example.org/iiif/photo"));
    }
    if path.split('/').any(|s| s.is_empty() || s == "." || s == "..") {
        return Err(why("has an empty, '.' or '..' path segment"));
    }
    let id = format!("{}{host}/{path}", &url[..url.len() - rest.len()]);
    Ok(id)
}

/// Whether `c`, at byte `at` of `url`, is one a URI holds as it is (RFC 3986 section 2:
/// unreserved, sub-delims, `:`, `@`, `/`, and `%` followed by two hex digits; `?` and `#` are
/// refused before this is asked).
fn uri_char(url: &str, at: usize, c: char) -> bool {
    match c {
        'a'..='z' | 'A'..='Z' | '0'..='9' | '-' | '.' | '_' | '~' => true,
        '!' | '$' | '&' | '\'' | '(' | ')' | '*' | '+' | ',' | ';' | '=' | ':' | '@' | '/' => true,
        '%' => url.as_bytes().get(at + 1..at + 3).is_some_and(|h| h.iter().all(u8::is_ascii_hexdigit)),
        _ => false,
    }
}

/// The LOD `full/max` is: the finest whose long side is at most [`MAX_WHOLE_SIDE`], else the
/// coarsest (a tile side above the bound).
pub(crate) fn max_lod(layout: &Layout) -> u32 {
    let within = |lod: &u32| {
        let (w, h) = layout.level_extent(*lod);
        w.max(h) <= MAX_WHOLE_SIDE
    };
    (0..layout.lod_count).find(within).unwrap_or(layout.lod_count - 1)
}

/// The whole-image sizes a service lists and holds as `full/{w},{h}`: LOD [`max_lod`] and
/// every coarser one, as (lod, width, height), smallest first.
pub(crate) fn whole_sizes(layout: &Layout) -> Vec<(u32, u32, u32)> {
    (max_lod(layout)..layout.lod_count)
        .rev()
        .map(|lod| {
            let (w, h) = layout.level_extent(lod);
            (lod, w, h)
        })
        .collect()
}

/// `full/{size}/0/default.{ext}`: the whole image at `size` (`w,h`, IIIF 2's `w,`, `max` or
/// `full`), as this writer names it and the IIIF reader ([`Iiif`]) looks for it.
pub(crate) fn whole_file(size: &str, extension: &str) -> String {
    format!("full/{size}/0/default.{extension}")
}

/// `{x},{y},{w},{h}/{size}/0/default.{ext}`: the region of the image at `size` (IIIF 3's
/// `w,h`, IIIF 2's `w,`), a tile's file for this writer and the IIIF reader alike.
pub(crate) fn region_file(x: u64, y: u64, w: u64, h: u64, size: &str, extension: &str) -> String {
    format!("{x},{y},{w},{h}/{size}/0/default.{extension}")
}

/// The file of the whole image at `width x height`.
pub(crate) fn full_path(width: u32, height: u32, extension: &str) -> String {
    whole_file(&format!("{width},{height}"), extension)
}

/// The file of the whole image at the service's `max` size.
pub(crate) fn max_path(extension: &str) -> String {
    whole_file("max", extension)
}

/// The tile of page (lod, col, row): `{rx},{ry},{rw},{rh}/{w},{h}/0/default.{ext}`, or
/// `full/{w},{h}/0/default.{ext}` for the coarsest LOD.
pub(crate) fn tile_path(layout: &Layout, lod: u32, col: u32, row: u32, extension: &str) -> String {
    let Crop { width, height, .. } = crop(layout, lod, col, row);
    if lod + 1 == layout.lod_count {
        return full_path(width, height, extension);
    }
    let side = (layout.payload() as u64) << lod;
    let (x, y) = (col as u64 * side, row as u64 * side);
    let (rw, rh) = (side.min(layout.width as u64 - x), side.min(layout.height as u64 - y));
    region_file(x, y, rw, rh, &format!("{width},{height}"), extension)
}

/// The second name of the full-resolution tile when the image is a single tile
/// (`full/max/...`, what OpenSeadragon asks for then).
pub(crate) fn full_max_path(layout: &Layout, lod: u32, extension: &str) -> Option<String> {
    (layout.lod_count == 1 && lod == 0).then(|| max_path(extension))
}

/// The texels a tile keeps: the page, cut at the image's edge (IIIF tiles have no overlap).
pub(crate) fn crop(layout: &Layout, lod: u32, col: u32, row: u32) -> Crop {
    let p = layout.payload();
    let (level_w, level_h) = layout.level_extent(lod);
    Crop { x: 0, y: 0, width: p.min(level_w - col * p), height: p.min(level_h - row * p) }
}

/// `info.json`: the image service description a viewer starts from. A `service` (an absolute
/// id: `--iiif-id`, `serve`) also lists the whole-image `sizes` and bounds `max` by
/// `maxWidth`/`maxHeight` where it is smaller than the image; without, the file is what
/// libvips writes.
pub(crate) fn info_json(layout: &Layout, id: &str, extension: &str, service: bool) -> String {
    let scale_factors: Vec<u64> = (0..layout.lod_count).map(|k| 1u64 << k).collect();
    let mut info = json!({
        "@context": "http://iiif.io/api/image/3/context.json",
        "id": id,
        "type": "ImageService3",
        "profile": "level0",
        "protocol": "http://iiif.io/api/image",
        "tiles": [{ "scaleFactors": scale_factors, "width": layout.payload() }],
        "width": layout.width,
        "height": layout.height,
    });
    if service {
        let sizes: Vec<_> = whole_sizes(layout).iter().map(|&(_, w, h)| json!({"width": w, "height": h})).collect();
        info["sizes"] = json!(sizes);
        let lod = max_lod(layout);
        if lod > 0 {
            let (w, h) = layout.level_extent(lod);
            info["maxWidth"] = json!(w);
            info["maxHeight"] = json!(h);
        }
    }
    if extension != "jpg" {
        // Level 0's default format is JPEG; viewers pick another only when told.
        info["preferredFormats"] = json!([extension]);
        info["extraFormats"] = json!([extension]);
    }
    let mut text = serde_json::to_string_pretty(&info).unwrap_or_default();
    text.push('\n');
    text
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::formats::viewer::Viewer;

    #[test]
    fn names_match_libvips() {
        // libvips 8.18, 3000 x 1100, tile 256: scale factors 1..16, the last as full/188,69.
        let l = Viewer::Iiif.page_grid(3000, 1100, 256, 0).unwrap();
        assert_eq!(l.lod_count, 5);
        assert_eq!(tile_path(&l, 0, 0, 0, "jpg"), "0,0,256,256/256,256/0/default.jpg");
        assert_eq!(tile_path(&l, 0, 11, 4, "jpg"), "2816,1024,184,76/184,76/0/default.jpg");
        assert_eq!(tile_path(&l, 3, 1, 0, "jpg"), "2048,0,952,1100/119,138/0/default.jpg");
        assert_eq!(tile_path(&l, 2, 2, 1, "jpg"), "2048,1024,952,76/238,19/0/default.jpg");
        assert_eq!(tile_path(&l, 4, 0, 0, "jpg"), "full/188,69/0/default.jpg");
        assert_eq!(full_max_path(&l, 4, "jpg"), None);
        let one = Viewer::Iiif.page_grid(300, 200, 512, 0).unwrap();
        assert_eq!(tile_path(&one, 0, 0, 0, "png"), "full/300,200/0/default.png");
        assert_eq!(full_max_path(&one, 0, "png").as_deref(), Some("full/max/0/default.png"));
    }

    /// Only characters a URI holds as they are pass (RFC 3986), so nothing that would need
    /// escaping in info.json or an HTML attribute reaches them; a valid escape passes as it is.
    #[test]
    fn an_id_is_a_uri() {
        for (id, says) in [
            ("https://example.org/a\"b", "'\"'"),
            ("https://example.org/<script>", "'<'"),
            ("https://example.org/a>b", "'>'"),
            ("https://example.org/a\\b", "'\\\\'"),
            ("https://example.org/{x}", "'{'"),
            ("https://example.org/a|b", "'|'"),
            ("https://example.org/a^b", "'^'"),
            ("https://example.org/a`b", "'`'"),
            ("https://example.org/caf\u{e9}", "%C3%A9"),
            ("https://example.org/a%zzb", "two-digit hex escape"),
            ("https://example.org/a%2", "two-digit hex escape"),
            ("https://example.org/a\tb", "control character"),
            ("https://example.org/a\u{1b}[31mb", "control character"),
        ] {
            let err = absolute_id(id).unwrap_err();
            assert!(err.contains(says) && err.contains("--iiif-id"), "{id}: {err}");
        }
        let fine = "https://user-host.example.org:8443/iiif/a%20b/c;d=e/~f(1)!$&'*+,@";
        assert_eq!(absolute_id(fine).as_deref(), Ok(fine));
        assert_eq!(absolute_id("http://example.org/p/").as_deref(), Ok("http://example.org/p"));
    }

    #[test]
    fn info_lists_every_scale_factor() {
        let l = Viewer::Iiif.page_grid(700, 500, 512, 0).unwrap();
        let info: serde_json::Value = serde_json::from_str(&info_json(&l, "https://x/y", "jpg", false)).unwrap();
        assert_eq!(info["tiles"][0]["scaleFactors"], json!([1, 2]));
        assert_eq!((info["width"].as_u64(), info["height"].as_u64()), (Some(700), Some(500)));
        assert_eq!(info["id"], "https://x/y");
        assert!(info.get("preferredFormats").is_none());
        let png: serde_json::Value = serde_json::from_str(&info_json(&l, ".", "png", false)).unwrap();
        assert_eq!(png["preferredFormats"], json!(["png"]));
    }
}
