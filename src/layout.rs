//! Geometry of the virtual texture: how an image of `width x height` texels maps onto a grid
//! of pages at every LOD.
//!
//! Each axis has its own page count: LOD 0 has `ceil(w / P)` x `ceil(h / P)` pages (P the
//! payload), LOD k's image is `ceil(w / 2^k)` x `ceil(h / 2^k)` texels in
//! `ceil(w_k / P)` x `ceil(h_k / P)` pages, and the last LOD is the first with a single page.
//! Because nested ceilings compose (`ceil(ceil(n / P) / 2) = ceil(n / 2P)`), LOD k has
//! `ceil(pages_0 / 2^k)` pages per axis and page (x, y)'s parent is (x / 2, y / 2), as in a
//! square quadtree; only the pages that would lie wholly outside the image are gone.
//!
//! Every size is checked before it is multiplied, and everything that can exceed 2^32 is a
//! `u64`, so absurd headers are refused here instead of overflowing later.

use crate::error::TilerError;

/// Largest image side accepted. 2^24 keeps every pyramid sum of 16-bit samples inside a `u64`
/// (65535 * 4^24 < 2^64) and is far beyond what any image format here can describe.
pub const MAX_SIDE: u64 = 1 << 24;

/// LODs of a grid whose longer axis has `pages` pages at LOD 0: one per halving, down to the
/// first LOD of one page (`info.json` readers check `lodCount` with it too).
pub(crate) fn lods_for(pages: u32) -> u32 {
    pages.next_power_of_two().trailing_zeros() + 1
}

/// The page grid of a virtual texture: `columns` x `rows` pages at LOD 0, halving (rounding
/// up) per LOD down to one page; each stored page is `tile_size` texels per side, of which
/// `payload = tile_size - 2 * border` are its own and the rest copied from neighbours.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Layout {
    /// Width of the image at LOD 0 in texels, 1 to [`MAX_SIDE`].
    pub width: u32,
    /// Height of the image at LOD 0 in texels, 1 to [`MAX_SIDE`].
    pub height: u32,
    /// Side of every stored page in texels, borders included: 8 to 16384.
    pub tile_size: u32,
    /// Texels each page repeats from its neighbours on every side; the payload
    /// (`tile_size - 2 * border`) is at least 4.
    pub border: u32,
    /// Pages per row at LOD 0.
    pub columns: u32,
    /// Page rows at LOD 0.
    pub rows: u32,
    /// LODs in the pyramid, LOD 0 the finest, down to the first LOD of one page.
    pub lod_count: u32,
}

impl Layout {
    /// The page grid of a `width` x `height` image in `tile_size`-texel pages with `border`
    /// texels of border. Refuses ([`TilerError::Geometry`]) an empty image, a side above
    /// [`MAX_SIDE`], a tile size outside 8..=16384 and a payload under 4 texels.
    pub fn new(width: u64, height: u64, tile_size: u32, border: u32) -> Result<Layout, TilerError> {
        if width == 0 || height == 0 {
            return Err(TilerError::Geometry(format!("the image is {width}x{height}: it has no pixels")));
        }
        if width > MAX_SIDE || height > MAX_SIDE {
            return Err(TilerError::Geometry(format!(
                "the image is {width}x{height}: sides above {MAX_SIDE} are not supported"
            )));
        }
        if !(8..=16384).contains(&tile_size) {
            return Err(TilerError::Geometry(format!("tile size {tile_size} is outside 8..=16384")));
        }
        let payload = tile_size.checked_sub(2 * border).filter(|p| *p >= 4).ok_or_else(|| {
            TilerError::Geometry(format!(
                "border {border} leaves no room in a {tile_size}-texel tile (payload = tile size - 2 x border must be at least 4)"
            ))
        })?;
        // MAX_SIDE / 4 pages per axis at most: every count below fits a u32.
        let (columns, rows) = (width.div_ceil(payload as u64) as u32, height.div_ceil(payload as u64) as u32);
        let lod_count = lods_for(columns.max(rows));
        Ok(Layout { width: width as u32, height: height as u32, tile_size, border, columns, rows, lod_count })
    }

    /// The same grid with LODs on below one page until the image is one texel (Deep Zoom's
    /// levels): `ceil(log2(max(w, h))) + 1` LODs, the extra ones a single page each.
    pub fn down_to_one_texel(self) -> Layout {
        let lod_count = self.lod_count.max(lods_for(self.width.max(self.height)));
        Layout { lod_count, ..self }
    }

    /// Texels of a page that are its own (the stored tile minus the borders).
    pub fn payload(&self) -> u32 {
        self.tile_size - 2 * self.border
    }

    /// Pages per row and page rows at `lod`: `ceil(pages_0 / 2^lod)` per axis.
    pub fn grid(&self, lod: u32) -> (u32, u32) {
        let shrink = |pages: u32| (((pages as u64) + (1u64 << lod) - 1) >> lod) as u32;
        (shrink(self.columns), shrink(self.rows))
    }

    /// Width and height of the virtual texture at `lod` (its pages' payloads side by side), in
    /// texels: the real image plus the padding of the last page of each row and column.
    pub fn virtual_extent(&self, lod: u32) -> (u64, u64) {
        let (c, r) = self.grid(lod);
        (c as u64 * self.payload() as u64, r as u64 * self.payload() as u64)
    }

    /// The thesis's `tileCount` (pages per side of a square power-of-two grid), for the grids
    /// that are one; other grids have no such number.
    pub(crate) fn square_tile_count(&self) -> Option<u32> {
        (self.columns == self.rows && self.columns.is_power_of_two()).then_some(self.columns)
    }

    /// Width and height of the real image at `lod`: `ceil(size / 2^lod)`.
    pub fn level_extent(&self, lod: u32) -> (u32, u32) {
        let shrink = |v: u32| (((v as u64) + (1u64 << lod) - 1) >> lod) as u32;
        (shrink(self.width), shrink(self.height))
    }

    /// The pack's level table for this grid (docs/pack-format.md), LOD 0 first.
    pub(crate) fn pack_levels(&self) -> Vec<vortex_pack::Level> {
        (0..self.lod_count)
            .map(|lod| {
                let ((tiles_w, tiles_h), (width, height)) = (self.grid(lod), self.level_extent(lod));
                vortex_pack::Level::new(tiles_w, tiles_h, width, height)
            })
            .collect()
    }

    /// Number of stored tiles over all LODs.
    pub fn total_tiles(&self) -> u64 {
        (0..self.lod_count).map(|l| self.grid(l)).map(|(c, r)| c as u64 * r as u64).sum()
    }

    /// Texels of one stored tile.
    pub(crate) fn tile_texels(&self) -> usize {
        (self.tile_size as usize).pow(2)
    }
}

/// The part of a stored page that a viewer's tile keeps, in the page's texels.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Crop {
    /// Left edge of the kept part, in texels from the page's left (its border included).
    pub x: u32,
    /// Top edge of the kept part, in texels from the page's top.
    pub y: u32,
    /// Width of the kept part in texels.
    pub width: u32,
    /// Height of the kept part in texels.
    pub height: u32,
}

impl Crop {
    pub(crate) fn whole(side: u32) -> Crop {
        Crop { x: 0, y: 0, width: side, height: side }
    }
}

/// One level of a pyramid that keeps a slide's own levels (any downsample between them): its
/// image and its tiles' size, across by down. The right and bottom tiles reach past the image,
/// whole, as a TIFF stores them.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(crate) struct Level {
    pub width: u32,
    pub height: u32,
    pub tile: (u32, u32),
}

impl Level {
    /// Levels of a file that holds `copied` (a slide's own, any downsample) where there are
    /// any, else `layout`'s power-of-two levels.
    pub fn count(copied: &[Level], layout: &Layout) -> u32 {
        match copied.len() {
            0 => layout.lod_count,
            n => n as u32,
        }
    }

    /// Level `k` of such a file: `copied[k]`, else `layout`'s level `k` in its square tiles.
    pub fn of(copied: &[Level], layout: &Layout, k: u32) -> Level {
        match copied.get(k as usize) {
            Some(level) => *level,
            None => {
                let (width, height) = layout.level_extent(k);
                Level { width, height, tile: (layout.tile_size, layout.tile_size) }
            }
        }
    }

    /// Tiles across and down.
    pub fn grid(&self) -> (u32, u32) {
        (self.width.div_ceil(self.tile.0), self.height.div_ceil(self.tile.1))
    }

    /// Tiles in all.
    pub fn tiles(&self) -> u64 {
        let (c, r) = self.grid();
        u64::from(c) * u64::from(r)
    }
}

/// Which levels a pyramidal file holds (`--levels`: a TIFF's or a DICOM series').
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq, Hash)]
pub enum Levels {
    /// The slide's own levels, every stored JPEG tile copied as it is, where the source is a
    /// pyramid of JPEG tiles the output can hold; else our pyramid, saying why.
    #[default]
    Stored,
    /// Our exact power-of-two pyramid (the full resolution's stored tiles still copied where
    /// they fit).
    Pow2,
}

impl Levels {
    /// `--levels`' name.
    pub fn name(self) -> &'static str {
        match self {
            Levels::Stored => "stored",
            Levels::Pow2 => "pow2",
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use proptest::prelude::*;

    #[test]
    fn thesis_example() {
        // 65536^2 texels in 128-texel pages: 512 pages per side, 10 LODs.
        let l = Layout::new(65536, 65536, 128, 0).unwrap();
        assert_eq!((l.columns, l.rows, l.lod_count, l.square_tile_count()), (512, 512, 10, Some(512)));
        // id Tech 5 pages: 120 payload + 4 border; 65536 / 120 = 546.1 -> 547 pages, 11 LODs.
        let l = Layout::new(65536, 65536, 128, 4).unwrap();
        assert_eq!((l.payload(), l.columns, l.lod_count, l.square_tile_count()), (120, 547, 11, None));
        assert_eq!(l.grid(10), (1, 1));
    }

    #[test]
    fn grids_follow_the_image() {
        // The examples: 700 x 500 in 128-texel pages is 6 x 4 pages, not 8 x 8.
        let l = Layout::new(700, 500, 128, 0).unwrap();
        assert_eq!((l.grid(0), l.grid(1), l.grid(2), l.grid(3), l.lod_count), ((6, 4), (3, 2), (2, 1), (1, 1), 4));
        assert_eq!(l.total_tiles(), 24 + 6 + 2 + 1);
        // 16384 x 131072 in 256-texel pages: 64 x 512 pages at LOD 0 and 43,695 in all,
        // where the square grid had 349,525.
        let l = Layout::new(16384, 131072, 256, 0).unwrap();
        assert_eq!((l.columns, l.rows, l.lod_count), (64, 512, 10));
        assert_eq!(l.total_tiles(), 43_695);
        // 16,000,000 x 1: one page row at every LOD.
        let l = Layout::new(16_000_000, 1, 256, 0).unwrap();
        assert_eq!((l.columns, l.rows, l.lod_count), (62_500, 1, 17));
        assert_eq!(l.total_tiles(), 125_007);
    }

    #[test]
    fn one_pixel_is_one_page() {
        let l = Layout::new(1, 1, 128, 4).unwrap();
        assert_eq!((l.columns, l.rows, l.lod_count, l.total_tiles()), (1, 1, 1, 1));
        assert_eq!(l.level_extent(0), (1, 1));
    }

    #[test]
    fn deep_zoom_levels_go_on_to_one_texel() {
        let l = Layout::new(700, 500, 256, 1).unwrap().down_to_one_texel();
        assert_eq!((l.lod_count, l.grid(10), l.level_extent(9), l.level_extent(10)), (11, (1, 1), (2, 1), (1, 1)));
        assert_eq!(l.total_tiles(), 6 + 2 + 1 + 8);
        let one = Layout::new(1, 1, 8, 0).unwrap().down_to_one_texel();
        assert_eq!(one.lod_count, 1);
    }

    #[test]
    fn refuses_degenerate_inputs() {
        assert!(Layout::new(0, 5, 128, 0).is_err());
        assert!(Layout::new(5, 0, 128, 0).is_err());
        assert!(Layout::new(MAX_SIDE + 1, 1, 128, 0).is_err());
        assert!(Layout::new(10, 10, 128, 63).is_err());
        assert!(Layout::new(10, 10, 128, 65).is_err());
        assert!(Layout::new(10, 10, 4, 0).is_err());
    }

    #[test]
    fn largest_side_has_no_overflow() {
        let l = Layout::new(MAX_SIDE, MAX_SIDE, 8, 2).unwrap();
        assert_eq!(l.payload(), 4);
        assert_eq!((l.columns, l.square_tile_count()), (1 << 22, Some(1 << 22)));
        assert_eq!(l.virtual_extent(0), (1 << 24, 1 << 24));
        assert!(l.total_tiles() > u32::MAX as u64);
    }

    proptest! {
        #[test]
        fn grid_covers_image_and_nothing_more(w in 1u64..100_000, h in 1u64..100_000, tile in 8u32..600, b in 0u32..8) {
            prop_assume!(tile >= 2 * b + 4);
            let l = Layout::new(w, h, tile, b).unwrap();
            let p = l.payload() as u64;
            for lod in 0..l.lod_count {
                let (c, r) = l.grid(lod);
                let (lw, lh) = l.level_extent(lod);
                // Every page holds some of the image, and the pages hold all of it.
                prop_assert_eq!((c as u64, r as u64), ((lw as u64).div_ceil(p), (lh as u64).div_ceil(p)));
                // The quadtree: a level's pages are its parents' children.
                if lod > 0 {
                    let (pc, pr) = l.grid(lod - 1);
                    prop_assert_eq!((c, r), (pc.div_ceil(2), pr.div_ceil(2)));
                }
            }
            let last = l.lod_count - 1;
            prop_assert_eq!(l.grid(last), (1, 1));
            // The last LOD is the first with a single page.
            prop_assert!(last == 0 || l.grid(last - 1) != (1, 1));
        }
    }
}
