//! Vertical stripes: the pyramid of an image too wide for its bands to fit `--max-memory`.
//!
//! A band holds a few rows of its level's full width, so its memory grows with the width. When
//! that would exceed the budget, the fine LODs `0..J` are made stripe by stripe: each stripe is
//! a run of whole page columns of LOD 0, starting at a multiple of `2^(J-1)` pages so that it
//! starts on a page of every LOD up to `J - 1`, read from the source with a margin of
//! `border x 2^(J-1)` texels on each side (every border it cuts, at every LOD, and every
//! footprint whole). The LODs `J..` are made in one more pass at full width: their first level
//! is summed straight from the source in `2^J x 2^J` blocks, the sums the cascade would have
//! passed down. Every texel therefore comes from the same exact sums as in one band, and the
//! tiles are the same, byte for byte; the source is read once per pass.
//!
//! The plan picks the smallest `J` whose coarse pass fits, then the widest stripe that fits.
//! Only the exact filters can be striped: lanczos3 and mitchell resample each level from the
//! one above across stripe edges.

use crate::error::{Result, TilerError};
use crate::layout::Layout;
use crate::limits::human_bytes;
use crate::limits::read_ahead;
use crate::pyramid::Filter;
use crate::pyramid::cascade::{Span, batch_tiles};

/// The passes of one run, in order: the stripes, then the coarse pass (if any); and how the
/// source is read.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct Plan {
    pub stripes: Vec<Span>,
    pub coarse: Option<Span>,
    /// Rows per chunk the source is read ahead in on its own thread (`source::read_ahead`), 0 to
    /// read it on the producer's: a one-band run reads ahead where the chunks fit the memory
    /// beside the band; a striped run, short of memory already, does not.
    pub read_ahead_rows: u64,
    /// Bytes the plan counts on holding at most: its largest pass's, the read-ahead included
    /// (what `--json`'s `memory.plannedBytes` reports beside what the stages held).
    pub held: u64,
}

impl Plan {
    /// One band over the whole image when it fits `memory`, else stripes.
    pub fn choose(layout: &Layout, texel_bytes: u64, filter: Filter, memory: u64) -> Result<Plan> {
        let whole = Span::whole(layout);
        let need = span_bytes(layout, &whole, texel_bytes);
        if need <= memory {
            let row_bytes = layout.width as u64 * texel_bytes;
            let with_read_ahead = need.saturating_add(read_ahead::bytes(row_bytes));
            let (read_ahead_rows, held) = match with_read_ahead <= memory {
                true => (read_ahead::rows_per_chunk(row_bytes), with_read_ahead),
                false => (0, need),
            };
            return Ok(Plan { stripes: vec![whole], coarse: None, read_ahead_rows, held });
        }
        let too_wide = |need: u64| {
            TilerError::Limit(format!(
                "cutting a {}-texel-wide image into {}-texel tiles (border {}) needs {} at least, more than --max-memory ({}); raise --max-memory",
                layout.width,
                layout.tile_size,
                layout.border,
                human_bytes(need),
                human_bytes(memory)
            ))
        };
        if !filter.is_exact() {
            return Err(TilerError::Limit(format!(
                "{}; --filter {filter} cannot be cut in vertical stripes (it resamples each level across their edges), an exact filter such as the default can",
                too_wide(need)
            )));
        }
        let mut least = need;
        for fine in 1..layout.lod_count {
            let (columns, rows) = layout.grid(fine);
            let coarse = Span { lods: fine..layout.lod_count, columns: 0..columns, rows: 0..rows };
            let coarse_need = coarse_bytes(layout, &coarse, texel_bytes);
            if coarse_need > memory {
                least = least.min(coarse_need);
                continue;
            }
            let unit = 1u32 << (fine - 1);
            let stripe = |units: u32| Span {
                lods: 0..fine,
                columns: 0..(units * unit).min(layout.columns),
                rows: 0..layout.rows,
            };
            let fits = |units: u32| span_bytes(layout, &stripe(units), texel_bytes) <= memory;
            if !fits(1) {
                // Wider units only need more.
                least = least.min(span_bytes(layout, &stripe(1), texel_bytes).max(coarse_need));
                break;
            }
            let max_units = layout.columns.div_ceil(unit);
            let (mut lo, mut hi) = (1, max_units);
            while lo < hi {
                let mid = lo + (hi - lo).div_ceil(2);
                if fits(mid) { lo = mid } else { hi = mid - 1 }
            }
            let pages = lo * unit;
            let stripes = (0..layout.columns.div_ceil(pages))
                .map(|i| Span {
                    lods: 0..fine,
                    columns: i * pages..((i + 1) * pages).min(layout.columns),
                    rows: 0..layout.rows,
                })
                .collect();
            let held = span_bytes(layout, &stripe(lo), texel_bytes).max(coarse_need);
            return Ok(Plan { stripes, coarse: Some(coarse), read_ahead_rows: 0, held });
        }
        Err(too_wide(least))
    }
}

/// Bytes the one-band run of `layout` holds: above this `--max-memory` there are no stripes.
#[cfg_attr(not(feature = "testing"), allow(dead_code))] // the tests pick budgets below it
pub fn one_band_bytes(layout: &Layout, texel_bytes: u64) -> u64 {
    span_bytes(layout, &Span::whole(layout), texel_bytes)
}

/// Bytes one span's cascade holds at once, rounded up generously: per LOD its band (the row of
/// its pages being filled, and the border rows the next one shares with it) and a row of
/// exact sums of its window, and three
/// batches of tiles (a row of its pages, or [`BATCH_BYTES`](crate::pyramid::cascade::BATCH_BYTES)
/// of them: at most four are held at once, over all LODs, being cut, queued, encoded and
/// stored); plus the source row that is read whole.
pub(crate) fn span_bytes(layout: &Layout, span: &Span, texel_bytes: u64) -> u64 {
    let tile = layout.tile_size as u64;
    let source_row = layout.width as u64 * texel_bytes;
    span.lods.clone().fold(source_row, |sum, lod| {
        let window = span.window(layout, lod);
        let width = window.end - window.start;
        let pages = span.columns_at(lod);
        let band = (tile + 2 * layout.border as u64) * (pages.end - pages.start) as u64 * tile * texel_bytes;
        // u64 sums per sample, or u128 for 16-bit samples: 8 bytes per texel byte either way.
        let sums = 8 * width * texel_bytes;
        let per_batch = batch_tiles(layout, texel_bytes as usize) as u64;
        let batches = 3 * ((pages.end - pages.start) as u64).min(per_batch) * tile * tile * texel_bytes;
        sum.saturating_add(band).saturating_add(sums).saturating_add(batches)
    })
}

/// [`span_bytes`] of the coarse pass, plus the block sums it builds from whole source rows
/// (the sums of one coarse row, and one source row as the filter prepares it).
fn coarse_bytes(layout: &Layout, coarse: &Span, texel_bytes: u64) -> u64 {
    let block_sums = 8 * layout.level_extent(coarse.lods.start).0 as u64 * texel_bytes;
    let prepared = 8 * layout.width as u64 * texel_bytes;
    span_bytes(layout, coarse, texel_bytes).saturating_add(block_sums).saturating_add(prepared)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_narrow_image_is_one_band() {
        let l = Layout::new(16384, 16384, 256, 0).unwrap();
        let plan = Plan::choose(&l, 3, Filter::default(), 1 << 30).unwrap();
        assert_eq!((plan.stripes, plan.coarse), (vec![Span::whole(&l)], None));
        assert_eq!(plan.read_ahead_rows, read_ahead::rows_per_chunk(16384 * 3), "read ahead within 1 GiB");
    }

    #[test]
    fn a_wide_image_is_cut_in_aligned_stripes_that_cover_it() {
        let l = Layout::new(200_000, 2000, 256, 4).unwrap();
        let plan = Plan::choose(&l, 3, Filter::default(), 64 << 20).unwrap();
        let coarse = plan.coarse.clone().unwrap();
        let fine = coarse.lods.start;
        assert!(plan.stripes.len() > 1);
        let mut next = 0;
        for s in &plan.stripes {
            assert_eq!((s.lods.clone(), s.columns.start), (0..fine, next));
            assert_eq!(s.columns.start % (1 << (fine - 1)), 0);
            // Every window starts on a whole footprint of its finest LOD's coarsest level.
            assert_eq!(s.window(&l, 0).start % (1 << (fine - 1)), 0);
            assert!(span_bytes(&l, s, 3) <= 64 << 20);
            next = s.columns.end;
        }
        assert_eq!(next, l.columns);
        assert!(coarse_bytes(&l, &coarse, 3) <= 64 << 20);
    }

    #[test]
    fn resampling_filters_are_not_striped() {
        let l = Layout::new(200_000, 2000, 256, 0).unwrap();
        let e = Plan::choose(&l, 3, Filter::Lanczos3, 64 << 20).unwrap_err().to_string();
        assert!(e.contains("--max-memory") && e.contains("lanczos3"), "{e}");
    }

    #[test]
    fn too_little_memory_names_what_is_needed() {
        let l = Layout::new(200_000, 2000, 256, 0).unwrap();
        let e = Plan::choose(&l, 3, Filter::default(), 1 << 20).unwrap_err().to_string();
        assert!(e.contains("--max-memory") && e.contains("1.0 MiB"), "{e}");
    }

    #[test]
    fn huge_tiles_with_tiny_payload_are_refused() {
        let l = Layout::new(1000, 1000, 16384, 8190).unwrap();
        let e = Plan::choose(&l, 3, Filter::default(), 1 << 30).unwrap_err().to_string();
        assert!(e.contains("--max-memory"), "{e}");
    }

    #[test]
    fn the_square_benchmark_fits_in_one_band() {
        // The bound stays near docs/architecture.md's figure for this image.
        let l = Layout::new(16384, 16384, 256, 0).unwrap();
        let need = span_bytes(&l, &Span::whole(&l), 3);
        assert!(need < 128 << 20, "{need}");
    }
}
