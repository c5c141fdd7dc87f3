//! Geometry of the virtual texture: how an image of `width x height` texels maps onto a
//! square, power-of-two grid of pages at every LOD.
//!
//! Every size is checked before it is multiplied, and everything that can exceed 2^32 is a
//! `u64`, so absurd headers are refused here instead of overflowing later.

use crate::error::TilerError;

/// Largest image side accepted. 2^24 keeps every pyramid sum of 16-bit samples inside a `u64`
/// (65535 * 4^24 < 2^64) and is far beyond what any image format here can describe.
pub const MAX_SIDE: u64 = 1 << 24;

/// The page grid of a virtual texture (the thesis's layout): `tile_count` pages per side at
/// LOD 0, halving per LOD down to one page; each stored page is `tile_size` texels per side,
/// of which `payload = tile_size - 2 * border` are its own and the rest copied from neighbours.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Layout {
    pub width: u32,
    pub height: u32,
    pub tile_size: u32,
    pub border: u32,
    pub tile_count: u32,
    pub lod_count: u32,
}

impl Layout {
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
        let pages = width.max(height).div_ceil(payload as u64);
        let tile_count = pages.next_power_of_two();
        let lod_count = tile_count.trailing_zeros() + 1;
        Ok(Layout {
            width: width as u32,
            height: height as u32,
            tile_size,
            border,
            tile_count: u32::try_from(tile_count)
                .map_err(|_| TilerError::Geometry(format!("{tile_count} pages per side do not fit the page grid")))?,
            lod_count,
        })
    }

    /// Texels of a page that are its own (the stored tile minus the borders).
    pub fn payload(&self) -> u32 {
        self.tile_size - 2 * self.border
    }

    /// Pages per side at `lod`.
    pub fn tiles_per_side(&self, lod: u32) -> u32 {
        self.tile_count >> lod
    }

    /// Side of the (square, padded) virtual texture at `lod`, in texels.
    pub fn virtual_side(&self, lod: u32) -> u64 {
        self.tiles_per_side(lod) as u64 * self.payload() as u64
    }

    /// Width and height of the real image at `lod`: `ceil(size / 2^lod)`.
    pub fn level_extent(&self, lod: u32) -> (u32, u32) {
        let shrink = |v: u32| (((v as u64) + (1u64 << lod) - 1) >> lod) as u32;
        (shrink(self.width), shrink(self.height))
    }

    /// Number of stored tiles over all LODs.
    pub fn total_tiles(&self) -> u64 {
        (0..self.lod_count).map(|l| (self.tiles_per_side(l) as u64).pow(2)).sum()
    }

    /// Texels of one stored tile.
    pub fn tile_texels(&self) -> usize {
        (self.tile_size as usize).pow(2)
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
        assert_eq!((l.tile_count, l.lod_count), (512, 10));
        // id Tech 5 pages: 120 payload + 4 border; 65536 / 120 = 546.1 -> 547 -> 1024.
        let l = Layout::new(65536, 65536, 128, 4).unwrap();
        assert_eq!((l.payload(), l.tile_count, l.lod_count), (120, 1024, 11));
    }

    #[test]
    fn one_pixel_is_one_page() {
        let l = Layout::new(1, 1, 128, 4).unwrap();
        assert_eq!((l.tile_count, l.lod_count, l.total_tiles()), (1, 1, 1));
        assert_eq!(l.level_extent(0), (1, 1));
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
        assert_eq!(l.tile_count, 1 << 22);
        assert_eq!(l.virtual_side(0), 1 << 24);
        assert!(l.total_tiles() > u32::MAX as u64);
    }

    proptest! {
        #[test]
        fn grid_covers_image(w in 1u64..100_000, h in 1u64..100_000, tile in 8u32..600, b in 0u32..8) {
            prop_assume!(tile >= 2 * b + 4);
            let l = Layout::new(w, h, tile, b).unwrap();
            prop_assert!(l.tile_count.is_power_of_two());
            prop_assert!(l.virtual_side(0) >= w.max(h));
            // Half the grid would not cover the image (the count is the smallest power of two).
            prop_assert!(l.tile_count == 1 || (l.tile_count as u64 / 2) * (l.payload() as u64) < w.max(h));
            let last = l.lod_count - 1;
            prop_assert_eq!(l.tiles_per_side(last), 1);
            let (lw, lh) = l.level_extent(last);
            prop_assert!(lw as u64 <= l.payload() as u64 && lh as u64 <= l.payload() as u64);
        }
    }
}
