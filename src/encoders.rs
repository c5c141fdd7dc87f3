//! The encode-and-store stage: batches of cut tiles encoded on the rayon pool and handed to the
//! sink.
//!
//! Tiles are encoded as tasks on the pool with no barrier between batches: a batch's tiles are
//! spawned as soon as it arrives, while the last tiles of the one before are still being encoded.
//! (A parallel loop per batch left a core idle at the end of every batch, waiting for the other's
//! last tile; issue 18.) A sink that takes tiles in any order stores each as it is encoded; an
//! ordered one (a pack) gets them from a writer thread, in the producer's order, batch by batch as
//! each completes, so that its bytes do not depend on the thread count. At most `LOTS_IN_FLIGHT`
//! lots are encoding or waiting for the writer at once.
//!
//! Where the source's stored JPEG tiles line up with the finest level's pages, a [`Copier`]
//! hands those pages' files over instead of encoding them ([`crate::source::stored`]); for
//! JPEG XL tiles each is recompressed losslessly ([`File::Recompressed`]: `djxl` gives the
//! stored JPEG back byte for byte).

use std::borrow::Cow;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::atomic::{AtomicU64, Ordering};
use std::sync::mpsc::{Receiver, TryRecvError, sync_channel};
use std::sync::{Arc, Condvar, Mutex};
use std::time::Instant;

use crate::background::Background;
use crate::codec::Codec;
use crate::codec::TileEncoder;
use crate::error::{Result, TilerError};
use crate::job::{Progress, Recompressed};
use crate::layout::Crop;
use crate::layout::Layout;
use crate::limits::in_flight::{GATHER_MOST, LOTS_IN_FLIGHT};
use crate::limits::{Gauge, Part};
use crate::pixel::Sample;
use crate::pyramid::cascade::{Batch, CutTile};
use crate::pyramid::cut::{self, Padding};
use crate::sink::Target;
use crate::source::stored::{StoredTiles, crop};
use crate::stages::{Stage, StageClock};

/// Tiles a lot is gathered up to: enough to keep every thread of the pool busy twice over.
fn gather_target() -> usize {
    (2 * rayon::current_num_threads()).min(GATHER_MOST)
}

/// What the stage counts: tiles encoded, tiles copied from the source (some cropped), and
/// what each target got.
#[derive(Default)]
pub(crate) struct Counts {
    pub encoded: AtomicU64,
    /// Tiles (places) that every sink they go to held already, kept from an interrupted run
    /// (`--resume`): not encoded again.
    pub kept: AtomicU64,
    pub copied: AtomicU64,
    /// Of the copied tiles, those cropped at the image's edge.
    pub cropped: AtomicU64,
    /// Of the copied tiles, those recompressed into JPEG XL.
    pub recompressed: Recompressing,
    pub targets: Vec<Placed>,
}

/// [`Recompressed`] as it is counted, from the pool's threads.
#[derive(Default)]
pub(crate) struct Recompressing {
    tiles: AtomicU64,
    jpeg_bytes: AtomicU64,
    jxl_bytes: AtomicU64,
    refused: AtomicU64,
}

impl Recompressing {
    fn add(&self, jpeg: usize, jxl: usize) {
        self.tiles.fetch_add(1, Ordering::Relaxed);
        self.jpeg_bytes.fetch_add(jpeg as u64, Ordering::Relaxed);
        self.jxl_bytes.fetch_add(jxl as u64, Ordering::Relaxed);
    }

    pub fn total(&self) -> Recompressed {
        Recompressed {
            tiles: self.tiles.load(Ordering::Relaxed),
            jpeg_bytes: self.jpeg_bytes.load(Ordering::Relaxed),
            jxl_bytes: self.jxl_bytes.load(Ordering::Relaxed),
            refused: self.refused.load(Ordering::Relaxed),
        }
    }
}

/// What one target got: tiles stored (places), and of them those copied from the source
/// (some cropped).
#[derive(Default)]
pub(crate) struct Placed {
    pub tiles: AtomicU64,
    pub copied: AtomicU64,
    pub cropped: AtomicU64,
    pub recompressed: Recompressing,
}

impl Counts {
    pub fn new(targets: usize) -> Counts {
        Counts { targets: (0..targets).map(|_| Placed::default()).collect(), ..Counts::default() }
    }
}

/// The finest level's pages that are a stored tile of the source, texel for texel: same grid,
/// no border, and what the sink keeps of the page inside the image. A page the sink keeps
/// whole there is the stored tile as it is; an edge page the sink crops (Deep Zoom, IIIF) is
/// the stored tile cropped losslessly ([`crop`]). A page padded past the image (a pack's or
/// XYZ's edge page) is encoded: the stored tile's padding is not ours.
pub(crate) struct Copier {
    pub tiles: std::sync::Arc<dyn StoredTiles>,
    /// The finest level's image, across and down.
    pub width: u32,
    pub height: u32,
    pub side: u32,
    /// Whether target t takes the copies (its encoding is the stored tiles'); the others get
    /// those pages encoded.
    pub takes: Vec<bool>,
}

impl Copier {
    /// Whether page (`lod`, `x`, `y`), kept as `crop` by the sink (`None`: whole), is copied.
    fn covers(&self, lod: u32, (x, y): (u32, u32), crop: Option<Crop>) -> bool {
        let c = crop.unwrap_or(Crop::whole(self.side));
        let inside = |at: u32, len: u32, extent: u32| at as u64 * self.side as u64 + len as u64 <= extent as u64;
        lod == 0 && (c.x, c.y) == (0, 0) && inside(x, c.width, self.width) && inside(y, c.height, self.height)
    }

    /// Page (`x`, `y`) of the finest level (no border: the copies' grid) cut from its stored
    /// tile, decoded whole, and padded past the image as the cascade pads (`padding`): where a
    /// run that has no texels of that level (`--fast-shrink`) must encode a page it cannot copy,
    /// the page the cascade would have cut.
    fn page<T: Sample>(&self, (x, y): (u32, u32), layout: &Layout, padding: &Padding<T>) -> Result<Vec<T>> {
        let Some(decoded) = self.tiles.decode(x, y, 1)? else {
            return Err(TilerError::Internal("a stored tile to copy cannot be decoded".into()));
        };
        let side = self.side;
        let (w, h) = (side.min(self.width - x * side) as usize, side.min(self.height - y * side) as usize);
        let channels = decoded.len() / (w * h).max(1);
        if decoded.len() != w * h * channels {
            return Err(TilerError::Internal(format!("{} bytes decoded for a {w}x{h} tile", decoded.len())));
        }
        let texels: Vec<T> = decoded.into_iter().map(T::from_u8_scaled).collect();
        let (extent, virtual_extent) = (layout.level_extent(0), layout.virtual_extent(0));
        let (edge, fill) = match padding {
            Padding::Edge => (true, &[][..]),
            Padding::Colour(texel) => (false, &texel[..]),
        };
        let x_runs = cut::shifted(cut::runs(layout, x, extent.0, virtual_extent.0, edge), u64::from(x * side));
        let y_runs = cut::shifted(cut::runs(layout, y, extent.1, virtual_extent.1, edge), u64::from(y * side));
        let row = |r: u32| Some(&texels[r as usize * w * channels..(r as usize + 1) * w * channels]);
        let mut page = Vec::with_capacity(side as usize * side as usize * channels);
        for run in y_runs {
            match run {
                cut::Run::Copy { start, len } => {
                    (start..start + len).for_each(|r| cut::push_row(&mut page, &x_runs, row(r), channels, fill))
                }
                cut::Run::Repeat { at, len } => {
                    (0..len).for_each(|_| cut::push_row(&mut page, &x_runs, row(at), channels, fill))
                }
                cut::Run::Fill { len } => {
                    (0..len).for_each(|_| cut::push_row(&mut page, &x_runs, None, channels, fill))
                }
            }
        }
        Ok(page)
    }

    /// Page (`x`, `y`) of the finest level, kept as `crop`, as a file made from the stored
    /// tile; `None` where the stored tile cannot be copied, or not cropped to exactly the texels
    /// the run decoded ([`crop::exact`]).
    fn file(&self, (x, y): (u32, u32), crop: Option<Crop>) -> Result<Option<File>> {
        let Some(file) = self.tiles.tile(x, y)? else { return Ok(None) };
        let size = crop.map_or((self.side, self.side), |c| (c.width, c.height));
        if size == (self.side, self.side) {
            return Ok(Some(File::Copied(file)));
        }
        if !crate::source::stored::read_header(&file).is_some_and(|h| crop::exact(&h, (self.side, self.side), size)) {
            return Ok(None);
        }
        let cropped = crop::crop(&file, size).map_err(|m| TilerError::Encode {
            lod: 0,
            x,
            y,
            message: format!("cropping the stored JPEG tile: {m}"),
        })?;
        Ok(Some(File::Cropped(cropped)))
    }
}

/// Encodes and writes batches as they arrive, until the producer is done or something fails.
/// `encoders`: one per distinct encoding of the targets, `which[t]` target t's.
/// `pages`: the grid the tiles were cut on and the background they were padded with.
#[expect(clippy::too_many_arguments, reason = "the stage's inputs, each from another part of the run")]
pub(crate) fn consume<T: Sample>(
    rx: Receiver<Result<Batch<T>>>,
    (encoders, which): (&[TileEncoder<T>], &[usize]),
    targets: &[Target],
    pages: (&Layout, Background),
    counts: &Counts,
    copier: Option<&Copier>,
    progress: &dyn Progress,
    clock: &StageClock,
) -> Result<()> {
    let busy = Busy::default();
    let memory = &clock.memory;
    let (layout, cut_with) = pages;
    let channels = layout_channels(encoders)?;
    // The colour each target pads with where the pages were cut with another (with the edge).
    let fills = targets
        .iter()
        .map(|t| match (t.background == cut_with, t.background.texel::<T>(channels)) {
            (true, _) => Ok(None),
            (false, Some(texel)) => Ok(Some(texel)),
            (false, None) => {
                Err(TilerError::Internal("a sink that repeats the edge was fed pages padded with a colour".into()))
            }
        })
        .collect::<Result<Vec<_>>>()?;
    let padding = match cut_with.texel::<T>(channels) {
        Some(texel) => Padding::Colour(texel),
        None => Padding::Edge,
    };
    let stage = Encoding {
        encoders,
        which,
        targets,
        fills: &fills,
        padding,
        layout,
        counts,
        copier,
        progress,
        busy: &busy,
        memory,
    };
    // The writer waits for each lot in turn and frees its place once it is stored; a lot is
    // received only into a free place, so the writer's queue never fills.
    let (to_writer, lots) = sync_channel::<Arc<Lot<T>>>(LOTS_IN_FLIGHT);
    let (free_place, places) = sync_channel::<()>(LOTS_IN_FLIGHT);
    for _ in 0..LOTS_IN_FLIGHT {
        let _ = free_place.send(());
    }
    let result = std::thread::scope(|threads| {
        let writer = threads.spawn(|| -> Result<()> {
            // Owned here, so that a writer that stops drops it.
            let free_place = free_place;
            for lot in lots {
                let results = lot.wait();
                // Only ordered sinks have anything left to store; every other one stored its
                // tiles as they were encoded.
                clock.time(Stage::Store, || {
                    results.into_iter().zip(&lot.jobs).try_for_each(|(result, job)| match result? {
                        Some(stored) => {
                            memory.add(Part::Encoded, -(stored.bytes() as i64));
                            stage.store(job, &stored, true)
                        }
                        None => Ok(()),
                    })
                })?;
                // The consumer holds none: this never waits. A writer that failed drops
                // `free_place`, which stops the consumer.
                let _ = free_place.try_send(());
            }
            Ok(())
        });
        let fed = rayon::in_place_scope(|pool| -> Result<()> {
            // Off the pool, plain blocking waits; on one of its threads, waits that run its tasks.
            let on_pool = rayon::current_thread_index().is_some();
            let next = || match on_pool {
                true => helping(|| rx.try_recv().map_err(|e| e == TryRecvError::Empty)),
                false => rx.recv().map_err(|_| ()),
            };
            let place = || match on_pool {
                true => helping(|| places.try_recv().map_err(|e| e == TryRecvError::Empty)),
                false => places.recv().map_err(|_| ()),
            };
            while place().is_ok()
                && let Ok(first) = next()
            {
                if progress.cancelled() {
                    return Err(TilerError::Interrupted);
                }
                let lot = Arc::new(Lot::of(gather(first?, &rx)?, &stage));
                for k in 0..lot.jobs.len() {
                    let lot = Arc::clone(&lot);
                    let stage = &stage;
                    pool.spawn(move |_| {
                        // A task that panicked must still finish its job, or the writer waits forever.
                        let run = catch_unwind(AssertUnwindSafe(|| stage.run(&lot.jobs[k])));
                        let panicked = || Err(TilerError::panicked("a tile encoder"));
                        lot.finish_job(k, run.unwrap_or_else(|_| panicked()));
                    });
                }
                // The lot has a place, so this never waits. Only a writer that failed hangs up:
                // its error is the one to report.
                if to_writer.try_send(lot).is_err() {
                    break;
                }
            }
            Ok(())
        });
        drop(to_writer);
        let written = writer.join().map_err(|_| TilerError::panicked("the tile writer"))?;
        written.and(fed)
    });
    clock.add(Stage::EncodersIdle, busy.idle());
    clock.add(Stage::Encode, busy.encoding() / rayon::current_num_threads().max(1) as u32);
    clock.add_cpu(Stage::Encode, busy.encoding_cpu());
    result
}

/// On one of the pool's threads (a caller inside `ThreadPool::install`), waits for `attempt` to
/// succeed (`Ok`) or to fail for good (`Err(false)`; `Err(true)` means "not yet"), running the
/// pool's pending tasks meanwhile: some may be the very tasks it waits for, which a one-thread
/// pool has no other thread to run. With none pending it sleeps a little between attempts.
fn helping<R>(mut attempt: impl FnMut() -> std::result::Result<R, bool>) -> std::result::Result<R, ()> {
    loop {
        match attempt() {
            Ok(r) => return Ok(r),
            Err(false) => return Err(()),
            Err(true) => {
                if rayon::yield_now() != Some(rayon::Yield::Executed) {
                    std::thread::sleep(std::time::Duration::from_micros(100));
                }
            }
        }
    }
}

/// The first batch and those waiting behind it, merged while they are fewer tiles than keep
/// every thread busy (coarse levels, narrow images).
fn gather<T>(first: Batch<T>, rx: &Receiver<Result<Batch<T>>>) -> Result<Vec<Batch<T>>> {
    let mut work = vec![first];
    let enough = gather_target();
    while work.iter().map(|b| b.tiles.len()).sum::<usize>() < enough {
        match rx.try_recv() {
            Ok(more) => work.push(more?),
            Err(_) => break,
        }
    }
    Ok(work)
}

/// What every encoding task needs.
struct Encoding<'a, T> {
    /// One per distinct encoding of the targets; `which[t]` is target t's.
    encoders: &'a [TileEncoder<T>],
    which: &'a [usize],
    targets: &'a [Target<'a>],
    /// Each target's padding colour, where it is not the one the pages were cut with.
    fills: &'a [Option<Vec<T>>],
    /// What the pages were padded with past the image, for pages cut here from a stored tile.
    padding: Padding<T>,
    layout: &'a Layout,
    counts: &'a Counts,
    copier: Option<&'a Copier>,
    progress: &'a dyn Progress,
    busy: &'a Busy,
    memory: &'a Gauge,
}

impl<T: Sample> Encoding<'_, T> {
    /// Encodes one job and stores it into the sinks that take tiles in any order; what the
    /// ordered ones (a pack) need is left for the writer, which stores it in the lot's order.
    fn run(&self, job: &Job<T>) -> JobResult {
        let _busy = self.busy.start();
        let texels = job.take_texels()?;
        let encoder = &self.encoders[job.encoder];
        // The page as this job's targets pad it: cut from the stored tile first where the
        // cascade did not cut it.
        let page = || -> Result<Cow<'_, [T]>> {
            let mut page = match (job.stored, self.copier) {
                (false, _) => Cow::Borrowed(&texels[..]),
                (true, Some(copier)) => Cow::Owned(copier.page(job.places[0].1, self.layout, &self.padding)?),
                (true, None) => return Err(TilerError::Internal("a stored page without the stored tiles".into())),
            };
            if let Some((from, t)) = job.pad {
                let (side, channels) = (self.layout.tile_size, encoder.source_layout().channels.count());
                let fill = self.fills[t].as_deref().unwrap_or_default();
                cut::fill_padding(page.to_mut(), side, channels, from, fill);
            }
            Ok(page)
        };
        // A tile every place of which a resumed run kept is neither encoded nor stored again.
        let kept = job.places.iter().all(|&(t, (x, y))| self.targets[t].sink.kept(job.lod, x, y));
        let stored = match kept {
            true => Stored { constant: None, file: Some(File::Kept) },
            false => {
                let colour = (job.stored && !texels.is_empty()).then_some(&texels[..]);
                prepare(encoder, self.targets, job, page, colour, self.copier, self.counts)?
            }
        };
        // The last job of a tile frees its texels here, not when the writer stores the lot.
        if let Some(texels) = Arc::into_inner(texels) {
            self.memory.add(Part::Tiles, -((texels.capacity() * size_of::<T>()) as i64));
        }
        match stored.file {
            Some(File::Encoded(_)) => self.counts.encoded.fetch_add(1, Ordering::Relaxed),
            // Every place of it kept (several, where identical pages were merged at the cut).
            Some(File::Kept) => self.counts.kept.fetch_add(job.places.len() as u64, Ordering::Relaxed),
            Some(File::Copied(_)) => self.counts.copied.fetch_add(1, Ordering::Relaxed),
            Some(File::Cropped(_)) => {
                self.counts.cropped.fetch_add(1, Ordering::Relaxed);
                self.counts.copied.fetch_add(1, Ordering::Relaxed)
            }
            Some(File::Recompressed { ref jxl, jpeg, cropped }) => {
                self.counts.recompressed.add(jpeg, jxl.len());
                self.counts.cropped.fetch_add(u64::from(cropped), Ordering::Relaxed);
                self.counts.copied.fetch_add(1, Ordering::Relaxed)
            }
            None => 0,
        };
        self.store(job, &stored, false)?;
        if job.places.iter().any(|&(t, _)| self.targets[t].sink.ordered()) {
            self.memory.add(Part::Encoded, stored.bytes() as i64);
            return Ok(Some(stored));
        }
        Ok(None)
    }

    /// Writes a prepared tile to every place of the ordered sinks (`ordered`) or of the others
    /// that gets it: as its one colour where the sink takes that, else as the file.
    fn store(&self, job: &Job<T>, stored: &Stored, ordered: bool) -> Result<()> {
        let mut count = 0;
        for &(t, (x, y)) in &job.places {
            let sink = self.targets[t].sink;
            if sink.ordered() != ordered {
                continue;
            }
            let placed = &self.counts.targets[t];
            match (&stored.constant, &stored.file) {
                // In the sink already.
                (_, Some(File::Kept)) => {}
                (Some(texel), _) if sink.takes_constants() => sink.write_constant(job.lod, x, y, texel)?,
                (_, Some(File::Encoded(bytes))) => sink.write_tile(job.lod, x, y, bytes)?,
                // A JPEG XL file is no stored JPEG tile: the sink is told it is a recompressed one.
                (_, Some(File::Recompressed { jxl, jpeg, cropped })) => {
                    sink.write_recompressed(job.lod, x, y, jxl)?;
                    placed.copied.fetch_add(1, Ordering::Relaxed);
                    placed.cropped.fetch_add(u64::from(*cropped), Ordering::Relaxed);
                    placed.recompressed.add(*jpeg, jxl.len());
                }
                (_, Some(file)) => {
                    sink.write_stored(job.lod, x, y, file.bytes())?;
                    placed.copied.fetch_add(1, Ordering::Relaxed);
                    if let File::Cropped(_) = file {
                        placed.cropped.fetch_add(1, Ordering::Relaxed);
                    }
                }
                (_, None) => return Err(TilerError::Internal("a tile was prepared without its file".into())),
            }
            placed.tiles.fetch_add(1, Ordering::Relaxed);
            count += 1;
        }
        self.progress.advance(count);
        Ok(())
    }
}

/// What became of a job: the tile for an ordered sink's writer to store (`None`: stored already).
type JobResult = Result<Option<Stored>>;

/// Batches received together, as the encodings they need, and what became of each.
struct Lot<T> {
    jobs: Vec<Job<T>>,
    /// Each job's result once it has one, and how many have none yet.
    finished: Mutex<(Vec<Option<JobResult>>, usize)>,
    done: Condvar,
}

impl<T: Sample> Lot<T> {
    fn of(batches: Vec<Batch<T>>, stage: &Encoding<T>) -> Lot<T> {
        let jobs: Vec<Job<T>> = batches
            .into_iter()
            .flat_map(|batch| {
                let (lod, stored) = (batch.lod, batch.stored);
                batch.tiles.into_iter().flat_map(move |tile| Job::of(stage, lod, stored, tile))
            })
            .collect();
        let finished = Mutex::new(((0..jobs.len()).map(|_| None).collect(), jobs.len()));
        Lot { jobs, finished, done: Condvar::new() }
    }

    fn finish_job(&self, k: usize, result: JobResult) {
        let mut finished = self.finished.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
        finished.0[k] = Some(result);
        finished.1 -= 1;
        if finished.1 == 0 {
            self.done.notify_all();
        }
    }

    /// Waits until every job has finished; their results, in order.
    fn wait(&self) -> Vec<JobResult> {
        let mut finished = self.finished.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
        while finished.1 > 0 {
            finished = self.done.wait(finished).unwrap_or_else(|poisoned| poisoned.into_inner());
        }
        let missing = || Err(TilerError::Internal("an encoding task stopped without a result".into()));
        finished.0.iter_mut().map(|r| r.take().unwrap_or_else(missing)).collect()
    }
}

/// One encoding: a cut tile's texels, the encoder and the part of them the sinks keep, and the
/// places that get it (each a target's index and a page).
struct Job<T> {
    lod: u32,
    /// Which of the run's encoders.
    encoder: usize,
    crop: Option<Crop>,
    /// One page whose source tile is copied rather than encoded (pages identical at the cut
    /// may have different stored bytes, so each page is a job of its own).
    copy: bool,
    /// A page of a stored batch ([`Batch::stored`]): no texels until it must be encoded.
    stored: bool,
    /// Where the page's padding starts (column, row) and the target whose colour fills it, for
    /// targets that pad with another colour than the pages were cut with.
    pad: Option<((u32, u32), usize)>,
    places: Vec<(usize, (u32, u32))>,
    /// Until the encoding takes them: the texels are freed as soon as every encoding of the
    /// tile is done, not kept until the writer has stored the whole lot, so that a row of
    /// tiles less is held at once (issue 28).
    texels: Mutex<Option<Arc<Vec<T>>>>,
}

impl<T: Sample> Job<T> {
    /// The encodings a cut tile needs: one for every distinct encoder and crop the targets
    /// keep of its places (identical pages merged at the cut may sit at a viewer tile's edge and in the
    /// middle; Deep Zoom crops an edge page that a pack keeps whole), and one per copied page.
    /// Targets past their last level get nothing; a padded page gets a job of its own for
    /// each padding colour its targets fill it with.
    fn of(stage: &Encoding<T>, lod: u32, stored: bool, cut: CutTile<T>) -> Vec<Job<T>> {
        let texels = Arc::new(cut.texels);
        let l = stage.layout;
        let (extent, virtual_extent) = (l.level_extent(lod), l.virtual_extent(lod));
        let mut jobs: Vec<Job<T>> = Vec::new();
        for page in cut.places {
            let from = (
                cut::padding_from(l, page.0, extent.0, virtual_extent.0),
                cut::padding_from(l, page.1, extent.1, virtual_extent.1),
            );
            for (t, target) in stage.targets.iter().enumerate().filter(|(_, target)| lod < target.lods) {
                // A crop that keeps the whole page is no crop: the same encoding as a pack's.
                let crop = target.sink.crop(lod, page.0, page.1).filter(|c| *c != Crop::whole(l.tile_size));
                let encoder = stage.which[t];
                let copy = stage.copier.is_some_and(|c| c.takes[t] && c.covers(lod, page, crop));
                let padded = stage.fills[t].is_some() && from != (l.tile_size, l.tile_size);
                let pad = padded.then_some((from, t));
                let fill = |pad: Option<((u32, u32), usize)>| pad.map(|(from, t)| (from, &stage.fills[t]));
                let same = |j: &&mut Job<T>| {
                    j.encoder == encoder
                        && j.crop == crop
                        && j.copy == copy
                        && (!(copy || stored) || j.places[0].1 == page)
                        && fill(j.pad) == fill(pad)
                };
                match jobs.iter_mut().find(same) {
                    Some(job) => job.places.push((t, page)),
                    None => jobs.push(Job {
                        lod,
                        encoder,
                        crop,
                        copy,
                        stored,
                        pad,
                        places: vec![(t, page)],
                        texels: Mutex::new(Some(Arc::clone(&texels))),
                    }),
                }
            }
        }
        jobs
    }

    /// The texels, for the one run of this job.
    fn take_texels(&self) -> Result<Arc<Vec<T>>> {
        let mut slot = self.texels.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
        slot.take().ok_or_else(|| TilerError::Internal("a tile was encoded twice".into()))
    }
}

/// A tile ready for the sinks: its one colour for those that store such tiles as their colour,
/// its file for the others.
struct Stored {
    /// Every texel is this one (stored layout, little-endian samples).
    constant: Option<Vec<u8>>,
    file: Option<File>,
}

/// A tile's file.
enum File {
    Encoded(Vec<u8>),
    /// The source's stored tile, as a file.
    Copied(Vec<u8>),
    /// The source's stored tile cropped losslessly to the part of an edge page the sink keeps.
    Cropped(Vec<u8>),
    /// The stored tile (`cropped` or not) recompressed losslessly into JPEG XL: `jxl`, from a
    /// JPEG of `jpeg` bytes, which `djxl` rebuilds byte for byte.
    Recompressed {
        jxl: Vec<u8>,
        jpeg: usize,
        cropped: bool,
    },
    /// None: the tile is in every sink of it already, kept from an interrupted run.
    Kept,
}

impl File {
    /// The file's bytes.
    fn bytes(&self) -> &[u8] {
        match self {
            File::Encoded(b) | File::Copied(b) | File::Cropped(b) | File::Recompressed { jxl: b, .. } => b,
            File::Kept => &[],
        }
    }

    /// The copy as `codec`'s tiles hold it: a JPEG as it is for JPEG tiles, recompressed for
    /// JPEG XL ones (less any quantisation table no component uses); `None` where libjxl cannot rebuild this JPEG exactly (counted in
    /// `refused`), so that the page is encoded from its texels instead.
    fn for_codec(self, codec: Codec, refused: &AtomicU64) -> Result<Option<File>> {
        let Codec::Jxl { effort, .. } = codec else { return Ok(Some(self)) };
        let cropped = matches!(self, File::Cropped(_));
        let jpeg = self.bytes();
        // A table no component uses (an RGB slide's chroma table) is not kept: libjxl would
        // refuse the JPEG, and it decodes the same without it.
        let used = crate::source::stored::without_unused_tables(jpeg).unwrap_or(std::borrow::Cow::Borrowed(jpeg));
        match vortex_jxl::recompress_jpeg(&used, effort) {
            Ok(jxl) => Ok(Some(File::Recompressed { jxl, jpeg: jpeg.len(), cropped })),
            Err(vortex_jxl::Error::JpegRecompression { .. }) => {
                refused.fetch_add(1, Ordering::Relaxed);
                Ok(None)
            }
            Err(e) => Err(TilerError::Internal(format!("recompressing a stored JPEG tile: {e}"))),
        }
    }
}

impl Stored {
    /// Bytes held until the writer stores it.
    fn bytes(&self) -> usize {
        let file = match &self.file {
            Some(File::Encoded(b) | File::Copied(b) | File::Cropped(b) | File::Recompressed { jxl: b, .. }) => {
                b.capacity()
            }
            Some(File::Kept) | None => 0,
        };
        file + self.constant.as_ref().map_or(0, Vec::capacity)
    }
}

/// Encodes a tile (or the part the sinks keep), unless it has one colour and every sink that
/// gets it stores such tiles as their colour, or it is copied from the source as stored.
///
/// `page` gives the texels (cut from the stored tile, for a stored job, only when asked): a
/// stored page to copy is copied without being decoded; `colour` is its one colour, where the
/// band found every texel of it to be one (`Band::drop_texels`).
fn prepare<'a, T: Sample>(
    encoder: &TileEncoder<T>,
    targets: &[Target],
    job: &Job<T>,
    page: impl Fn() -> Result<Cow<'a, [T]>>,
    colour: Option<&[T]>,
    copier: Option<&Copier>,
    counts: &Counts,
) -> Result<Stored> {
    let channels = encoder.source_layout().channels.count();
    let takes_constants = |&(t, _): &(usize, _)| targets[t].sink.takes_constants();
    // A pack entry holds a constant texel of up to 8 bytes (not 3 or 4 samples of 32 bits).
    let may_be_constant = job.places.iter().any(takes_constants) && encoder.stored_layout().bytes_per_pixel() <= 8;
    // A stored page to copy is not decoded to find out: the band said whether it is one colour.
    let copied_as_stored = job.stored && job.copy;
    let looked_at = if may_be_constant && !copied_as_stored { Some(page()?) } else { None };
    let one_colour = match &looked_at {
        Some(texels) => texels.chunks_exact(channels).all(|t| t == &texels[..channels]).then(|| &texels[..channels]),
        None => colour.filter(|_| may_be_constant && copied_as_stored),
    };
    let constant = one_colour.map(|texel| encoder.stored_texel(texel));
    if constant.is_some() && job.places.iter().all(takes_constants) {
        return Ok(Stored { constant, file: None });
    }
    let (lod, (x, y)) = (job.lod, job.places[0].1);
    if let Some(copier) = copier.filter(|_| job.copy)
        && let Some(file) = copier.file((x, y), job.crop)?
        && job.places.iter().all(|&(t, _)| targets[t].sink.takes_stored_jpeg(file.bytes()))
        && let Some(file) = file.for_codec(encoder.codec(), &counts.recompressed.refused)?
    {
        return Ok(Stored { constant, file: Some(file) });
    }
    let texels = match looked_at {
        Some(texels) => texels,
        None => page()?,
    };
    let mut bytes = Vec::new();
    let encoded = match job.crop {
        None => encoder.encode(&texels, &mut bytes),
        Some(crop) => encoder.encode_crop(&texels, crop, &mut bytes),
    };
    encoded.map_err(|e| TilerError::Encode { lod, x, y, message: e.to_string() })?;
    // A JPEG or PNG grows its buffer as it writes, up to twice its length: what waits for the
    // writer is only the encoding, as the plan counts it (`Codec::most_encoded_bytes`).
    bytes.shrink_to_fit();
    Ok(Stored { constant, file: Some(File::Encoded(bytes)) })
}

/// The source's channels, which every encoder of a run shares.
fn layout_channels<T: Sample>(encoders: &[TileEncoder<T>]) -> Result<crate::pixel::Channels> {
    match encoders.first() {
        Some(encoder) => Ok(encoder.source_layout().channels),
        None => Err(TilerError::Internal("a run without an encoder".into())),
    }
}

/// When the pool's encoders were busy: the time all of them waited at once, and the time spent
/// encoding (summed over threads).
#[derive(Default)]
struct Busy {
    state: Mutex<BusyState>,
}

#[derive(Default)]
struct BusyState {
    running: usize,
    /// When the last task before an idle spell finished (`None` before the first task).
    idle_since: Option<Instant>,
    idle: std::time::Duration,
    encoding: std::time::Duration,
    /// The tasks' CPU time, from their threads' CPU clocks (summed, not divided by threads).
    encoding_cpu: std::time::Duration,
}

impl Busy {
    /// Marks a task running until the guard drops.
    fn start(&self) -> BusyGuard<'_> {
        let now = Instant::now();
        let mut s = self.state.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
        if s.running == 0
            && let Some(since) = s.idle_since
        {
            s.idle += now - since;
        }
        s.running += 1;
        BusyGuard { busy: self, started: now, cpu: crate::stages::thread_cpu() }
    }

    fn idle(&self) -> std::time::Duration {
        self.state.lock().map_or_else(|p| p.into_inner().idle, |s| s.idle)
    }

    fn encoding(&self) -> std::time::Duration {
        self.state.lock().map_or_else(|p| p.into_inner().encoding, |s| s.encoding)
    }

    fn encoding_cpu(&self) -> std::time::Duration {
        self.state.lock().map_or_else(|p| p.into_inner().encoding_cpu, |s| s.encoding_cpu)
    }
}

struct BusyGuard<'a> {
    busy: &'a Busy,
    started: Instant,
    cpu: Option<std::time::Duration>,
}

impl Drop for BusyGuard<'_> {
    fn drop(&mut self) {
        let cpu = self.cpu.zip(crate::stages::thread_cpu()).map(|(from, to)| to.saturating_sub(from));
        let now = Instant::now();
        let mut s = self.busy.state.lock().unwrap_or_else(|poisoned| poisoned.into_inner());
        s.encoding += now - self.started;
        s.encoding_cpu += cpu.unwrap_or_default();
        s.running -= 1;
        if s.running == 0 {
            s.idle_since = Some(now);
        }
    }
}
