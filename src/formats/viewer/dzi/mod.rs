//! Deep Zoom (`.dzi`), as Microsoft defines it and `vips dzsave` writes it.
//!
//! Level `maxLevel = ceil(log2(max(w, h)))` is the full image and each level below halves it
//! (rounding up) down to level 0, 1 x 1. A level is cut into `TileSize` tiles; each tile also
//! holds `Overlap` texels of every neighbour it has, so edge tiles are narrower, and the last
//! tile of a row or column stops at the image. Our page of payload P and border B is that
//! tile before cropping: Deep Zoom level `maxLevel - k` is our LOD k, tile size P, overlap B.

mod read;

pub use read::DeepZoom;

use super::Crop;
use crate::layout::Layout;

/// vips dzsave's default tile size (254 + 2 x 1 overlap = 256 texels stored).
pub(crate) const DEFAULT_TILE_SIZE: u32 = 254;
/// vips dzsave's default overlap.
pub(crate) const DEFAULT_OVERLAP: u32 = 1;

/// Deep Zoom's finest level, where the image has its full size: `ceil(log2(max(w, h)))`. The
/// writer's level names and the reader's finest level ([`DeepZoom`]) both come
/// from here; any side a descriptor can state has one, `u32::MAX` included.
pub fn max_level(width: u32, height: u32) -> u32 {
    u32::BITS - width.max(height).saturating_sub(1).leading_zeros()
}

/// The Deep Zoom level of our LOD `lod`.
pub(crate) fn level_of(layout: &Layout, lod: u32) -> u32 {
    max_level(layout.width, layout.height) - lod
}

/// `NAME_files/LEVEL`: the directory of a level's tiles, beside `NAME.dzi`.
pub(crate) fn level_dir(name: &str, level: u32) -> String {
    format!("{name}_files/{level}")
}

/// `LEVEL_DIR/COL_ROW.EXT`: a tile in its level's directory.
pub(crate) fn tile_in(level_dir: &str, col: u32, row: u32, extension: &str) -> String {
    format!("{level_dir}/{col}_{row}.{extension}")
}

/// `NAME_files/LEVEL/COL_ROW.EXT`.
pub(crate) fn tile_path(name: &str, level: u32, col: u32, row: u32, extension: &str) -> String {
    tile_in(&level_dir(name, level), col, row, extension)
}

/// The texels of its level that tile `index` of a row (column) holds, `start..end`: its cell
/// of `cell` texels, plus `overlap` on each side that has a neighbour, stopping at the level's
/// `extent`. What the writer crops a page to and what the reader expects a tile to hold.
pub(crate) fn tile_span(index: u32, cell: u64, overlap: u64, extent: u32) -> (u64, u64) {
    let own = index as u64 * cell;
    let start = if index == 0 { own } else { own.saturating_sub(overlap) };
    (start, (own + cell + overlap).min(extent as u64))
}

/// The texels of page (lod, col, row) that its Deep Zoom tile keeps: the left (top) border
/// only where there is a tile to the left (above), and nothing past the image's edge.
pub(crate) fn crop(layout: &Layout, lod: u32, col: u32, row: u32) -> Crop {
    let (p, b) = (layout.payload() as u64, layout.border as u64);
    let (level_w, level_h) = layout.level_extent(lod);
    let axis = |index: u32, extent: u32| -> (u32, u32) {
        let (start, end) = tile_span(index, p, b, extent);
        ((start + b - index as u64 * p) as u32, (end - start) as u32)
    };
    let ((x, width), (y, height)) = (axis(col, level_w), axis(row, level_h));
    Crop { x, y, width, height }
}

/// The `.dzi` descriptor.
pub(crate) fn descriptor(layout: &Layout, extension: &str) -> String {
    format!(
        concat!(
            "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n",
            "<Image xmlns=\"http://schemas.microsoft.com/deepzoom/2008\" Format=\"{}\" Overlap=\"{}\" TileSize=\"{}\">\n",
            "  <Size Width=\"{}\" Height=\"{}\"/>\n",
            "</Image>\n"
        ),
        extension,
        layout.border,
        layout.payload(),
        layout.width,
        layout.height
    )
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn max_level_is_ceil_log2() {
        let cases = [(1, 0), (2, 1), (3, 2), (4, 2), (5, 3), (255, 8), (256, 8), (257, 9), (u32::MAX, 32)];
        for (side, level) in cases {
            assert_eq!(max_level(side, 1), level, "side {side}");
            assert_eq!(max_level(1, side), level, "side {side}");
        }
    }
    use crate::formats::viewer::Viewer;

    #[test]
    fn levels_go_down_to_one_texel() {
        assert_eq!(max_level(1, 1), 0);
        assert_eq!(max_level(700, 500), 10);
        assert_eq!(max_level(1024, 3), 10);
        assert_eq!(max_level(1025, 3), 11);
        let l = Viewer::Dzi.page_grid(700, 500, 254, 1).unwrap();
        assert_eq!(l.lod_count, 11);
        assert_eq!(level_of(&l, 0), 10);
        assert_eq!(l.level_extent(10), (1, 1));
    }

    #[test]
    fn edge_tiles_lose_the_overlap_they_have_no_neighbour_for() {
        // 700 x 500, tile 254, overlap 1: level 10 is 3 x 2 tiles (vips' 10/0_0 .. 10/2_1).
        let l = Viewer::Dzi.page_grid(700, 500, 254, 1).unwrap();
        assert_eq!(l.grid(0), (3, 2));
        assert_eq!(crop(&l, 0, 0, 0), Crop { x: 1, y: 1, width: 255, height: 255 });
        assert_eq!(crop(&l, 0, 1, 0), Crop { x: 0, y: 1, width: 256, height: 255 });
        // The last column starts at 508 - 1 and stops at 700: 193 wide.
        assert_eq!(crop(&l, 0, 2, 1), Crop { x: 0, y: 0, width: 193, height: 500 - 253 });
        // Level 9 (350 x 250): 2 x 1 tiles.
        assert_eq!(l.grid(1), (2, 1));
        assert_eq!(crop(&l, 1, 1, 0), Crop { x: 0, y: 1, width: 350 - 253, height: 250 });
        // Level 0: one texel.
        assert_eq!(crop(&l, 10, 0, 0), Crop { x: 1, y: 1, width: 1, height: 1 });
    }

    #[test]
    fn descriptor_names_size_tile_and_overlap() {
        let l = Viewer::Dzi.page_grid(700, 500, 254, 1).unwrap();
        let d = descriptor(&l, "jpeg");
        assert!(d.contains("Format=\"jpeg\" Overlap=\"1\" TileSize=\"254\""), "{d}");
        assert!(d.contains("<Size Width=\"700\" Height=\"500\"/>"), "{d}");
    }
}
