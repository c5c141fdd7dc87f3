//! The `split` pipeline: source -> bands -> tiles and pyramid -> sink.
//!
//! A producer thread reads the source row by row into the LOD-0 band and cascades every row
//! down the pyramid (each level keeps its own band and one half-built row for the next). As
//! soon as a band holds everything a row of tiles needs, the tiles are cut and sent, in a
//! bounded channel, to the calling thread, which encodes them in parallel on the rayon pool
//! and hands them to the sink. Peak memory is therefore a few bands of the image's width,
//! whatever its height; output bytes do not depend on the thread count.

use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, SyncSender, sync_channel};

use rayon::prelude::*;

use crate::background::Background;
use crate::band::Band;
use crate::codec::{Codec, TileEncoder};
use crate::cut::{self, Padding, Run};
use crate::error::{Result, TilerError};
use crate::filter::{ExactFilter, Filter};
use crate::layout::Layout;
use crate::pixel::{Depth, PixelLayout, Sample};
use crate::pyramid::{Acc, ExactRow, Reducer};
use crate::resample::Resampler;
use crate::sink::TileSink;
use crate::source::RowSource;

/// How to cut and store the pyramid.
#[derive(Clone, Debug)]
pub struct SplitOptions {
    pub tile_size: u32,
    pub border: u32,
    pub codec: Codec,
    pub background: Background,
    /// Composite alpha over the background (or black) instead of storing it.
    pub flatten: bool,
    /// Store tiles at this depth instead of the source's (JPEG is always 8-bit).
    pub tile_depth: Option<Depth>,
    /// How each LOD is made from the finer ones.
    pub filter: Filter,
}

/// Watches a run: told of finished tiles, asked whether to stop.
pub trait Progress: Sync {
    fn advance(&self, _tiles: u64) {}
    /// Checked once per source row and per batch of tiles; a run that sees `true` stops with
    /// [`TilerError::Interrupted`].
    fn cancelled(&self) -> bool {
        false
    }
}

/// No progress reporting, never cancelled.
impl Progress for () {}

/// What a finished run produced.
#[derive(Clone, Debug)]
pub struct Summary {
    pub layout: Layout,
    pub source: PixelLayout,
    pub stored: PixelLayout,
    pub tiles: u64,
    /// Tiles encoded; the others share an identical neighbour's bytes or were stored as their one colour.
    pub encoded: u64,
    pub bytes: u64,
}

/// Batches of tiles waiting for the encoder: cutting is much cheaper than encoding, so one
/// waiting batch keeps the encoders busy, and each extra one would cost a row of tiles of memory.
const QUEUE_BATCHES: usize = 1;

/// One row of tiles of one LOD.
struct Batch<T> {
    lod: u32,
    tiles: Vec<CutTile<T>>,
}

/// Texels of a tile and every (x, y) that holds them: neighbours with identical texels (most
/// often padding) share one encoding.
struct CutTile<T> {
    texels: Vec<T>,
    places: Vec<(u32, u32)>,
}

/// Cuts `source` into the pyramid and writes every tile to `sink`. Runs the encoders on the
/// current rayon pool; `progress` hears of every finished tile and can stop the run.
pub fn split(
    source: Box<dyn RowSource>,
    sink: &dyn TileSink,
    opts: &SplitOptions,
    progress: &dyn Progress,
) -> Result<Summary> {
    let layout = Layout::new(source.width() as u64, source.height() as u64, opts.tile_size, opts.border)?;
    match source.layout().depth {
        Depth::U8 => run::<u8>(source, sink, opts, layout, progress),
        Depth::U16 => run::<u16>(source, sink, opts, layout, progress),
    }
}

fn run<T: Sample>(
    source: Box<dyn RowSource>,
    sink: &dyn TileSink,
    opts: &SplitOptions,
    layout: Layout,
    progress: &dyn Progress,
) -> Result<Summary> {
    let src_layout = source.layout();
    let channels = src_layout.channels;
    let matte = opts.background.matte::<T>(channels);
    let encoder =
        TileEncoder::<T>::new(opts.codec, src_layout, opts.flatten, opts.tile_depth, layout.tile_size, matte)?;
    let padding = match opts.background.texel::<T>(channels) {
        Some(texel) => Padding::Colour(texel),
        None => Padding::Edge,
    };

    let (tx, rx) = sync_channel::<Result<Batch<T>>>(QUEUE_BATCHES);
    let encoded = AtomicU64::new(0);
    let tiles = AtomicU64::new(0);
    std::thread::scope(|scope| {
        let producer = scope.spawn(move || {
            let exact = ExactFilter::new(opts.filter, src_layout);
            let result = if exact.is_some_and(|f| f.needs_u128(layout.lod_count)) {
                Pyramid::<T, u128>::new(layout, src_layout, opts.filter, padding, tx.clone()).run(source, progress)
            } else {
                Pyramid::<T, u64>::new(layout, src_layout, opts.filter, padding, tx.clone()).run(source, progress)
            };
            if let Err(e) = result {
                let _ = tx.send(Err(e));
            }
        });
        let consumed = consume(rx, &encoder, sink, &encoded, &tiles, progress);
        // Dropping the receiver (on error) makes the producer's next send fail, so it stops.
        producer.join().map_err(|_| TilerError::Options("the tiling thread panicked".into()))?;
        consumed
    })?;
    Ok(Summary {
        layout,
        source: src_layout,
        stored: encoder.stored_layout(),
        tiles: tiles.into_inner(),
        encoded: encoded.into_inner(),
        bytes: sink.bytes_written(),
    })
}

/// Encodes and writes batches as they arrive. Small batches (coarse levels, narrow images) are
/// merged with the ones waiting behind them so that every thread has work.
fn consume<T: Sample>(
    rx: Receiver<Result<Batch<T>>>,
    encoder: &TileEncoder<T>,
    sink: &dyn TileSink,
    encoded: &AtomicU64,
    tiles: &AtomicU64,
    progress: &dyn Progress,
) -> Result<()> {
    while let Ok(first) = rx.recv() {
        if progress.cancelled() {
            return Err(TilerError::Interrupted);
        }
        let mut work = vec![first?];
        let enough = 2 * rayon::current_num_threads();
        while work.iter().map(|b| b.tiles.len()).sum::<usize>() < enough {
            match rx.try_recv() {
                Ok(more) => work.push(more?),
                Err(_) => break,
            }
        }
        let jobs: Vec<(u32, &CutTile<T>)> = work.iter().flat_map(|b| b.tiles.iter().map(move |t| (b.lod, t))).collect();
        let store = |(lod, tile, stored): (u32, &CutTile<T>, Stored)| -> Result<()> {
            for &(x, y) in &tile.places {
                match &stored {
                    Stored::Encoded(bytes) => sink.write_tile(lod, x, y, bytes)?,
                    Stored::Constant(texel) => sink.write_constant(lod, x, y, texel)?,
                }
            }
            tiles.fetch_add(tile.places.len() as u64, Ordering::Relaxed);
            progress.advance(tile.places.len() as u64);
            Ok(())
        };
        let prepared = jobs.par_iter().map(|&(lod, tile)| {
            let stored = prepare(encoder, sink, lod, tile)?;
            if matches!(stored, Stored::Encoded(_)) {
                encoded.fetch_add(1, Ordering::Relaxed);
            }
            Ok((lod, tile, stored))
        });
        if sink.ordered() {
            // Encode in parallel, store in the producer's (deterministic) order.
            let prepared: Vec<Result<_>> = prepared.collect();
            prepared.into_iter().try_for_each(|p| store(p?))?;
        } else {
            prepared.try_for_each(|p| store(p?))?;
        }
    }
    Ok(())
}

/// A tile ready for the sink.
enum Stored {
    Encoded(Vec<u8>),
    /// Every texel is this one (stored layout, little-endian samples).
    Constant(Vec<u8>),
}

/// Encodes a tile, unless it has one colour and the sink stores such tiles as their colour.
fn prepare<T: Sample>(encoder: &TileEncoder<T>, sink: &dyn TileSink, lod: u32, tile: &CutTile<T>) -> Result<Stored> {
    let channels = encoder.source_layout().channels.count();
    let texels = &tile.texels;
    if sink.takes_constants() && texels.chunks_exact(channels).all(|t| t == &texels[..channels]) {
        return Ok(Stored::Constant(encoder.stored_texel(&texels[..channels])));
    }
    let mut bytes = Vec::new();
    let (x, y) = tile.places[0];
    encoder.encode(texels, &mut bytes).map_err(|message| TilerError::Encode { lod, x, y, message })?;
    Ok(Stored::Encoded(bytes))
}

/// How a level makes the next one.
enum Down<T, A> {
    /// The exact filters: a cascade of sums.
    Exact(Reducer<A>),
    /// The resampling filters: the next level from this one's rounded rows.
    Resample(Box<Resampler<T>>),
}

/// One LOD in flight: its band, the tile rows cut so far and the reduction to the next LOD.
struct Level<T, A> {
    lod: u32,
    extent: (u32, u32),
    band: Band<T>,
    next_tile_row: u32,
    x_runs: Vec<Vec<Run>>,
    down: Option<Down<T, A>>,
    /// The current row, rounded from exact sums.
    row: Vec<T>,
}

/// What every level's cutting needs.
struct Cutter<'a, T> {
    layout: &'a Layout,
    channels: usize,
    padding: &'a Padding<T>,
    out: &'a SyncSender<Result<Batch<T>>>,
}

struct Pyramid<T, A> {
    layout: Layout,
    channels: usize,
    padding: Padding<T>,
    levels: Vec<Level<T, A>>,
    out: SyncSender<Result<Batch<T>>>,
    /// What the exact cascade sums when it is not the samples themselves.
    exact: Option<ExactFilter>,
    /// A source row as `exact` sums it.
    prepared: Vec<u64>,
}

impl<T: Sample + Into<A>, A: Acc> Pyramid<T, A> {
    fn new(
        layout: Layout,
        pixels: PixelLayout,
        filter: Filter,
        padding: Padding<T>,
        out: SyncSender<Result<Batch<T>>>,
    ) -> Self {
        let edge = padding == Padding::Edge;
        let channels = pixels.channels.count();
        let levels = (0..layout.lod_count)
            .map(|lod| {
                let extent = layout.level_extent(lod);
                let row_len = extent.0 as usize * channels;
                let x_runs =
                    (0..layout.tiles_per_side(lod)).map(|t| cut::runs(&layout, lod, t, extent.0, edge)).collect();
                let down = (lod + 1 < layout.lod_count).then(|| {
                    if filter.is_exact() {
                        let (w, h) = (layout.width as u64, layout.height as u64);
                        Down::Exact(Reducer::new(w, h, lod, extent.0 as usize, channels))
                    } else {
                        Down::Resample(Box::new(Resampler::new(filter, pixels, extent.0 as usize, extent.1 as u64)))
                    }
                });
                Level {
                    lod,
                    extent,
                    band: Band::new(row_len, layout.tile_size as usize + 1),
                    next_tile_row: 0,
                    x_runs,
                    down,
                    row: vec![T::default(); row_len],
                }
            })
            .collect();
        let exact = ExactFilter::new(filter, pixels);
        let prepared = if exact.is_some() { vec![0; layout.width as usize * channels] } else { Vec::new() };
        Pyramid { layout, channels, padding, levels, out, exact, prepared }
    }

    fn run(&mut self, mut source: Box<dyn RowSource>, progress: &dyn Progress) -> Result<()> {
        let mut row = vec![T::default(); self.levels[0].row.len()];
        for _ in 0..self.layout.height {
            if progress.cancelled() {
                return Err(TilerError::Interrupted);
            }
            source.read_row(bytemuck::cast_slice_mut(&mut row))?;
            self.push_source_row(&row)?;
        }
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

    fn push_source_row(&mut self, row: &[T]) -> Result<()> {
        let cutter = Cutter { layout: &self.layout, channels: self.channels, padding: &self.padding, out: &self.out };
        let (first, rest) = self.levels.split_first_mut().expect("at least one level");
        first.band.push(row);
        first.cut_ready(&cutter)?;
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
        if let Some(Down::Exact(reducer)) = &mut this.down
            && let Some(next) = reducer.push(exact.sums)
        {
            Self::feed_exact(rest, &next, cutter, filter)?;
        }
        Ok(())
    }

    /// Gives `levels[0]` its next rows (row-major) and resamples them into the levels below it.
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
        let rows = layout.tiles_per_side(self.lod);
        while self.next_tile_row < rows
            && self.band.end() > cut::last_row_needed(layout, self.lod, self.next_tile_row, height)
        {
            let ty = self.next_tile_row;
            // Rows of tiles entirely below the image are all alike (they repeat the last image
            // row, or are background): cut the first, and give it the places of all the others.
            let below_image = cut::first_row_needed(layout, ty) >= height as i64;
            let row_span = if below_image { ty..rows } else { ty..ty + 1 };
            let y_runs = cut::runs(layout, self.lod, ty, height, *padding == Padding::Edge);
            let mut tiles: Vec<CutTile<T>> = Vec::new();
            let mut texels = Vec::with_capacity(layout.tile_texels() * channels);
            for (tx, x_runs) in self.x_runs.iter().enumerate() {
                let places = row_span.clone().map(|y| (tx as u32, y));
                // Columns of tiles right of the image read the same texels as their left neighbour.
                if tx > 0 && self.x_runs[tx - 1] == *x_runs {
                    tiles.last_mut().expect("a tile left of this one").places.extend(places);
                    continue;
                }
                cut::cut_tile(&self.band, channels, x_runs, &y_runs, padding, &mut texels);
                match tiles.last_mut() {
                    Some(prev) if prev.texels == texels => prev.places.extend(places),
                    _ => {
                        let full = std::mem::replace(&mut texels, Vec::with_capacity(layout.tile_texels() * channels));
                        tiles.push(CutTile { texels: full, places: places.collect() })
                    }
                }
            }
            out.send(Ok(Batch { lod: self.lod, tiles }))
                .map_err(|_| TilerError::Options("the encoder stopped".into()))?;
            self.next_tile_row = row_span.end;
            self.band.drop_before(cut::first_row_kept(layout, ty, height));
        }
        Ok(())
    }
}
