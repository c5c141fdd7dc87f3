//! Feedback analysis: from the words of one feedback buffer to the list of pages the frame
//! needs, most urgent first. Runs once per frame on the CPU, so it counts without a hash map:
//! the words are run-length coded along the buffer (neighbouring pixels mostly want the same
//! page), the runs gathered in a small direct-mapped table (which absorbs repeats that are not
//! neighbours), whatever the table evicts and holds at the end sorted and merged, and the
//! ancestors added one LOD at a time. The answer depends only on the multiset of words.
//!
//! Every ancestor of a requested page is part of the answer: when a page is missing the GPU
//! falls back to its finest resident ancestor, so ancestors are what keeps a frame from
//! blurring badly while the fine pages load. An ancestor's `samples` is its own samples plus
//! all of its descendants' (the pixels it stands in for), so the root of a texture counts every
//! valid sample of that texture.
//!
//! Priority, highest first:
//! 1. `distance` = LOD of the finest resident ancestor-or-self minus the page's LOD: how many
//!    LODs too coarse its pixels are drawn now (0 for a resident page);
//! 2. `samples`, more first;
//! 3. `PageId` ascending, so that equal pages never depend on input or hash order.
//!
//! Resident pages (distance 0) are listed too, last among equals, so that the cache can mark
//! them used this frame.

use crate::feedback::{INDEX_MASK, LOD_SHIFT, NO_REQUEST, NO_REQUEST_LOD, decode};
use crate::page::{PageId, TextureGrid};

/// One page the frame needs.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct PageRequest {
    /// The page.
    pub page: PageId,
    /// Samples that asked for exactly this page (0 for a page only needed as an ancestor).
    pub direct: u32,
    /// Samples of this page and of all its descendants.
    pub samples: u32,
    /// LOD of the finest resident ancestor-or-self minus this page's LOD; with nothing resident
    /// at all, `lod_count` minus this page's LOD (one more than the root would give).
    pub distance: u8,
}

/// The result of analysing one feedback buffer.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub struct Analysis {
    /// Every requested page and every ancestor of one, in priority order (see the module doc).
    pub requests: Vec<PageRequest>,
    /// Distinct pages asked for directly (the figure to hold against a high-water mark).
    pub requested: usize,
    /// Words that asked for a valid page.
    pub samples: u32,
    /// Words with "no request" (LOD field 15).
    pub no_request: u32,
    /// Words naming an unknown texture or a page outside its texture's grid; skipped.
    pub invalid: u32,
}

/// Feedback analysis with its scratch buffers, to reuse from frame to frame without allocating.
#[derive(Debug, Default)]
pub struct Analyzer {
    /// `(word << 32) | count`, sorted, then merged in place.
    runs: Vec<u64>,
    /// The direct-mapped table in front of `runs`, `(word << 32) | count` or `EMPTY`.
    slots: Vec<u64>,
    /// The pages of the current LOD of one texture: `(word, direct, samples)`, sorted by word.
    level: Vec<(u32, u32, u32)>,
    /// The parents of `level`, `(word << 32) | samples`.
    parents: Vec<u64>,
    result: Analysis,
}

impl Analyzer {
    /// An analyzer with nothing seen yet.
    pub fn new() -> Analyzer {
        Analyzer::default()
    }

    /// Analyses one feedback buffer. `grids[t]` is the page grid of texture id `t`;
    /// `resident_lod(p)` answers the LOD of the finest resident ancestor-or-self of `p`, or
    /// `None` when none is resident. Panics if there are more than `u32::MAX` words.
    pub fn analyze(
        &mut self,
        words: &[u32],
        grids: &[TextureGrid],
        mut resident_lod: impl FnMut(PageId) -> Option<u8>,
    ) -> &Analysis {
        assert!(u32::try_from(words.len()).is_ok(), "a feedback buffer of {} words", words.len());
        let r = &mut self.result;
        r.requests.clear();
        (r.requested, r.samples, r.no_request, r.invalid) = (0, 0, 0, 0);

        // Run-length code, dropping "no request", through the table.
        self.runs.clear();
        self.slots.clear();
        self.slots.resize(SLOTS, EMPTY);
        let mut it = words.iter().copied();
        if let Some(first) = it.next() {
            let (mut word, mut count) = (first, 1u32);
            for w in it {
                if w == word {
                    count += 1;
                } else {
                    push_run(&mut self.slots, &mut self.runs, &mut r.no_request, word, count);
                    (word, count) = (w, 1);
                }
            }
            push_run(&mut self.slots, &mut self.runs, &mut r.no_request, word, count);
        }
        self.runs.extend(self.slots.iter().filter(|&&s| s != EMPTY));

        // Sort and merge equal words, validating each distinct word once.
        self.runs.sort_unstable();
        let mut kept = 0;
        let mut i = 0;
        while i < self.runs.len() {
            let word = (self.runs[i] >> 32) as u32;
            let mut count = 0u32;
            while i < self.runs.len() && (self.runs[i] >> 32) as u32 == word {
                count += self.runs[i] as u32;
                i += 1;
            }
            let valid = decode(word).and_then(|r| r.page(grids)).is_some();
            if valid {
                r.samples += count;
                self.runs[kept] = (word as u64) << 32 | count as u64;
                kept += 1;
            } else {
                r.invalid += count;
            }
        }
        self.runs.truncate(kept);
        r.requested = kept;

        // Per texture, per LOD from the finest: this LOD's direct requests merged with the
        // parents of the LOD below.
        let mut start = 0;
        while start < self.runs.len() {
            let texture = (self.runs[start] >> 60) as usize;
            let end = start + self.runs[start..].partition_point(|&r| (r >> 60) as usize == texture);
            let grid = grids[texture];
            let mut direct = &self.runs[start..end];
            self.parents.clear();
            for lod in 0..grid.lod_count() {
                let n = direct.partition_point(|&r| lod_of((r >> 32) as u32) == lod);
                merge(&direct[..n], &self.parents, &mut self.level);
                direct = &direct[n..];
                if self.level.is_empty() {
                    continue;
                }
                self.parents.clear();
                let rows = [grid.pages_at(lod)[0], grid.pages_at(lod + 1)[0]].map(u32::from);
                for &(word, _, samples) in &self.level {
                    let p = (parent(word, rows) as u64) << 32 | samples as u64;
                    match self.parents.last_mut() {
                        // Horizontal neighbours share a parent: merge them before sorting.
                        Some(last) if *last >> 32 == p >> 32 => *last += samples as u64,
                        _ => self.parents.push(p),
                    }
                }
                self.parents.sort_unstable();
                merge_in_place(&mut self.parents);
                for &(word, direct, samples) in &self.level {
                    // Every word in `level` named a page of `grid` when it was collected (its
                    // parents are in the grid too).
                    let Some(page) = decode(word).and_then(|r| grid.page_at_index(r.texture, r.lod, r.index)) else {
                        continue;
                    };
                    let resident = resident_lod(page).unwrap_or(grid.lod_count());
                    let distance = resident.saturating_sub(page.lod);
                    r.requests.push(PageRequest { page, direct, samples, distance });
                }
            }
            start = end;
        }

        r.requests.sort_unstable_by_key(priority_key);
        &self.result
    }
}

/// Analyses one feedback buffer with fresh scratch buffers; see [`Analyzer::analyze`].
pub fn analyze(words: &[u32], grids: &[TextureGrid], resident_lod: impl FnMut(PageId) -> Option<u8>) -> Analysis {
    let mut a = Analyzer::new();
    a.analyze(words, grids, resident_lod);
    a.result
}

/// Orders as `(Reverse(distance), Reverse(samples), page)`, in one integer (faster to sort).
fn priority_key(q: &PageRequest) -> u128 {
    let p = q.page;
    let page = (p.texture as u64) << 48 | (p.lod as u64) << 32 | (p.x as u64) << 16 | p.y as u64;
    ((!q.distance) as u128) << 96 | ((!q.samples) as u128) << 64 | page as u128
}

/// Slots of the direct-mapped table: enough for the few hundred pages of a frame.
const SLOTS: usize = 4096;
/// An empty slot: the "no request" word, which never enters the table.
const EMPTY: u64 = (NO_REQUEST as u64) << 32;

#[inline(always)]
fn push_run(slots: &mut [u64], runs: &mut Vec<u64>, no_request: &mut u32, word: u32, count: u32) {
    if lod_of(word) == NO_REQUEST_LOD {
        *no_request += count;
        return;
    }
    // Fibonacci hashing; `SLOTS` is 2^12.
    let slot = &mut slots[(word.wrapping_mul(0x9E37_79B9) >> 20) as usize];
    if (*slot >> 32) as u32 == word {
        *slot += count as u64;
    } else {
        if *slot != EMPTY {
            runs.push(*slot);
        }
        *slot = (word as u64) << 32 | count as u64;
    }
}

fn lod_of(word: u32) -> u8 {
    (word >> LOD_SHIFT & 0xF) as u8
}

/// The word of the parent page: x and y halved, LOD plus one, same texture. `rows` are the
/// pages per row of the word's LOD and of the next; the index is row by row in each.
fn parent(word: u32, rows: [u32; 2]) -> u32 {
    let index = word & INDEX_MASK;
    let (x, y) = (index % rows[0], index / rows[0]);
    ((word & !INDEX_MASK) + (1 << LOD_SHIFT)) | ((y >> 1) * rows[1] + (x >> 1))
}

/// Merges equal words of sorted `(word << 32) | count` entries, summing the counts.
fn merge_in_place(v: &mut Vec<u64>) {
    let mut kept = 0;
    for i in 0..v.len() {
        if kept > 0 && v[kept - 1] >> 32 == v[i] >> 32 {
            v[kept - 1] += v[i] & 0xFFFF_FFFF;
        } else {
            v[kept] = v[i];
            kept += 1;
        }
    }
    v.truncate(kept);
}

/// Merges sorted direct requests and sorted descendant sums (both `(word << 32) | count`, no
/// duplicates within either) into `(word, direct, samples)`.
fn merge(direct: &[u64], below: &[u64], out: &mut Vec<(u32, u32, u32)>) {
    out.clear();
    let (mut i, mut j) = (0, 0);
    loop {
        let d = direct.get(i).map(|&r| ((r >> 32) as u32, r as u32));
        let b = below.get(j).map(|&r| ((r >> 32) as u32, r as u32));
        match (d, b) {
            (Some((dw, dc)), Some((bw, bc))) if dw == bw => {
                out.push((dw, dc, dc + bc));
                (i, j) = (i + 1, j + 1);
            }
            (Some((dw, dc)), Some((bw, _))) if dw < bw => {
                out.push((dw, dc, dc));
                i += 1;
            }
            (Some((dw, dc)), None) => {
                out.push((dw, dc, dc));
                i += 1;
            }
            (_, Some((bw, bc))) => {
                out.push((bw, 0, bc));
                j += 1;
            }
            (None, None) => break,
        }
    }
}

#[cfg(test)]
mod tests {
    use std::cmp::Reverse;
    use std::collections::BTreeMap;

    use proptest::prelude::*;

    use super::*;
    use crate::feedback::{decode, encode, encode_index};

    /// The naive oracle: a map over every ancestor of every word.
    fn naive(words: &[u32], grids: &[TextureGrid], resident_lod: impl Fn(PageId) -> Option<u8>) -> Analysis {
        let mut a = Analysis::default();
        let mut map: BTreeMap<PageId, (u32, u32)> = BTreeMap::new();
        for &w in words {
            let Some(r) = decode(w) else {
                a.no_request += 1;
                continue;
            };
            let Some((p, g)) = r.page(grids).map(|p| (p, &grids[p.texture as usize])) else {
                a.invalid += 1;
                continue;
            };
            a.samples += 1;
            map.entry(p).or_default().0 += 1;
            for q in p.ancestors_and_self(g) {
                map.entry(q).or_default().1 += 1;
            }
        }
        a.requested = map.values().filter(|e| e.0 > 0).count();
        a.requests = map
            .into_iter()
            .map(|(page, (direct, samples))| {
                let lod_count = grids[page.texture as usize].lod_count();
                let distance = resident_lod(page).unwrap_or(lod_count).saturating_sub(page.lod);
                PageRequest { page, direct, samples, distance }
            })
            .collect();
        a.requests.sort_by_key(|q| (Reverse(q.distance), Reverse(q.samples), q.page));
        a
    }

    /// Resident: the root of each texture and, of texture 0, LOD 2 pages with even x.
    fn resident(p: PageId, grids: &[TextureGrid]) -> Option<u8> {
        let g = &grids[p.texture as usize];
        p.ancestors_and_self(g)
            .find(|q| q.lod == g.lod_count() - 1 || (q.texture == 0 && q.lod == 2 && q.x % 2 == 0))
            .map(|q| q.lod)
    }

    /// A wide grid with odd rows, a tall one and a single page.
    fn grids() -> Vec<TextureGrid> {
        vec![TextureGrid::new(21, 5).unwrap(), TextureGrid::new(3, 10).unwrap(), TextureGrid::new(1, 1).unwrap()]
    }

    #[test]
    fn counts_ancestors_and_priorities() {
        let g = [TextureGrid::new(4, 4).unwrap()]; // LODs 0 (4x4), 1 (2x2), 2 (1x1)
        let w = |lod, x, y| encode(PageId::new(0, lod, x, y), &g[0]);
        let words = [w(0, 3, 3), w(0, 3, 3), w(0, 3, 3), w(0, 0, 0), w(1, 1, 1), NO_REQUEST, w(0, 0, 0)];
        // Only the root is resident.
        let a = analyze(&words, &g, |_| Some(2));
        assert_eq!((a.samples, a.no_request, a.invalid, a.requested), (6, 1, 0, 3));
        let r = |lod, x, y, direct, samples, distance| PageRequest {
            page: PageId::new(0, lod, x, y),
            direct,
            samples,
            distance,
        };
        assert_eq!(
            a.requests,
            [
                r(0, 3, 3, 3, 3, 2), // distance 2, more samples first
                r(0, 0, 0, 2, 2, 2),
                r(1, 1, 1, 1, 4, 1), // its own sample plus (3, 3)'s
                r(1, 0, 0, 0, 2, 1), // an ancestor only
                r(2, 0, 0, 0, 6, 0), // the root: every sample, resident
            ]
        );
    }

    #[test]
    fn nothing_resident_ranks_beyond_the_root() {
        let g = [TextureGrid::new(2, 2).unwrap()];
        let nothing: &dyn Fn(PageId) -> Option<u8> = &|_| None; // a `dyn Fn` works too
        let a = analyze(&[encode(PageId::new(0, 0, 1, 0), &g[0])], &g, nothing);
        let d: Vec<(u8, u8)> = a.requests.iter().map(|q| (q.page.lod, q.distance)).collect();
        assert_eq!(d, [(0, 2), (1, 1)]);
    }

    #[test]
    fn invalid_words_are_counted_and_skipped() {
        let g = grids();
        let words = [
            encode_index(3, 0, 0),  // unknown texture
            encode_index(1, 0, 30), // past the 3x10 pages of LOD 0
            encode_index(1, 1, 10), // past LOD 1's 2x5
            encode_index(1, 5, 0),  // LOD beyond the grid's 5
            encode_index(2, 0, 0),  // valid: the 1-page texture
            0x3F00_0000,            // no request (LOD 15), other bits not all set
            NO_REQUEST,
        ];
        let a = analyze(&words, &g, |p| resident(p, &g));
        assert_eq!((a.samples, a.no_request, a.invalid, a.requested), (1, 2, 4, 1));
        assert_eq!(a.requests, [PageRequest { page: PageId::new(2, 0, 0, 0), direct: 1, samples: 1, distance: 0 }]);
        assert_eq!(analyze(&[], &g, |_| None), Analysis::default());
    }

    #[test]
    fn reuse_gives_the_same_answer() {
        let g = grids();
        let words: Vec<u32> = (0..500u32).map(|i| encode_index(0, (i % 3) as u8, i % 37 + (i / 37) * 4)).collect();
        let mut an = Analyzer::new();
        let first = an.analyze(&words, &g, |p| resident(p, &g)).clone();
        an.analyze(&[NO_REQUEST; 7], &g, |_| None);
        assert_eq!(an.analyze(&words, &g, |p| resident(p, &g)), &first);
        assert_eq!(first, naive(&words, &g, |p| resident(p, &g)));
    }

    #[test]
    fn more_distinct_pages_than_table_slots() {
        // 4096 + 1024 distinct pages, each twice, far apart: the table must evict and the
        // evicted counts must still add up.
        let g = [TextureGrid::new(128, 32).unwrap()];
        let mut words: Vec<u32> = (0..2u8)
            .flat_map(|lod| (0..32u16 >> lod).flat_map(move |y| (0..128u16 >> lod).map(move |x| (lod, x, y))))
            .map(|(lod, x, y)| encode(PageId::new(0, lod, x, y), &g[0]))
            .collect();
        words.extend(words.clone().iter().rev());
        assert!(words.len() / 2 > SLOTS);
        let resident = |p: PageId| Some(p.lod.max(3));
        let a = analyze(&words, &g, resident);
        assert_eq!(a.requested, 5120);
        assert_eq!(a, naive(&words, &g, resident));
    }

    /// Words mostly valid, with runs (as neighbouring pixels give), some invalid and no-request.
    fn feedback_words() -> impl Strategy<Value = Vec<u32>> {
        let word = prop_oneof![
            // Indices a little past the largest level (105 pages), so some are invalid.
            8 => (0u8..3, 0u8..6, 0u32..120).prop_map(|(t, l, i)| encode_index(t, l, i)),
            1 => Just(NO_REQUEST),
            1 => any::<u32>(),
        ];
        proptest::collection::vec((word, 1usize..6), 0..300)
            .prop_map(|runs| runs.into_iter().flat_map(|(w, n)| std::iter::repeat_n(w, n)).collect())
    }

    proptest! {
        #[test]
        fn matches_the_naive_oracle(words in feedback_words()) {
            let g = grids();
            let fast = analyze(&words, &g, |p| resident(p, &g));
            prop_assert_eq!(&fast, &naive(&words, &g, |p| resident(p, &g)));
            prop_assert_eq!(fast.samples + fast.no_request + fast.invalid, words.len() as u32);
        }

        #[test]
        fn input_order_does_not_matter(words in feedback_words(), seed in any::<u64>()) {
            let g = grids();
            let mut shuffled = words.clone();
            // Fisher-Yates with a small xorshift: deterministic per seed.
            let mut s = seed | 1;
            for i in (1..shuffled.len()).rev() {
                s ^= s << 13;
                s ^= s >> 7;
                s ^= s << 17;
                shuffled.swap(i, (s % (i as u64 + 1)) as usize);
            }
            prop_assert_eq!(analyze(&words, &g, |p| resident(p, &g)), analyze(&shuffled, &g, |p| resident(p, &g)));
        }
    }
}
