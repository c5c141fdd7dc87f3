//! The LOD cascade: every level of the pyramid in flight at once, in bounded memory.
//!
//! Each level keeps its own [`Band`] and the means to make the next level: a [`Reducer`] of
//! exact sums for the exact filters (one half-built row of sums per level), a [`Resampler`] for
//! lanczos3 and mitchell. A source row goes into LOD 0 and cascades down as far as it
//! completes rows; whenever a level's band holds every row a row of tiles reads, those tiles
//! are cut ([`cut`]) and sent as one [`Batch`] to the encoders. The cascade knows nothing of
//! where rows come from or where tiles go: `split.rs` feeds it and drains the channel.

use std::sync::mpsc::SyncSender;

use super::band::Band;
use super::cut::{self, Padding, Run};
use super::filter::{ExactFilter, Filter};
use super::reduce::{Acc, ExactRow, Reducer};
use super::resample::Resampler;
use crate::error::{Result, TilerError};
use crate::layout::Layout;
use crate::pixel::{PixelLayout, Sample};

/// Where the cascade sends each row of tiles (or the error that stopped it).
pub(crate) type BatchSender<T> = SyncSender<Result<Batch<T>>>;

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
    pub fn new(layout: Layout, pixels: PixelLayout, filter: Filter, padding: Padding<T>, out: BatchSender<T>) -> Self {
        let edge = padding == Padding::Edge;
        let channels = pixels.channels.count();
        let levels = (0..layout.lod_count)
            .map(|lod| {
                let extent = layout.level_extent(lod);
                let row_len = extent.0 as usize * channels;
                let (columns, _) = layout.grid(lod);
                let virtual_width = layout.virtual_extent(lod).0;
                let x_runs = (0..columns).map(|t| cut::runs(&layout, t, extent.0, virtual_width, edge)).collect();
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
                    band: Band::new(row_len, (layout.tile_size + 1).min(extent.1) as usize),
                    next_tile_row: 0,
                    x_runs,
                    down,
                    row: vec![T::default(); row_len],
                }
            })
            .collect();
        let exact = ExactFilter::new(filter, pixels);
        let prepared = if exact.is_some() { vec![0; layout.width as usize * channels] } else { Vec::new() };
        Cascade { layout, channels, padding, levels, out, exact, prepared }
    }

    /// Samples in one source row (the LOD-0 width times the channels).
    pub fn row_len(&self) -> usize {
        self.levels[0].row.len()
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
        let (_, rows) = layout.grid(self.lod);
        let virtual_height = layout.virtual_extent(self.lod).1;
        while self.next_tile_row < rows && self.band.end() > cut::last_row_needed(layout, self.next_tile_row, height) {
            let ty = self.next_tile_row;
            let y_runs = cut::runs(layout, ty, height, virtual_height, *padding == Padding::Edge);
            let mut tiles: Vec<CutTile<T>> = Vec::new();
            let mut texels = Vec::with_capacity(layout.tile_texels() * channels);
            for (tx, x_runs) in self.x_runs.iter().enumerate() {
                cut::cut_tile(&self.band, channels, x_runs, &y_runs, padding, &mut texels);
                // Neighbours with the same texels (most often one colour) share one encoding.
                match tiles.last_mut() {
                    Some(prev) if prev.texels == texels => prev.places.push((tx as u32, ty)),
                    _ => {
                        let full = std::mem::replace(&mut texels, Vec::with_capacity(layout.tile_texels() * channels));
                        tiles.push(CutTile { texels: full, places: vec![(tx as u32, ty)] })
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
