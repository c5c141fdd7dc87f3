//! The LOD cascade: every level of the pyramid in flight at once, in bounded memory.
//!
//! Each level keeps its own [`Band`] and the means to make the next level: a [`Reducer`] of
//! exact sums for the exact filters (one half-built row of sums per level), a [`Resampler`] for
//! lanczos3 and mitchell. A source row goes into LOD 0 and cascades down as far as it
//! completes rows; each row is copied into the tiles that hold it ([`cut`]), and whenever a
//! level's band completes a row of tiles, those tiles are sent as one [`Batch`] to the
//! encoders. The cascade knows nothing of where rows come from or where tiles go: `split.rs`
//! feeds it and drains the channel.
//!
//! The work has two halves that can run on two threads (issue 18): [`Sums`], the arithmetic
//! (every level's sums, rounding, resampling), which records the rows it makes in order as
//! [`Derived`] rows; and [`Cuts`], every level's band of tiles being filled, which replays
//! them after the source rows that made them. The tiles, and the order they are sent in, are
//! the same whether one thread runs both halves ([`Cascade`]) or two do.

use std::ops::Range;
use std::sync::Arc;
use std::sync::mpsc::{SendError, SyncSender};

use super::band::Band;
use super::cut::{self, Padding};
use super::filter::{ExactFilter, Filter};
use super::labels::LabelReducer;
use super::reduce::{Acc, ExactRow, Reducer};
use super::resample::Resampler;
use crate::error::{Result, TilerError};
use crate::layout::Layout;
use crate::limits::Part;
use crate::pixel::{PixelLayout, Sample};
use crate::stages::{Stage, StageClock};

/// Where the cascade sends each row of tiles (or the error that stopped it): a bounded channel
/// to the encoders, whose waits are timed as the producer's [`Stage::ProducerBlocked`].
pub(crate) struct BatchSender<T> {
    tx: SyncSender<Result<Batch<T>>>,
    clock: Arc<StageClock>,
    /// Levels added to every batch's: 1 where the cascade starts at the run's first reduced
    /// level (`--fast-shrink`: the finest level is copied, not cut).
    lods_above: u32,
}

impl<T> Clone for BatchSender<T> {
    fn clone(&self) -> Self {
        BatchSender { tx: self.tx.clone(), clock: Arc::clone(&self.clock), lods_above: self.lods_above }
    }
}

impl<T> BatchSender<T> {
    pub(crate) fn new(tx: SyncSender<Result<Batch<T>>>, clock: Arc<StageClock>) -> BatchSender<T> {
        BatchSender { tx, clock, lods_above: 0 }
    }

    /// This sender for a cascade whose level 0 is the run's level `lods_above`.
    pub(crate) fn above(&self, lods_above: u32) -> BatchSender<T> {
        BatchSender { lods_above, ..self.clone() }
    }

    /// Sends `batch`, waiting while the channel is full; fails once the encoders have stopped.
    pub(crate) fn send(&self, batch: Result<Batch<T>>) -> std::result::Result<(), SendError<Result<Batch<T>>>> {
        let batch = batch.map(|b| Batch { lod: b.lod + self.lods_above, ..b });
        self.clock.time(Stage::ProducerBlocked, || self.tx.send(batch))
    }
}

/// One row of tiles of one LOD.
pub(crate) struct Batch<T> {
    pub lod: u32,
    pub tiles: Vec<CutTile<T>>,
    /// The pages are the source's stored tiles, copied (`--fast-shrink`'s finest level): their
    /// texels are empty, decoded from the stored tile only where a page cannot be copied.
    pub stored: bool,
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
    /// The label filters: one texel of each 2x2 block of this level's rows.
    Labels(LabelReducer<T>),
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

/// The arithmetic side of one LOD: how its rows are made and passed down.
struct LevelSums<T, A> {
    down: Option<Down<T, A>>,
    /// The current row, rounded from exact sums.
    row: Vec<T>,
    /// The exact sums this level keeps of its pages (a shard's last level: its subtree roots).
    roots: Option<RootSums<A>>,
}

/// Rows [`Sums`] made, in the order it made them, each with the index of its level in the
/// span; marked after each source row, so that [`Cuts::replay`] can push them into the bands
/// exactly when the one-thread cascade would have.
#[derive(Default)]
pub(crate) struct Derived<T> {
    samples: Vec<T>,
    /// Per row: its level and where its samples end.
    rows: Vec<(usize, usize)>,
    /// Per source row: how many of `rows` had been made once it was in.
    after_source_row: Vec<usize>,
}

impl<T: Copy> Derived<T> {
    fn push(&mut self, level: usize, row: &[T]) {
        self.samples.extend_from_slice(row);
        self.rows.push((level, self.samples.len()));
    }

    /// Marks the end of what one source row made.
    pub fn end_source_row(&mut self) {
        self.after_source_row.push(self.rows.len());
    }

    /// Bytes it holds (its capacity), for the memory gauge.
    pub fn bytes(&self) -> usize {
        self.samples.capacity() * size_of::<T>()
            + self.rows.capacity() * size_of::<(usize, usize)>()
            + self.after_source_row.capacity() * size_of::<usize>()
    }

    /// Empties it for reuse, keeping the memory.
    pub fn clear(&mut self) {
        self.samples.clear();
        self.rows.clear();
        self.after_source_row.clear();
    }

    /// Rows `range` of `rows`, with their levels.
    fn rows(&self, range: Range<usize>) -> impl Iterator<Item = (usize, &[T])> {
        range.map(|i| {
            let start = if i == 0 { 0 } else { self.rows[i - 1].1 };
            let (level, end) = self.rows[i];
            (level, &self.samples[start..end])
        })
    }
}

/// Every level's band and the tiles cut from it, sent on as soon as they are cut.
pub(crate) struct Cuts<T> {
    layout: Layout,
    channels: usize,
    padding: Padding<T>,
    /// Per level, the band that fills its tiles as its rows arrive.
    levels: Vec<Band<T>>,
    /// Whether the first level's pages are the source's stored tiles, sent without texels
    /// ([`Cascade::with_stored_first`]).
    stored_first: bool,
    out: BatchSender<T>,
}

impl<T: Sample> Cuts<T> {
    /// Pushes the span's first level's `source_rows` (none when it is fed exact sums) and the
    /// rows `derived` made of them, in the order they were made, cutting tiles as they complete.
    pub fn replay<'r>(&mut self, source_rows: impl Iterator<Item = &'r [T]>, derived: &Derived<T>) -> Result<()> {
        let mut done = 0;
        for (i, row) in source_rows.enumerate() {
            self.push(0, row)?;
            let made = derived.after_source_row[i];
            for (level, row) in derived.rows(done..made) {
                self.push(level, row)?;
            }
            done = made;
        }
        // Rows made after the last source row: from exact sums, or by `finish`.
        for (level, row) in derived.rows(done..derived.rows.len()) {
            self.push(level, row)?;
        }
        Ok(())
    }

    /// Row `row` into level `level`'s band; sends every row of tiles it completes.
    fn push(&mut self, level: usize, row: &[T]) -> Result<()> {
        let Cuts { layout, channels, padding, levels, stored_first, out } = self;
        let stored = *stored_first && level == 0;
        let band = &mut levels[level];
        let lod = band.lod();
        let per_batch = batch_tiles(layout, *channels * size_of::<T>());
        let memory = &out.clock.memory;
        // Bytes of the band's tiles moved into batches during this push.
        let moved = std::cell::Cell::new(0i64);
        let send = |tiles: Vec<CutTile<T>>| {
            // Counted as the encoders' from here until they free the texels (`encoders.rs`), and
            // no longer as the band's: moved, not copied, so never counted twice (the plan
            // counts the batch being sent within the band's bytes).
            let bytes = tiles.iter().map(|t| (t.texels.capacity() * size_of::<T>()) as i64).sum::<i64>();
            memory.add(Part::Bands, -bytes);
            memory.add(Part::Tiles, bytes);
            moved.set(moved.get() + bytes);
            out.send(Ok(Batch { lod, tiles, stored })).map_err(|_| TilerError::Options("the encoder stopped".into()))
        };
        let held = band.held_bytes();
        let pushed = band.push(row, padding, |row| {
            let mut tiles: Vec<CutTile<T>> = Vec::new();
            for (tx, texels) in row.tiles {
                if tiles.len() == per_batch {
                    send(std::mem::take(&mut tiles))?;
                }
                // Neighbours in a batch with the same texels (most often one colour) share one
                // encoding; stored pages have none yet, and are each a page of their own.
                match tiles.last_mut() {
                    Some(prev) if !stored && prev.texels == texels => prev.places.push((tx, row.index)),
                    _ => tiles.push(CutTile { texels, places: vec![(tx, row.index)] }),
                }
            }
            send(tiles)
        });
        memory.add(Part::Bands, band.held_bytes() as i64 - held as i64 + moved.get());
        pushed
    }
}

/// Every level's arithmetic: the sums (or resampling) that make each level's rows from the one
/// above, recorded as [`Derived`] rows for [`Cuts`].
pub(crate) struct Sums<T, A> {
    channels: usize,
    levels: Vec<LevelSums<T, A>>,
    /// What the exact cascade sums when it is not the samples themselves.
    exact: Option<ExactFilter>,
    /// A source row as `exact` sums it.
    prepared: Vec<u64>,
    /// Image row of the first level that the next source row is.
    next_row: u64,
}

impl<T: Sample + Into<A>, A: Acc> Sums<T, A> {
    /// Takes the next source row (the first level is LOD 0) and makes what it completes below.
    #[expect(clippy::expect_used, reason = "a cascade has at least one level")]
    pub fn push_source_row(&mut self, row: &[T], derived: &mut Derived<T>) -> Result<()> {
        let channels = self.channels;
        let (first, rest) = self.levels.split_first_mut().expect("at least one level");
        let y = self.next_row;
        self.next_row += 1;
        if let Some(roots) = &mut first.roots {
            // LOD 0 is the last level: its sums are the source values, as the filter sums them.
            let values: Vec<A> = match &self.exact {
                None => row.iter().map(|&v| v.into()).collect(),
                Some(filter) => {
                    filter.prepare(row, &mut self.prepared);
                    self.prepared.iter().map(|&v| A::from(v)).collect()
                }
            };
            roots.take(y, &values, channels);
        }
        match &mut first.down {
            Some(Down::Exact(reducer)) => {
                let exact = match &self.exact {
                    None => reducer.push(row),
                    Some(filter) => filter.push_row(reducer, row, &mut self.prepared),
                };
                if let Some(exact) = exact {
                    feed_exact(rest, 1, &exact, self.exact.as_ref(), channels, derived);
                }
            }
            Some(Down::Resample(resampler)) => {
                if let Some(rows) = resampler.push(row)? {
                    feed_rows(rest, 1, rows, derived)?;
                }
            }
            Some(Down::Labels(labels)) => {
                if let Some(next) = labels.push(row) {
                    feed_rows(rest, 1, next, derived)?;
                }
            }
            None => {}
        }
        Ok(())
    }

    /// Takes the next row of exact sums of the first level (a span that starts below LOD 0).
    pub fn push_exact(&mut self, exact: &ExactRow<A>, derived: &mut Derived<T>) {
        feed_exact(&mut self.levels, 0, exact, self.exact.as_ref(), self.channels, derived);
    }

    /// Completes the pyramid once the last source row is in: odd heights leave a half-built
    /// row in each reducer, flushed top-down. (Resamplers finish with their last input row.)
    #[expect(clippy::expect_used, reason = "k indexes the levels")]
    pub fn finish(&mut self, derived: &mut Derived<T>) {
        for k in 0..self.levels.len() {
            let (this, rest) = self.levels[k..].split_first_mut().expect("level k exists");
            if let Some(Down::Exact(reducer)) = &mut this.down
                && let Some(exact) = reducer.finish()
            {
                feed_exact(rest, k + 1, &exact, self.exact.as_ref(), self.channels, derived);
            }
        }
    }
}

/// Gives `levels[0]` (level `index` of the span) its next exact row and cascades into the
/// levels below it.
#[expect(clippy::expect_used, reason = "a level below the reducer exists")]
fn feed_exact<T: Sample, A: Acc>(
    levels: &mut [LevelSums<T, A>],
    index: usize,
    exact: &ExactRow<A>,
    filter: Option<&ExactFilter>,
    channels: usize,
    derived: &mut Derived<T>,
) {
    let (this, rest) = levels.split_first_mut().expect("a level below the reducer");
    match filter {
        None => exact.round_into(&mut this.row),
        Some(f) => f.finish(exact, &mut this.row),
    }
    derived.push(index, &this.row);
    if let Some(roots) = &mut this.roots {
        roots.take(exact.y, exact.sums, channels);
    }
    if let Some(Down::Exact(reducer)) = &mut this.down
        && let Some(next) = reducer.push(exact.sums)
    {
        feed_exact(rest, index + 1, &next, filter, channels, derived);
    }
}

/// Gives `levels[0]` (level `index`) its next rows (row-major) and resamples them into the
/// levels below it.
#[expect(clippy::expect_used, reason = "a level below the resampler exists")]
fn feed_rows<T: Sample, A>(
    levels: &mut [LevelSums<T, A>],
    index: usize,
    rows: &[T],
    derived: &mut Derived<T>,
) -> Result<()> {
    let (this, rest) = levels.split_first_mut().expect("a level below the resampler");
    for row in rows.chunks_exact(this.row.len()) {
        derived.push(index, row);
        let next = match &mut this.down {
            Some(Down::Resample(resampler)) => resampler.push(row)?,
            Some(Down::Labels(labels)) => labels.push(row),
            _ => None,
        };
        if let Some(next) = next {
            feed_rows(rest, index + 1, next, derived)?;
        }
    }
    Ok(())
}

/// Every LOD of one pass, from its first level (fed source rows or exact sums) down to the
/// coarsest, both halves on the calling thread; sends each row of tiles, as soon as it is cut,
/// to the encoders. [`parts`](Self::parts) hands the halves to two threads instead.
pub(crate) struct Cascade<T, A> {
    sums: Sums<T, A>,
    cuts: Cuts<T>,
    derived: Derived<T>,
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
        let (mut cut_levels, mut sum_levels) = (Vec::new(), Vec::new());
        for lod in span.lods.clone() {
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
                } else if filter.is_label() {
                    Down::Labels(LabelReducer::new(filter, channels, width, extent.1 as u64))
                } else {
                    Down::Resample(Box::new(Resampler::new(filter, pixels, width, extent.1 as u64)))
                }
            });
            let first_row = span.window_rows(&layout, lod).start;
            cut_levels.push(Band::new(layout, lod, channels, x_runs, span.rows_at(lod), first_row, edge));
            sum_levels.push(LevelSums { down, row: vec![T::default(); row_len], roots: None });
        }
        let exact = ExactFilter::new(filter, pixels);
        let first_width = span.window(&layout, span.lods.start);
        let prepared = if exact.is_some() {
            vec![0; (first_width.end - first_width.start) as usize * channels]
        } else {
            Vec::new()
        };
        let next_row = span.window_rows(&layout, span.lods.start).start;
        Cascade {
            sums: Sums { channels, levels: sum_levels, exact, prepared, next_row },
            cuts: Cuts { layout, channels, padding, levels: cut_levels, stored_first: false, out },
            derived: Derived::default(),
        }
    }

    /// This cascade with its first level's pages sent as the source's stored tiles: no texel of
    /// that level is cut or held, and its rows of pages go on when their rows are in, as they
    /// would cut ([`Batch::stored`]).
    pub fn with_stored_first(mut self) -> Self {
        self.cuts.levels.iter_mut().take(1).for_each(Band::drop_texels);
        self.cuts.stored_first = true;
        self
    }

    /// Whether the first level's pages are sent as the source's stored tiles
    /// ([`with_stored_first`](Self::with_stored_first)).
    pub fn first_level_stored(&self) -> bool {
        self.cuts.stored_first
    }

    /// Keeps the exact sums of the pages of the span's last LOD, its payload texels only (a
    /// shard's subtree roots), for [`take_root_sums`](Self::take_root_sums).
    #[expect(clippy::expect_used, reason = "a cascade has at least one level")]
    pub fn keep_root_sums(&mut self, span: &Span) {
        let layout = &self.cuts.layout;
        let channels = self.sums.channels;
        let lod = span.lods.end - 1;
        let p = layout.payload() as u64;
        let (width, height) = layout.level_extent(lod);
        let (columns, rows) = (span.columns_at(lod), span.rows_at(lod));
        let columns = columns.start as u64 * p..(columns.end as u64 * p).min(width as u64);
        let skip = (columns.start - span.window(layout, lod).start) as usize * channels;
        let rows = rows.start as u64 * p..(rows.end as u64 * p).min(height as u64);
        let len = (columns.end - columns.start) * (rows.end - rows.start) * channels as u64;
        let last = self.sums.levels.last_mut().expect("a level");
        last.roots = Some(RootSums { columns, rows, sums: Vec::with_capacity(len as usize), skip });
    }

    /// The sums kept by [`keep_root_sums`](Self::keep_root_sums), once [`finish`](Self::finish)ed.
    pub fn take_root_sums(&mut self) -> Option<RootSums<A>> {
        self.sums.levels.last_mut().and_then(|l| l.roots.take())
    }

    /// Whether the span has levels below its first: only then is there arithmetic to run
    /// beside the cutting.
    pub fn has_levels_below(&self) -> bool {
        self.sums.levels.len() > 1
    }

    /// The two halves, for two threads: the sums' [`Derived`] rows go to the cuts' `replay`
    /// after the source rows that made them.
    pub fn parts(&mut self) -> (&mut Sums<T, A>, &mut Cuts<T>) {
        (&mut self.sums, &mut self.cuts)
    }

    /// Takes the next source row: into LOD 0's band, and on down the levels below.
    pub fn push_source_row(&mut self, row: &[T]) -> Result<()> {
        self.derived.clear();
        self.sums.push_source_row(row, &mut self.derived)?;
        self.derived.end_source_row();
        self.cuts.replay(std::iter::once(row), &self.derived)
    }

    /// Takes the next row of exact sums of the first LOD (a span that starts below LOD 0).
    pub fn push_exact(&mut self, exact: &ExactRow<A>) -> Result<()> {
        self.derived.clear();
        self.sums.push_exact(exact, &mut self.derived);
        self.cuts.replay(std::iter::empty(), &self.derived)
    }

    /// Completes the pyramid once the last source row is in.
    pub fn finish(&mut self) -> Result<()> {
        self.derived.clear();
        self.sums.finish(&mut self.derived);
        self.cuts.replay(std::iter::empty(), &self.derived)
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::pixel::{Channels, Depth};
    use std::sync::mpsc::sync_channel;

    /// Every batch a pass sends: its LOD, and each tile's places and texels.
    type Sent = Vec<(u32, Vec<(Vec<(u32, u32)>, Vec<u8>)>)>;

    /// A 61 x 45 RGBA image (odd sizes, partial footprints) in 8-texel tiles with a border of 1:
    /// 5 LODs, tile rows of several cut after the same source row.
    fn pass(filter: Filter, run: impl FnOnce(&mut Cascade<u8, u64>, &[Vec<u8>])) -> Sent {
        pass_sending(filter, false, run).into_iter().map(|(lod, _, tiles)| (lod, tiles)).collect()
    }

    /// [`pass`], its first level sent as stored pages where `stored_first`; each batch says
    /// whether it is.
    #[expect(clippy::type_complexity, reason = "a test's record of what was sent")]
    fn pass_sending(
        filter: Filter,
        stored_first: bool,
        run: impl FnOnce(&mut Cascade<u8, u64>, &[Vec<u8>]),
    ) -> Vec<(u32, bool, Vec<(Vec<(u32, u32)>, Vec<u8>)>)> {
        let (w, h) = (61u32, 45u32);
        let layout = Layout::new(w as u64, h as u64, 8, 1).unwrap();
        let pixels = PixelLayout::new(Channels::Rgba, Depth::U8);
        // Varied texels, but for a block of one colour that fills a few pages.
        let texel = |i: u32, y: u32| match (i / 4, y) {
            (0..30, 0..20) => [10, 20, 30, 40][i as usize % 4],
            _ => ((i * 37 + y * 101) % 256) as u8,
        };
        let rows: Vec<Vec<u8>> = (0..h).map(|y| (0..w * 4).map(|i| texel(i, y)).collect()).collect();
        let (tx, rx) = sync_channel(1000); // more than the batches of this image
        let out = BatchSender::new(tx, StageClock::new());
        let mut cascade = Cascade::new(layout, &Span::whole(&layout), pixels, filter, Padding::Edge, out);
        if stored_first {
            cascade = cascade.with_stored_first();
        }
        run(&mut cascade, &rows);
        drop(cascade);
        rx.into_iter()
            .map(|b| {
                let b = b.unwrap();
                (b.lod, b.stored, b.tiles.into_iter().map(|t| (t.places, t.texels)).collect())
            })
            .collect()
    }

    /// With its first level's pages stored, a cascade sends the same batches in the same order
    /// (which is what makes a pack's bytes): the first level's a page each (they are not
    /// merged: their texels are not known), each without texels but for its one colour where
    /// it has one, the others as they were.
    #[test]
    fn stored_first_pages_go_where_their_cut_pages_went() {
        let run = |cascade: &mut Cascade<u8, u64>, rows: &[Vec<u8>]| {
            for row in rows {
                cascade.push_source_row(row).unwrap();
            }
            cascade.finish().unwrap();
        };
        let cut = pass_sending(Filter::Box, false, run);
        let stored = pass_sending(Filter::Box, true, run);
        assert_eq!(cut.len(), stored.len(), "one batch for each");
        let mut one_colour = 0;
        for ((lod, was_stored, tiles), (stored_lod, is_stored, stored_tiles)) in cut.iter().zip(&stored) {
            assert_eq!((lod, *was_stored, *is_stored), (stored_lod, false, *lod == 0));
            match lod {
                0 => {
                    let places: Vec<_> = tiles.iter().flat_map(|(places, _)| places.clone()).collect();
                    let pages: Vec<_> = stored_tiles.iter().map(|(places, _)| places.clone()).collect();
                    assert_eq!(pages, places.iter().map(|&p| vec![p]).collect::<Vec<_>>());
                    let cut_texels = |page| &tiles.iter().find(|(places, _)| places.contains(page)).unwrap().1;
                    for (page, texels) in stored_tiles.iter().map(|(places, texels)| (&places[0], texels)) {
                        let cut = cut_texels(page);
                        match cut.chunks_exact(4).all(|t| t == &cut[..4]) {
                            true => assert_eq!(texels, &cut[..4], "page {page:?}'s colour"),
                            false => assert!(texels.is_empty(), "page {page:?} has no one colour"),
                        }
                        one_colour += usize::from(!texels.is_empty());
                    }
                }
                _ => assert!(tiles == stored_tiles, "LOD {lod} as it was"),
            }
        }
        assert_eq!(one_colour, 4 * 3, "the pages the block of one colour fills");
    }

    #[test]
    fn the_halves_on_their_own_send_what_the_whole_cascade_sends() {
        for filter in [Filter::LinearPremultiplied, Filter::Box, Filter::Lanczos3] {
            let one_thread = pass(filter, |cascade, rows| {
                for row in rows {
                    cascade.push_source_row(row).unwrap();
                }
                cascade.finish().unwrap();
            });
            let lods = Layout::new(61, 45, 8, 1).unwrap().lod_count;
            assert!(one_thread.iter().map(|(lod, _)| *lod + 1).max() == Some(lods), "every LOD is cut");
            // The sums run ahead by chunks of 7 rows; the cuts replay each chunk afterwards.
            let halves = pass(filter, |cascade, rows| {
                let (sums, cuts) = cascade.parts();
                for chunk in rows.chunks(7) {
                    let mut derived = Derived::default();
                    for row in chunk {
                        sums.push_source_row(row, &mut derived).unwrap();
                        derived.end_source_row();
                    }
                    cuts.replay(chunk.iter().map(Vec::as_slice), &derived).unwrap();
                }
                let mut derived = Derived::default();
                sums.finish(&mut derived);
                cuts.replay(std::iter::empty(), &derived).unwrap();
            });
            assert!(one_thread == halves, "{filter}: the same batches in the same order");
        }
    }
}
