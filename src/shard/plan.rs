//! Which shard makes which pages: the cut level and the regions.
//!
//! The pages of the cut level `K` are roots of subtrees: page (x, y) of LOD `K` and every page
//! below it, down to the LOD-0 pages `[x 2^K, (x + 1) 2^K) x [y 2^K, (y + 1) 2^K)` (clipped to
//! the grid, as nested ceilings compose). A shard makes whole subtrees, so it needs nothing of
//! its neighbours' pages but the margin of texels its borders read, and the levels above `K`
//! are made at `merge` from the exact sums of the roots.
//!
//! Subtrees are taken in row-major order and cut into `N` runs of about the same weight: the
//! real pages of the subtree over LODs `0..=K` (a subtree at the right or bottom edge holds
//! fewer than `4^K`-ish pages, so equal areas would not be equal work). `K` is the coarsest
//! level whose runs are within [`BALANCE`] of the mean: coarse levels leave less for `merge`
//! (the sums of the level-`K` texels, and the levels above), fine ones balance better.
//! A run is a rectangle or up to three (the end of one row of roots, whole rows, the start of
//! another), each read from the source with its margin as one pass.

use std::ops::Range;

use crate::error::{Result, TilerError};
use crate::layout::Layout;
use crate::pyramid::cascade::Span;

/// The heaviest shard may hold this much more than the mean.
pub const BALANCE: f64 = 1.1;

/// The shards of one image, the same for every shard and for `merge`: computed from the
/// layout and the shard count alone.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct ShardPlan {
    /// The cut level `K`: shards make LODs `0..=K`, `merge` the rest.
    pub cut: u32,
    /// Per shard, its run of subtrees: indices of LOD-`K` pages in row-major order.
    pub runs: Vec<Range<u64>>,
    /// Columns of LOD `K`'s page grid.
    columns: u32,
}

/// A rectangle of subtree roots: page columns and rows of the cut level.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct Region {
    pub columns: Range<u32>,
    pub rows: Range<u32>,
}

impl ShardPlan {
    /// Cuts `layout` into `count` shards.
    pub fn choose(layout: &Layout, count: u32) -> Result<ShardPlan> {
        let top = layout.lod_count - 1;
        let (c0, r0) = layout.grid(0);
        let most = c0 as u64 * r0 as u64;
        if count == 0 || count as u64 > most {
            return Err(TilerError::Options(format!(
                "{count} shards for {most} pages: a shard makes at least one page ({}x{} pages at LOD 0); use 1 to {most} shards",
                c0, r0
            )));
        }
        let mut best: Option<(f64, ShardPlan)> = None;
        for cut in (0..=top).rev() {
            let weights = subtree_weights(layout, cut);
            if (weights.len() as u64) < count as u64 {
                continue;
            }
            let runs = partition(&weights, count);
            let total: u64 = weights.iter().sum();
            let heaviest = runs.iter().map(|r| weights[r.start as usize..r.end as usize].iter().sum::<u64>()).max();
            let imbalance = heaviest.unwrap_or(0) as f64 * count as f64 / total as f64;
            let plan = ShardPlan { cut, runs, columns: layout.grid(cut).0 };
            if imbalance <= BALANCE {
                return Ok(plan);
            }
            if best.as_ref().is_none_or(|(b, _)| imbalance < *b) {
                best = Some((imbalance, plan));
            }
        }
        // No level balances within BALANCE (a few pages for many shards): the best one.
        best.map(|(_, plan)| plan)
            .ok_or_else(|| TilerError::Options(format!("no level of the pyramid has {count} pages or more")))
    }

    pub fn count(&self) -> u32 {
        self.runs.len() as u32
    }

    /// The shard that makes page (x, y) of `lod` (`lod <= cut`).
    pub fn owner(&self, lod: u32, x: u32, y: u32) -> u32 {
        let k = self.cut - lod;
        let root = (y >> k) as u64 * self.columns as u64 + (x >> k) as u64;
        self.runs.partition_point(|r| r.end <= root) as u32
    }

    /// The rectangles of roots shard `index` makes, top to bottom.
    pub fn regions(&self, index: u32) -> Vec<Region> {
        let run = &self.runs[index as usize];
        let w = self.columns as u64;
        let (first_row, first_col) = ((run.start / w) as u32, (run.start % w) as u32);
        let (last_row, end_col) = (((run.end - 1) / w) as u32, ((run.end - 1) % w + 1) as u32);
        let row = |y: u32, columns: Range<u32>| Region { columns, rows: y..y + 1 };
        if first_row == last_row {
            return vec![row(first_row, first_col..end_col)];
        }
        let mut regions = Vec::new();
        let mut whole = first_row..last_row + 1;
        if first_col > 0 {
            regions.push(row(first_row, first_col..self.columns));
            whole.start += 1;
        }
        let tail = (end_col < self.columns).then(|| row(last_row, 0..end_col));
        if tail.is_some() {
            whole.end -= 1;
        }
        if !whole.is_empty() {
            regions.push(Region { columns: 0..self.columns, rows: whole });
        }
        regions.extend(tail);
        regions
    }

    /// Whether the merge makes levels above the cut (from the roots' sums).
    pub fn has_levels_above(&self, layout: &Layout) -> bool {
        self.cut + 1 < layout.lod_count
    }

    /// The texels of the level above the cut whose sums `region` contributes to: its roots'
    /// texels, halved (rounding outwards: an odd edge is shared with the neighbour).
    pub fn sums_rect(&self, layout: &Layout, region: &Region) -> (Range<u64>, Range<u64>) {
        let p = layout.payload() as u64;
        let (width, height) = layout.level_extent(self.cut);
        let texels = |pages: &Range<u32>, extent: u32| {
            let (start, end) = (pages.start as u64 * p, (pages.end as u64 * p).min(extent as u64));
            start / 2..end.div_ceil(2)
        };
        (texels(&region.columns, width), texels(&region.rows, height))
    }

    /// The span of LOD 0 pages (and the LODs up to the cut) of `region`.
    pub(crate) fn span(&self, layout: &Layout, region: &Region) -> Span {
        let k = self.cut;
        let clip = |r: &Range<u32>, n: u32| (r.start << k).min(n)..(r.end << k).min(n);
        Span { lods: 0..k + 1, columns: clip(&region.columns, layout.columns), rows: clip(&region.rows, layout.rows) }
    }
}

/// Real pages over LODs `0..=cut` under each page of LOD `cut`, row-major.
fn subtree_weights(layout: &Layout, cut: u32) -> Vec<u64> {
    let (columns, rows) = layout.grid(cut);
    let mut weights = Vec::with_capacity(columns as usize * rows as usize);
    for y in 0..rows {
        for x in 0..columns {
            let pages = (0..=cut).map(|lod| {
                let k = cut - lod;
                let (w, h) = layout.grid(lod);
                let across = ((x + 1) << k).min(w) - (x << k);
                let down = ((y + 1) << k).min(h) - (y << k);
                across as u64 * down as u64
            });
            weights.push(pages.sum());
        }
    }
    weights
}

/// `count` contiguous, non-empty runs of `weights` (`count <= weights.len()`): run `i` ends
/// where the running total comes nearest `i + 1` shares of the whole.
fn partition(weights: &[u64], count: u32) -> Vec<Range<u64>> {
    let total: u128 = weights.iter().map(|&w| w as u128).sum();
    let n = weights.len() as u64;
    let mut runs = Vec::with_capacity(count as usize);
    let (mut start, mut sum) = (0u64, 0u128);
    for i in 1..=count as u64 {
        let target = total * i as u128 / count as u128;
        // Leave at least one root for each shard still to come; the last takes the rest.
        let last = if i == count as u64 { n } else { n - (count as u64 - i) };
        let mut end = start;
        while end < last && (end == start || i == count as u64 || sum + weights[end as usize] as u128 <= target) {
            sum += weights[end as usize] as u128;
            end += 1;
        }
        // One more root if that lands nearer the target.
        if end < last && sum < target && (target - sum) * 2 > weights[end as usize] as u128 {
            sum += weights[end as usize] as u128;
            end += 1;
        }
        runs.push(start..end);
        start = end;
    }
    runs
}

#[cfg(test)]
mod tests {
    use super::*;

    fn weight(layout: &Layout, plan: &ShardPlan, index: u32) -> u64 {
        let w = subtree_weights(layout, plan.cut);
        w[plan.runs[index as usize].start as usize..plan.runs[index as usize].end as usize].iter().sum()
    }

    #[test]
    fn every_page_has_one_owner_and_regions_cover_the_runs() {
        for (w, h, tile, n) in
            [(16384, 16384, 256, 16), (1000, 700, 64, 7), (200_000, 2000, 256, 16), (300, 5000, 32, 5)]
        {
            let l = Layout::new(w, h, tile, 0).unwrap();
            let plan = ShardPlan::choose(&l, n).unwrap();
            assert_eq!(plan.count(), n);
            let (cw, ch) = l.grid(plan.cut);
            let mut seen = vec![u32::MAX; (cw * ch) as usize];
            for i in 0..n {
                assert!(!plan.runs[i as usize].is_empty());
                for r in plan.regions(i) {
                    for y in r.rows.clone() {
                        for x in r.columns.clone() {
                            let at = (y * cw + x) as usize;
                            assert_eq!(seen[at], u32::MAX, "root ({x}, {y}) in two regions");
                            seen[at] = i;
                            assert_eq!(plan.owner(plan.cut, x, y), i);
                        }
                    }
                }
            }
            assert!(seen.iter().all(|&s| s != u32::MAX));
            // A LOD-0 page belongs to its root's shard.
            let (x, y) = (l.columns - 1, l.rows - 1);
            let k = plan.cut;
            assert_eq!(plan.owner(0, x, y), plan.owner(k, x >> k, y >> k));
        }
    }

    #[test]
    fn shards_are_balanced_by_real_pages() {
        for (w, h, n) in
            [(16384, 16384, 16), (16384, 131_072, 16), (16384, 16384, 64), (200_000, 2000, 16), (16384, 16384, 3)]
        {
            let l = Layout::new(w, h, 256, 0).unwrap();
            let plan = ShardPlan::choose(&l, n).unwrap();
            let weights: Vec<u64> = (0..n).map(|i| weight(&l, &plan, i)).collect();
            let mean = weights.iter().sum::<u64>() as f64 / n as f64;
            let max = *weights.iter().max().unwrap() as f64;
            assert!(max <= BALANCE * mean, "{w}x{h} in {n}: cut {}, weights {weights:?}", plan.cut);
        }
    }

    #[test]
    fn the_coarsest_balanced_level_is_cut() {
        let l = Layout::new(16384, 16384, 256, 0).unwrap();
        // 64 x 64 pages: 16 shards are the 16 subtrees of LOD 4, one each.
        let plan = ShardPlan::choose(&l, 16).unwrap();
        assert_eq!((plan.cut, plan.regions(5)), (4, vec![Region { columns: 1..2, rows: 1..2 }]));
        assert_eq!(ShardPlan::choose(&l, 1).unwrap().cut, l.lod_count - 1);
    }

    #[test]
    fn a_run_across_rows_is_up_to_three_rectangles() {
        let plan = ShardPlan { cut: 0, runs: vec![0..3, 3..13, 13..16], columns: 4 };
        assert_eq!(
            plan.regions(1),
            vec![
                Region { columns: 3..4, rows: 0..1 },
                Region { columns: 0..4, rows: 1..3 },
                Region { columns: 0..1, rows: 3..4 }
            ]
        );
        assert_eq!(plan.regions(0), vec![Region { columns: 0..3, rows: 0..1 }]);
    }

    #[test]
    fn more_shards_than_pages_is_an_error() {
        let l = Layout::new(100, 100, 64, 0).unwrap();
        let e = ShardPlan::choose(&l, 5).unwrap_err().to_string();
        assert!(e.contains("5 shards for 4 pages"), "{e}");
    }
}
