//! The `split` pipeline's wiring: source -> pyramid cascade -> encoders -> sink.
//!
//! The source is read ahead on a thread of its own; a producer thread makes the [LOD
//! cascade](crate::pyramid)'s sums from it and a cutting thread copies every level's rows into
//! their tiles and sends each row of tiles, once complete, in a bounded channel, to the calling
//! thread; that thread spawns each tile's encoding on the rayon pool ([`crate::codec`]) and a
//! writer hands them to the [sink](crate::sink). Peak memory is a few bands of the image's width,
//! whatever its height; an image too wide for that under `max_memory` is read once per vertical
//! stripe (`pyramid::stripes`) for the same tiles. Output bytes do not depend on the thread count.
//! This file is only that orchestration; the stages live in their modules.

use std::sync::Arc;
use std::sync::atomic::Ordering::Relaxed;
use std::sync::mpsc::sync_channel;

use crate::codec::TileEncoder;
use crate::encoders::{self, Copier};
use crate::error::{Result, TilerError};
use crate::job::TileEncoding;
use crate::layout::Layout;
use crate::limits::{Part, in_flight};
use crate::pixel::{Depth, PixelLayout, Sample};
use crate::pyramid::cascade::{Batch, BatchSender, Cascade, CutTile, Derived, Span};
use crate::pyramid::cut::Padding;
use crate::pyramid::filter::{ExactFilter, sums_need_u128};
use crate::pyramid::reduce::{Acc, Reducer};
use crate::pyramid::stripes::{Beside, Plan};
use crate::shard::sums::RootRows;
use crate::shard::sums::{self, EncodedRoots};
use crate::sink::{Target, TileSink};
use crate::source::{ImageHeader, RowSource, read_ahead};
use crate::stages::{Stage, StageClock};

pub(crate) use crate::job::Written;
pub use crate::job::{MemoryReport, Progress, Recompressed, SplitOptions, StoredReport, Summary};
pub use crate::stages::StageTimes;

/// Whether the finest level's pages are copied from `source`'s stored tiles (the copier, and
/// which targets take the copies) and what the summary says of them; neither where the source
/// stores none. A target whose encoding is not the stored tiles' (another codec, a re-encode
/// asked) gets its pages encoded beside the others' copies.
fn plan_copy(source: &dyn RowSource, targets: &[Target], layout: &Layout) -> (Option<Copier>, Option<StoredReport>) {
    let Some(tiles) = source.stored_tiles() else { return (None, None) };
    let (tile_size, side) = (tiles.tile_size(), layout.tile_size);
    let declined_by: Vec<Option<String>> = targets.iter().map(|t| t.encoding.declines_stored()).collect();
    let declined = if declined_by.iter().all(Option::is_some) {
        declined_by.first().cloned().flatten()
    } else if layout.border != 0 {
        Some(format!("the pages have a border (overlap) of {}", layout.border))
    } else if tile_size != (side, side) {
        Some(format!("they are not on the grid of {side}-texel pages"))
    } else {
        None
    };
    let report = StoredReport { tile_size, quality: tiles.quality(), declined, halved: false };
    let copier = report.declined.is_none().then(|| Copier {
        tiles,
        width: layout.width,
        height: layout.height,
        side,
        takes: declined_by.iter().map(Option::is_none).collect(),
    });
    (copier, Some(report))
}

/// Chunks of source rows, with the rows the pyramid's sums made of them, waiting for the
/// cutting thread: those the read-ahead's memory bound allows beyond the one it cuts.
const HANDOFF_CHUNKS: usize = read_ahead::CHUNKS_HANDED_ON as usize - 1;

/// [`HANDOFF_CHUNKS`] where the finest level's pages are the source's stored tiles: the cutter
/// copies none of those rows' texels, only compares them, so it keeps up with fewer. On the
/// 16384² JPEG-tiled BigTIFF to a pack, 3 instead of 7 held 5 MB less at the peak, with the
/// same wall time (medians of 5).
const STORED_HANDOFF_CHUNKS: usize = 3;

/// Cuts `source` into the pyramid and writes every tile to `sink`. Runs the encoders on the
/// current rayon pool; best called from outside it (inside, the calling worker runs the pool's
/// tasks while it waits for tiles, polling). `progress` hears of every finished tile and can
/// stop the run.
pub fn split(
    source: Box<dyn RowSource>,
    sink: &dyn TileSink,
    opts: &SplitOptions,
    progress: &dyn Progress,
) -> Result<Summary> {
    let mut source = source;
    let lods = opts.layout(source.width(), source.height())?.lod_count;
    let target = Target { sink, lods, background: opts.background, encoding: opts.encoding() };
    split_to(source.as_mut(), &[target], opts, progress)
}

/// [`split`] into several sinks at once, each taking the levels it has: every page is cut once,
/// and encoded once for all the sinks that keep the same part of it (those that crop it alike
/// and pad it alike). `opts` cut the pyramid down to the deepest target's levels, padded with
/// `opts.background`; a target that pads with another colour gets its padded pages filled
/// with it (pages cut with the edge repeated can take any colour).
pub(crate) fn split_to(
    source: &mut dyn RowSource,
    targets: &[Target],
    opts: &SplitOptions,
    progress: &dyn Progress,
) -> Result<Summary> {
    let layout = opts.layout(source.width(), source.height())?;
    let mut copy = plan_copy(source, targets, &layout);
    let header = source.header();
    let passes = match opts.fast_shrink && layout.lod_count > 1 {
        true => {
            let halved = halved(source, targets, &copy)?;
            if let Some(report) = &mut copy.1 {
                report.halved = true;
            }
            let half = opts.layout(halved.width(), halved.height())?;
            Passes::Halved(plan(halved.as_ref(), targets, opts)?, half, halved)
        }
        false => Passes::Whole(plan(source, targets, opts)?, source),
    };
    let (summary, _) = by_depth(header, targets, opts, layout, copy, passes, progress)?;
    Ok(summary)
}

/// `--fast-shrink`'s source: `source` at half size, decoded from its stored JPEG tiles, where
/// every target copies those tiles into its finest level (which then needs no texel); else
/// why not.
fn halved(source: &dyn RowSource, targets: &[Target], (copier, report): &CopyPlan) -> Result<Box<dyn RowSource>> {
    let refuse = |why: String| Err(TilerError::Options(format!("--fast-shrink: {why}")));
    let Some(copier) = copier else {
        return match report.as_ref().and_then(|r| r.declined.as_ref()) {
            Some(why) => refuse(format!(
                "the first reduced level is made from the stored JPEG tiles that the finest level copies, and this run does not copy them: {why}"
            )),
            None => refuse(format!(
                "the source stores no JPEG tiles its rows are decoded from ({}); it takes JPEG-tiled TIFFs, slides and DICOM JPEG series",
                source.describe()
            )),
        };
    };
    if let Some(t) = copier.takes.iter().position(|takes| !takes) {
        let why = targets[t].encoding.declines_stored().unwrap_or_default();
        return refuse(format!(
            "every output must copy the stored JPEG tiles into its finest level, and output {} encodes them ({why})",
            t + 1
        ));
    }
    match source.halved() {
        Some(halved) => Ok(halved),
        None => refuse(format!("the stored tiles of {} cannot be decoded at half size", source.describe())),
    }
}

/// How [`split_to`] reads `source`: in one band, or in stripes (and a coarse pass) where one
/// band over the whole width does not fit in `opts.max_memory`.
pub(crate) fn plan(source: &dyn RowSource, targets: &[Target], opts: &SplitOptions) -> Result<Plan> {
    let layout = opts.layout(source.width(), source.height())?;
    let copies = plan_copy(source, targets, &layout).0.is_some();
    // An ordered sink's tiles wait for the writer, once per distinct encoding.
    let mut encodings: Vec<TileEncoding> = Vec::new();
    let mut encoded_tile = 0;
    for target in targets {
        let stored = target.encoding.stored(source.layout())?;
        if target.sink.ordered() && !encodings.contains(&target.encoding) {
            encodings.push(target.encoding);
            encoded_tile += target.encoding.codec.most_encoded_bytes(layout.tile_size, stored);
        }
    }
    let beside = Beside { decoder: source.most_buffer_bytes(), encoded_tile, copies };
    Plan::choose(&layout, source.layout().bytes_per_pixel() as u64, opts.filter, opts.max_memory, beside)
}

/// A shard's rectangles of the pyramid (`spans`, top to bottom, each of the LODs up to the
/// cut): their pages, and the exact sums of their roots for `merge` ([`crate::shard`]).
pub(crate) fn split_shard(
    source: Box<dyn RowSource>,
    sink: &dyn TileSink,
    opts: &SplitOptions,
    spans: Vec<Span>,
    progress: &dyn Progress,
) -> Result<(Summary, Vec<EncodedRoots>)> {
    let layout = opts.layout(source.width(), source.height())?;
    if !source.layout().depth.is_narrow_int() {
        // A shard's manifest names its texels by their size alone, which f32 and u32 share.
        return Err(TilerError::Options(format!(
            "--shard takes 8- and 16-bit images; the source is {}: split it on one machine",
            source.layout()
        )));
    }
    let targets = [Target { sink, lods: layout.lod_count, background: opts.background, encoding: opts.encoding() }];
    let copy = plan_copy(source.as_ref(), &targets, &layout);
    by_depth(source.header(), &targets, opts, layout, copy, Passes::Shard(spans, source), progress)
}

/// The levels above a sharded run's cut level, from the exact sums of its roots: what
/// `merge` makes ([`crate::scale_out::merge`]). `image` is the source's size and texels.
pub(crate) fn above_cut(
    image: ImageHeader,
    roots: RootRows<'_>,
    sink: &dyn TileSink,
    opts: &SplitOptions,
    progress: &dyn Progress,
) -> Result<Summary> {
    let layout = opts.layout(image.width, image.height)?;
    let targets = [Target { sink, lods: layout.lod_count, background: opts.background, encoding: opts.encoding() }];
    let (summary, _) = by_depth(image, &targets, opts, layout, (None, None), Passes::AboveCut(roots), progress)?;
    Ok(summary)
}

/// Largest value one source pixel adds to an exact sum of a run of `opts` on `source`.
/// (Floats: the sums are `f64`, which do not overflow; this is `u32::MAX` for them, unused.)
pub(crate) fn max_summand(opts: &SplitOptions, source: PixelLayout) -> u64 {
    match ExactFilter::new(opts.filter, source) {
        Some(filter) => filter.max_value(),
        None if source.depth.is_float() => u32::MAX as u64,
        None => (1 << (8 * source.depth.bytes())) - 1,
    }
}

/// Bytes of one exact sum of a run of `opts` on a `source` image cut into `layout`: 8, or 16
/// where the filter's sums could overflow a `u64` over the pyramid's depth (32-bit samples'
/// `box` past 4^15 pixels a texel). Float sums are 8-byte `f64`s.
pub(crate) fn sum_bytes(opts: &SplitOptions, source: PixelLayout, layout: &Layout) -> usize {
    let wide = match source.depth {
        Depth::U32 => sums_need_u128(u32::MAX as u64, layout.lod_count),
        Depth::F32 | Depth::F16 => false,
        Depth::U8 | Depth::U16 => ExactFilter::new(opts.filter, source).is_some_and(|f| f.needs_u128(layout.lod_count)),
    };
    if wide { 16 } else { 8 }
}

/// What a run reads, and in which passes.
enum Passes<'a> {
    /// The whole pyramid from the source: one band, or stripes and a coarse pass.
    Whole(Plan, &'a mut dyn RowSource),
    /// A shard's rectangles of the source, top to bottom, keeping their roots' sums.
    Shard(Vec<Span>, Box<dyn RowSource>),
    /// The levels above the cut, from the roots' sums.
    AboveCut(RootRows<'a>),
    /// `--fast-shrink`: the finest level's pages copied from the source's stored tiles, then
    /// the rest of the pyramid from the source at half size (whose levels are the `Layout`'s),
    /// as the `Whole` pass reads it.
    Halved(Plan, Layout, Box<dyn RowSource>),
}

/// Which of the finest level's pages are copied from the source, and what the summary says.
type CopyPlan = (Option<Copier>, Option<StoredReport>);

fn by_depth(
    image: ImageHeader,
    targets: &[Target],
    opts: &SplitOptions,
    layout: Layout,
    copy: CopyPlan,
    passes: Passes,
    progress: &dyn Progress,
) -> Result<(Summary, Vec<EncodedRoots>)> {
    match image.layout.depth {
        Depth::U8 => run::<u8>(image.layout, targets, opts, layout, copy, passes, progress),
        Depth::U16 => run::<u16>(image.layout, targets, opts, layout, copy, passes, progress),
        Depth::U32 => run::<u32>(image.layout, targets, opts, layout, copy, passes, progress),
        Depth::F32 => run::<f32>(image.layout, targets, opts, layout, copy, passes, progress),
        Depth::F16 => Err(TilerError::Options(
            "half-float samples are read as 32-bit floats; a source never hands them on as half".into(),
        )),
    }
}

fn run<T: Sample>(
    src_layout: PixelLayout,
    targets: &[Target],
    opts: &SplitOptions,
    layout: Layout,
    (copier, stored_tiles): CopyPlan,
    passes: Passes,
    progress: &dyn Progress,
) -> Result<(Summary, Vec<EncodedRoots>)> {
    let channels = src_layout.channels;
    // One encoder per distinct encoding of the targets; `which[t]` is target t's.
    let mut encodings: Vec<TileEncoding> = Vec::new();
    let which: Vec<usize> = (targets.iter())
        .map(|t| match encodings.iter().position(|e| *e == t.encoding) {
            Some(k) => k,
            None => {
                encodings.push(t.encoding);
                encodings.len() - 1
            }
        })
        .collect();
    let encoders = (encodings.iter())
        .map(|e| {
            let matte = e.matte.matte::<T>(channels);
            TileEncoder::<T>::new(e.codec, src_layout, e.flatten, e.tile_depth, layout.tile_size, matte)
        })
        .collect::<Result<Vec<_>>>()?;
    let Some(first) = encoders.first() else { return Err(TilerError::Internal("a run without a target".into())) };
    let padding = match opts.background.texel::<T>(channels) {
        Some(texel) => Padding::Colour(texel),
        None => Padding::Edge,
    };

    let (stripes, pass_count, planned) = match &passes {
        Passes::Whole(plan, _) | Passes::Halved(plan, ..) => {
            (plan.stripes.len(), plan.stripes.len() + plan.coarse.is_some() as usize, Some(plan.held))
        }
        Passes::Shard(spans, _) => (0, spans.len(), None),
        Passes::AboveCut(_) => (1, 0, None),
    };

    let (tx, rx) = sync_channel::<Result<Batch<T>>>(in_flight::QUEUE_BATCHES);
    let clock = StageClock::new();
    let tx = BatchSender::new(tx, Arc::clone(&clock));
    let counts = encoders::Counts::new(targets.len());
    // A halved pass's cascade starts at the run's first reduced level.
    let (cascade_layout, lods_above) = match &passes {
        Passes::Halved(_, half, _) => (*half, 1),
        _ => (layout, 0),
    };
    // Where every target copies the finest level's pages from the source's stored tiles, and a
    // page that cannot be copied can be cut from its decoded stored tile, the cascade sends
    // those pages without texels, as a halved pass does: the level's texels still make the
    // sums, but none is cut or held for the encoders (issue 45): each page's texels are only
    // compared as they pass, so that a pack still stores a page of one colour as its colour.
    let stored_finest = (copier.as_ref()).is_some_and(|c| c.tiles.decodes() && c.takes.iter().all(|&takes| takes));
    let roots = std::thread::scope(|scope| {
        let producer_clock = Arc::clone(&clock);
        let producer = scope.spawn(move || {
            let producer = Producer {
                layout: cascade_layout,
                pixels: src_layout,
                opts,
                padding,
                out: tx.above(lods_above),
                stored_finest: stored_finest && lods_above == 0,
                progress,
                clock: producer_clock,
            };
            let result = producer.clock.time(Stage::Producer, || {
                if lods_above > 0 {
                    send_stored_pages(&tx, &layout, &producer)?;
                }
                match sum_bytes(opts, src_layout, &cascade_layout) {
                    16 => producer.run::<T::Wide>(passes),
                    _ => producer.run::<T::Narrow>(passes),
                }
            });
            // An error goes to the consumer, which stops and returns it.
            result.unwrap_or_else(|e| {
                let _ = tx.send(Err(e));
                Vec::new()
            })
        });
        let consumed = encoders::consume(
            rx,
            (&encoders, &which),
            targets,
            (&layout, opts.background),
            &counts,
            copier.as_ref(),
            progress,
            &clock,
        );
        // Dropping the receiver (on error) makes the producer's next send fail, so it stops.
        let produced = producer.join().map_err(|_| TilerError::panicked("the tiling thread"))?;
        consumed.map(|()| produced)
    })?;
    let summary = Summary {
        layout,
        source: src_layout,
        stored: first.stored_layout(),
        tiles: counts.targets.iter().map(|t| t.tiles.load(Relaxed)).sum(),
        per_target: (counts.targets.iter().zip(targets))
            .map(|(t, target)| Written {
                tiles: t.tiles.load(Relaxed),
                bytes: target.sink.bytes_written(),
                copied: t.copied.load(Relaxed),
                cropped: t.cropped.load(Relaxed),
                recompressed: t.recompressed.total(),
            })
            .collect(),
        encoded: counts.encoded.into_inner(),
        kept: counts.kept.into_inner(),
        copied: counts.copied.into_inner(),
        cropped: counts.cropped.into_inner(),
        recompressed: counts.recompressed.total(),
        stored_tiles,
        bytes: targets.iter().map(|t| t.sink.bytes_written()).sum(),
        stripes,
        passes: pass_count,
        stages: clock.times(),
        memory: MemoryReport { budget: opts.max_memory, planned, peaks: clock.memory.peaks() },
    };
    Ok((summary, roots))
}

/// Every page of `layout`'s finest level, one batch per row, as pages to copy from the source's
/// stored tiles (`--fast-shrink`: no texel of that level is decoded, and a batch holds none).
fn send_stored_pages<T: Sample>(out: &BatchSender<T>, layout: &Layout, producer: &Producer<T>) -> Result<()> {
    let (columns, rows) = layout.grid(0);
    for y in 0..rows {
        producer.check_cancelled()?;
        let tiles = (0..columns).map(|x| CutTile { texels: Vec::new(), places: vec![(x, y)] }).collect();
        let sent = out.send(Ok(Batch { lod: 0, tiles, stored: true }));
        sent.map_err(|_| TilerError::Internal("the encoders stopped".into()))?;
    }
    Ok(())
}

/// The producer: reads the source row by row into each pass's cascade, which sends the cut
/// tiles on.
struct Producer<'a, T> {
    layout: Layout,
    pixels: PixelLayout,
    opts: &'a SplitOptions,
    padding: Padding<T>,
    out: BatchSender<T>,
    /// Whether LOD 0's pages go to the encoders as the source's stored tiles, without texels.
    stored_finest: bool,
    progress: &'a dyn Progress,
    clock: Arc<StageClock>,
}

impl<T: Sample> Producer<'_, T> {
    fn run<A: Acc>(&self, passes: Passes) -> Result<Vec<EncodedRoots>>
    where
        T: Into<A>,
    {
        let mut halved;
        let (plan, source) = match passes {
            Passes::Whole(plan, source) => (plan, source),
            Passes::Halved(plan, _, source) => {
                halved = source;
                (plan, halved.as_mut())
            }
            Passes::Shard(spans, mut source) => return self.shard::<A>(&spans, source.as_mut()),
            Passes::AboveCut(roots) => return self.above_cut::<A>(roots).map(|()| Vec::new()),
        };
        for (i, stripe) in plan.stripes.iter().enumerate() {
            if i > 0 {
                source.rewind()?;
            }
            let mut cascade = self.cascade::<A>(stripe);
            self.stripe::<A>(stripe, &mut *source, &mut cascade, plan.read_ahead_rows)?;
        }
        if let Some(coarse) = &plan.coarse {
            source.rewind()?;
            self.coarse::<A>(coarse, &mut *source)?;
        }
        Ok(Vec::new())
    }

    /// A shard's rectangles, each one pass over its rows of the source (with the margin its
    /// borders read), keeping the exact sums of its roots (halved: the sums of the texels of
    /// the level above them, or this rectangle's part of them).
    #[expect(clippy::expect_used, reason = "the cascade was asked to keep its root sums")]
    fn shard<A: Acc>(&self, spans: &[Span], source: &mut dyn RowSource) -> Result<Vec<EncodedRoots>>
    where
        T: Into<A>,
    {
        let mut at = 0u64;
        let mut all = Vec::with_capacity(spans.len());
        for span in spans {
            let rows = span.window_rows(&self.layout, 0);
            if rows.start < at {
                source.rewind()?;
                at = 0;
            }
            source.skip_rows((rows.start - at) as u32)?;
            let mut cascade = self.cascade::<A>(span);
            let above = span.lods.end < self.layout.lod_count;
            if above {
                cascade.keep_root_sums(span);
            }
            self.stripe::<A>(span, source, &mut cascade, 0)?;
            at = rows.end;
            if above {
                // What merge needs are the sums of the level above the roots.
                let channels = self.pixels.channels.count();
                let roots = cascade.take_root_sums().expect("kept").halved(channels);
                let bytes = sums::encode(&roots, channels)?;
                all.push(EncodedRoots { columns: roots.columns, rows: roots.rows, bytes });
            }
        }
        Ok(all)
    }

    fn cascade<A: Acc>(&self, span: &Span) -> Cascade<T, A>
    where
        T: Into<A>,
    {
        let cascade =
            Cascade::new(self.layout, span, self.pixels, self.opts.filter, self.padding.clone(), self.out.clone());
        match self.stored_finest && span.lods.start == 0 {
            true => cascade.with_stored_first(),
            false => cascade,
        }
    }

    /// LOD 0 onwards for the columns and rows of `span`, from the source's next row on: the
    /// window's part of each source row, read alone where the source can
    /// ([`RowSource::read_columns`]), else cut from the whole row; read ahead in chunks of
    /// `chunk_rows` (0: on this thread).
    fn stripe<A: Acc>(
        &self,
        span: &Span,
        source: &mut dyn RowSource,
        cascade: &mut Cascade<T, A>,
        chunk_rows: u64,
    ) -> Result<()>
    where
        T: Into<A>,
    {
        let channels = self.pixels.channels.count();
        let window = span.window(&self.layout, 0);
        let whole = window.end - window.start == self.layout.width as u64;
        // Asked even for all the columns: a shard's earlier pass may have asked for fewer.
        let narrow = source.read_columns(window.start as u32..window.end as u32) && !whole;
        let columns = match narrow {
            true => 0..(window.end - window.start) as usize * channels,
            false => window.start as usize * channels..window.end as usize * channels,
        };
        let row_len = if narrow { columns.end } else { self.layout.width as usize * channels };
        let rows = span.window_rows(&self.layout, 0);
        let count = rows.end - rows.start;
        if chunk_rows > 0 && cascade.has_levels_below() {
            return self.two_threads(source, cascade, count, row_len, columns, chunk_rows);
        }
        read_ahead::rows(source, count, row_len, chunk_rows, &self.clock, |row: &[T]| {
            self.check_cancelled()?;
            cascade.push_source_row(&row[columns.clone()])
        })?;
        cascade.finish()
    }

    /// [`stripe`](Self::stripe)'s pass with the pyramid's arithmetic on this thread and its
    /// cutting on another (issue 18: one thread doing both bound the run). Each chunk of source
    /// rows goes from the sums to the cutter with the rows the sums made of it; the cutter
    /// replays them in the order one thread would have, so the tiles and their order are the same.
    fn two_threads<A: Acc>(
        &self,
        source: &mut dyn RowSource,
        cascade: &mut Cascade<T, A>,
        count: u64,
        row_len: usize,
        columns: std::ops::Range<usize>,
        chunk_rows: u64,
    ) -> Result<()>
    where
        T: Into<A>,
    {
        let handoff = if cascade.first_level_stored() { STORED_HANDOFF_CHUNKS } else { HANDOFF_CHUNKS };
        let (sums, cuts) = cascade.parts();
        let (to_cutter, from_sums) = sync_channel::<(Option<read_ahead::Chunk<T>>, Derived<T>)>(handoff);
        let (spare_tx, spare_rx) = std::sync::mpsc::channel::<Derived<T>>();
        let clock = &self.clock;
        // Bytes of the rows handed on to the cutter: live until the pass ends (they come back to
        // be filled again).
        let mut derived_bytes = 0;
        let mut count_derived = |derived: &Derived<T>, had: usize| {
            let grown = derived.bytes() as i64 - had as i64;
            clock.memory.add(Part::SumRows, grown);
            derived_bytes += grown;
        };
        let cut_columns = columns.clone();
        let result = std::thread::scope(|scope| {
            let cutter = std::thread::Builder::new().name("vortex-cut".into()).spawn_scoped(scope, move || {
                clock.time(Stage::Cutter, || -> Result<()> {
                    while let Ok((chunk, derived)) = clock.time(Stage::CutWait, || from_sums.recv()) {
                        let source_rows = chunk.iter().flat_map(|c| c.rows().chunks_exact(row_len));
                        cuts.replay(source_rows.map(|row| &row[cut_columns.clone()]), &derived)?;
                        let _ = spare_tx.send(derived);
                    }
                    Ok(())
                })
            });
            let cutter = cutter.map_err(|e| TilerError::Internal(format!("cannot start the cutting thread: {e}")))?;
            let hand_on = move |chunk, derived| {
                let sent = clock.time(Stage::Handoff, || to_cutter.send((chunk, derived)));
                sent.map_err(|_| TilerError::Internal("the cutting thread stopped".into()))
            };
            let summed =
                read_ahead::chunks(source, count, row_len, chunk_rows, clock, |chunk: read_ahead::Chunk<T>| {
                    let mut derived = spare_rx.try_recv().unwrap_or_default();
                    derived.clear();
                    let had = derived.bytes();
                    for row in chunk.rows().chunks_exact(row_len) {
                        self.check_cancelled()?;
                        sums.push_source_row(&row[columns.clone()], &mut derived)?;
                        derived.end_source_row();
                    }
                    count_derived(&derived, had);
                    hand_on(Some(chunk), derived)
                })
                .and_then(|()| {
                    let mut derived = Derived::default();
                    sums.finish(&mut derived);
                    count_derived(&derived, 0);
                    hand_on(None, derived)
                });
            drop(hand_on);
            let cut = cutter.join().map_err(|_| TilerError::panicked("the cutting thread"))?;
            // A cutter that failed made the sums' hand-over fail: its error is the one to report.
            cut.and(summed)
        });
        clock.memory.add(Part::SumRows, -derived_bytes);
        result
    }

    /// The LODs above the cut level, from the exact sums of the first of them, assembled row
    /// by row from the shards' roots.
    fn above_cut<A: Acc>(&self, mut roots: RootRows) -> Result<()>
    where
        T: Into<A>,
    {
        let lod = roots.lod();
        let (columns, rows) = self.layout.grid(lod);
        let span = Span { lods: lod..self.layout.lod_count, columns: 0..columns, rows: 0..rows };
        let mut cascade = self.cascade::<A>(&span);
        let (w, h) = (self.layout.width as u64, self.layout.height as u64);
        let (width, height) = self.layout.level_extent(lod);
        let channels = self.pixels.channels.count();
        // Zero levels: each row of sums comes back as itself, weighed by its place.
        let mut weigh = Reducer::<A>::window(w, h, lod, 0, 0, width as usize, channels);
        let mut row = vec![A::default(); width as usize * channels];
        for y in 0..height as u64 {
            self.check_cancelled()?;
            roots.read(y, &mut row)?;
            if let Some(sums) = weigh.push(&row) {
                cascade.push_exact(&sums)?;
            }
        }
        roots.finish()?;
        cascade.finish()
    }

    /// The LODs of `span` (all columns, from its first LOD down) from block sums of the source.
    fn coarse<A: Acc>(&self, span: &Span, source: &mut dyn RowSource) -> Result<()>
    where
        T: Into<A>,
    {
        let mut cascade = self.cascade::<A>(span);
        let channels = self.pixels.channels.count();
        let (w, h) = (self.layout.width, self.layout.height);
        let mut blocks = Reducer::<A>::window(w as u64, h as u64, 0, span.lods.start, 0, w as usize, channels);
        let exact = ExactFilter::new(self.opts.filter, self.pixels);
        let mut prepared = vec![0u64; if exact.is_some() { w as usize * channels } else { 0 }];
        read_ahead::rows(source, h as u64, w as usize * channels, 0, &self.clock, |row: &[T]| {
            self.check_cancelled()?;
            let sums = match &exact {
                None => blocks.push(row),
                Some(filter) => filter.push_row(&mut blocks, row, &mut prepared),
            };
            match sums {
                Some(sums) => cascade.push_exact(&sums),
                None => Ok(()),
            }
        })?;
        if let Some(sums) = blocks.finish() {
            cascade.push_exact(&sums)?;
        }
        cascade.finish()
    }

    fn check_cancelled(&self) -> Result<()> {
        match self.progress.cancelled() {
            true => Err(TilerError::Interrupted),
            false => Ok(()),
        }
    }
}
