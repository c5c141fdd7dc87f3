//! Web-map tiles ("slippy map"): zoom level z is a 2^z x 2^z grid of tiles, z = 0 one tile
//! holding the whole image, as Leaflet, OpenLayers and MapLibre number them (`{z}/{x}/{y}`)
//! or as `vips dzsave --layout google` writes them (`{z}/{y}/{x}`).
//!
//! Our LOD k is zoom `Z - k` (Z = the finest). The image sits at the top left of the square;
//! like vips, only the tiles that hold some of it are written, the part of an edge tile past
//! the image filled with the background, and a viewer shows its own background where a tile
//! is missing. A `tilejson.json` (TileJSON 3.0) names the pattern and zoom range.

mod read;

pub use read::Xyz;

use serde_json::json;

use super::Viewer;
use crate::layout::Layout;

/// The tile side web maps use.
pub(crate) const DEFAULT_TILE_SIZE: u32 = 256;
/// The manifest's file name.
pub(crate) const TILEJSON: &str = "tilejson.json";

/// Which coordinate the directories under a zoom level are named by: the one difference
/// between the two layouts, which the writer (`tile_path`) and the reader
/// ([`Xyz`]) both take from here.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Order {
    /// `z/y/x.ext`: a directory per row (Google, vips dzsave --layout google).
    Zyx,
    /// `z/x/y.ext`: a directory per column (XYZ web-map tiles).
    Zxy,
}

impl Order {
    /// [`Viewer::Google`]'s order, else the web maps'.
    pub fn of(viewer: Viewer) -> Order {
        match viewer {
            Viewer::Google => Order::Zyx,
            _ => Order::Zxy,
        }
    }

    /// The pattern, for messages.
    pub(crate) fn pattern(self) -> &'static str {
        match self {
            Order::Zyx => "z/y/x.ext",
            Order::Zxy => "z/x/y.ext",
        }
    }

    /// What the directory under a zoom level and the file in it are named by, for messages:
    /// ("row", "x") or ("column", "y").
    pub(crate) fn names(self) -> (&'static str, &'static str) {
        match self {
            Order::Zyx => ("row", "x"),
            Order::Zxy => ("column", "y"),
        }
    }

    /// The tile's (x, y) from the numbers of its directory (`outer`) and its file (`inner`).
    pub(crate) fn xy(self, outer: u32, inner: u32) -> (u32, u32) {
        match self {
            Order::Zyx => (inner, outer),
            Order::Zxy => (outer, inner),
        }
    }

    /// `{zoom}/{outer}/{inner}.{extension}` of tile (`x`, `y`), each part as given: numbers for
    /// a file, `{x}` and `{y}` for TileJSON's pattern.
    fn path(self, zoom: &str, x: &str, y: &str, extension: &str) -> String {
        match self {
            Order::Zyx => format!("{zoom}/{y}/{x}.{extension}"),
            Order::Zxy => format!("{zoom}/{x}/{y}.{extension}"),
        }
    }
}

/// `{z}/{x}/{y}.EXT`, or `{z}/{y}/{x}.EXT` for [`Viewer::Google`].
pub(crate) fn tile_path(viewer: Viewer, zoom: u32, x: u32, y: u32, extension: &str) -> String {
    Order::of(viewer).path(&zoom.to_string(), &x.to_string(), &y.to_string(), extension)
}

/// TileJSON 3.0 for the directory, with the image's size under `vortex` (a map has no notion
/// of it, a viewer that shows one image does).
pub(crate) fn tilejson(viewer: Viewer, layout: &Layout, name: &str, extension: &str) -> String {
    let pattern = Order::of(viewer).path("{z}", "{x}", "{y}", extension);
    let doc = json!({
        "tilejson": "3.0.0",
        "name": name,
        "tiles": [pattern],
        "minzoom": 0,
        "maxzoom": layout.lod_count - 1,
        "scheme": "xyz",
        "vortex": {
            "layout": viewer.name(),
            "width": layout.width,
            "height": layout.height,
            "tileSize": layout.tile_size,
        },
    });
    let mut text = serde_json::to_string_pretty(&doc).unwrap_or_default();
    text.push('\n');
    text
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn zoom_levels_are_lods_upside_down() {
        // vips --layout google, 700 x 500 in 256-texel tiles: 2/0/0 .. 2/1/2, 1/0/0, 1/0/1, 0/0/0.
        let l = Viewer::Google.page_grid(700, 500, 256, 0).unwrap();
        assert_eq!((l.lod_count, l.grid(0), l.grid(1), l.grid(2)), (3, (3, 2), (2, 1), (1, 1)));
        assert_eq!(tile_path(Viewer::Google, 2, 2, 1, "jpg"), "2/1/2.jpg");
        assert_eq!(tile_path(Viewer::Xyz, 2, 2, 1, "png"), "2/2/1.png");
        // The reader's view of the same names: directory 1, file 2 under Google's order.
        assert_eq!((Order::Zyx.xy(1, 2), Order::Zxy.xy(2, 1)), ((2, 1), (2, 1)));
        let doc: serde_json::Value = serde_json::from_str(&tilejson(Viewer::Xyz, &l, "m", "png")).unwrap();
        assert_eq!((doc["maxzoom"].as_u64(), doc["tiles"][0].as_str()), (Some(2), Some("{z}/{x}/{y}.png")));
    }
}
