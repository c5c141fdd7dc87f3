//! The LOD cascade: every level of the pyramid in flight at once, in bounded memory.
//!
//! Each level keeps its own [`Band`] and the means to make the next level: a [`Reducer`] of
//! exact sums for the exact filters (one half-built row of sums per level), a [`Resampler`] for
//! lanczos3 and mitchell. A source row goes into LOD 0 and cascades down as far as it
//! completes rows; whenever a level's band holds every row a row of tiles reads, those tiles
//! are cut ([`cut`]) and sent as one [`Batch`] to the encoders. The cascade knows nothing of
//! where rows come from or where tiles go: `split.rs` feeds it and drains the channel.

use std::ops::Range;
use std::sync::Arc;
use std::sync::mpsc::{SendError, SyncSender};

use super::band::Band;
use super::cut::{self, Padding, Run};
use super::filter::{ExactFilter, Filter};
use super::reduce::{Acc, ExactRow, Reducer};
use super::resample::Resampler;
use crate::error::{Result, TilerError};
use crate::layout::Layout;
use crate::pixel::{PixelLayout, Sample};
use crate::stages::{Stage, StageClock};

/// Where the cascade sends each row of tiles (or the error that stopped it): a bounded channel
/// to the encoders, whose waits are timed as the producer's [`Stage::ProducerBlocked`].
pub(crate) struct BatchSender<T> {
    tx: SyncSender<Result<Batch<T>>>,
    clock: Arc<StageClock>,
}

impl<T> Clone for BatchSender<T> {
    fn clone(&self) -> Self {
        BatchSender { tx: self.tx.clone(), clock: Arc::clone(&self.clock) }
    }
}

impl<T> BatchSender<T> {
    pub(crate) fn new(tx: SyncSender<Result<Batch<T>>>, clock: Arc<StageClock>) -> BatchSender<T> {
        BatchSender { tx, clock }
    }

    /// Sends `batch`, waiting while the channel is full; fails once the encoders have stopped.
    pub(crate) fn send(&self, batch: Result<Batch<T>>) -> std::result::Result<(), SendError<Result<Batch<T>>>> {
        self.clock.time(Stage::ProducerBlocked, || self.tx.send(batch))
    }
}

/// One row of tiles of one LOD.
pub(crate) struct Batch<T> {
    pub lod: u32,
    pub tiles: Vec<CutTile<T>>,
}

/// Texels of a tile and every (x, y) that holds them: neighbours with identical texels (most
/// often padding) share one encoding.
pub(crate) struct CutTile<T> {
    pub texels: Vec<T>,
    pub places: Vec<(u32, u32)>,
}

/// Bytes of texels one batch holds at most: a row of tiles of a wide image is sent in pieces,
/// so that the tiles in flight do not grow with the width. A row of 64 256-texel RGB tiles
/// (a 16384-wide image) is one batch: 4 MiB batches made that benchmark 13% slower (the
/// encoders wait on the one queued batch), for 20 MiB less memory.
pub(crate) const BATCH_BYTES: usize = 16 << 20;

/// Tiles in one batch of tiles of `texel_bytes`-byte texels: [`BATCH_BYTES`] of them, but at
/// least 8, which keeps a few encoders busy on small machines whatever the tile size.
pub(crate) fn batch_tiles(layout: &Layout, texel_bytes: usize) -> usize {
    (BATCH_BYTES / (layout.tile_texels() * texel_bytes)).max(8)
}

/// How a level makes the next one.
enum Down<T, A> {
    /// The exact filters: a cascade of sums.
    Exact(Reducer<A>),
    /// The resampling filters: the next level from this one's rounded rows.
    Resample(Box<Resampler<T>>),
}

/// The part of the pyramid one cascade makes: LODs `lods`, and of the first of them the page
/// columns `columns` and page rows `rows` (of each LOD below it, the pages above those). The
/// whole pyramid is one span; a stripe of a wide image ([`crate::pyramid::stripes`]) is the
/// fine LODs of a few page columns, and its coarse pass the remaining LODs at full width; a
/// shard's region ([`crate::shard`]) is a rectangle of whole subtrees of its last LOD.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct Span {
    pub lods: Range<u32>,
    pub columns: Range<u32>,
    pub rows: Range<u32>,
}

impl Span {
    pub fn whole(layout: &Layout) -> Span {
        Span { lods: 0..layout.lod_count, columns: 0..layout.columns, rows: 0..layout.rows }
    }

    /// Page columns of `lod` that this span cuts: the parents of its first LOD's pages (a
    /// stripe starts on a page of every LOD it makes, and the grid's last column's parent is
    /// the next LOD's last column, as nested ceilings compose).
    pub fn columns_at(&self, lod: u32) -> Range<u32> {
        parents(&self.columns, lod - self.lods.start)
    }

    /// Page rows of `lod` that this span cuts, as [`columns_at`](Self::columns_at).
    pub fn rows_at(&self, lod: u32) -> Range<u32> {
        parents(&self.rows, lod - self.lods.start)
    }

    /// Texel columns of `lod` the span's cascade holds: its pages, their borders, and as much
    /// more as keeps every finer LOD's window an exact multiple of its footprints (the margin
    /// of the last LOD, doubled per finer LOD), clipped to the image.
    pub fn window(&self, layout: &Layout, lod: u32) -> Range<u64> {
        self.texels(layout, lod, &self.columns, layout.level_extent(self.lods.start).0)
    }

    /// Texel rows of `lod` the span's cascade holds, as [`window`](Self::window) for columns.
    pub fn window_rows(&self, layout: &Layout, lod: u32) -> Range<u64> {
        self.texels(layout, lod, &self.rows, layout.level_extent(self.lods.start).1)
    }

    fn texels(&self, layout: &Layout, lod: u32, pages: &Range<u32>, extent: u32) -> Range<u64> {
        let first = self.lods.start;
        let margin = (layout.border as u64) << (self.lods.end - 1 - first);
        let p = layout.payload() as u64;
        let start = (pages.start as u64 * p).saturating_sub(margin);
        let end = (pages.end as u64 * p + margin).min(extent as u64);
        let k = lod - first;
        (start >> k)..end.div_ceil(1 << k)
    }
}

/// The pages `k` levels coarser than `pages` that are their parents.
fn parents(pages: &Range<u32>, k: u32) -> Range<u32> {
    pages.start >> k..pages.end.div_ceil(1 << k)
}

/// One LOD in flight: its band, the tile rows cut so far and the reduction to the next LOD.
struct Level<T, A> {
    lod: u32,
    extent: (u32, u32),
    /// The rows of the level's window (all its columns but in a stripe).
    band: Band<T>,
    next_tile_row: u32,
    /// Per page column cut: its index, and which band columns its texels come from.
    x_runs: Vec<(u32, Vec<Run>)>,
    /// One past the last page row of the level this span cuts.
    end_tile_row: u32,
    down: Option<Down<T, A>>,
    /// The current row, rounded from exact sums.
    row: Vec<T>,
    /// The exact sums this level keeps of its pages (a shard's last level: its subtree roots).
    roots: Option<RootSums<A>>,
}

/// The exact sums (not the rounded texels) of a rectangle of one level, row-major, as a shard
/// hands its subtree roots to `merge` so that the levels above them can be made exactly.
#[derive(Clone, Debug, PartialEq, Eq)]
pub(crate) struct RootSums<A> {
    /// Texel columns and rows of the level.
    pub columns: Range<u64>,
    pub rows: Range<u64>,
    /// `columns x rows x channels` sums.
    pub sums: Vec<A>,
    /// Where `columns` start in the level's window, in samples.
    skip: usize,
}

impl<A: Acc> RootSums<A> {
    /// The sums one level coarser: texel (x, y) of this level adds into (x / 2, y / 2). Where
    /// a rectangle's edge is odd, an edge texel of the next level gets only this rectangle's
    /// part of its footprint; `merge` adds the neighbour's.
    pub fn halved(&self, channels: usize) -> RootSums<A> {
        let columns = self.columns.start / 2..self.columns.end.div_ceil(2);
        let rows = self.rows.start / 2..self.rows.end.div_ceil(2);
        let width = (columns.end - columns.start) as usize;
        let mut sums = vec![A::default(); width * (rows.end - rows.start) as usize * channels];
        let in_width = (self.columns.end - self.columns.start) as usize;
        for (i, row) in self.sums.chunks_exact(in_width * channels).enumerate() {
            let y = (self.rows.start + i as u64) / 2 - rows.start;
            let out = &mut sums[y as usize * width * channels..][..width * channels];
            for (j, texel) in row.chunks_exact(channels).enumerate() {
                let x = ((self.columns.start + j as u64) / 2 - columns.start) as usize;
                for (o, &v) in out[x * channels..][..channels].iter_mut().zip(texel) {
                    *o = *o + v;
                }
            }
        }
        RootSums { columns, rows, sums, skip: 0 }
    }
}

impl<A: Copy> RootSums<A> {
    /// Keeps row `y` of the window if it is one of the rectangle's.
    fn take(&mut self, y: u64, window_row: &[A], channels: usize) {
        if self.rows.contains(&y) {
            let len = (self.columns.end - self.columns.start) as usize * channels;
            self.sums.extend_from_slice(&window_row[self.skip..self.skip + len]);
        }
    }
}

/// What every level's cutting needs.
struct Cutter<'a, T> {
    layout: &'a Layout,
    channels: usize,
    padding: &'a Padding<T>,
    out: &'a BatchSender<T>,
}

/// Every LOD of one run, from LOD 0 (fed source rows) down to the coarsest; sends each row of
/// tiles, as soon as it is cut, to the encoders.
pub(crate) struct Cascade<T, A> {
    layout: Layout,
    channels: usize,
    padding: Padding<T>,
    levels: Vec<Level<T, A>>,
    out: BatchSender<T>,
    /// What the exact cascade sums when it is not the samples themselves.
    exact: Option<ExactFilter>,
    /// A source row as `exact` sums it.
    prepared: Vec<u64>,
}

impl<T: Sample + Into<A>, A: Acc> Cascade<T, A> {
    /// The cascade of `span`: fed the rows of its first LOD's window, by
    /// [`push_source_row`](Self::push_source_row) when that is LOD 0, else by
    /// [`push_exact`](Self::push_exact). A span narrower than the image needs an exact filter.
    pub fn new(
        layout: Layout,
        span: &Span,
        pixels: PixelLayout,
        filter: Filter,
        padding: Padding<T>,
        out: BatchSender<T>,
    ) -> Self {
        let edge = padding == Padding::Edge;
        let channels = pixels.channels.count();
        let levels = span
            .lods
            .clone()
            .map(|lod| {
                let extent = layout.level_extent(lod);
                let window = span.window(&layout, lod);
                let width = (window.end - window.start) as usize;
                let row_len = width * channels;
                let virtual_width = layout.virtual_extent(lod).0;
                let x_runs = span
                    .columns_at(lod)
                    .map(|t| (t, cut::shifted(cut::runs(&layout, t, extent.0, virtual_width, edge), window.start)))
                    .collect();
                let down = (lod + 1 < span.lods.end).then(|| {
                    if filter.is_exact() {
                        let (w, h) = (layout.width as u64, layout.height as u64);
                        let next = span.window(&layout, lod + 1).start;
                        let next_row = span.window_rows(&layout, lod + 1).start;
                        Down::Exact(Reducer::window(w, h, lod, 1, next, width, channels).starting_at_row(next_row))
                    } else {
                        Down::Resample(Box::new(Resampler::new(filter, pixels, width, extent.1 as u64)))
                    }
                });
                let first_row = span.window_rows(&layout, lod).start;
                let tile_rows = span.rows_at(lod);
                Level {
                    lod,
                    extent,
                    band: Band::starting_at(first_row, row_len, (layout.tile_size + 1).min(extent.1) as usize),
                    next_tile_row: tile_rows.start,
                    end_tile_row: tile_rows.end,
                    x_runs,
                    down,
                    row: vec![T::default(); row_len],
                    roots: None,
                }
            })
            .collect();
        let exact = ExactFilter::new(filter, pixels);
        let first_width = span.window(&layout, span.lods.start);
        let prepared = if exact.is_some() {
            vec![0; (first_width.end - first_width.start) as usize * channels]
        } else {
            Vec::new()
        };
        Cascade { layout, channels, padding, levels, out, exact, prepared }
    }

    /// Keeps the exact sums of the pages of the span's last LOD, its payload texels only (a
    /// shard's subtree roots), for [`take_root_sums`](Self::take_root_sums).
    #[expect(clippy::expect_used, reason = "a cascade has at least one level")]
    pub fn keep_root_sums(&mut self, span: &Span) {
        let layout = &self.layout;
        let lod = span.lods.end - 1;
        let p = layout.payload() as u64;
        let (width, height) = layout.level_extent(lod);
        let (columns, rows) = (span.columns_at(lod), span.rows_at(lod));
        let columns = columns.start as u64 * p..(columns.end as u64 * p).min(width as u64);
        let skip = (columns.start - span.window(layout, lod).start) as usize * self.channels;
        let rows = rows.start as u64 * p..(rows.end as u64 * p).min(height as u64);
        let len = (columns.end - columns.start) * (rows.end - rows.start) * self.channels as u64;
        let last = self.levels.last_mut().expect("a level");
        last.roots = Some(RootSums { columns, rows, sums: Vec::with_capacity(len as usize), skip });
    }

    /// The sums kept by [`keep_root_sums`](Self::keep_root_sums), once [`finish`](Self::finish)ed.
    pub fn take_root_sums(&mut self) -> Option<RootSums<A>> {
        self.levels.last_mut().and_then(|l| l.roots.take())
    }

    /// Takes the next row of exact sums of the first LOD (a span that starts below LOD 0).
    pub fn push_exact(&mut self, exact: &ExactRow<A>) -> Result<()> {
        let cutter = Cutter { layout: &self.layout, channels: self.channels, padding: &self.padding, out: &self.out };
        Self::feed_exact(&mut self.levels, exact, &cutter, self.exact.as_ref())
    }

    /// Completes the pyramid once the last source row is in.
    #[expect(clippy::expect_used, reason = "a cascade has one level per LOD and the callers index within them")]
    pub fn finish(&mut self) -> Result<()> {
        // Odd heights leave a half-built row in each reducer: flush them top-down. (Resamplers
        // finish with their last input row.)
        let cutter = Cutter { layout: &self.layout, channels: self.channels, padding: &self.padding, out: &self.out };
        for k in 0..self.levels.len() {
            let (this, rest) = self.levels[k..].split_first_mut().expect("level k exists");
            if let Some(Down::Exact(reducer)) = &mut this.down
                && let Some(exact) = reducer.finish()
            {
                Self::feed_exact(rest, &exact, &cutter, self.exact.as_ref())?;
            }
        }
        Ok(())
    }

    /// Takes the next source row: into LOD 0's band, and on down the levels below.
    #[expect(clippy::expect_used, reason = "a cascade has one level per LOD and the callers index within them")]
    pub fn push_source_row(&mut self, row: &[T]) -> Result<()> {
        let cutter = Cutter { layout: &self.layout, channels: self.channels, padding: &self.padding, out: &self.out };
        let (first, rest) = self.levels.split_first_mut().expect("at least one level");
        first.band.push(row);
        first.cut_ready(&cutter)?;
        if let Some(roots) = &mut first.roots {
            // LOD 0 is the last level: its sums are the source values, as the filter sums them.
            let y = first.band.end() - 1;
            let values: Vec<A> = match &self.exact {
                None => row.iter().map(|&v| v.into()).collect(),
                Some(filter) => {
                    filter.prepare(row, &mut self.prepared);
                    self.prepared.iter().map(|&v| A::from(v)).collect()
                }
            };
            roots.take(y, &values, self.channels);
        }
        match &mut first.down {
            Some(Down::Exact(reducer)) => {
                let exact = match &self.exact {
                    None => reducer.push(row),
                    Some(filter) => filter.push_row(reducer, row, &mut self.prepared),
                };
                if let Some(exact) = exact {
                    Self::feed_exact(rest, &exact, &cutter, self.exact.as_ref())?;
                }
            }
            Some(Down::Resample(resampler)) => {
                if let Some(rows) = resampler.push(row)? {
                    Self::feed_rows(rest, rows, &cutter)?;
                }
            }
            None => {}
        }
        Ok(())
    }

    /// Gives `levels[0]` its next exact row and cascades into the levels below it.
    #[expect(clippy::expect_used, reason = "a cascade has one level per LOD and the callers index within them")]
    fn feed_exact(
        levels: &mut [Level<T, A>],
        exact: &ExactRow<A>,
        cutter: &Cutter<T>,
        filter: Option<&ExactFilter>,
    ) -> Result<()> {
        let (this, rest) = levels.split_first_mut().expect("a level below the reducer");
        match filter {
            None => exact.round_into(&mut this.row),
            Some(f) => f.finish(exact, &mut this.row),
        }
        this.band.push(&this.row);
        this.cut_ready(cutter)?;
        if let Some(roots) = &mut this.roots {
            roots.take(exact.y, exact.sums, cutter.channels);
        }
        if let Some(Down::Exact(reducer)) = &mut this.down
            && let Some(next) = reducer.push(exact.sums)
        {
            Self::feed_exact(rest, &next, cutter, filter)?;
        }
        Ok(())
    }

    /// Gives `levels[0]` its next rows (row-major) and resamples them into the levels below it.
    #[expect(clippy::expect_used, reason = "a cascade has one level per LOD and the callers index within them")]
    fn feed_rows(levels: &mut [Level<T, A>], rows: &[T], cutter: &Cutter<T>) -> Result<()> {
        let (this, rest) = levels.split_first_mut().expect("a level below the resampler");
        for row in rows.chunks_exact(this.row.len()) {
            this.band.push(row);
            this.cut_ready(cutter)?;
            if let Some(Down::Resample(resampler)) = &mut this.down
                && let Some(next) = resampler.push(row)?
            {
                Self::feed_rows(rest, next, cutter)?;
            }
        }
        Ok(())
    }
}

impl<T: Sample, A> Level<T, A> {
    /// Cuts every tile row whose rows are all in the band, then drops rows no longer needed.
    fn cut_ready(&mut self, cutter: &Cutter<T>) -> Result<()> {
        let Cutter { layout, channels, padding, out } = *cutter;
        let (_, height) = self.extent;
        let virtual_height = layout.virtual_extent(self.lod).1;
        while self.next_tile_row < self.end_tile_row
            && self.band.end() > cut::last_row_needed(layout, self.next_tile_row, height)
        {
            let ty = self.next_tile_row;
            let y_runs = cut::runs(layout, ty, height, virtual_height, *padding == Padding::Edge);
            let mut tiles: Vec<CutTile<T>> = Vec::new();
            let mut texels = Vec::with_capacity(layout.tile_texels() * channels);
            let per_batch = batch_tiles(layout, channels * size_of::<T>());
            for (tx, x_runs) in &self.x_runs {
                if tiles.len() == per_batch {
                    let full = std::mem::take(&mut tiles);
                    out.send(Ok(Batch { lod: self.lod, tiles: full }))
                        .map_err(|_| TilerError::Options("the encoder stopped".into()))?;
                }
                cut::cut_tile(&self.band, channels, x_runs, &y_runs, padding, &mut texels);
                // Neighbours with the same texels (most often one colour) share one encoding.
                match tiles.last_mut() {
                    Some(prev) if prev.texels == texels => prev.places.push((*tx, ty)),
                    _ => {
                        let full = std::mem::replace(&mut texels, Vec::with_capacity(layout.tile_texels() * channels));
                        tiles.push(CutTile { texels: full, places: vec![(*tx, ty)] })
                    }
                }
            }
            out.send(Ok(Batch { lod: self.lod, tiles }))
                .map_err(|_| TilerError::Options("the encoder stopped".into()))?;
            self.next_tile_row = ty + 1;
            self.band.drop_before(cut::first_row_kept(layout, ty, height));
        }
        Ok(())
    }
}
