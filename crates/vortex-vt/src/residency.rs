//! Residency: which pages live in which slot of the physical page cache. Runs on the render thread
//! once per frame, after feedback analysis and before the page-table update.
//!
//! Each frame the caller passes the frame number and the pages the frame wants, most wanted first
//! (plain [`PageId`]s: the priority is the order, so the analysis decides it). [`Residency::update`]
//! answers with a [`FrameUpdate`]: the pages to upload into which slot, the pages whose slots are
//! taken from them, and the LOD bias for the next feedback pass. The rules:
//!
//! - **Pinned roots.** The coarsest page of every texture is loaded by the first update, before
//!   anything else and outside the upload budget, and is never evicted: the fallback of last resort.
//! - **Implicit ancestors.** A request stands for the page and all its coarser ancestors; the caller
//!   may list them or not. The request list is expanded, keeping the caller's order, into a list of
//!   distinct pages in which every page comes after its ancestors (the "wanted" list).
//! - **Protection.** Every wanted page that is resident gets this frame's stamp, and a page stamped
//!   this frame (wanted, or loaded) is never evicted this frame.
//! - **Coarse before fine.** The wanted list is loaded in order, and a page is loaded only if its
//!   parent is resident (possibly loaded earlier in the same frame), so a resident page's parent is
//!   always resident: the fallback chain has no holes.
//! - **Budget.** At most `upload_budget` pages are loaded per frame (the pinned roots aside).
//! - **Replacement.** When no slot is free, the victim is the unprotected page of the finest LOD, then
//!   the least recently used (older stamp), then the smallest [`PageId`]. The victim is reported in
//!   [`FrameUpdate::evictions`] with the slot that the same update's [`FrameUpdate::loads`] gives to
//!   the new page, so the renderer unmaps it (apply evictions first) before the slot is overwritten.
//!   (Since a page's parent is stamped whenever the page is, and is coarser, a page is never chosen
//!   while one of its children is resident.)
//! - **Oversubscription.** If the distinct wanted pages exceed `high_water * slots`, the LOD bias rises
//!   by `bias_step` (default 0.25 per frame, so a full LOD in 4 frames: quick enough to stop thrashing,
//!   smooth enough not to pop); under `low_water * slots` it falls by the same step. It stays within
//!   `0..=lod_count - 1` (the largest `lod_count` of the textures). The renderer feeds
//!   [`Residency::lod_bias`] into the next feedback pass.
//!
//! Loads are synchronous at this level: the renderer uploads the texels of each load into its slot
//! and then applies the update to the page table (`page_table`), which maps the page.

use std::cmp::Reverse;
use std::collections::{BinaryHeap, HashMap, HashSet};
use std::hash::{BuildHasherDefault, Hasher};

use crate::page::{MAX_LODS, MAX_TEXTURES, PageId, TextureGrid};

/// Index of a slot of the physical page cache.
pub type Slot = u16;

/// Most slots a cache can have (every [`Slot`] value).
pub const MAX_SLOTS: usize = 1 << 16;

/// The knobs of a [`Residency`].
#[derive(Clone, Copy, Debug, PartialEq)]
pub struct ResidencyConfig {
    /// Slots of the physical page cache (at least one per texture, at most [`MAX_SLOTS`]).
    pub slots: usize,
    /// Most pages loaded per frame, the pinned roots aside (0 stops streaming).
    pub upload_budget: usize,
    /// The bias rises while the distinct wanted pages exceed `high_water * slots`.
    pub high_water: f32,
    /// The bias falls while the distinct wanted pages are under `low_water * slots`.
    pub low_water: f32,
    /// LODs added to or taken from the bias per frame.
    pub bias_step: f32,
}

impl ResidencyConfig {
    /// `slots` and `upload_budget` with the default controller: high water at 90% of the slots, low
    /// water at 70%, 0.25 LOD per frame.
    pub fn new(slots: usize, upload_budget: usize) -> ResidencyConfig {
        ResidencyConfig { slots, upload_budget, high_water: 0.9, low_water: 0.7, bias_step: 0.25 }
    }
}

/// Why a [`Residency`] cannot be made.
#[derive(Clone, Debug, PartialEq, thiserror::Error)]
#[non_exhaustive]
pub enum ConfigError {
    /// No texture given.
    #[error("a residency needs at least one texture")]
    NoTextures,
    /// More textures than a feedback word can name.
    #[error("{0} textures, at most {MAX_TEXTURES}")]
    TooManyTextures(usize),
    /// Too few slots for the textures' roots, or more than the page table can address.
    #[error("{slots} slots for {textures} textures: need one per texture at least, {MAX_SLOTS} at most")]
    Slots {
        /// Slots asked for.
        slots: usize,
        /// Textures given.
        textures: usize,
    },
    /// Water marks that are not `0 <= low <= high`, finite.
    #[error("water marks must be finite with 0 <= low ({low}) <= high ({high})")]
    WaterMarks {
        /// The low water mark.
        low: f32,
        /// The high water mark.
        high: f32,
    },
    /// A LOD bias step that is not finite and positive.
    #[error("the bias step ({0}) must be finite and positive")]
    BiasStep(f32),
}

/// Why a [`Residency::update`] was refused; the residency is left as it was.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum UpdateError {
    /// The frame numbers stamp the pages' last use (the LRU order): each call's must be greater
    /// than the last's.
    #[error("frame numbers must increase: {frame} after {last}")]
    FrameOrder {
        /// The frame number given.
        frame: u64,
        /// The last call's.
        last: u64,
    },
}

/// Counters of one [`Residency::update`]. "Wanted" pages are the requests expanded with their
/// ancestors, without repeats.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct FrameStats {
    /// Distinct wanted pages (what the oversubscription controller compares with the slots).
    pub requested: usize,
    /// Wanted pages that were already resident.
    pub hits: usize,
    /// Pages loaded (the pinned roots included, on the first frame).
    pub loaded: usize,
    /// Pages evicted.
    pub evicted: usize,
    /// Wanted pages still not resident after this frame (budget, or a cache full of wanted pages).
    pub deferred: usize,
    /// Requests ignored: a texture the residency does not know, or a page outside its grid.
    pub invalid: usize,
}

/// What one frame changes in the cache. Apply `evictions` (unmap) before `loads` (upload, map): a
/// slot in `evictions` is reused by a page in `loads`.
#[derive(Clone, Debug, Default, PartialEq)]
pub struct FrameUpdate {
    /// The frame the update is for.
    pub frame: u64,
    /// Pages to upload and map, coarse before fine, with their slots.
    pub loads: Vec<(PageId, Slot)>,
    /// Pages that lost their slot this frame, in eviction order, with that slot.
    pub evictions: Vec<(PageId, Slot)>,
    /// The LOD bias for the next feedback pass (see [`Residency::lod_bias`]).
    pub lod_bias: f32,
    /// What the frame did, counted.
    pub stats: FrameStats,
}

#[derive(Clone, Copy, Debug)]
struct Resident {
    slot: Slot,
    /// Frame of last use (wanted or loaded).
    stamp: u64,
}

/// A cheap hasher for [`PageId`] keys (SipHash costs more than the rest of a lookup here).
#[derive(Default)]
struct PageHasher(u64);

impl Hasher for PageHasher {
    fn finish(&self) -> u64 {
        self.0
    }
    fn write(&mut self, bytes: &[u8]) {
        for &b in bytes {
            self.write_u64(b as u64);
        }
    }
    fn write_u8(&mut self, n: u8) {
        self.write_u64(n as u64);
    }
    fn write_u16(&mut self, n: u16) {
        self.write_u64(n as u64);
    }
    fn write_u64(&mut self, n: u64) {
        self.0 = (self.0.rotate_left(5) ^ n).wrapping_mul(0x51_7c_c1_b7_27_22_0a_95);
    }
}

type PageMap<V> = HashMap<PageId, V, BuildHasherDefault<PageHasher>>;
type PageSet = HashSet<PageId, BuildHasherDefault<PageHasher>>;

/// The residency manager of one physical page cache shared by up to [`MAX_TEXTURES`] textures
/// (texture `i` has grid `grids[i]`). See the module documentation for the rules.
#[derive(Clone, Debug)]
pub struct Residency {
    grids: Vec<TextureGrid>,
    config: ResidencyConfig,
    pages: PageMap<Resident>,
    owners: Vec<Option<PageId>>,
    /// Free slots, popped from the end (so slot 0 goes first).
    free: Vec<Slot>,
    /// The evictable (resident, not pinned) pages of each LOD as min-heaps of (stamp, page): the top
    /// is the least recently used, ties by page. Lazy: touching a page pushes its new stamp and
    /// leaves the old entry, which is dropped when it reaches the top (its stamp is no longer the
    /// page's) or when stale entries outnumber the live ones.
    lru: [BinaryHeap<Reverse<(u64, PageId)>>; MAX_LODS as usize],
    /// Live entries of each `lru` heap: the evictable resident pages of each LOD.
    evictable: [usize; MAX_LODS as usize],
    bias: f32,
    max_bias: f32,
    last_frame: Option<u64>,
    // Scratch reused across frames.
    seen: PageSet,
    wanted: Vec<PageId>,
    missing: Vec<PageId>,
    chain: Vec<PageId>,
}

impl Residency {
    /// A residency of the textures of `grids` (texture id = index), with nothing resident; refused
    /// with a [`ConfigError`] when `config` cannot work with them.
    pub fn new(grids: &[TextureGrid], config: ResidencyConfig) -> Result<Residency, ConfigError> {
        if grids.is_empty() {
            return Err(ConfigError::NoTextures);
        }
        if grids.len() > MAX_TEXTURES as usize {
            return Err(ConfigError::TooManyTextures(grids.len()));
        }
        if config.slots < grids.len() || config.slots > MAX_SLOTS {
            return Err(ConfigError::Slots { slots: config.slots, textures: grids.len() });
        }
        let (low, high) = (config.low_water, config.high_water);
        if !(low.is_finite() && high.is_finite() && 0.0 <= low && low <= high) {
            return Err(ConfigError::WaterMarks { low, high });
        }
        if !(config.bias_step.is_finite() && config.bias_step > 0.0) {
            return Err(ConfigError::BiasStep(config.bias_step));
        }
        let max_bias = grids.iter().map(|g| g.lod_count() - 1).max().unwrap_or(0) as f32;
        Ok(Residency {
            grids: grids.to_vec(),
            config,
            pages: PageMap::default(),
            owners: vec![None; config.slots],
            free: (0..config.slots).rev().map(|s| s as Slot).collect(),
            lru: std::array::from_fn(|_| BinaryHeap::new()),
            evictable: [0; MAX_LODS as usize],
            bias: 0.0,
            max_bias,
            last_frame: None,
            seen: PageSet::default(),
            wanted: Vec::new(),
            missing: Vec::new(),
            chain: Vec::new(),
        })
    }

    /// The grids of the textures, by texture id.
    pub fn grids(&self) -> &[TextureGrid] {
        &self.grids
    }

    /// What it was made with.
    pub fn config(&self) -> &ResidencyConfig {
        &self.config
    }

    /// Slots of the physical cache.
    pub fn slots(&self) -> usize {
        self.config.slots
    }

    /// The LOD bias for the next feedback pass: added to the LOD each feedback sample asks for.
    pub fn lod_bias(&self) -> f32 {
        self.bias
    }

    /// Whether `page` is its texture's pinned root (the single page of the coarsest LOD).
    pub fn is_root(&self, page: PageId) -> bool {
        self.grids.get(page.texture as usize).is_some_and(|g| g.root(page.texture) == page)
    }

    /// Whether `page` is a page of a texture of this residency.
    pub fn is_valid(&self, page: PageId) -> bool {
        self.grids.get(page.texture as usize).is_some_and(|g| g.contains(page))
    }

    /// The slot of `page`, if resident.
    pub fn is_resident(&self, page: PageId) -> Option<Slot> {
        self.pages.get(&page).map(|r| r.slot)
    }

    /// The frame in which `page` was last wanted or loaded, if resident.
    pub fn last_used(&self, page: PageId) -> Option<u64> {
        self.pages.get(&page).map(|r| r.stamp)
    }

    /// The page in `slot`, if any.
    pub fn slot_owner(&self, slot: Slot) -> Option<PageId> {
        self.owners.get(slot as usize).copied().flatten()
    }

    /// The LOD of the finest resident ancestor-or-self of `page`: the LOD the renderer samples it at.
    /// Once the first update has pinned the roots there always is one; before, this is the root's LOD.
    ///
    /// Panics if `page` is not [valid](Self::is_valid).
    pub fn finest_resident_lod(&self, page: PageId) -> u8 {
        let grid = self.grid(page);
        page.ancestors_and_self(&grid).find(|p| self.pages.contains_key(p)).map_or(grid.lod_count() - 1, |p| p.lod)
    }

    /// Pages resident now.
    pub fn resident_count(&self) -> usize {
        self.pages.len()
    }

    /// Every resident page with its slot, in no particular order.
    pub fn resident(&self) -> impl Iterator<Item = (PageId, Slot)> + '_ {
        self.pages.iter().map(|(&p, r)| (p, r.slot))
    }

    fn grid(&self, page: PageId) -> TextureGrid {
        assert!(self.is_valid(page), "{page:?} is not a page of this residency's textures");
        self.grids[page.texture as usize]
    }

    /// One frame: `frame` must increase from call to call; `requests` are the pages the frame wants,
    /// most wanted first (ancestors implied, repeats and invalid pages ignored). A `frame` not
    /// after the last call's is refused, and nothing changes.
    pub fn update(&mut self, frame: u64, requests: &[PageId]) -> Result<FrameUpdate, UpdateError> {
        if let Some(last) = self.last_frame.filter(|&last| frame <= last) {
            return Err(UpdateError::FrameOrder { frame, last });
        }
        self.last_frame = Some(frame);
        let mut out = FrameUpdate { frame, ..FrameUpdate::default() };

        // Pinned roots, first and outside the budget (only the first frame finds them missing).
        for (t, grid) in self.grids.iter().enumerate() {
            let root = grid.root(t as u8);
            if !self.pages.contains_key(&root) {
                // `new` refuses a cache with fewer slots than textures, so one is always free here.
                let Some(slot) = self.free.pop() else { break };
                self.pages.insert(root, Resident { slot, stamp: frame });
                self.owners[slot as usize] = Some(root);
                out.loads.push((root, slot));
            }
        }
        let roots_loaded = out.loads.len();

        // The wanted list: requests in order, each preceded by its not yet listed ancestors.
        self.seen.clear();
        self.wanted.clear();
        for &p in requests {
            let Some(grid) = self.grids.get(p.texture as usize).copied().filter(|g| g.contains(p)) else {
                out.stats.invalid += 1;
                continue;
            };
            self.chain.clear();
            for q in p.ancestors_and_self(&grid) {
                if !self.seen.insert(q) {
                    break;
                }
                self.chain.push(q);
            }
            self.wanted.extend(self.chain.iter().rev());
        }

        // Stamp the resident wanted pages: protected this frame, most recently used. The others are
        // missing, in wanted order.
        self.missing.clear();
        for &p in &self.wanted {
            match self.pages.get_mut(&p) {
                Some(r) => {
                    out.stats.hits += 1;
                    if r.stamp != frame {
                        r.stamp = frame;
                        if p.lod + 1 < self.grids[p.texture as usize].lod_count() {
                            self.lru[p.lod as usize].push(Reverse((frame, p)));
                        }
                    }
                }
                None => self.missing.push(p),
            }
        }
        for (heap, &live) in self.lru.iter_mut().zip(&self.evictable) {
            if heap.len() > 2 * live + 64 {
                let pages = &self.pages;
                heap.retain(|&Reverse((stamp, p))| pages.get(&p).is_some_and(|r| r.stamp == stamp));
            }
        }

        // Load in wanted order, coarse before fine, within the budget.
        let mut budget = self.config.upload_budget;
        for i in 0..self.missing.len() {
            let p = self.missing[i];
            if budget == 0 {
                break;
            }
            let grid = self.grids[p.texture as usize];
            // A guard: the parent comes earlier in the wanted list, and a wanted page that cannot be
            // loaded ends the loop, so the parent is resident by now.
            if p.parent(&grid).is_some_and(|q| !self.pages.contains_key(&q)) {
                continue;
            }
            let slot = match self.free.pop() {
                Some(slot) => slot,
                None => match self.evict_victim(frame) {
                    Some((victim, slot)) => {
                        out.evictions.push((victim, slot));
                        slot
                    }
                    None => break, // every slot holds a page protected this frame
                },
            };
            self.pages.insert(p, Resident { slot, stamp: frame });
            self.owners[slot as usize] = Some(p);
            self.lru[p.lod as usize].push(Reverse((frame, p)));
            self.evictable[p.lod as usize] += 1;
            out.loads.push((p, slot));
            budget -= 1;
        }

        // Oversubscription controller.
        let wanted = self.wanted.len() as f32;
        let slots = self.config.slots as f32;
        if wanted > self.config.high_water * slots {
            self.bias = (self.bias + self.config.bias_step).min(self.max_bias);
        } else if wanted < self.config.low_water * slots {
            self.bias = (self.bias - self.config.bias_step).max(0.0);
        }

        out.lod_bias = self.bias;
        out.stats.requested = self.wanted.len();
        out.stats.loaded = out.loads.len();
        out.stats.evicted = out.evictions.len();
        out.stats.deferred = self.missing.len() - (out.loads.len() - roots_loaded);
        Ok(out)
    }

    /// Takes the slot of the unprotected page of the finest LOD, least recently used, smallest id.
    fn evict_victim(&mut self, frame: u64) -> Option<(PageId, Slot)> {
        for (heap, live) in self.lru.iter_mut().zip(&mut self.evictable) {
            // Drop stale tops; the live top is the LOD's oldest, and if it is protected, all are.
            while let Some(&Reverse((stamp, p))) = heap.peek() {
                if self.pages.get(&p).is_none_or(|r| r.stamp != stamp) {
                    heap.pop();
                } else if stamp < frame {
                    heap.pop();
                    *live -= 1;
                    let Some(r) = self.pages.remove(&p) else { continue };
                    self.owners[r.slot as usize] = None;
                    return Some((p, r.slot));
                } else {
                    break;
                }
            }
        }
        None
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    fn grid(pages: u16) -> TextureGrid {
        TextureGrid::new(pages.into(), pages.into()).unwrap()
    }

    fn residency(pages: &[u16], slots: usize, budget: usize) -> Residency {
        let grids: Vec<TextureGrid> = pages.iter().map(|&p| grid(p)).collect();
        Residency::new(&grids, ResidencyConfig::new(slots, budget)).unwrap()
    }

    fn p(lod: u8, x: u16, y: u16) -> PageId {
        PageId::new(0, lod, x, y)
    }

    #[test]
    fn config_is_checked() {
        let g = [grid(16)];
        let ok = ResidencyConfig::new(8, 2);
        assert_eq!(Residency::new(&[], ok).unwrap_err(), ConfigError::NoTextures);
        assert_eq!(Residency::new(&[grid(8); 17], ok).unwrap_err(), ConfigError::TooManyTextures(17));
        assert!(matches!(Residency::new(&[grid(8); 3], ResidencyConfig::new(2, 1)), Err(ConfigError::Slots { .. })));
        assert!(matches!(Residency::new(&g, ResidencyConfig::new(MAX_SLOTS + 1, 1)), Err(ConfigError::Slots { .. })));
        let bad_marks = ResidencyConfig { low_water: 0.95, ..ok };
        assert!(matches!(Residency::new(&g, bad_marks), Err(ConfigError::WaterMarks { .. })));
        let bad_step = ResidencyConfig { bias_step: 0.0, ..ok };
        assert!(matches!(Residency::new(&g, bad_step), Err(ConfigError::BiasStep(_))));
        assert!(Residency::new(&g, ResidencyConfig::new(MAX_SLOTS, 0)).is_ok());
    }

    #[test]
    fn roots_are_loaded_first_outside_the_budget() {
        let mut r = residency(&[16, 8], 8, 1);
        assert_eq!(r.finest_resident_lod(p(0, 3, 3)), 4);
        let u = r.update(0, &[p(4, 0, 0), p(3, 1, 1)]).unwrap();
        // Both roots, then one page of budget.
        assert_eq!(u.loads, vec![(p(4, 0, 0), 0), (PageId::new(1, 3, 0, 0), 1), (p(3, 1, 1), 2)]);
        assert_eq!(u.stats, FrameStats { requested: 2, hits: 1, loaded: 3, evicted: 0, deferred: 0, invalid: 0 });
        assert_eq!(r.is_resident(PageId::new(1, 3, 0, 0)), Some(1));
        // Later frames find them resident.
        assert!(r.update(1, &[]).unwrap().loads.is_empty());
    }

    #[test]
    fn roots_are_never_evicted() {
        let mut r = residency(&[16, 8], 2, 8);
        r.update(0, &[]).unwrap();
        for f in 1..20 {
            let u = r.update(f, &[p(3, (f % 2) as u16, 0), PageId::new(1, 2, 1, 1)]).unwrap();
            assert!(u.loads.is_empty() && u.evictions.is_empty());
            assert_eq!(u.stats.deferred, 2);
        }
        let mut r = residency(&[16, 8], 3, 8);
        for f in 0..20 {
            let u = r.update(f, &[p(3, (f % 2) as u16, (f % 3 % 2) as u16)]).unwrap();
            assert!(u.evictions.iter().all(|(v, _)| !r.is_root(*v)));
            assert!(r.is_resident(p(4, 0, 0)).is_some() && r.is_resident(PageId::new(1, 3, 0, 0)).is_some());
        }
    }

    #[test]
    fn ancestors_are_implied_and_loaded_coarse_first() {
        // 16 pages per side: LODs 0..=4. One page of budget per frame walks down the chain.
        let mut r = residency(&[16], 16, 1);
        let want = [p(0, 13, 6)];
        let mut got = vec![];
        for f in 0..6 {
            let u = r.update(f, &want).unwrap();
            assert_eq!(u.stats.requested, 5);
            got.extend(u.loads.iter().map(|&(q, _)| q));
        }
        assert_eq!(got, vec![p(4, 0, 0), p(3, 1, 0), p(2, 3, 1), p(1, 6, 3), p(0, 13, 6)]);
        assert_eq!(r.finest_resident_lod(p(0, 13, 6)), 0);
        assert_eq!(r.finest_resident_lod(p(0, 12, 6)), 1);
        assert_eq!(r.finest_resident_lod(p(0, 0, 15)), 4);
    }

    #[test]
    fn loading_stops_when_every_slot_is_protected() {
        // 3 slots: root + 2. The third wanted page finds neither a free slot nor a victim.
        let mut r = residency(&[16], 3, 8);
        r.update(0, &[]).unwrap();
        let u = r.update(1, &[p(3, 0, 0), p(3, 1, 1), p(2, 2, 2)]).unwrap();
        assert_eq!(u.loads.iter().map(|l| l.0).collect::<Vec<_>>(), vec![p(3, 0, 0), p(3, 1, 1)]);
        assert_eq!(u.stats.deferred, 1);
        let u = r.update(2, &[p(2, 0, 0), p(3, 1, 1)]).unwrap();
        // p(3,0,0) is the parent of p(2,0,0) and is wanted, so protected; nothing else to evict.
        assert!(u.loads.is_empty() && u.evictions.is_empty());
    }

    #[test]
    fn the_budget_caps_loads() {
        let mut r = residency(&[16], 64, 3);
        r.update(0, &[]).unwrap();
        let want: Vec<PageId> = (0..4).flat_map(|y| (0..4).map(move |x| p(2, x, y))).collect();
        let mut total = 0;
        for f in 1..10 {
            let u = r.update(f, &want).unwrap();
            assert!(u.loads.len() <= 3);
            total += u.loads.len();
        }
        // 4 LOD-3 pages + 16 LOD-2 pages, 3 per frame.
        assert_eq!(total, 20);
        assert_eq!(r.update(10, &want).unwrap().stats.hits, 21);
        assert!(r.update(11, &want).unwrap().stats.deferred == 0);
    }

    #[test]
    fn pages_wanted_this_frame_are_never_evicted() {
        let mut r = residency(&[16], 4, 8);
        let want = [p(3, 0, 0), p(3, 1, 0), p(3, 0, 1)];
        r.update(0, &want).unwrap();
        assert_eq!(r.resident_count(), 4);
        // Full of wanted pages: a new want waits instead of evicting.
        let mut more = want.to_vec();
        more.push(p(3, 1, 1));
        let u = r.update(1, &more).unwrap();
        assert!(u.evictions.is_empty() && u.loads.is_empty());
        assert_eq!(u.stats.deferred, 1);
        // Once one of them is no longer wanted, it makes room.
        let u = r.update(2, &[p(3, 1, 1), p(3, 0, 0), p(3, 1, 0)]).unwrap();
        assert_eq!(u.evictions, vec![(p(3, 0, 1), 3)]);
        assert_eq!(u.loads, vec![(p(3, 1, 1), 3)]);
    }

    #[test]
    fn victims_are_finer_lod_first_then_lru_then_smallest_id() {
        let mut r = residency(&[16], 8, 8);
        // Frame 0: a LOD-3 page and its LOD-2 child; frame 1: two LOD-2 pages of another parent.
        r.update(0, &[p(2, 0, 0)]).unwrap();
        r.update(1, &[p(2, 3, 3), p(2, 2, 2)]).unwrap();
        // Resident: root, (3,0,0)@0, (2,0,0)@0, (3,1,1)@1, (2,3,3)@1, (2,2,2)@1: 6 of 8.
        assert_eq!(r.resident_count(), 6);
        // Frame 2 wants (3,0,1) and two of its children: 3 loads, 2 free slots -> 1 victim: the
        // finest LOD is 2, the oldest there is (2,0,0) (stamped 0), even though (3,0,0) is as old.
        let u = r.update(2, &[p(2, 0, 2), p(2, 1, 3)]).unwrap();
        assert_eq!(u.evictions.iter().map(|e| e.0).collect::<Vec<_>>(), vec![p(2, 0, 0)]);
        // Frame 3 wants 3 new LOD-3 pages... with 8 slots all full: victims are LOD 2 first, oldest
        // first ((2,3,3) and (2,2,2) from frame 1, ties by id: (2,2,2) < (2,3,3)), then LOD 3.
        let u = r.update(3, &[p(3, 1, 0)]).unwrap();
        assert_eq!(u.evictions.iter().map(|e| e.0).collect::<Vec<_>>(), vec![p(2, 2, 2)]);
        let u = r.update(4, &[p(3, 1, 0), p(2, 2, 0)]).unwrap();
        assert_eq!(u.evictions.iter().map(|e| e.0).collect::<Vec<_>>(), vec![p(2, 3, 3)]);
        // Now only (2,0,2), (2,1,3) (frame 2) remain at LOD 2 besides the protected (2,2,0).
        let u = r.update(5, &[p(3, 1, 0), p(2, 2, 0), p(2, 3, 0), p(2, 2, 1)]).unwrap();
        assert_eq!(u.evictions.iter().map(|e| e.0).collect::<Vec<_>>(), vec![p(2, 0, 2), p(2, 1, 3)]);
        // Then LOD 3 goes, oldest first: (3,0,0) (frame 0), not the root.
        let u = r.update(6, &[p(3, 1, 0), p(2, 2, 0), p(2, 3, 0), p(2, 2, 1), p(2, 3, 1)]).unwrap();
        assert_eq!(u.evictions.iter().map(|e| e.0).collect::<Vec<_>>(), vec![p(3, 0, 0)]);
    }

    #[test]
    fn a_replaced_page_is_evicted_in_the_same_update_with_its_slot() {
        let mut r = residency(&[16], 3, 8);
        r.update(0, &[p(3, 0, 0), p(3, 1, 0)]).unwrap();
        let old = r.is_resident(p(3, 0, 0)).unwrap();
        let u = r.update(1, &[p(3, 1, 1), p(3, 1, 0)]).unwrap();
        assert_eq!(u.evictions, vec![(p(3, 0, 0), old)]);
        assert_eq!(u.loads, vec![(p(3, 1, 1), old)]);
        assert_eq!(r.slot_owner(old), Some(p(3, 1, 1)));
        assert_eq!(r.is_resident(p(3, 0, 0)), None);
    }

    #[test]
    fn repeats_and_invalid_requests_are_ignored() {
        let mut r = residency(&[16], 8, 8);
        let u = r.update(0, &[p(3, 0, 0), p(3, 0, 0), p(0, 16, 0), p(5, 0, 0), PageId::new(1, 0, 0, 0)]).unwrap();
        assert_eq!(u.stats.invalid, 3);
        assert_eq!(u.stats.requested, 2);
        assert_eq!(u.loads.len(), 2);
    }

    #[test]
    fn frames_must_increase() {
        let mut r = residency(&[16], 8, 8);
        let first = r.update(3, &[]).unwrap();
        assert_eq!(r.update(3, &[p(3, 0, 0)]), Err(UpdateError::FrameOrder { frame: 3, last: 3 }));
        assert_eq!(r.update(2, &[]), Err(UpdateError::FrameOrder { frame: 2, last: 3 }));
        // Refused calls change nothing: the next frame sees what the first one left.
        assert_eq!(r.resident_count(), first.loads.len());
        assert_eq!(r.update(4, &[p(3, 0, 0)]).unwrap().stats.loaded, 1);
    }

    #[test]
    fn the_bias_rises_when_oversubscribed_and_falls_back() {
        // 16 pages per side: 5 LODs, bias within 0..=4. 10 slots: high water 9, low water 7.
        let mut r = residency(&[16], 10, 8);
        let lod2: Vec<PageId> = (0..4).flat_map(|y| (0..4).map(move |x| p(2, x, y))).collect(); // 21 wanted
        let mut biases = vec![];
        for f in 0..20 {
            biases.push(r.update(f, &lod2).unwrap().lod_bias);
        }
        assert_eq!(&biases[..5], &[0.25, 0.5, 0.75, 1.0, 1.25]);
        assert_eq!(biases[19], 4.0, "capped at lod_count - 1");
        assert_eq!(r.lod_bias(), 4.0);
        // 8 wanted: between the marks, the bias holds.
        let eight = [p(2, 0, 0), p(2, 1, 0), p(2, 0, 1), p(2, 1, 1), p(3, 1, 1), p(3, 0, 1)];
        assert_eq!(r.update(20, &eight).unwrap().stats.requested, 8);
        assert_eq!(r.lod_bias(), 4.0);
        // 9 wanted is not over 9.
        assert_eq!(r.update(21, &[&eight[..], &[p(3, 1, 0)]].concat()).unwrap().lod_bias, 4.0);
        // 2 wanted: it falls to 0 and stays there.
        for f in 22..50 {
            r.update(f, &[p(3, 0, 0)]).unwrap();
        }
        assert_eq!(r.lod_bias(), 0.0);
        assert_eq!(r.update(50, &[p(3, 0, 0)]).unwrap().lod_bias, 0.0);
        // The marks exactly: 10 wanted is over 9 (rises), 7 is not under 7 (holds), 6 is (falls).
        let ten = [&eight[..], &[p(3, 1, 0), p(2, 2, 0)]].concat();
        assert_eq!(r.update(51, &ten).unwrap().stats.requested, 10);
        assert_eq!(r.lod_bias(), 0.25);
        let seven = &eight[..5];
        assert_eq!(r.update(52, seven).unwrap().stats.requested, 7);
        assert_eq!(r.lod_bias(), 0.25);
        assert_eq!(r.update(53, &eight[..4]).unwrap().stats.requested, 6);
        assert_eq!(r.lod_bias(), 0.0);
    }

    #[test]
    fn the_bias_step_is_configurable() {
        let config = ResidencyConfig { bias_step: 1.0, ..ResidencyConfig::new(4, 1) };
        let mut r = Residency::new(&[grid(8)], config).unwrap();
        let all: Vec<PageId> = (0..4).flat_map(|y| (0..4).map(move |x| p(1, x, y))).collect();
        assert_eq!(r.update(0, &all).unwrap().lod_bias, 1.0);
        assert_eq!(r.update(1, &all).unwrap().lod_bias, 2.0);
        assert_eq!(r.update(2, &all).unwrap().lod_bias, 3.0);
        assert_eq!(r.update(3, &all).unwrap().lod_bias, 3.0);
        assert_eq!(r.update(4, &[]).unwrap().lod_bias, 2.0);
    }
}
