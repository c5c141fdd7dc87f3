//! The loader's pool: plain std threads (`vortex-loader-N`) that take pages from one queue,
//! read and decode them (`decode`) and answer on a channel, the blocking [`Loader::load`] and the
//! asynchronous [`Loader::request`] / [`Loader::poll`] over it, and the counters. Everything
//! about threads and their failures is here: a worker that dies answers nothing, which `load`
//! turns into [`LoadError::Lost`]; a decoder that panics is caught and answered with the
//! stand-in tile and an error.

use std::collections::VecDeque;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::sync::atomic::{AtomicBool, AtomicU8, AtomicU64, AtomicUsize, Ordering};
use std::sync::mpsc::{self, Receiver, Sender};
use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError};
use std::thread::JoinHandle;
use std::time::Duration;

use vortex_pack::Pack;
use vortex_vt::page::{MAX_TEXTURES, PageId};
use vortex_vt::residency::Slot;

use super::decode::{self, Made, Tally};
use super::tier::{Tier, TierUsage};
use super::transcode::transcode;
use super::{LoadCounters, LoadError, LoadedPage, LoaderError, RetryPolicy, stand_in_tile};
use crate::bc7;
#[cfg(not(target_arch = "wasm32"))]
use crate::clock::Instant;
use crate::layer::LayerKind;
use crate::page_cache::CacheFormat;
use crate::source::{PageSource, ReadErrorKind};
use crate::texture::VirtualTexture;

/// One page to load, and where its answer goes.
struct Job {
    index: usize,
    page: PageId,
    slot: Slot,
    reply: Sender<(usize, LoadedPage)>,
    /// Queued by [`Loader::request`] (so [`Loader::cancel`] may take it back), not by `load`.
    requested: bool,
}

struct Queue {
    jobs: VecDeque<Job>,
    shutdown: bool,
}

/// What the workers share with the loader.
struct Shared {
    sources: Vec<Arc<dyn PageSource>>,
    textures: Vec<VirtualTexture>,
    tile_size: u32,
    queue: Mutex<Queue>,
    ready: Condvar,
    pages: AtomicU64,
    tiles_decoded: AtomicU64,
    absent_filled: AtomicU64,
    bytes_read: AtomicU64,
    errors: AtomicU64,
    tier_hits: AtomicU64,
    tier_misses: AtomicU64,
    read_retries: AtomicU64,
    /// How reads that fail with an I/O error are tried again ([`Loader::set_retry`]).
    retry: Mutex<RetryPolicy>,
    /// Stored tiles kept in RAM ([`Loader::set_memory_tier`]).
    tier: Tier,
    /// The format pages are answered in ([`Loader::set_format`]), as its index in
    /// [`CacheFormat::ALL`].
    format: AtomicU8,
    /// The sources hold colour, premultiplied on load, not data ([`Loader::set_kind`]).
    colour: AtomicBool,
    /// Every source gives every tile as BC7 blocks as stored: a BC7 cache takes them as they are.
    stored_bc7: bool,
    /// In the browser: the most pages read at once, and the tasks reading them now (`web`).
    #[cfg(target_arch = "wasm32")]
    concurrency: usize,
    #[cfg(target_arch = "wasm32")]
    drivers: AtomicUsize,
}

/// Reads pages of up to 16 virtual textures (texture id = index in the sources given to
/// [`Loader::with_sources`]) on a pool of worker threads. Dropping it stops the workers: queued pages are
/// discarded and the pages being decoded are finished first (one tile per worker).
pub struct Loader {
    shared: Arc<Shared>,
    workers: Vec<JoinHandle<()>>,
    /// Where workers answer [`Loader::request`]s, and where [`Loader::poll`] collects them.
    async_tx: Sender<(usize, LoadedPage)>,
    async_rx: Mutex<Receiver<(usize, LoadedPage)>>,
    /// Requested pages not yet returned by [`Loader::poll`].
    pending: AtomicUsize,
    /// Time callers spent blocked in [`Loader::load`], in nanoseconds.
    waited: AtomicU64,
}

impl Loader {
    /// A loader of `packs` on `threads` worker threads: [`Loader::with_sources`] of packs.
    pub fn new(packs: Vec<Arc<Pack>>, threads: usize) -> Result<Loader, LoaderError> {
        Loader::with_sources(packs.into_iter().map(|p| p as Arc<dyn PageSource>).collect(), threads)
    }

    /// A loader of `sources` on `threads` worker threads (0: one per available core). The
    /// sources must all be virtual textures ([`PageSource::texture`]) with the same tile size and
    /// border, since their pages share one physical page cache. Sources that wait (on a disk or
    /// a network) want more threads than cores.
    pub fn with_sources(sources: Vec<Arc<dyn PageSource>>, threads: usize) -> Result<Loader, LoaderError> {
        let first = sources.first().ok_or(LoaderError::NoTextures)?;
        if sources.len() > MAX_TEXTURES as usize {
            return Err(LoaderError::TooManyTextures { count: sources.len() });
        }
        let textures = sources.iter().map(|s| s.texture()).collect::<Result<Vec<_>, _>>()?;
        let reference = textures[0];
        for (source, texture) in sources.iter().zip(&textures).skip(1) {
            for (field, a, b) in
                [("tile_size", reference.tile_size, texture.tile_size), ("border", reference.border, texture.border)]
            {
                if a != b {
                    return Err(LoaderError::Mismatch {
                        field,
                        first: first.location().to_path_buf(),
                        first_value: a,
                        other: source.location().to_path_buf(),
                        other_value: b,
                    });
                }
            }
        }
        // In the browser `threads` is how many pages are read at once (0: six, a browser's
        // connections per host), on the page's event loop.
        #[cfg(target_arch = "wasm32")]
        let (concurrency, threads) = (if threads == 0 { 6 } else { threads }, 0);
        let threads = match threads {
            #[cfg(not(target_arch = "wasm32"))]
            0 => std::thread::available_parallelism().map_or(1, |n| n.get()),
            n => n,
        };
        let stored_bc7 = reference.tile_size.is_multiple_of(4) && sources.iter().all(|s| s.holds_only_bc7());
        let shared = Arc::new(Shared {
            sources,
            textures,
            tile_size: reference.tile_size,
            queue: Mutex::new(Queue { jobs: VecDeque::new(), shutdown: false }),
            ready: Condvar::new(),
            pages: AtomicU64::new(0),
            tiles_decoded: AtomicU64::new(0),
            absent_filled: AtomicU64::new(0),
            bytes_read: AtomicU64::new(0),
            errors: AtomicU64::new(0),
            tier_hits: AtomicU64::new(0),
            tier_misses: AtomicU64::new(0),
            read_retries: AtomicU64::new(0),
            retry: Mutex::new(RetryPolicy::default()),
            tier: Tier::new(0),
            format: AtomicU8::new(0),
            colour: AtomicBool::new(true),
            stored_bc7,
            #[cfg(target_arch = "wasm32")]
            concurrency,
            #[cfg(target_arch = "wasm32")]
            drivers: AtomicUsize::new(0),
        });
        let (async_tx, async_rx) = mpsc::channel();
        // Built before the workers so that, if one fails to start, Drop stops those already started.
        #[cfg_attr(target_arch = "wasm32", allow(unused_mut))]
        let mut loader = Loader {
            shared,
            workers: Vec::with_capacity(threads),
            async_tx,
            async_rx: Mutex::new(async_rx),
            pending: AtomicUsize::new(0),
            waited: AtomicU64::new(0),
        };
        #[cfg(not(target_arch = "wasm32"))]
        for index in 0..threads {
            let shared = Arc::clone(&loader.shared);
            let worker = std::thread::Builder::new()
                .name(format!("vortex-loader-{index}"))
                .spawn(move || work(&shared))
                .map_err(|source| LoaderError::Spawn { index, source })?;
            loader.workers.push(worker);
        }
        Ok(loader)
    }

    /// The textures, indexed by texture id.
    pub fn textures(&self) -> &[VirtualTexture] {
        &self.shared.textures
    }

    /// The sources, by texture id.
    pub fn sources(&self) -> &[Arc<dyn PageSource>] {
        &self.shared.sources
    }

    /// Side of every tile of every texture, borders included (the page cache's slot side).
    pub fn tile_size(&self) -> u32 {
        self.shared.tile_size
    }

    /// Whether every source can give every tile as BC7 blocks as stored, so that pages can be
    /// streamed into a BC7 cache as they are (for packs: every stored tile is a BC7 payload or one
    /// colour; absent tiles would need decoding and re-encoding).
    pub fn holds_only_bc7(&self) -> bool {
        self.shared.stored_bc7
    }

    /// Whether every source's tiles are opaque, so that BC1 (which has no alpha) can hold them.
    pub fn opaque(&self) -> bool {
        self.shared.sources.iter().all(|s| s.opaque())
    }

    /// Whether pages come in with straight alpha: BC7 blocks taken as stored. Everything else is
    /// premultiplied on the loader's threads.
    pub fn straight_alpha(&self) -> bool {
        self.format() == CacheFormat::Bc7 && self.shared.stored_bc7
    }

    /// Makes every later page come in `format`: RGBA8 texels, or BC1 or BC7 blocks. BC7 blocks
    /// are taken as stored where every source [holds only BC7](Loader::holds_only_bc7); other
    /// pages are decoded, premultiplied and transcoded on the loader's threads.
    pub fn set_format(&self, format: CacheFormat) {
        let index = CacheFormat::ALL.iter().position(|&f| f == format).unwrap_or(0);
        self.shared.format.store(index as u8, Ordering::Relaxed);
    }

    /// The format pages come in ([`Loader::set_format`]).
    pub fn format(&self) -> CacheFormat {
        self.shared.format()
    }

    /// Makes every later page be taken as `kind`: colour is premultiplied on load, data is not.
    pub fn set_kind(&self, kind: LayerKind) {
        self.shared.colour.store(kind == LayerKind::Colour, Ordering::Relaxed);
    }

    /// Keeps up to `bytes` of stored tiles in RAM (the memory tier, least recently used out
    /// first), so that a page read again is decoded from RAM instead of read from its source;
    /// 0 (a new loader's setting) keeps none. A smaller budget drops tiles at once.
    pub fn set_memory_tier(&self, bytes: u64) {
        self.shared.tier.set_budget(bytes);
    }

    /// Makes every later read that fails with an I/O error be tried again as `retry` says
    /// ([`RetryPolicy::default`] for a new loader).
    pub fn set_retry(&self, retry: RetryPolicy) {
        *lock(&self.shared.retry) = retry;
    }

    /// What the memory tier holds now.
    pub fn memory_tier(&self) -> TierUsage {
        self.shared.tier.usage()
    }

    /// Texels of border on each side of every tile.
    pub fn border(&self) -> u32 {
        self.shared.textures[0].border
    }

    /// Worker threads.
    pub fn threads(&self) -> usize {
        self.workers.len()
    }

    /// Loads `pages` on the workers and waits for all of them; the answers are in the order of
    /// `pages` (one per entry, duplicates included). Pages queued by [`Loader::request`] before
    /// this call are decoded first.
    pub fn load(&self, pages: &[(PageId, Slot)]) -> Vec<LoadedPage> {
        if pages.is_empty() {
            return Vec::new();
        }
        // In the browser nothing may wait: the pages are decoded here, from what their sources
        // hold without waiting (`PageSource::prepare` is not awaited).
        #[cfg(target_arch = "wasm32")]
        return pages.iter().map(|&(page, slot)| self.shared.load_page(page, slot)).collect();
        #[cfg(not(target_arch = "wasm32"))]
        self.load_on_workers(pages)
    }

    #[cfg(not(target_arch = "wasm32"))]
    fn load_on_workers(&self, pages: &[(PageId, Slot)]) -> Vec<LoadedPage> {
        let (tx, rx) = mpsc::channel();
        self.enqueue(pages.iter().enumerate().map(|(index, &(page, slot))| Job {
            index,
            page,
            slot,
            reply: tx.clone(),
            requested: false,
        }));
        // Only the jobs hold senders now: if every one of them is gone, `recv` stops waiting.
        drop(tx);
        let started = Instant::now();
        let mut answers: Vec<Option<LoadedPage>> = vec![None; pages.len()];
        for _ in 0..pages.len() {
            let Ok((index, answer)) = rx.recv() else { break };
            if let Some(place) = answers.get_mut(index) {
                *place = Some(answer);
            }
        }
        let waited = u64::try_from(started.elapsed().as_nanos()).unwrap_or(u64::MAX);
        self.waited.fetch_add(waited, Ordering::Relaxed);
        answers
            .into_iter()
            .zip(pages)
            .map(|(answer, &(page, slot))| {
                answer.unwrap_or_else(|| LoadedPage {
                    page,
                    slot,
                    texels: stand_in_tile(self.shared.tile_size),
                    bytes_read: 0,
                    tier_hits: 0,
                    tier_misses: 0,
                    error: Some(LoadError::Lost { page }),
                })
            })
            .collect()
    }

    /// Queues `pages` and returns at once; [`Loader::poll`] collects them as they finish. Each
    /// entry is answered once (a page requested twice is loaded twice).
    pub fn request(&self, pages: &[(PageId, Slot)]) {
        self.pending.fetch_add(pages.len(), Ordering::Relaxed);
        self.enqueue(pages.iter().map(|&(page, slot)| Job {
            index: 0,
            page,
            slot,
            reply: self.async_tx.clone(),
            requested: true,
        }));
    }

    /// Takes back the [`Loader::request`]ed loads of `pages` (page, slot) that no worker has
    /// started yet: their answers will never come. Returns how many it took back. Pages being
    /// read are answered as usual.
    pub fn cancel(&self, pages: &[(PageId, Slot)]) -> usize {
        if pages.is_empty() {
            return 0;
        }
        let cancelled: std::collections::HashSet<(PageId, Slot)> = pages.iter().copied().collect();
        let mut queue = lock(&self.shared.queue);
        let before = queue.jobs.len();
        queue.jobs.retain(|job| !job.requested || !cancelled.contains(&(job.page, job.slot)));
        let taken = before - queue.jobs.len();
        drop(queue);
        self.pending.fetch_sub(taken, Ordering::Relaxed);
        taken
    }

    /// The requested pages finished since the last call, in the order they finished; never waits.
    pub fn poll(&self) -> Vec<LoadedPage> {
        let rx = self.async_rx.lock().unwrap_or_else(PoisonError::into_inner);
        let finished: Vec<LoadedPage> = rx.try_iter().map(|(_, page)| page).collect();
        self.pending.fetch_sub(finished.len(), Ordering::Relaxed);
        finished
    }

    /// Pages requested and not yet returned by [`Loader::poll`].
    pub fn pending(&self) -> usize {
        self.pending.load(Ordering::Relaxed)
    }

    /// The time callers have spent blocked in [`Loader::load`] waiting for pages: what reading
    /// and decoding cost the calling thread. [`Loader::request`] and [`Loader::poll`] never add
    /// to it.
    pub fn waited(&self) -> Duration {
        Duration::from_nanos(self.waited.load(Ordering::Relaxed))
    }

    /// What it has done so far.
    pub fn counters(&self) -> LoadCounters {
        let s = &self.shared;
        LoadCounters {
            pages: s.pages.load(Ordering::Relaxed),
            tiles_decoded: s.tiles_decoded.load(Ordering::Relaxed),
            absent_filled: s.absent_filled.load(Ordering::Relaxed),
            bytes_read: s.bytes_read.load(Ordering::Relaxed),
            errors: s.errors.load(Ordering::Relaxed),
            tier_hits: s.tier_hits.load(Ordering::Relaxed),
            tier_misses: s.tier_misses.load(Ordering::Relaxed),
            read_retries: s.read_retries.load(Ordering::Relaxed),
        }
    }

    fn enqueue(&self, jobs: impl Iterator<Item = Job>) {
        let mut queue = lock(&self.shared.queue);
        queue.jobs.extend(jobs);
        drop(queue);
        self.shared.ready.notify_all();
        #[cfg(target_arch = "wasm32")]
        drive(&self.shared);
    }
}

impl Drop for Loader {
    fn drop(&mut self) {
        let mut queue = lock(&self.shared.queue);
        queue.shutdown = true;
        queue.jobs.clear();
        drop(queue);
        self.shared.ready.notify_all();
        for worker in self.workers.drain(..) {
            // A worker that panicked has nothing left to clean up; its panic was already reported.
            let _ = worker.join();
        }
    }
}

/// No lock is held across anything that can panic, so a poisoned lock still holds consistent data.
fn lock<T>(mutex: &Mutex<T>) -> MutexGuard<'_, T> {
    mutex.lock().unwrap_or_else(PoisonError::into_inner)
}

impl Shared {
    /// The next queued job, or `None` once there is none or the loader shut down.
    #[cfg(target_arch = "wasm32")]
    fn next_job(&self) -> Option<Job> {
        let mut queue = lock(&self.queue);
        if queue.shutdown { None } else { queue.jobs.pop_front() }
    }

    /// Answers `job` with its page, loaded now.
    #[cfg(target_arch = "wasm32")]
    fn answer(&self, job: Job) {
        let answer = self.load_page(job.page, job.slot);
        let _ = job.reply.send((job.index, answer));
    }
}

/// In the browser: starts tasks on the page's event loop, up to the loader's concurrency, each of
/// which takes queued jobs until none is left. A task awaits its page's [`PageSource::prepare`]
/// (the page's tile, and while that is absent its ancestors', fetched) and then decodes it at
/// once, as a worker thread would.
#[cfg(target_arch = "wasm32")]
fn drive(shared: &Arc<Shared>) {
    while shared.drivers.load(Ordering::Relaxed) < shared.concurrency && !lock(&shared.queue).jobs.is_empty() {
        shared.drivers.fetch_add(1, Ordering::Relaxed);
        let shared = Arc::clone(shared);
        wasm_bindgen_futures::spawn_local(async move {
            while let Some(job) = shared.next_job() {
                shared.prepare(job.page).await;
                shared.answer(job);
            }
            shared.drivers.fetch_sub(1, Ordering::Relaxed);
        });
    }
}

#[cfg(target_arch = "wasm32")]
impl Shared {
    /// Awaits the page's tile and, while it is absent, its ancestors' (what `decode` will read).
    async fn prepare(&self, page: PageId) {
        let (Some(source), Some(texture)) =
            (self.sources.get(page.texture as usize), self.textures.get(page.texture as usize))
        else {
            return;
        };
        if !texture.grid.contains(page) {
            return;
        }
        for tile in page.ancestors_and_self(&texture.grid) {
            let tile = crate::source::tile_id(tile);
            if let Some(ready) = source.prepare(tile) {
                ready.await;
            }
            let absent = matches!(
                source.read_stored(tile),
                Ok(Some(crate::source::StoredRead { tile: crate::source::StoredTile::Absent, .. }))
            );
            if !absent {
                return;
            }
        }
    }
}

/// A worker: takes jobs until the loader shuts down.
#[cfg(not(target_arch = "wasm32"))]
fn work(shared: &Shared) {
    loop {
        let job = {
            let mut queue = lock(&shared.queue);
            loop {
                if queue.shutdown {
                    return;
                }
                if let Some(job) = queue.jobs.pop_front() {
                    break job;
                }
                queue = shared.ready.wait(queue).unwrap_or_else(PoisonError::into_inner);
            }
        };
        let answer = shared.load_page(job.page, job.slot);
        // The receiver is gone only if nobody wants the answer any more (a dropped loader).
        let _ = job.reply.send((job.index, answer));
    }
}

impl Shared {
    fn format(&self) -> CacheFormat {
        CacheFormat::ALL[usize::from(self.format.load(Ordering::Relaxed)).min(CacheFormat::ALL.len() - 1)]
    }

    /// One page, its counters updated. Never panics on bad data: a panicking decoder is caught and
    /// reported like any other decoding error.
    fn load_page(&self, page: PageId, slot: Slot) -> LoadedPage {
        let format = self.format();
        // Stored BC7 blocks are taken as they are; anything else is decoded (and transcoded).
        let read_as = if format == CacheFormat::Bc7 && self.stored_bc7 { CacheFormat::Bc7 } else { CacheFormat::Rgba8 };
        let colour = self.colour.load(Ordering::Relaxed);
        let retry = *lock(&self.retry);
        let mut tally = Tally::default();
        let texels = || {
            decode::texels(&self.sources, &self.textures, &self.tier, retry, page, read_as, colour, &mut tally).map(
                |(texels, made)| {
                    (if read_as == format { texels } else { transcode(texels, self.tile_size, format) }, made)
                },
            )
        };
        let result = catch_unwind(AssertUnwindSafe(texels)).unwrap_or_else(|panic| {
            let what = panic
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_default();
            let path = self.sources.get(page.texture as usize).map(|s| s.location().to_path_buf()).unwrap_or_default();
            Err(LoadError::Tile {
                path,
                lod: page.lod.into(),
                x: page.x.into(),
                y: page.y.into(),
                kind: ReadErrorKind::Corrupt,
                message: format!("the decoder panicked: {what}"),
            })
        });
        let Tally { bytes_read, tiles_decoded, tier_hits, tier_misses, read_retries } = tally;
        self.read_retries.fetch_add(read_retries.into(), Ordering::Relaxed);
        self.tiles_decoded.fetch_add(tiles_decoded, Ordering::Relaxed);
        self.tier_hits.fetch_add(tier_hits.into(), Ordering::Relaxed);
        self.tier_misses.fetch_add(tier_misses.into(), Ordering::Relaxed);
        self.pages.fetch_add(1, Ordering::Relaxed);
        self.bytes_read.fetch_add(bytes_read, Ordering::Relaxed);
        let (texels, error) = match result {
            Ok((texels, made)) => {
                if let Made::FromAncestor = made {
                    self.absent_filled.fetch_add(1, Ordering::Relaxed);
                }
                (texels, None)
            }
            Err(e) => {
                self.errors.fetch_add(1, Ordering::Relaxed);
                let stand_in = stand_in_tile(self.tile_size);
                let texels = match format {
                    CacheFormat::Bc7 => bc7::solid_blocks(&stand_in, self.tile_size),
                    other => transcode(stand_in, self.tile_size, other),
                };
                (texels, Some(e))
            }
        };
        LoadedPage { page, slot, texels, bytes_read, tier_hits, tier_misses, error }
    }
}
