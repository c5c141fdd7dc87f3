//! IIIF Image API 3.0 at compliance level 0: static tiles a plain web server can serve, named
//! by the request that fetches them, as libvips 8.18 writes them (`dzsave layout="iiif3"`).
//!
//! Our LOD k is scale factor 2^k. Page (x, y) at LOD k is the region
//! `x * P * 2^k, y * P * 2^k` of the full image, `P * 2^k` on a side and cropped to the image,
//! delivered at `ceil(region / 2^k)` texels: `{rx},{ry},{rw},{rh}/{w},{h}/0/default.{ext}`. The
//! coarsest LOD (one page) is the whole image, which viewers ask for as `full/{w},{h}`; when
//! that is the full resolution too, OpenSeadragon asks for `full/max`, so that name is written
//! as well (libvips does not).

use serde_json::json;

use super::Crop;
use crate::layout::Layout;

/// libvips' default tile size for IIIF.
pub const DEFAULT_TILE_SIZE: u32 = 512;
/// The image's `id` when none is given: relative, resolved by a viewer against the page it
/// runs in (see docs/viewers.md); `serve` rewrites it to its own URL.
pub const DEFAULT_ID: &str = ".";

/// The tile of page (lod, col, row): `{rx},{ry},{rw},{rh}/{w},{h}/0/default.{ext}`, or
/// `full/{w},{h}/0/default.{ext}` for the coarsest LOD.
pub fn tile_path(layout: &Layout, lod: u32, col: u32, row: u32, extension: &str) -> String {
    let Crop { width, height, .. } = crop(layout, lod, col, row);
    if lod + 1 == layout.lod_count {
        return format!("full/{width},{height}/0/default.{extension}");
    }
    let side = (layout.payload() as u64) << lod;
    let (x, y) = (col as u64 * side, row as u64 * side);
    let (rw, rh) = (side.min(layout.width as u64 - x), side.min(layout.height as u64 - y));
    format!("{x},{y},{rw},{rh}/{width},{height}/0/default.{extension}")
}

/// The second name of the full-resolution tile when the image is a single tile
/// (`full/max/...`, what OpenSeadragon asks for then).
pub fn full_max_path(layout: &Layout, lod: u32, extension: &str) -> Option<String> {
    (layout.lod_count == 1 && lod == 0).then(|| format!("full/max/0/default.{extension}"))
}

/// The texels a tile keeps: the page, cut at the image's edge (IIIF tiles have no overlap).
pub fn crop(layout: &Layout, lod: u32, col: u32, row: u32) -> Crop {
    let p = layout.payload();
    let (level_w, level_h) = layout.level_extent(lod);
    Crop { x: 0, y: 0, width: p.min(level_w - col * p), height: p.min(level_h - row * p) }
}

/// `info.json`: the image service description a viewer starts from.
pub fn info_json(layout: &Layout, id: &str, extension: &str) -> String {
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
    use crate::viewer::Viewer;

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

    #[test]
    fn info_lists_every_scale_factor() {
        let l = Viewer::Iiif.page_grid(700, 500, 512, 0).unwrap();
        let info: serde_json::Value = serde_json::from_str(&info_json(&l, "https://x/y", "jpg")).unwrap();
        assert_eq!(info["tiles"][0]["scaleFactors"], json!([1, 2]));
        assert_eq!((info["width"].as_u64(), info["height"].as_u64()), (Some(700), Some(500)));
        assert_eq!(info["id"], "https://x/y");
        assert!(info.get("preferredFormats").is_none());
        let png: serde_json::Value = serde_json::from_str(&info_json(&l, ".", "png")).unwrap();
        assert_eq!(png["preferredFormats"], json!(["png"]));
    }
}
