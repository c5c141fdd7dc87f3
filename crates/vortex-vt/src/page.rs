//! Page addressing: which page of which virtual texture, at which LOD. Runs on any thread.
//!
//! The limits come from the feedback word (see `feedback`): up to 16 textures, LODs 0 to 14
//! (15 means "no request"), and 4096 pages per side at LOD 0.

/// Most virtual textures a scene can use at once (4 bits of the feedback word).
pub const MAX_TEXTURES: u8 = 16;
/// Most LODs of one texture (LOD 15 is the feedback word's "no request").
pub const MAX_LODS: u8 = 15;
/// Most pages per side at LOD 0 (12 bits of x and y in the feedback word).
pub const MAX_PAGES_PER_SIDE: u16 = 4096;

/// One page of one virtual texture.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash, PartialOrd, Ord)]
pub struct PageId {
    pub texture: u8,
    pub lod: u8,
    pub x: u16,
    pub y: u16,
}

impl PageId {
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

/// The page grid of one virtual texture: square, a power of two per side, halving per LOD down
/// to one page (the tiler's layout).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct TextureGrid {
    /// Pages per side at LOD 0.
    pub pages: u16,
    pub lod_count: u8,
}

impl TextureGrid {
    /// The grid of `pages` per side at LOD 0 (a power of two up to 4096).
    pub fn new(pages: u16) -> Option<TextureGrid> {
        (pages.is_power_of_two() && pages <= MAX_PAGES_PER_SIDE)
            .then(|| TextureGrid { pages, lod_count: pages.trailing_zeros() as u8 + 1 })
    }

    pub fn pages_per_side(&self, lod: u8) -> u16 {
        self.pages >> lod
    }

    /// The single page of the coarsest LOD (always resident: the fallback of last resort).
    pub fn root(&self, texture: u8) -> PageId {
        PageId::new(texture, self.lod_count - 1, 0, 0)
    }

    pub fn contains(&self, p: PageId) -> bool {
        p.lod < self.lod_count && p.x < self.pages_per_side(p.lod) && p.y < self.pages_per_side(p.lod)
    }

    /// Pages over all LODs.
    pub fn page_count(&self) -> u64 {
        (0..self.lod_count).map(|l| (self.pages_per_side(l) as u64).pow(2)).sum()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn ancestors_end_at_the_root() {
        let g = TextureGrid::new(512).unwrap();
        assert_eq!(g.lod_count, 10);
        let p = PageId::new(3, 0, 511, 300);
        let chain: Vec<PageId> = p.ancestors_and_self(&g).collect();
        assert_eq!(chain.len(), 10);
        assert_eq!(*chain.last().unwrap(), g.root(3));
        assert_eq!(chain[1], PageId::new(3, 1, 255, 150));
        assert!(chain.iter().all(|c| g.contains(*c)));
        assert!(TextureGrid::new(8192).is_none() && TextureGrid::new(100).is_none());
    }
}
