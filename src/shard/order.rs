//! The order in which `split --pack` stores its pages, so that `merge` can store the same
//! pages in the same order and write the same bytes.
//!
//! A pack's payloads follow the producer: each row of pages is cut as soon as its level's band
//! holds every row it reads, the levels of one source row in order from LOD 0 down, and the
//! odd rows that end a level are flushed at the end, top-down (`pyramid/cascade.rs`). That
//! order is a function of the page grid and the pass plan alone, so it can be replayed by
//! counting rows, without texels. The pack writer stores a payload the first time it sees
//! its bytes, so replaying the order with the same payloads gives the same file.

use std::ops::Range;

use crate::layout::Layout;
use crate::pyramid::cascade::Span;
use crate::pyramid::cut::last_row_needed;
use crate::pyramid::stripes::Plan;

/// One row of pages, as the cascade cuts and sends it.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct PageRow {
    pub lod: u32,
    pub y: u32,
    pub columns: Range<u32>,
}

/// Every row of pages of `layout`, in the order a run of `plan` sends them to the pack.
pub(crate) fn split_order(layout: &Layout, plan: &Plan) -> Vec<PageRow> {
    let mut rows = Vec::new();
    for span in plan.stripes.iter().chain(&plan.coarse) {
        replay(layout, span, &mut rows);
    }
    rows
}

/// One level of a replayed cascade: rows received, the next page row to cut, and whether
/// its reducer holds half of the next level's row.
struct Level {
    lod: u32,
    height: u32,
    rows_in: u64,
    next: u32,
    end: u32,
    half: bool,
}

/// The page rows one pass over `span` sends, in order: its first level receives every row of
/// its window (source rows, or the coarse pass's block sums), each row cascading down.
fn replay(layout: &Layout, span: &Span, out: &mut Vec<PageRow>) {
    let mut levels: Vec<Level> = span
        .lods
        .clone()
        .map(|lod| {
            let rows = span.rows_at(lod);
            Level {
                lod,
                height: layout.level_extent(lod).1,
                rows_in: span.window_rows(layout, lod).start,
                next: rows.start,
                end: rows.end,
                half: false,
            }
        })
        .collect();
    let first = span.window_rows(layout, span.lods.start);
    for _ in first {
        push(layout, span, &mut levels, 0, out);
    }
    for k in 0..levels.len().saturating_sub(1) {
        if std::mem::take(&mut levels[k].half) {
            push(layout, span, &mut levels, k + 1, out);
        }
    }
}

/// A row arrives at `levels[k]`: cut what it completes, then pass every second row down.
fn push(layout: &Layout, span: &Span, levels: &mut [Level], k: usize, out: &mut Vec<PageRow>) {
    let below = k + 1 < levels.len();
    let level = &mut levels[k];
    level.rows_in += 1;
    while level.next < level.end && level.rows_in > last_row_needed(layout, level.next, level.height) {
        out.push(PageRow { lod: level.lod, y: level.next, columns: span.columns_at(level.lod) });
        level.next += 1;
    }
    if below {
        level.half = !level.half;
        if !level.half {
            push(layout, span, levels, k + 1, out);
        }
    }
}
