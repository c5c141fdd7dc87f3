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
//! The plan picks the smallest `J` whose coarse pass and narrowest stripe fit, then the widest
//! stripe that fits; what fits counts every part a run holds at once, the source's decoder
//! and the tiles in flight included ([`Plan::held`]).
//! Only the exact filters can be striped: lanczos3 and mitchell resample each level from the
//! one above across stripe edges.

use crate::error::{Result, TilerError};
use crate::layout::Layout;
use crate::limits::human_bytes;
use crate::limits::in_flight::{QUEUE_BATCHES, most_tiles_in_lots};
use crate::limits::read_ahead;
use crate::pyramid::Filter;
use crate::pyramid::band;
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
    /// Bytes the run holds at most, every part the stages count (`limits::Part`) at once, in
    /// its largest pass: what `--json`'s `memory.plannedBytes` reports beside what they held.
    pub held: u64,
}

impl Plan {
    /// Times the source is read: once per stripe, and once more for the coarse levels.
    pub fn passes(&self) -> usize {
        self.stripes.len() + self.coarse.is_some() as usize
    }
}

/// What a run holds beside its passes' cascades, which the plan counts in every pass.
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub(crate) struct Beside {
    /// The source decoder's buffers at most (`RowSource::most_buffer_bytes`).
    pub decoder: u64,
    /// One tile's encoding at most, while it waits for an ordered sink's writer
    /// (`Codec::most_encoded_bytes`); 0 where the sink stores each tile as it is encoded.
    pub encoded_tile: u64,
    /// Some of the finest level's pages are copied from the source as stored: a page's copy is
    /// held while its texels still are (each other encoding is made after they are freed).
    pub copies: bool,
}

impl Plan {
    /// One band over the whole image when it fits `memory` with everything `beside` it, else
    /// stripes. Nothing depends on the thread count, so that neither does a pack's order.
    pub fn choose(layout: &Layout, texel_bytes: u64, filter: Filter, memory: u64, beside: Beside) -> Result<Plan> {
        let whole = Span::whole(layout);
        let row_bytes = layout.width as u64 * texel_bytes;
        let held = |cascades: u64, batch: u64| {
            beside.decoder.saturating_add(cascades).saturating_add(in_flight_bytes(layout, batch, texel_bytes, beside))
        };
        let one_band = held(cascade_bytes(layout, &whole, texel_bytes), pass_batch(layout, &whole, texel_bytes));
        let need = one_band.saturating_add(row_bytes);
        if need <= memory {
            // The chunks read ahead take the place of the one row read on the producer's thread.
            let with_read_ahead = one_band.saturating_add(read_ahead::bytes(row_bytes, texel_bytes));
            let (read_ahead_rows, held) = match with_read_ahead <= memory {
                true => (read_ahead::rows_per_chunk(row_bytes), with_read_ahead),
                false => (0, need),
            };
            return Ok(Plan { stripes: vec![whole], coarse: None, read_ahead_rows, held });
        }
        let too_wide = |need: u64| {
            let decoder = match beside.decoder {
                0 => String::new(),
                bytes => format!(" (the source's decoder holds {} of it)", human_bytes(bytes)),
            };
            TilerError::Limit(format!(
                "cutting a {}-texel-wide image into {}-texel tiles (border {}) needs {} at least{decoder}, more than --max-memory ({}); raise --max-memory",
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
            let coarse_cascade = coarse_bytes(layout, &coarse, texel_bytes);
            let coarse_batch = pass_batch(layout, &coarse, texel_bytes);
            let coarse_need = held(coarse_cascade, coarse_batch);
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
            // Tiles of a pass may still be in flight while the next one runs: the largest
            // batch of either counts for both.
            let need = |units: u32| {
                let stripe = stripe(units);
                let cascades = (cascade_bytes(layout, &stripe, texel_bytes) + row_bytes).max(coarse_cascade);
                held(cascades, pass_batch(layout, &stripe, texel_bytes).max(coarse_batch))
            };
            if need(1) > memory {
                // A finer split's stripes are wider, but its coarse pass, and its batches in
                // flight beside every stripe, are smaller: it may still fit.
                least = least.min(need(1));
                continue;
            }
            let max_units = layout.columns.div_ceil(unit);
            let (mut lo, mut hi) = (1, max_units);
            while lo < hi {
                let mid = lo + (hi - lo).div_ceil(2);
                if need(mid) <= memory { lo = mid } else { hi = mid - 1 }
            }
            let pages = lo * unit;
            let stripes = (0..layout.columns.div_ceil(pages))
                .map(|i| Span {
                    lods: 0..fine,
                    columns: i * pages..((i + 1) * pages).min(layout.columns),
                    rows: 0..layout.rows,
                })
                .collect();
            return Ok(Plan { stripes, coarse: Some(coarse), read_ahead_rows: 0, held: need(lo) });
        }
        Err(too_wide(least))
    }
}

/// Bytes the one-band run of `layout` holds from rows in memory into a sink that stores tiles
/// as they are encoded, read on the producer's thread: above this `--max-memory` there are no
/// stripes.
#[cfg_attr(not(feature = "testing"), allow(dead_code))] // the tests pick budgets below it
pub fn one_band_bytes(layout: &Layout, texel_bytes: u64) -> u64 {
    span_bytes(layout, &Span::whole(layout), texel_bytes)
}

/// Bytes one span's pass holds at once from rows in memory into a sink that stores tiles as
/// they are encoded: its cascade, its tiles in flight and one source row read whole (a shard's
/// region, which checks it against `--max-memory` beside its roots' sums).
pub(crate) fn span_bytes(layout: &Layout, span: &Span, texel_bytes: u64) -> u64 {
    let in_flight = in_flight_bytes(layout, pass_batch(layout, span, texel_bytes), texel_bytes, Beside::default());
    let source_row = layout.width as u64 * texel_bytes;
    cascade_bytes(layout, span, texel_bytes).saturating_add(in_flight).saturating_add(source_row)
}

/// Bytes one span's cascade holds at once, per LOD: its band (`band::most_bytes`) and a row of
/// exact sums of its window (u64 sums per sample, or u128 for 16-bit samples: 8 bytes per
/// texel byte either way; not counted by the gauge, but held).
fn cascade_bytes(layout: &Layout, span: &Span, texel_bytes: u64) -> u64 {
    span.lods.clone().fold(0, |sum: u64, lod| {
        let window = span.window(layout, lod);
        let pages = span.columns_at(lod);
        let band = band::most_bytes(layout, (pages.end - pages.start) as u64, texel_bytes);
        sum.saturating_add(band).saturating_add(8 * (window.end - window.start) * texel_bytes)
    })
}

/// Tiles of the largest batch a span's pass sends: a row of its first LOD's pages, at most
/// [`batch_tiles`].
fn pass_batch(layout: &Layout, span: &Span, texel_bytes: u64) -> u64 {
    let pages = span.columns_at(span.lods.start);
    ((pages.end - pages.start) as u64).min(batch_tiles(layout, texel_bytes as usize) as u64)
}

/// Bytes of the tiles cut and not yet stored, where batches hold at most `batch` tiles: those
/// queued for the encoders ([`QUEUE_BATCHES`]; the one the
/// cutting thread is sending is its band's row of tiles, counted there), and the encoders' lots
/// ([`most_tiles_in_lots`]), each of whose tiles is its texels until they are encoded and then
/// its encoding, waiting for an ordered sink's writer (both at once where pages are copied).
fn in_flight_bytes(layout: &Layout, batch: u64, texel_bytes: u64, beside: Beside) -> u64 {
    let tile = band::most_tile_bytes(layout, texel_bytes);
    let in_lots = match beside.copies {
        true => tile.saturating_add(beside.encoded_tile),
        false => tile.max(beside.encoded_tile),
    };
    let sent = (QUEUE_BATCHES as u64).saturating_mul(batch).saturating_mul(tile);
    sent.saturating_add(most_tiles_in_lots(batch).saturating_mul(in_lots))
}

/// [`cascade_bytes`] of the coarse pass, plus the block sums it builds from whole source rows
/// (the sums of one coarse row, and one source row as the filter prepares it) and the source
/// row it reads.
fn coarse_bytes(layout: &Layout, coarse: &Span, texel_bytes: u64) -> u64 {
    let block_sums = 8 * layout.level_extent(coarse.lods.start).0 as u64 * texel_bytes;
    let prepared = 8 * layout.width as u64 * texel_bytes;
    let source_row = layout.width as u64 * texel_bytes;
    cascade_bytes(layout, coarse, texel_bytes).saturating_add(block_sums + prepared + source_row)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn a_narrow_image_is_one_band() {
        let l = Layout::new(16384, 16384, 256, 0).unwrap();
        let plan = Plan::choose(&l, 3, Filter::default(), 1 << 30, Beside::default()).unwrap();
        assert_eq!((plan.stripes, plan.coarse), (vec![Span::whole(&l)], None));
        assert_eq!(plan.read_ahead_rows, read_ahead::rows_per_chunk(16384 * 3), "read ahead within 1 GiB");
    }

    #[test]
    fn a_wide_image_is_cut_in_aligned_stripes_that_cover_it() {
        let l = Layout::new(200_000, 2000, 256, 4).unwrap();
        let plan = Plan::choose(&l, 3, Filter::default(), 64 << 20, Beside::default()).unwrap();
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
    fn what_the_source_and_the_sink_hold_is_in_the_plan() {
        let l = Layout::new(8000, 2000, 256, 1).unwrap();
        let none = Beside::default();
        let budget = one_band_bytes(&l, 3);
        let alone = Plan::choose(&l, 3, Filter::default(), budget, none).unwrap();
        assert_eq!((alone.coarse, alone.read_ahead_rows, alone.held), (None, 0, budget));
        // A decoder's band of 8 MiB beside it: stripes and a coarse pass, within the budget.
        let decoder = Beside { decoder: 8 << 20, ..none };
        let striped = Plan::choose(&l, 3, Filter::default(), budget, decoder).unwrap();
        assert!(striped.coarse.is_some() && striped.held <= budget, "{striped:?}");
        // Encodings waiting for a pack's writer, at a JPEG's worst case, count in every lot.
        let pack = Beside { encoded_tile: 3 * 256 * 256 + 2048, ..none };
        let p = Plan::choose(&l, 3, Filter::default(), budget, pack).unwrap();
        assert!(p.coarse.is_some() && p.held <= budget, "{p:?}");
        // More than the budget alone: refused, naming the decoder's part.
        let e = Plan::choose(&l, 3, Filter::default(), budget, Beside { decoder: budget, ..none }).unwrap_err();
        assert!(e.to_string().contains("the source's decoder holds"), "{e}");
    }

    #[test]
    fn resampling_filters_are_not_striped() {
        let l = Layout::new(200_000, 2000, 256, 0).unwrap();
        let e = Plan::choose(&l, 3, Filter::Lanczos3, 64 << 20, Beside::default()).unwrap_err().to_string();
        assert!(e.contains("--max-memory") && e.contains("lanczos3"), "{e}");
    }

    #[test]
    fn too_little_memory_names_what_is_needed() {
        let l = Layout::new(200_000, 2000, 256, 0).unwrap();
        let e = Plan::choose(&l, 3, Filter::default(), 1 << 20, Beside::default()).unwrap_err().to_string();
        assert!(e.contains("--max-memory") && e.contains("1.0 MiB"), "{e}");
    }

    #[test]
    fn huge_tiles_with_tiny_payload_are_refused() {
        let l = Layout::new(1000, 1000, 16384, 8190).unwrap();
        let e = Plan::choose(&l, 3, Filter::default(), 1 << 30, Beside::default()).unwrap_err().to_string();
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
