//! The page table (indirection table): for each texture and each LOD a `w x h` grid of entries,
//! one per page of that LOD (`TextureGrid::pages_at`), row by row. The entry of a page points at the finest resident
//! ancestor-or-self of that page, so a missing page falls back to its nearest resident coarser page.
//!
//! The table is updated incrementally from each [`FrameUpdate`] ([`PageTable::apply`]): a load
//! rewrites the entries of the loaded page's quad-tree that pointed at something coarser, stopping at
//! subtrees covered by a finer resident page; an eviction rewrites the entries that pointed at the
//! evicted page to what its parent's entry points at. The cost is proportional to the entries that
//! change (each visited entry changes; the walk also looks at the four children of each), never to
//! the table size, and the returned [`Change`]s are exactly the entries whose value changed, to be
//! uploaded to the GPU. [`PageTable::rebuild`] builds the same table from scratch (the test oracle).
//!
//! # Packing for the GPU
//!
//! [`Entry::pack`] packs an entry into a `u32` of the GPU's table (`vortex-vt-wgpu`'s `page_table`: a
//! storage buffer laid out as this table, texture by texture, LOD by LOD, row by row), given the cache's slots per row `cache_side` (at most 256; slot `s` sits at
//! `(s % cache_side, s / cache_side)` in the physical cache texture):
//!
//! | bits  | field                                  |
//! |-------|----------------------------------------|
//! | 0-7   | slot column in the cache grid          |
//! | 8-15  | slot row in the cache grid             |
//! | 16-23 | LOD of the page the entry points at    |
//! | 24-31 | 0                                      |
//!
//! An unmapped entry (only before the first update has pinned the roots) packs to `0xFFFF_FFFF`
//! ([`UNMAPPED_WORD`]). In WGSL, with `base` the index of the LOD's entry (0, 0), `row` its pages
//! per row and `at` the sample's address (`vortex_vt::address`):
//!
//! ```wgsl
//! let word = page_table[base + at.page.y * row + at.page.x];
//! let slot = vec2<f32>(f32(word & 0xffu), f32((word >> 8u) & 0xffu));
//! let page_lod = (word >> 16u) & 0xffu;
//! let within = ancestor(at, page_lod - lod, payload).within; // inside the page it points at
//! ```

use crate::page::{MAX_LODS, PageId, TextureGrid};
use crate::residency::{FrameUpdate, Slot};

/// What a page-table entry points at: the slot of a resident page and that page's LOD.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub struct Entry {
    /// The slot of the physical cache holding the page.
    pub slot: Slot,
    /// The LOD of that page (`u8::MAX`: unmapped).
    pub lod: u8,
}

/// [`Entry::UNMAPPED`] packed.
pub const UNMAPPED_WORD: u32 = u32::MAX;

impl Entry {
    /// Points at nothing: the entries of a texture whose root is not resident yet.
    pub const UNMAPPED: Entry = Entry { slot: Slot::MAX, lod: u8::MAX };

    /// Whether it points at a slot.
    pub fn is_mapped(self) -> bool {
        self.lod != u8::MAX
    }

    /// The `u32` the shader reads (see the module documentation), for a cache of `cache_side` slots
    /// per row. Panics if `cache_side` is 0 or over 256, or the slot's row is over 255.
    pub fn pack(self, cache_side: u16) -> u32 {
        if !self.is_mapped() {
            return UNMAPPED_WORD;
        }
        assert!((1..=256).contains(&cache_side), "cache side {cache_side} must be 1..=256");
        let (x, y) = (self.slot % cache_side, self.slot / cache_side);
        assert!(y < 256, "slot {} is past row 255 of a {cache_side}-wide cache", self.slot);
        x as u32 | (y as u32) << 8 | (self.lod as u32) << 16
    }

    /// The inverse of [`Entry::pack`].
    pub fn unpack(word: u32, cache_side: u16) -> Entry {
        if word == UNMAPPED_WORD {
            return Entry::UNMAPPED;
        }
        let (x, y) = ((word & 0xff) as u16, (word >> 8 & 0xff) as u16);
        Entry { slot: y * cache_side + x, lod: (word >> 16 & 0xff) as u8 }
    }
}

/// One entry whose value changed: the entry of page `at` (texture, LOD, x, y) is now `entry`.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct Change {
    /// The page whose entry changed.
    pub at: PageId,
    /// Its new entry.
    pub entry: Entry,
}

/// The page tables of the textures of one residency (texture `i` has grid `grids[i]`).
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PageTable {
    grids: Vec<TextureGrid>,
    entries: Vec<Entry>,
    /// Index in `entries` of entry (0, 0) of each texture's each LOD.
    base: Vec<[usize; MAX_LODS as usize]>,
    /// One bit per entry: written during the current `apply_mappings` (all clear between calls).
    written: Vec<u64>,
}

/// An entry written during one `apply_mappings`, with its value before the call.
struct Touched {
    at: PageId,
    index: usize,
    old: Entry,
}

impl PageTable {
    /// A table with every entry [unmapped](Entry::UNMAPPED): the state before the first update.
    pub fn new(grids: &[TextureGrid]) -> PageTable {
        let mut base = Vec::with_capacity(grids.len());
        let mut len = 0;
        for g in grids {
            let mut b = [0; MAX_LODS as usize];
            for lod in 0..g.lod_count() {
                b[lod as usize] = len;
                len += g.level_len(lod);
            }
            base.push(b);
        }
        PageTable {
            grids: grids.to_vec(),
            entries: vec![Entry::UNMAPPED; len],
            base,
            written: vec![0; len.div_ceil(64)],
        }
    }

    /// The table for the resident pages `resident` (page, slot), built from scratch: every entry
    /// from its own page if resident, else from its parent's entry, coarse LODs first.
    pub fn rebuild(grids: &[TextureGrid], resident: impl IntoIterator<Item = (PageId, Slot)>) -> PageTable {
        let mut table = PageTable::new(grids);
        for (p, slot) in resident {
            let i = table.index(p);
            table.entries[i] = Entry { slot, lod: p.lod };
        }
        for (t, g) in grids.iter().enumerate() {
            for lod in (0..g.lod_count().saturating_sub(1)).rev() {
                let [w, h] = g.pages_at(lod).map(usize::from);
                let parent_w = usize::from(g.pages_at(lod + 1)[0]);
                let (base, parent_base) = (table.base[t][lod as usize], table.base[t][lod as usize + 1]);
                for y in 0..h {
                    for x in 0..w {
                        let i = base + y * w + x;
                        if table.entries[i].lod != lod {
                            table.entries[i] = table.entries[parent_base + (y / 2) * parent_w + x / 2];
                        }
                    }
                }
            }
        }
        table
    }

    /// The grids of the textures, by texture id.
    pub fn grids(&self) -> &[TextureGrid] {
        &self.grids
    }

    /// The entry of page (`texture`, `lod`, `x`, `y`). Panics outside the grids.
    pub fn entry(&self, texture: u8, lod: u8, x: u16, y: u16) -> Entry {
        self.entries[self.index(PageId::new(texture, lod, x, y))]
    }

    /// The entry of `page`. Panics outside the grids.
    pub fn get(&self, page: PageId) -> Entry {
        self.entries[self.index(page)]
    }

    /// The entries of one LOD of one texture, row by row.
    pub fn level(&self, texture: u8, lod: u8) -> &[Entry] {
        let g = self.grid(texture);
        assert!(lod < g.lod_count(), "LOD {lod} of a texture of {} LODs", g.lod_count());
        let start = self.base[texture as usize][lod as usize];
        &self.entries[start..start + g.level_len(lod)]
    }

    /// One LOD of one texture packed for the GPU (the whole-level upload of the first frame).
    pub fn packed_level(&self, texture: u8, lod: u8, cache_side: u16) -> Vec<u32> {
        self.level(texture, lod).iter().map(|e| e.pack(cache_side)).collect()
    }

    /// Applies one frame's evictions then loads; returns the entries whose value changed.
    pub fn apply(&mut self, update: &FrameUpdate) -> Vec<Change> {
        self.apply_mappings(&update.evictions, &update.loads)
    }

    /// Unmaps `evictions` (pages resident in this table, with the slot they had), in order, then
    /// maps `loads` (page, slot), in order. Returns the entries whose final value differs from their
    /// value before the call, each once, in the order they were first written.
    pub fn apply_mappings(&mut self, evictions: &[(PageId, Slot)], loads: &[(PageId, Slot)]) -> Vec<Change> {
        let mut touched = Vec::new();
        let mut stack = Vec::new();
        for &(p, slot) in evictions {
            debug_assert_eq!(self.get(p), Entry { slot, lod: p.lod }, "evicting {p:?}, which is not mapped there");
            let fallback = match p.parent(&self.grid(p.texture)) {
                Some(q) => self.get(q),
                None => Entry::UNMAPPED,
            };
            self.fill(p, fallback, &mut touched, &mut stack);
        }
        for &(p, slot) in loads {
            self.fill(p, Entry { slot, lod: p.lod }, &mut touched, &mut stack);
        }
        // `touched` holds each written entry once, with its value before the call: clear the marks,
        // and drop the entries that came back to where they began.
        touched
            .into_iter()
            .filter_map(|Touched { at, index, old }| {
                self.written[index / 64] &= !(1 << (index % 64));
                let entry = self.entries[index];
                (entry != old).then_some(Change { at, entry })
            })
            .collect()
    }

    /// Writes entry `index` (of page `at`), recording its old value on its first write of the call.
    fn write(&mut self, at: PageId, index: usize, value: Entry, touched: &mut Vec<Touched>) {
        let (word, bit) = (index / 64, 1 << (index % 64));
        if self.written[word] & bit == 0 {
            self.written[word] |= bit;
            touched.push(Touched { at, index, old: self.entries[index] });
        }
        self.entries[index] = value;
    }

    /// Sets `start`'s entry and those of its descendants not covered by a finer resident page to
    /// `value`, recording (page, old value) of each entry written. A resident child (its entry points
    /// at its own LOD) covers its subtree; a child already equal to `value` has a subtree equal to it
    /// too wherever not covered, so both stop the walk.
    fn fill(&mut self, start: PageId, value: Entry, touched: &mut Vec<Touched>, stack: &mut Vec<PageId>) {
        let i = self.index(start);
        if self.entries[i] == value {
            return;
        }
        self.write(start, i, value, touched);
        stack.clear();
        stack.push(start);
        while let Some(p) = stack.pop() {
            if p.lod == 0 {
                continue;
            }
            let lod = p.lod - 1;
            let [w, h] = self.grids[p.texture as usize].pages_at(lod);
            let base = self.base[p.texture as usize][lod as usize];
            for (dx, dy) in [(0, 0), (1, 0), (0, 1), (1, 1)] {
                let (x, y) = (2 * p.x + dx, 2 * p.y + dy);
                // The last page of an odd row or column has one child along that axis.
                if x >= w || y >= h {
                    continue;
                }
                let i = base + y as usize * w as usize + x as usize;
                let old = self.entries[i];
                if old.lod == lod || old == value {
                    continue;
                }
                let child = PageId { lod, x, y, ..p };
                self.write(child, i, value, touched);
                stack.push(child);
            }
        }
    }

    fn grid(&self, texture: u8) -> TextureGrid {
        *self.grids.get(texture as usize).unwrap_or_else(|| panic!("texture {texture} is not in this page table"))
    }

    fn index(&self, p: PageId) -> usize {
        let g = self.grid(p.texture);
        assert!(g.contains(p), "{p:?} is outside its texture's grid");
        self.base[p.texture as usize][p.lod as usize] + g.index(p.lod, p.x, p.y) as usize
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grids() -> Vec<TextureGrid> {
        vec![TextureGrid::new(16, 16).unwrap(), TextureGrid::new(8, 8).unwrap()]
    }

    /// Odd, rectangular grids: a wide one, a tall one.
    fn odd_grids() -> Vec<TextureGrid> {
        vec![TextureGrid::new(11, 3).unwrap(), TextureGrid::new(2, 7).unwrap()]
    }

    fn p(lod: u8, x: u16, y: u16) -> PageId {
        PageId::new(0, lod, x, y)
    }

    fn roots(g: &[TextureGrid]) -> Vec<(PageId, Slot)> {
        g.iter().enumerate().map(|(t, g)| (g.root(t as u8), t as Slot)).collect()
    }

    #[test]
    fn sizes_and_unmapped_start() {
        let t = PageTable::new(&grids());
        assert_eq!(t.entries.len() as u64, grids()[0].page_count() + grids()[1].page_count());
        assert_eq!(t.level(0, 0).len(), 256);
        assert_eq!(t.level(1, 3).len(), 1);
        assert!(!t.entry(1, 0, 7, 7).is_mapped());
    }

    #[test]
    fn mapping_the_roots_maps_everything() {
        let g = grids();
        let mut t = PageTable::new(&g);
        let changes = t.apply_mappings(&[], &roots(&g));
        assert_eq!(changes.len() as u64, g[0].page_count() + g[1].page_count());
        assert_eq!(t.entry(0, 0, 15, 15), Entry { slot: 0, lod: 4 });
        assert_eq!(t.entry(1, 0, 3, 5), Entry { slot: 1, lod: 3 });
        assert_eq!(t, PageTable::rebuild(&g, roots(&g)));
    }

    #[test]
    fn a_load_touches_its_uncovered_subtree_only() {
        let g = grids();
        let mut t = PageTable::new(&g);
        t.apply_mappings(&[], &roots(&g));
        // A LOD-1 page first covers 2x2 LOD-0 entries: 5 changes.
        let c = t.apply_mappings(&[], &[(p(1, 3, 3), 7)]);
        assert_eq!(c.len(), 5);
        assert!(c.iter().all(|c| c.entry == Entry { slot: 7, lod: 1 }));
        assert_eq!(c[0].at, p(1, 3, 3));
        // Its LOD-2 parent then covers 1 + 4 + 16 entries minus the 5 already covered by the child.
        let c = t.apply_mappings(&[], &[(p(2, 1, 1), 9)]);
        assert_eq!(c.len(), 1 + 3 + 12);
        assert_eq!(t.entry(0, 0, 6, 7), Entry { slot: 7, lod: 1 });
        assert_eq!(t.entry(0, 0, 5, 7), Entry { slot: 9, lod: 2 });
        // Evicting the parent falls back to the root except under the child.
        let c = t.apply_mappings(&[(p(2, 1, 1), 9)], &[]);
        assert_eq!(c.len(), 16);
        assert!(c.iter().all(|c| c.entry == Entry { slot: 0, lod: 4 }));
        assert_eq!(t.entry(0, 0, 6, 7), Entry { slot: 7, lod: 1 });
        assert_eq!(t, PageTable::rebuild(&g, [roots(&g), vec![(p(1, 3, 3), 7)]].concat()));
    }

    #[test]
    fn odd_edges_have_fewer_children() {
        // 11x3 pages: LOD 1 is 6x2, so page (5, 1) of LOD 1 covers only (10, 2) of LOD 0.
        let g = odd_grids();
        let mut t = PageTable::new(&g);
        t.apply_mappings(&[], &roots(&g));
        let c = t.apply_mappings(&[], &[(p(1, 5, 1), 4)]);
        assert_eq!(c.iter().map(|c| c.at).collect::<Vec<_>>(), [p(1, 5, 1), p(0, 10, 2)]);
        assert_eq!(t.level(0, 0).len(), 33);
        assert_eq!(t.level(1, 1).len(), 4, "2x7 pages: LOD 1 is 1x4");
        assert_eq!(t, PageTable::rebuild(&g, [roots(&g), vec![(p(1, 5, 1), 4)]].concat()));
    }

    #[test]
    fn changes_are_net_of_the_whole_update() {
        let g = grids();
        let mut t = PageTable::new(&g);
        t.apply_mappings(&[], &[roots(&g), vec![(p(1, 0, 0), 5)]].concat());
        // Slot 5 goes from (1,0,0) to its sibling (1,1,0): the four children of each change.
        let c = t.apply_mappings(&[(p(1, 0, 0), 5)], &[(p(1, 1, 0), 5)]);
        assert_eq!(c.len(), 10);
        // Evict and reload the same page into the same slot: nothing changed on the whole.
        let c = t.apply_mappings(&[(p(1, 1, 0), 5)], &[(p(1, 1, 0), 5)]);
        assert!(c.is_empty());
        // Into another slot: its 5 entries change.
        let c = t.apply_mappings(&[(p(1, 1, 0), 5)], &[(p(1, 1, 0), 6)]);
        assert_eq!(c.len(), 5);
        assert_eq!(t, PageTable::rebuild(&g, [roots(&g), vec![(p(1, 1, 0), 6)]].concat()));
    }

    proptest::proptest! {
        /// Any mappings, not only a residency's (children before parents, parents evicted under
        /// resident children, roots evicted): the table stays equal to the rebuild, and the changes
        /// are exactly the entries that differ.
        #[test]
        fn incremental_equals_rebuild_for_any_mappings(
            steps in proptest::collection::vec(
                (proptest::collection::vec(proptest::num::u16::ANY, 0..6), proptest::collection::vec(proptest::num::u16::ANY, 0..6)),
                1..30,
            ),
            rectangular in proptest::bool::ANY,
        ) {
            let g = if rectangular { odd_grids() } else { grids() };
            let all: Vec<PageId> = g
                .iter()
                .enumerate()
                .flat_map(|(t, g)| {
                    (0..g.lod_count()).flat_map(move |lod| {
                        (0..g.level_len(lod) as u32).filter_map(move |i| g.page_at_index(t as u8, lod, i))
                    })
                })
                .collect();
            let mut resident: std::collections::BTreeMap<PageId, Slot> = Default::default();
            let mut table = PageTable::new(&g);
            let mut next_slot = 0;
            for (evict, load) in steps {
                let mut evictions = vec![];
                for e in evict {
                    if resident.is_empty() {
                        break;
                    }
                    let p = *resident.keys().nth(e as usize % resident.len()).unwrap();
                    evictions.push((p, resident.remove(&p).unwrap()));
                }
                let mut loads = vec![];
                for l in load {
                    let p = all[l as usize % all.len()];
                    if let std::collections::btree_map::Entry::Vacant(v) = resident.entry(p) {
                        next_slot += 1;
                        v.insert(next_slot);
                        loads.push((p, next_slot));
                    }
                }
                let before = table.clone();
                let mut changes = table.apply_mappings(&evictions, &loads);
                changes.sort_by_key(|c| c.at);
                let rebuilt = PageTable::rebuild(&g, resident.iter().map(|(&p, &s)| (p, s)));
                proptest::prop_assert!(table == rebuilt);
                let mut diff: Vec<Change> =
                    all.iter().filter(|&&p| before.get(p) != table.get(p)).map(|&p| Change { at: p, entry: table.get(p) }).collect();
                diff.sort_by_key(|c| c.at);
                proptest::prop_assert_eq!(changes, diff);
            }
        }
    }

    #[test]
    fn packing_round_trips() {
        for (e, side) in
            [(Entry { slot: 0, lod: 0 }, 32), (Entry { slot: 1023, lod: 9 }, 32), (Entry { slot: 65535, lod: 14 }, 256)]
        {
            let w = e.pack(side);
            assert_eq!(w >> 24, 0);
            assert_eq!(Entry::unpack(w, side), e);
        }
        assert_eq!(Entry { slot: 33, lod: 2 }.pack(32), 1 | 1 << 8 | 2 << 16);
        assert_eq!(Entry::UNMAPPED.pack(32), UNMAPPED_WORD);
        assert_eq!(Entry::unpack(UNMAPPED_WORD, 32), Entry::UNMAPPED);
        let mut t = PageTable::new(&grids());
        t.apply_mappings(&[], &roots(&grids()));
        assert_eq!(t.packed_level(1, 0, 16), vec![1 | 3 << 16; 64]);
    }
}
