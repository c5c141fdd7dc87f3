//! Page addressing: which page of which virtual texture, at which LOD, and the page grid of a
//! texture. Runs on any thread.
//!
//! A grid is rectangular: LOD 0 has `w x h` pages (`ceil(width / payload)` by
//! `ceil(height / payload)` for an image of `width x height` texels) and each coarser LOD has
//! `ceil(n / 2)` pages per axis of the one finer, down to the first LOD where both axes have a
//! single page. The image is anchored at the top-left at every LOD (LOD k texel `c` covers LOD-0
//! texels `[c 2^k, (c + 1) 2^k)`), so the parent of page `(x, y)` is `(x / 2, y / 2)` whatever the
//! sizes, and the last page of a row or column may hold padding beyond the image.
//!
//! The limits come from the feedback word (see `feedback`): up to 16 textures, LODs 0 to 14 (15
//! means "no request", so at most 2^14 pages along either axis), and at most 2^24 pages at LOD 0
//! (the word's page index), whatever the aspect ratio.

/// Most virtual textures a scene can use at once (4 bits of the feedback word).
pub const MAX_TEXTURES: u8 = 16;
/// Most LODs of one texture (LOD 15 is the feedback word's "no request").
pub const MAX_LODS: u8 = 15;
/// Most pages along either axis at LOD 0: a grid of 2^14 pages has [`MAX_LODS`] LODs.
pub const MAX_PAGES_PER_AXIS: u32 = 1 << (MAX_LODS - 1);
/// Most pages at LOD 0 of one texture: the 24-bit page index of the feedback word.
pub const MAX_PAGES_AT_LOD0: u64 = 1 << 24;

/// One page of one virtual texture.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct PageId {
    /// The virtual texture, an index of the runtime's textures.
    pub texture: u8,
    /// The level, 0 the finest.
    pub lod: u8,
    /// The column of pages in that level.
    pub x: u16,
    /// The row of pages in that level.
    pub y: u16,
}

impl PageId {
    /// The page (`texture`, `lod`, `x`, `y`).
    pub const fn new(texture: u8, lod: u8, x: u16, y: u16) -> PageId {
        PageId { texture, lod, x, y }
    }

    /// The page one LOD coarser that covers this one, if any.
    pub fn parent(self, grid: &TextureGrid) -> Option<PageId> {
        (self.lod + 1 < grid.lod_count).then(|| PageId { lod: self.lod + 1, x: self.x / 2, y: self.y / 2, ..self })
    }

    /// This page and every coarser page covering it, finest first.
    pub fn ancestors_and_self(self, grid: &TextureGrid) -> impl Iterator<Item = PageId> + '_ {
        std::iter::successors(Some(self), move |p| p.parent(grid))
    }
}

/// Why a page grid cannot be made.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum GridError {
    /// An axis has no page.
    #[error("a grid of {w}x{h} pages: each axis needs at least one page")]
    Empty {
        /// Pages across at LOD 0.
        w: u64,
        /// Pages down at LOD 0.
        h: u64,
    },
    /// An axis has more pages than the feedback word's LODs can halve down to one.
    #[error(
        "{w}x{h} pages at LOD 0: at most {MAX_PAGES_PER_AXIS} along each axis (the feedback word's {MAX_LODS} LODs)"
    )]
    TooWide {
        /// Pages across at LOD 0.
        w: u64,
        /// Pages down at LOD 0.
        h: u64,
    },
    /// More pages at LOD 0 than the feedback word's page index can name.
    #[error("{w}x{h} pages at LOD 0: at most {MAX_PAGES_AT_LOD0} in all (the feedback word's 24-bit page index)")]
    TooManyPages {
        /// Pages across at LOD 0.
        w: u64,
        /// Pages down at LOD 0.
        h: u64,
    },
    /// Pages whose payload (tile size less its borders) has no texel.
    #[error("a {payload}-texel payload: pages need at least one texel")]
    NoPayload {
        /// The payload's side in texels.
        payload: u32,
    },
    /// A level is not the previous one halved, rounded up.
    #[error("level {lod} has {found:?} pages; halving level {} ({:?}) gives {expected:?}", .lod - 1, .previous)]
    NotHalving {
        /// The level.
        lod: u8,
        /// Its pages across and down.
        found: [u32; 2],
        /// The previous level's.
        previous: [u32; 2],
        /// What halving those gives.
        expected: [u32; 2],
    },
    /// The levels stop before one page.
    #[error("{levels} levels; a grid of {w}x{h} pages at LOD 0 needs {needed} (down to one page)")]
    TooFewLevels {
        /// Levels given.
        levels: usize,
        /// Pages across at LOD 0.
        w: u16,
        /// Pages down at LOD 0.
        h: u16,
        /// Levels needed.
        needed: u8,
    },
}

/// The page grid of one virtual texture: `w x h` pages at LOD 0, halving (rounded up) per LOD
/// down to one page (see the module documentation). Made only through its constructors, which
/// check the feedback word's limits, so every grid can be addressed by it.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TextureGrid {
    pages: [u16; 2],
    lod_count: u8,
}

impl TextureGrid {
    /// The grid of `w x h` pages at LOD 0.
    pub fn new(w: u32, h: u32) -> Result<TextureGrid, GridError> {
        let (w64, h64) = (u64::from(w), u64::from(h));
        if w == 0 || h == 0 {
            return Err(GridError::Empty { w: w64, h: h64 });
        }
        if w > MAX_PAGES_PER_AXIS || h > MAX_PAGES_PER_AXIS {
            return Err(GridError::TooWide { w: w64, h: h64 });
        }
        if w64 * h64 > MAX_PAGES_AT_LOD0 {
            return Err(GridError::TooManyPages { w: w64, h: h64 });
        }
        // The first LOD with one page along the longer axis: ceil(log2(max)) halvings.
        let lod_count = (32 - (w.max(h) - 1).leading_zeros()) as u8 + 1;
        Ok(TextureGrid { pages: [w as u16, h as u16], lod_count })
    }

    /// The grid of an image of `width x height` texels cut into pages of `payload` texels per
    /// side: `ceil(width / payload) x ceil(height / payload)` pages at LOD 0.
    pub fn for_image(width: u32, height: u32, payload: u32) -> Result<TextureGrid, GridError> {
        if payload == 0 {
            return Err(GridError::NoPayload { payload });
        }
        let (w, h) = (width.div_ceil(payload), height.div_ceil(payload));
        TextureGrid::new(w, h)
    }

    /// The grid a pack's level table describes (tiles per row and per column of each level,
    /// LOD 0 first). Each level must be the previous one halved, rounded up, down to one page;
    /// levels past that one page are ignored (older packs may hold a few).
    pub fn from_levels(levels: impl IntoIterator<Item = [u32; 2]>) -> Result<TextureGrid, GridError> {
        let mut levels = levels.into_iter();
        let Some([w, h]) = levels.next() else {
            return Err(GridError::Empty { w: 0, h: 0 });
        };
        let grid = TextureGrid::new(w, h)?;
        let mut previous = [w, h];
        let mut count = 1;
        for (lod, found) in (1..grid.lod_count).zip(levels) {
            let expected = grid.pages_at(lod).map(u32::from);
            if found != expected {
                return Err(GridError::NotHalving { lod, found, previous, expected });
            }
            previous = found;
            count += 1;
        }
        if count < grid.lod_count as usize {
            let [w, h] = grid.pages;
            return Err(GridError::TooFewLevels { levels: count, w, h, needed: grid.lod_count });
        }
        Ok(grid)
    }

    /// Pages per row and per column at LOD 0.
    pub fn pages(&self) -> [u16; 2] {
        self.pages
    }

    /// LODs, finest (0) to the single root page (`lod_count - 1`).
    pub fn lod_count(&self) -> u8 {
        self.lod_count
    }

    /// Pages per row and per column at `lod`: LOD 0's halved `lod` times, rounded up (1 from the
    /// root on).
    pub fn pages_at(&self, lod: u8) -> [u16; 2] {
        let lod = u32::from(lod).min(15);
        self.pages.map(|n| ((n - 1) >> lod) + 1)
    }

    /// Pages of one LOD.
    pub fn level_len(&self, lod: u8) -> usize {
        let [w, h] = self.pages_at(lod);
        w as usize * h as usize
    }

    /// The single page of the coarsest LOD (always resident: the fallback of last resort).
    pub fn root(&self, texture: u8) -> PageId {
        PageId::new(texture, self.lod_count - 1, 0, 0)
    }

    /// Whether `p` lies in this grid (its LOD below `lod_count`, its page inside that level).
    pub fn contains(&self, p: PageId) -> bool {
        let [w, h] = self.pages_at(p.lod);
        p.lod < self.lod_count && p.x < w && p.y < h
    }

    /// Position of page (`x`, `y`) of `lod` in its level, row by row: the feedback word's page
    /// index. The page must be in the grid.
    pub fn index(&self, lod: u8, x: u16, y: u16) -> u32 {
        u32::from(y) * u32::from(self.pages_at(lod)[0]) + u32::from(x)
    }

    /// The page at `index` of `lod` (row by row), or `None` outside the grid.
    pub fn page_at_index(&self, texture: u8, lod: u8, index: u32) -> Option<PageId> {
        let [w, h] = self.pages_at(lod).map(u32::from);
        (lod < self.lod_count && index < w * h)
            .then(|| PageId::new(texture, lod, (index % w) as u16, (index / w) as u16))
    }

    /// Pages over all LODs.
    pub fn page_count(&self) -> u64 {
        (0..self.lod_count).map(|l| self.level_len(l) as u64).sum()
    }
}

#[cfg(test)]
mod tests {
    use proptest::prelude::*;

    use super::*;

    #[test]
    fn ancestors_end_at_the_root() {
        let g = TextureGrid::new(512, 512).unwrap();
        assert_eq!(g.lod_count, 10);
        let p = PageId::new(3, 0, 511, 300);
        let chain: Vec<PageId> = p.ancestors_and_self(&g).collect();
        assert_eq!(chain.len(), 10);
        assert_eq!(*chain.last().unwrap(), g.root(3));
        assert_eq!(chain[1], PageId::new(3, 1, 255, 150));
        assert!(chain.iter().all(|c| g.contains(*c)));
    }

    #[test]
    fn rectangular_grids_halve_rounding_up() {
        // 2^20 x 2^10 texels in 120-texel pages.
        let g = TextureGrid::for_image(1 << 20, 1 << 10, 120).unwrap();
        assert_eq!(g.pages(), [8739, 9]);
        assert_eq!(g.lod_count(), 15);
        assert_eq!(g.pages_at(1), [4370, 5]);
        assert_eq!(g.pages_at(4), [547, 1]);
        assert_eq!(g.pages_at(14), [1, 1]);
        let p = PageId::new(0, 0, 8738, 8);
        assert!(g.contains(p) && !g.contains(PageId::new(0, 0, 8739, 0)) && !g.contains(PageId::new(0, 1, 0, 5)));
        assert!(p.ancestors_and_self(&g).all(|q| g.contains(q)));
        assert_eq!(p.ancestors_and_self(&g).last(), Some(g.root(0)));
        // Tall, odd, and one page.
        let g = TextureGrid::new(5, 13).unwrap();
        assert_eq!(
            (0..g.lod_count()).map(|l| g.pages_at(l)).collect::<Vec<_>>(),
            [[5, 13], [3, 7], [2, 4], [1, 2], [1, 1]]
        );
        assert_eq!(g.page_count(), 65 + 21 + 8 + 2 + 1);
        assert_eq!(TextureGrid::new(1, 1).unwrap().lod_count(), 1);
        assert_eq!(g.index(1, 2, 3), 11);
        assert_eq!(g.page_at_index(2, 1, 11), Some(PageId::new(2, 1, 2, 3)));
        assert_eq!(g.page_at_index(2, 1, 21), None);
        assert_eq!(g.page_at_index(2, 5, 0), None);
    }

    #[test]
    fn limits_are_typed_errors() {
        assert_eq!(TextureGrid::new(0, 4), Err(GridError::Empty { w: 0, h: 4 }));
        assert_eq!(TextureGrid::new(1 << 14, 1).unwrap().lod_count(), MAX_LODS);
        assert_eq!(TextureGrid::new((1 << 14) + 1, 1), Err(GridError::TooWide { w: (1 << 14) + 1, h: 1 }));
        assert_eq!(TextureGrid::new(1 << 14, 1 << 10).unwrap().level_len(0), 1 << 24);
        assert_eq!(TextureGrid::new(1 << 14, 1025), Err(GridError::TooManyPages { w: 1 << 14, h: 1025 }));
        assert_eq!(TextureGrid::for_image(10, 10, 0), Err(GridError::NoPayload { payload: 0 }));
        // 2^20 texels wide in 56-texel pages: 18725 pages, 16 LODs.
        assert!(matches!(TextureGrid::for_image(1 << 20, 64, 56), Err(GridError::TooWide { .. })));
    }

    #[test]
    fn level_tables_must_halve() {
        let g = TextureGrid::from_levels([[5, 13], [3, 7], [2, 4], [1, 2], [1, 1]]).unwrap();
        assert_eq!(g, TextureGrid::new(5, 13).unwrap());
        // An old square pack: power-of-two levels, and a level past the root is ignored.
        let old = TextureGrid::from_levels([[8, 8], [4, 4], [2, 2], [1, 1], [1, 1]]).unwrap();
        assert_eq!(old, TextureGrid::new(8, 8).unwrap());
        assert_eq!(
            TextureGrid::from_levels([[5, 13], [2, 7], [1, 4], [1, 2], [1, 1]]),
            Err(GridError::NotHalving { lod: 1, found: [2, 7], previous: [5, 13], expected: [3, 7] })
        );
        assert_eq!(
            TextureGrid::from_levels([[5, 13], [3, 7]]),
            Err(GridError::TooFewLevels { levels: 2, w: 5, h: 13, needed: 5 })
        );
        assert_eq!(TextureGrid::from_levels([]), Err(GridError::Empty { w: 0, h: 0 }));
        let message = TextureGrid::from_levels([[4, 4], [2, 1]]).unwrap_err().to_string();
        assert_eq!(message, "level 1 has [2, 1] pages; halving level 0 ([4, 4]) gives [2, 2]");
    }

    proptest! {
        #[test]
        fn parents_are_in_the_grid_and_levels_halve(w in 1u32..3000, h in 1u32..3000, x in any::<u16>(), y in any::<u16>()) {
            let g = TextureGrid::new(w, h).unwrap();
            let [pw, ph] = g.pages_at(g.lod_count() - 1);
            prop_assert_eq!([pw, ph], [1, 1]);
            if g.lod_count() > 1 {
                prop_assert!(g.pages_at(g.lod_count() - 2) != [1, 1], "the root is the first single page");
            }
            for lod in 1..g.lod_count() {
                let (fine, coarse) = (g.pages_at(lod - 1), g.pages_at(lod));
                prop_assert_eq!(coarse, fine.map(|n| n.div_ceil(2)));
            }
            let p = PageId::new(0, 0, x % w as u16, y % h as u16);
            for q in p.ancestors_and_self(&g) {
                prop_assert!(g.contains(q));
                prop_assert_eq!(g.page_at_index(0, q.lod, g.index(q.lod, q.x, q.y)), Some(q));
            }
        }
    }
}
