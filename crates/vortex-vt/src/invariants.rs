//! Consistency checks of a [`Residency`] and the [`PageTable`] kept in step with it, for tests and
//! debug builds. [`check`] walks the whole table (cost: entries × LODs), so it is not for every frame
//! of a release build.

use std::collections::HashMap;

use crate::page::PageId;
use crate::page_table::{Entry, PageTable};
use crate::residency::{Residency, Slot};

/// The first broken rule [`check`] finds.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum Violation {
    /// The page table and the residency address different grids.
    #[error("the page table's texture grids differ from the residency's")]
    GridMismatch,
    /// A texture's root page (its coarsest, which every page falls back to) is not resident.
    #[error("the root of texture {0} is not resident")]
    RootNotResident(u8),
    /// More pages are resident than the cache has slots.
    #[error("{resident} pages resident in a cache of {slots} slots")]
    TooManyResident {
        /// Pages resident.
        resident: usize,
        /// Slots of the cache.
        slots: usize,
    },
    /// Two resident pages hold one slot.
    #[error("slot {slot} holds both {a:?} and {b:?}")]
    SlotShared {
        /// The slot.
        slot: Slot,
        /// One page that holds it.
        a: PageId,
        /// The other.
        b: PageId,
    },
    /// A slot's recorded owner is not the page resident in it.
    #[error("slot {slot} is recorded as holding {owner:?}, but the resident page there is {page:?}")]
    SlotOwner {
        /// The slot.
        slot: Slot,
        /// The page resident in it.
        page: Option<PageId>,
        /// The page recorded as its owner.
        owner: Option<PageId>,
    },
    /// A resident page's parent is not resident.
    #[error("{page:?} is resident but its parent is not: the fallback chain has a hole")]
    Hole {
        /// The page.
        page: PageId,
    },
    /// A page-table entry is not its page's finest resident ancestor-or-self.
    #[error("the entry of {page:?} is {entry:?}, but its finest resident ancestor-or-self gives {expected:?}")]
    WrongEntry {
        /// The page.
        page: PageId,
        /// Its entry.
        entry: Entry,
        /// The entry it should have.
        expected: Entry,
    },
    /// A page-table entry differs from a table rebuilt from the resident pages.
    #[error("the entry of {page:?} is {entry:?}, but a rebuilt table has {rebuilt:?}")]
    DiffersFromRebuild {
        /// The page.
        page: PageId,
        /// Its entry.
        entry: Entry,
        /// The rebuilt table's entry.
        rebuilt: Entry,
    },
}

/// Checks, after at least one update has been applied to both:
///
/// - the table covers the residency's textures;
/// - every texture's root is resident;
/// - at most `slots` pages are resident, no slot holds two pages, and the residency's slot owners
///   agree with its pages;
/// - every resident page's parent is resident (no holes in the fallback chains);
/// - every entry points at (the slot and LOD of) the finest resident ancestor-or-self of its page;
/// - the table equals [`PageTable::rebuild`] of the resident pages.
pub fn check(residency: &Residency, table: &PageTable) -> Result<(), Violation> {
    let grids = residency.grids();
    if table.grids() != grids {
        return Err(Violation::GridMismatch);
    }
    for (t, g) in grids.iter().enumerate() {
        if residency.is_resident(g.root(t as u8)).is_none() {
            return Err(Violation::RootNotResident(t as u8));
        }
    }
    if residency.resident_count() > residency.slots() {
        return Err(Violation::TooManyResident { resident: residency.resident_count(), slots: residency.slots() });
    }

    let mut by_slot: HashMap<Slot, PageId> = HashMap::with_capacity(residency.resident_count());
    for (page, slot) in residency.resident() {
        if let Some(&other) = by_slot.get(&slot) {
            let (a, b) = (other.min(page), other.max(page));
            return Err(Violation::SlotShared { slot, a, b });
        }
        by_slot.insert(slot, page);
        let grid = grids[page.texture as usize];
        if page.parent(&grid).is_some_and(|q| residency.is_resident(q).is_none()) {
            return Err(Violation::Hole { page });
        }
    }
    for slot in 0..residency.slots() {
        let slot = slot as Slot;
        let (page, owner) = (by_slot.get(&slot).copied(), residency.slot_owner(slot));
        if page != owner {
            return Err(Violation::SlotOwner { slot, page, owner });
        }
    }

    let rebuilt = PageTable::rebuild(grids, residency.resident());
    for (t, g) in grids.iter().enumerate() {
        let t = t as u8;
        for lod in 0..g.lod_count() {
            let [w, h] = g.pages_at(lod);
            for y in 0..h {
                for x in 0..w {
                    let page = PageId::new(t, lod, x, y);
                    let entry = table.get(page);
                    let expected = page
                        .ancestors_and_self(g)
                        .find_map(|q| residency.is_resident(q).map(|slot| Entry { slot, lod: q.lod }))
                        .unwrap_or(Entry::UNMAPPED);
                    if entry != expected {
                        return Err(Violation::WrongEntry { page, entry, expected });
                    }
                    let rebuilt = rebuilt.get(page);
                    if entry != rebuilt {
                        return Err(Violation::DiffersFromRebuild { page, entry, rebuilt });
                    }
                }
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use std::collections::{HashMap, HashSet};

    use proptest::prelude::*;

    use super::*;
    use crate::page::TextureGrid;
    use crate::residency::{FrameUpdate, ResidencyConfig};

    fn grids(textures: usize) -> Vec<TextureGrid> {
        [16, 8][..textures].iter().map(|&p| TextureGrid::new(p, p).unwrap()).collect()
    }

    #[test]
    fn a_fresh_pair_fails_until_the_first_update() {
        let g = grids(2);
        let mut r = Residency::new(&g, ResidencyConfig::new(8, 2)).unwrap();
        let mut t = PageTable::new(&g);
        assert_eq!(check(&r, &t), Err(Violation::RootNotResident(0)));
        let u = r.update(0, &[]).unwrap();
        assert_eq!(
            check(&r, &t),
            Err(Violation::WrongEntry {
                page: PageId::new(0, 0, 0, 0),
                entry: Entry::UNMAPPED,
                expected: Entry { slot: 0, lod: 4 }
            })
        );
        t.apply(&u);
        assert_eq!(check(&r, &t), Ok(()));
        assert_eq!(check(&r, &PageTable::new(&g[..1])), Err(Violation::GridMismatch));
    }

    #[test]
    fn a_stale_table_is_caught() {
        let g = grids(1);
        let mut r = Residency::new(&g, ResidencyConfig::new(8, 2)).unwrap();
        let mut t = PageTable::new(&g);
        t.apply(&r.update(0, &[]).unwrap());
        let _ = r.update(1, &[PageId::new(0, 3, 1, 0)]).unwrap();
        let err = check(&r, &t).unwrap_err();
        assert_eq!(
            err,
            Violation::WrongEntry {
                page: PageId::new(0, 0, 8, 0),
                entry: Entry { slot: 0, lod: 4 },
                expected: Entry { slot: 1, lod: 3 }
            }
        );
    }

    /// One frame's requests: (texture, LOD, x, y) drawn wide, folded into the grids.
    fn fold(g: &[TextureGrid], raw: &[(u8, u8, u16, u16)]) -> Vec<PageId> {
        raw.iter()
            .map(|&(t, lod, x, y)| {
                let t = t % g.len() as u8;
                let grid = g[t as usize];
                // Fine LODs are the common case of real feedback: weight towards LOD 0.
                let lod = (lod % (2 * grid.lod_count())).saturating_sub(grid.lod_count());
                let [w, h] = grid.pages_at(lod);
                PageId::new(t, lod, x % w, y % h)
            })
            .collect()
    }

    /// A residency's state before an update.
    struct Before {
        pages: HashMap<PageId, Slot>,
        stamps: HashMap<PageId, u64>,
        bias: f32,
    }

    impl Before {
        fn of(r: &Residency) -> Before {
            let pages: HashMap<PageId, Slot> = r.resident().collect();
            let stamps = pages.keys().map(|&p| (p, r.last_used(p).unwrap())).collect();
            Before { pages, stamps, bias: r.lod_bias() }
        }
    }

    /// The rules of one update against the state before it.
    fn check_update(
        before: &Before,
        r: &Residency,
        u: &FrameUpdate,
        requests: &[PageId],
        budget: usize,
        first: bool,
    ) -> Result<(), TestCaseError> {
        let (bias_before, before_stamps, before) = (before.bias, &before.stamps, &before.pages);
        let g = r.grids();
        let wanted: HashSet<PageId> =
            requests.iter().flat_map(|p| p.ancestors_and_self(&g[p.texture as usize]).collect::<Vec<_>>()).collect();
        let roots: Vec<PageId> = g.iter().enumerate().map(|(t, g)| g.root(t as u8)).collect();
        let root_loads = u.loads.iter().filter(|(p, _)| roots.contains(p)).count();
        prop_assert_eq!(root_loads, if first { g.len() } else { 0 });
        prop_assert!(u.loads.len() - root_loads <= budget, "{} loads over a budget of {}", u.loads.len(), budget);
        prop_assert_eq!(u.stats.requested, wanted.len());
        // The controller with the default marks (90%, 70%) and step (0.25).
        let (n, slots, max_bias) =
            (wanted.len() as f32, r.slots() as f32, g.iter().map(|g| g.lod_count() - 1).max().unwrap_or(0) as f32);
        let bias = if n > 0.9 * slots {
            (bias_before + 0.25).min(max_bias)
        } else if n < 0.7 * slots {
            (bias_before - 0.25).max(0.0)
        } else {
            bias_before
        };
        prop_assert_eq!(u.lod_bias, bias);
        // Coarse before fine: each load's parent was resident or loaded earlier in this update.
        let mut have: HashSet<PageId> = before.keys().copied().collect();
        for (p, _) in &u.evictions {
            prop_assert!(!wanted.contains(p), "{:?} was wanted this frame and evicted", p);
            prop_assert!(!roots.contains(p), "root {:?} evicted", p);
            have.remove(p);
        }
        for (p, _) in &u.loads {
            prop_assert!(roots.contains(p) || wanted.contains(p), "{:?} loaded but not wanted", p);
            prop_assert!(!before.contains_key(p), "{:?} loaded twice", p);
            if let Some(q) = p.parent(&g[p.texture as usize]) {
                prop_assert!(have.contains(&q), "{:?} loaded before its parent", p);
            }
            have.insert(*p);
        }
        // Evicted slots go to loads of the same update; other loads take slots that were free.
        let used: HashSet<Slot> = before.values().copied().collect();
        let evicted: HashMap<Slot, PageId> = u.evictions.iter().map(|&(p, s)| (s, p)).collect();
        prop_assert_eq!(evicted.len(), u.evictions.len());
        for (p, s) in &u.evictions {
            prop_assert_eq!(before.get(p), Some(s));
            prop_assert!(u.loads.iter().any(|l| l.1 == *s), "slot {} evicted but not reused", s);
        }
        for (_, s) in &u.loads {
            prop_assert!(!used.contains(s) || evicted.contains_key(s), "slot {} taken from a page not evicted", s);
        }
        // Each victim was the first unprotected page by (LOD, stamp, id) among those left.
        let mut candidates: Vec<(u8, u64, PageId)> = before_stamps
            .iter()
            .filter(|(p, _)| !roots.contains(p) && !wanted.contains(p))
            .map(|(&p, &s)| (p.lod, s, p))
            .collect();
        candidates.sort();
        let victims: Vec<PageId> = u.evictions.iter().map(|e| e.0).collect();
        let expected: Vec<PageId> = candidates.iter().take(victims.len()).map(|c| c.2).collect();
        prop_assert_eq!(victims, expected);
        // A wanted page left out: the budget ran out, or no victim was left, or its parent is missing.
        if u.stats.deferred > 0 {
            let budget_spent = u.loads.len() - root_loads == budget;
            let no_victims = candidates.len() == u.evictions.len() && r.resident_count() == r.slots();
            let all_blocked = wanted
                .iter()
                .filter(|p| r.is_resident(**p).is_none())
                .all(|p| p.parent(&g[p.texture as usize]).is_some_and(|q| r.is_resident(q).is_none()));
            prop_assert!(budget_spent || no_victims || all_blocked, "pages deferred for no reason");
        }
        Ok(())
    }

    proptest! {
        #![proptest_config(ProptestConfig { cases: 200, ..ProptestConfig::default() })]

        #[test]
        fn random_frames_keep_every_rule(
            sizes in prop::collection::vec((1u32..40, 1u32..40), 1..=2),
            slots in 8usize..=40,
            budget in 1usize..=8,
            frames in prop::collection::vec(prop::collection::vec(any::<(u8, u8, u16, u16)>(), 0..30), 1..40),
        ) {
            // Random rectangular grids: odd rows and columns, wide, tall, single pages.
            let g: Vec<TextureGrid> = sizes.iter().map(|&(w, h)| TextureGrid::new(w, h).unwrap()).collect();
            let mut r = Residency::new(&g, ResidencyConfig::new(slots, budget)).unwrap();
            let mut table = PageTable::new(&g);
            // The GPU's copy, updated only through the changes.
            let mut mirror: HashMap<PageId, Entry> = HashMap::new();
            for (f, raw) in frames.iter().enumerate() {
                let requests = fold(&g, raw);
                let before = Before::of(&r);
                let u = r.update(f as u64, &requests).unwrap();
                check_update(&before, &r, &u, &requests, budget, f == 0)?;
                let changes = table.apply(&u);
                let mut seen = HashSet::new();
                for c in &changes {
                    prop_assert!(seen.insert(c.at), "{:?} changed twice", c.at);
                    let old = mirror.get(&c.at).copied().unwrap_or(Entry::UNMAPPED);
                    prop_assert_ne!(old, c.entry, "{:?} reported without a change", c.at);
                    mirror.insert(c.at, c.entry);
                }
                let rebuilt = PageTable::rebuild(&g, r.resident());
                for (t, grid) in g.iter().enumerate() {
                    for lod in 0..grid.lod_count() {
                        let [w, h] = grid.pages_at(lod);
                        for y in 0..h {
                            for x in 0..w {
                                let p = PageId::new(t as u8, lod, x, y);
                                prop_assert_eq!(mirror.get(&p).copied().unwrap_or(Entry::UNMAPPED), rebuilt.get(p));
                            }
                        }
                    }
                }
                if let Err(v) = check(&r, &table) {
                    return Err(TestCaseError::fail(format!("frame {f}: {v}")));
                }
            }
        }

        #[test]
        fn oversubscription_raises_then_lowers_the_bias(
            textures in 1usize..=2,
            slots in 8usize..=40,
            budget in 1usize..=8,
            busy in 8usize..30,
        ) {
            let g = grids(textures);
            let mut r = Residency::new(&g, ResidencyConfig::new(slots, budget)).unwrap();
            // Every LOD-0 page of texture 0: 256 + 85 wanted pages, far over any cache here.
            let all: Vec<PageId> = (0..16).flat_map(|y| (0..16).map(move |x| PageId::new(0, 0, x, y))).collect();
            let mut last = 0.0;
            for f in 0..busy {
                let u = r.update(f as u64, &all).unwrap();
                prop_assert!(u.lod_bias > last || u.lod_bias == 4.0, "frame {}: {} after {}", f, u.lod_bias, last);
                prop_assert!(u.lod_bias <= 4.0);
                last = u.lod_bias;
            }
            prop_assert!(last >= 2.0);
            // The request shrinks to the root: the bias falls every frame down to 0.
            for f in busy..busy + 20 {
                let u = r.update(f as u64, &[PageId::new(0, 4, 0, 0)]).unwrap();
                prop_assert!(u.lod_bias < last || u.lod_bias == 0.0);
                prop_assert!(u.lod_bias >= 0.0);
                last = u.lod_bias;
            }
            prop_assert_eq!(last, 0.0);
        }
    }
}
