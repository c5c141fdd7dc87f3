//! The tile loader: reads the pages the residency asks for from Vortex tile packs and turns them
//! into RGBA8 texels ready for `queue.write_texture` into a slot of the page cache. Decoding runs
//! on the loader's own pool of worker threads (plain std threads named `vortex-loader-N`); the
//! caller's thread only queues pages and collects texels, blocking ([`Loader::load`]) or not
//! ([`Loader::request`] and [`Loader::poll`]). Pure CPU: nothing here touches wgpu.
//!
//! Every page gets texels, so a slot is never left holding stale or garbage data:
//!
//! - a stored tile (PNG, JPEG, zstd, raw or constant) is decoded by `vortex_pack::decode_rgba8`,
//!   which checks its CRC-32C;
//! - an `absent` tile ("the runtime falls back to the parent tile", pack format) is built from its
//!   nearest stored ancestor by bilinear magnification (`magnify` below); that is not an error;
//! - a tile that cannot be read or decoded, or a page outside its texture, gets the
//!   [stand-in tile](stand_in_tile) (a magenta and black checkerboard) and a [`LoadError`] that
//!   names the pack and the tile.
//!
//! A page's result depends only on the pack and the page, never on the thread that decoded it or
//! on other pages (nothing is cached between pages), so results and counters are the same
//! whatever the thread count.

use std::collections::VecDeque;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::sync::atomic::{AtomicBool, AtomicU64, AtomicUsize, Ordering};
use std::sync::mpsc::{self, Receiver, Sender};
use std::sync::{Arc, Condvar, Mutex, MutexGuard, PoisonError};
use std::thread::JoinHandle;

use vortex_pack::{Pack, PackError, Tile, TileKind};
use vortex_vt::page::{MAX_TEXTURES, PageId, TextureGrid};
use vortex_vt::residency::Slot;

use crate::bc7;
use crate::page_cache::CacheFormat;

use crate::texture::VirtualTexture;

/// Why a [`VirtualTexture`] or a [`Loader`] cannot be made.
#[derive(Debug, thiserror::Error)]
pub enum LoaderError {
    /// The pack's layout is not a virtual texture's (square power-of-two page grid, halving per LOD).
    #[error("{}: {field}: {message}", path.display())]
    Layout { path: PathBuf, field: &'static str, message: String },

    #[error("a loader needs at least one pack")]
    NoTextures,

    #[error("{count} packs: a scene has at most {MAX_TEXTURES} virtual textures")]
    TooManyTextures { count: usize },

    /// Two packs whose tiles cannot share one physical page cache.
    #[error(
        "{}: {field} {first_value}, but {}: {field} {other_value}; the textures of one page cache need the same tile size and border",
        first.display(),
        other.display()
    )]
    Mismatch { field: &'static str, first: PathBuf, first_value: u32, other: PathBuf, other_value: u32 },

    #[error("cannot start loader thread {index}: {source}")]
    Spawn {
        index: usize,
        #[source]
        source: std::io::Error,
    },
}

/// Why a page came back with stand-in texels.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
pub enum LoadError {
    /// The page's texture id is not an index of the loader's packs.
    #[error("page {page:?}: no texture {}; the loader has {textures}", page.texture)]
    UnknownTexture { page: PageId, textures: usize },

    /// The page lies outside its texture's page grid.
    #[error(
        "{}: no page (lod {lod}, x {x}, y {y}): the texture has {pages} pages per side at LOD 0 and {lod_count} LODs",
        path.display()
    )]
    OutOfGrid { path: PathBuf, lod: u8, x: u16, y: u16, pages: u16, lod_count: u8 },

    /// A stored tile could not be read, failed its checksum or did not decode. For an absent page
    /// this names the ancestor that failed (the message says which page it was read for).
    #[error("{}: tile (lod {lod}, x {x}, y {y}): {message}", path.display())]
    Tile { path: PathBuf, lod: u32, x: u32, y: u32, message: String },

    /// The tile and every coarser tile covering it are absent: nothing to build it from.
    #[error("{}: tile (lod {lod}, x {x}, y {y}) is absent and so is every coarser tile covering it", path.display())]
    NoAncestor { path: PathBuf, lod: u8, x: u16, y: u16 },

    /// A worker stopped without answering (it cannot happen unless a worker thread died).
    #[error("page {page:?}: the loader's worker stopped before loading it")]
    Lost { page: PageId },
}

/// Reading a texture's shape from its pack (the type lives in [`crate::texture`], shared with the
/// renderer).
impl VirtualTexture {
    /// The texture stored in `pack`. The pack must hold a square power-of-two grid of at most
    /// 4096 pages per side at LOD 0, halving per LOD down to one page (the tiler's layout, which
    /// the page table and the feedback word assume); levels past that one page are ignored.
    pub fn from_pack(pack: &Pack) -> Result<VirtualTexture, LoaderError> {
        let layout = |field: &'static str, message: String| LoaderError::Layout {
            path: pack.path().to_path_buf(),
            field,
            message,
        };
        let d = pack.description();
        let levels = pack.levels();
        let first = levels.first().ok_or_else(|| layout("level_count", "the pack has no levels".into()))?;
        if first.tiles_w != first.tiles_h {
            return Err(layout(
                "tiles_h",
                format!("LOD 0 is {}x{} tiles; a virtual texture's page grid is square", first.tiles_w, first.tiles_h),
            ));
        }
        let grid = u16::try_from(first.tiles_w).ok().and_then(TextureGrid::new).ok_or_else(|| {
            layout("tiles_w", format!("{} tiles per side at LOD 0; expected a power of two up to 4096", first.tiles_w))
        })?;
        if levels.len() < grid.lod_count as usize {
            return Err(layout(
                "level_count",
                format!(
                    "{} levels; {} pages per side need {} (down to one page)",
                    levels.len(),
                    grid.pages,
                    grid.lod_count
                ),
            ));
        }
        for (lod, level) in levels.iter().enumerate().take(grid.lod_count as usize) {
            let side = u32::from(grid.pages_per_side(lod as u8));
            for (field, value) in [("tiles_w", level.tiles_w), ("tiles_h", level.tiles_h)] {
                if value != side {
                    return Err(layout(
                        field,
                        format!("level {lod} has {field} {value}; a power-of-two pyramid has {side} there"),
                    ));
                }
            }
        }
        let payload = d.tile_size - 2 * d.border;
        let covered = u64::from(grid.pages) * u64::from(payload);
        for (field, value) in [("width", d.width), ("height", d.height)] {
            if u64::from(value) > covered {
                return Err(layout(
                    field,
                    format!("{field} {value} exceeds the {covered} texels of {} pages of {payload}", grid.pages),
                ));
            }
        }
        Ok(VirtualTexture { grid, width: d.width, height: d.height, tile_size: d.tile_size, border: d.border })
    }
}

/// The texels of one requested page.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LoadedPage {
    pub page: PageId,
    /// The slot it was requested for, passed through.
    pub slot: Slot,
    /// `tile_size²` RGBA8 texels (sRGB-encoded colour, straight alpha), rows top down, borders
    /// included: one slot of the page cache. The [stand-in](stand_in_tile) when `error` is set.
    pub texels: Vec<u8>,
    /// Payload bytes read from the pack for this page: its tile's, or for an absent tile its
    /// ancestor's; counted even when they failed to decode. Constant tiles have none.
    pub bytes_read: u64,
    pub error: Option<LoadError>,
}

impl LoadedPage {
    pub fn is_ok(&self) -> bool {
        self.error.is_none()
    }
}

/// What a loader has done since it started (every page it finished, whether or not it was
/// collected yet).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub struct LoadCounters {
    /// Pages finished, with or without an error.
    pub pages: u64,
    /// Stored tiles decoded to texels (a page's own tile, or the ancestor of an absent one).
    pub tiles_decoded: u64,
    /// Pages built from an ancestor because their tile is absent.
    pub absent_filled: u64,
    /// Payload bytes read from the packs (the sum of [`LoadedPage::bytes_read`]).
    pub bytes_read: u64,
    /// Pages answered with the stand-in tile and an error.
    pub errors: u64,
}

/// The two colours of the [stand-in tile](stand_in_tile): opaque magenta and opaque black, which
/// no real texture is likely to show in a checkerboard.
pub const STAND_IN_COLORS: [[u8; 4]; 2] = [[255, 0, 255, 255], [0, 0, 0, 255]];

/// The texels given to a page that could not be loaded: a checkerboard of 8 x 8 squares
/// alternating [`STAND_IN_COLORS`], magenta at the top-left (squares of `tile_size / 8` texels,
/// at least one), over the whole stored tile, borders included. Visible at a glance, unlike a
/// black or transparent tile that could pass for content.
pub fn stand_in_tile(tile_size: u32) -> Vec<u8> {
    let side = tile_size as usize;
    let square = (side / 8).max(1);
    let mut texels = Vec::with_capacity(side * side * 4);
    for y in 0..side {
        for x in 0..side {
            texels.extend_from_slice(&STAND_IN_COLORS[(x / square + y / square) % 2]);
        }
    }
    texels
}

/// One page to load, and where its answer goes.
struct Job {
    index: usize,
    page: PageId,
    slot: Slot,
    reply: Sender<(usize, LoadedPage)>,
}

struct Queue {
    jobs: VecDeque<Job>,
    shutdown: bool,
}

/// What the workers share with the loader.
struct Shared {
    packs: Vec<Arc<Pack>>,
    textures: Vec<VirtualTexture>,
    tile_size: u32,
    queue: Mutex<Queue>,
    ready: Condvar,
    pages: AtomicU64,
    tiles_decoded: AtomicU64,
    absent_filled: AtomicU64,
    bytes_read: AtomicU64,
    errors: AtomicU64,
    /// Answer BC7 blocks instead of RGBA8 texels ([`Loader::set_format`]).
    bc7: AtomicBool,
}

/// Reads pages of up to 16 virtual textures (texture id = index in the packs given to
/// [`Loader::new`]) on a pool of worker threads. Dropping it stops the workers: queued pages are
/// discarded and the pages being decoded are finished first (one tile per worker).
pub struct Loader {
    shared: Arc<Shared>,
    workers: Vec<JoinHandle<()>>,
    /// Where workers answer [`Loader::request`]s, and where [`Loader::poll`] collects them.
    async_tx: Sender<(usize, LoadedPage)>,
    async_rx: Mutex<Receiver<(usize, LoadedPage)>>,
    /// Requested pages not yet returned by `poll`.
    pending: AtomicUsize,
}

impl Loader {
    /// A loader of `packs` on `threads` worker threads (0: one per available core). The packs
    /// must all be virtual textures ([`VirtualTexture::from_pack`]) with the same tile size and
    /// border, since their pages share one physical page cache.
    pub fn new(packs: Vec<Arc<Pack>>, threads: usize) -> Result<Loader, LoaderError> {
        let first = packs.first().ok_or(LoaderError::NoTextures)?;
        if packs.len() > MAX_TEXTURES as usize {
            return Err(LoaderError::TooManyTextures { count: packs.len() });
        }
        let textures = packs.iter().map(|p| VirtualTexture::from_pack(p)).collect::<Result<Vec<_>, _>>()?;
        let reference = textures[0];
        for (pack, texture) in packs.iter().zip(&textures).skip(1) {
            for (field, a, b) in
                [("tile_size", reference.tile_size, texture.tile_size), ("border", reference.border, texture.border)]
            {
                if a != b {
                    return Err(LoaderError::Mismatch {
                        field,
                        first: first.path().to_path_buf(),
                        first_value: a,
                        other: pack.path().to_path_buf(),
                        other_value: b,
                    });
                }
            }
        }
        let threads = match threads {
            0 => std::thread::available_parallelism().map_or(1, |n| n.get()),
            n => n,
        };
        let shared = Arc::new(Shared {
            packs,
            textures,
            tile_size: reference.tile_size,
            queue: Mutex::new(Queue { jobs: VecDeque::new(), shutdown: false }),
            ready: Condvar::new(),
            pages: AtomicU64::new(0),
            tiles_decoded: AtomicU64::new(0),
            absent_filled: AtomicU64::new(0),
            bytes_read: AtomicU64::new(0),
            errors: AtomicU64::new(0),
            bc7: AtomicBool::new(false),
        });
        let (async_tx, async_rx) = mpsc::channel();
        // Built before the workers so that, if one fails to start, Drop stops those already started.
        let mut loader = Loader {
            shared,
            workers: Vec::with_capacity(threads),
            async_tx,
            async_rx: Mutex::new(async_rx),
            pending: AtomicUsize::new(0),
        };
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

    pub fn packs(&self) -> &[Arc<Pack>] {
        &self.shared.packs
    }

    /// Side of every tile of every texture, borders included (the page cache's slot side).
    pub fn tile_size(&self) -> u32 {
        self.shared.tile_size
    }

    /// Whether every stored tile of every pack is a BC7 payload or one colour, so that pages can be
    /// streamed into a BC7 cache as they are (absent tiles would need decoding and re-encoding).
    pub fn holds_only_bc7(&self) -> bool {
        self.shared.tile_size.is_multiple_of(4)
            && self.shared.packs.iter().all(|pack| {
                (0..pack.header().index_count).all(|i| {
                    let kind = TileKind::from_u8(pack.entry(i).kind);
                    matches!(kind, Some(TileKind::Bc7 | TileKind::Constant))
                })
            })
    }

    /// Makes every later page come in `format`: RGBA8 texels, or BC7 blocks (which only packs
    /// that [hold only BC7](Loader::holds_only_bc7) can give; other tiles then get the stand-in
    /// and an error).
    pub fn set_format(&self, format: CacheFormat) {
        self.shared.bc7.store(format == CacheFormat::Bc7, Ordering::Relaxed);
    }

    pub fn format(&self) -> CacheFormat {
        if self.shared.bc7.load(Ordering::Relaxed) { CacheFormat::Bc7 } else { CacheFormat::Rgba8 }
    }

    /// Texels of border on each side of every tile.
    pub fn border(&self) -> u32 {
        self.shared.textures[0].border
    }

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
        let (tx, rx) = mpsc::channel();
        self.enqueue(pages.iter().enumerate().map(|(index, &(page, slot))| Job {
            index,
            page,
            slot,
            reply: tx.clone(),
        }));
        // Only the jobs hold senders now: if every one of them is gone, `recv` stops waiting.
        drop(tx);
        let mut answers: Vec<Option<LoadedPage>> = vec![None; pages.len()];
        for _ in 0..pages.len() {
            let Ok((index, answer)) = rx.recv() else { break };
            if let Some(place) = answers.get_mut(index) {
                *place = Some(answer);
            }
        }
        answers
            .into_iter()
            .zip(pages)
            .map(|(answer, &(page, slot))| {
                answer.unwrap_or_else(|| LoadedPage {
                    page,
                    slot,
                    texels: stand_in_tile(self.shared.tile_size),
                    bytes_read: 0,
                    error: Some(LoadError::Lost { page }),
                })
            })
            .collect()
    }

    /// Queues `pages` and returns at once; [`Loader::poll`] collects them as they finish. Each
    /// entry is answered once (a page requested twice is loaded twice).
    pub fn request(&self, pages: &[(PageId, Slot)]) {
        self.pending.fetch_add(pages.len(), Ordering::Relaxed);
        self.enqueue(pages.iter().map(|&(page, slot)| Job { index: 0, page, slot, reply: self.async_tx.clone() }));
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

    pub fn counters(&self) -> LoadCounters {
        let s = &self.shared;
        LoadCounters {
            pages: s.pages.load(Ordering::Relaxed),
            tiles_decoded: s.tiles_decoded.load(Ordering::Relaxed),
            absent_filled: s.absent_filled.load(Ordering::Relaxed),
            bytes_read: s.bytes_read.load(Ordering::Relaxed),
            errors: s.errors.load(Ordering::Relaxed),
        }
    }

    fn enqueue(&self, jobs: impl Iterator<Item = Job>) {
        let mut queue = lock(&self.shared.queue);
        queue.jobs.extend(jobs);
        drop(queue);
        self.shared.ready.notify_all();
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

/// A worker: takes jobs until the loader shuts down.
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

/// How a page's texels were made.
enum Made {
    Stored,
    FromAncestor,
}

impl Shared {
    /// One page, its counters updated. Never panics on bad data: a panicking decoder is caught and
    /// reported like any other decoding error.
    fn load_page(&self, page: PageId, slot: Slot) -> LoadedPage {
        let mut bytes_read = 0u64;
        let result = catch_unwind(AssertUnwindSafe(|| self.texels(page, &mut bytes_read))).unwrap_or_else(|panic| {
            let what = panic
                .downcast_ref::<&str>()
                .map(|s| s.to_string())
                .or_else(|| panic.downcast_ref::<String>().cloned())
                .unwrap_or_default();
            let path = self.packs.get(page.texture as usize).map(|p| p.path().to_path_buf()).unwrap_or_default();
            Err(LoadError::Tile {
                path,
                lod: page.lod.into(),
                x: page.x.into(),
                y: page.y.into(),
                message: format!("the decoder panicked: {what}"),
            })
        });
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
                (
                    if self.bc7.load(Ordering::Relaxed) {
                        bc7::solid_blocks(&stand_in, self.tile_size)
                    } else {
                        stand_in
                    },
                    Some(e),
                )
            }
        };
        LoadedPage { page, slot, texels, bytes_read, error }
    }

    /// The page's texels from its tile, or from its nearest stored ancestor if the tile is absent.
    fn texels(&self, page: PageId, bytes_read: &mut u64) -> Result<(Vec<u8>, Made), LoadError> {
        let index = page.texture as usize;
        let (Some(pack), Some(texture)) = (self.packs.get(index), self.textures.get(index)) else {
            return Err(LoadError::UnknownTexture { page, textures: self.packs.len() });
        };
        let grid = texture.grid;
        if !grid.contains(page) {
            return Err(LoadError::OutOfGrid {
                path: pack.path().to_path_buf(),
                lod: page.lod,
                x: page.x,
                y: page.y,
                pages: grid.pages,
                lod_count: grid.lod_count,
            });
        }
        if self.bc7.load(Ordering::Relaxed) {
            return self.blocks(pack, texture, page, bytes_read).map(|b| (b, Made::Stored));
        }
        for tile in page.ancestors_and_self(&grid) {
            let levels_up = tile.lod - page.lod;
            let (lod, x, y) = (u32::from(tile.lod), u32::from(tile.x), u32::from(tile.y));
            let failed = |e: PackError| tile_error(pack.path(), page, tile, e);
            match pack.tile(lod, x, y).map_err(failed)? {
                Tile::Absent => continue,
                Tile::Constant(_) => {}
                Tile::Data(_, payload) => *bytes_read += payload.len() as u64,
            }
            let Some(texels) = vortex_pack::decode_rgba8(pack, lod, x, y).map_err(failed)? else {
                continue;
            };
            let expected = (texture.tile_size as usize).pow(2) * 4;
            if texels.len() != expected {
                let message = format!("decodes to {} bytes, not {expected} of RGBA8", texels.len());
                return Err(tile_error_message(pack.path(), page, tile, message));
            }
            self.tiles_decoded.fetch_add(1, Ordering::Relaxed);
            return Ok(if levels_up == 0 {
                (texels, Made::Stored)
            } else {
                (magnify(&texels, texture, page, levels_up), Made::FromAncestor)
            });
        }
        Err(LoadError::NoAncestor { path: pack.path().to_path_buf(), lod: page.lod, x: page.x, y: page.y })
    }

    /// The page's BC7 blocks: its BC7 payload as stored (checksum checked), or blocks of its one
    /// colour.
    fn blocks(
        &self,
        pack: &Pack,
        texture: &VirtualTexture,
        page: PageId,
        bytes_read: &mut u64,
    ) -> Result<Vec<u8>, LoadError> {
        let (lod, x, y) = (u32::from(page.lod), u32::from(page.x), u32::from(page.y));
        let failed = |e: PackError| tile_error(pack.path(), page, page, e);
        let wanted = CacheFormat::Bc7.tile_bytes(texture.tile_size);
        let blocks = match pack.tile_checked(lod, x, y).map_err(failed)? {
            Tile::Data(TileKind::Bc7, payload) => {
                *bytes_read += payload.len() as u64;
                payload.to_vec()
            }
            Tile::Constant(_) => {
                let texels = vortex_pack::decode_rgba8(pack, lod, x, y).map_err(failed)?.unwrap_or_default();
                let colour = texels.first_chunk::<4>().copied().unwrap_or_default();
                bc7::solid_block(colour).repeat(wanted / bc7::BLOCK_BYTES)
            }
            Tile::Data(kind, _) => {
                let message = format!("a BC7 cache takes BC7 and one-colour tiles, not {}", kind.name());
                return Err(tile_error_message(pack.path(), page, page, message));
            }
            Tile::Absent => {
                let message = "an absent tile cannot be made into BC7 blocks".to_string();
                return Err(tile_error_message(pack.path(), page, page, message));
            }
        };
        if blocks.len() != wanted {
            let message = format!("holds {} bytes of BC7 blocks, not {wanted}", blocks.len());
            return Err(tile_error_message(pack.path(), page, page, message));
        }
        self.tiles_decoded.fetch_add(1, Ordering::Relaxed);
        Ok(blocks)
    }
}

/// `e`, read for `page` from its tile or ancestor `tile`, as a [`LoadError::Tile`] naming `tile`.
fn tile_error(path: &Path, page: PageId, tile: PageId, e: PackError) -> LoadError {
    // The pack error already names the path and tile; keep only what it adds.
    let message = match e {
        PackError::Tile { offset, message, .. } => format!("at byte {offset}: {message}"),
        PackError::OutOfRange { message, .. } => message,
        other => other.to_string(),
    };
    tile_error_message(path, page, tile, message)
}

fn tile_error_message(path: &Path, page: PageId, tile: PageId, mut message: String) -> LoadError {
    if tile != page {
        message.push_str(&format!(
            " (the nearest stored ancestor of absent tile lod {}, x {}, y {})",
            page.lod, page.x, page.y
        ));
    }
    LoadError::Tile { path: path.to_path_buf(), lod: tile.lod.into(), x: tile.x.into(), y: tile.y.into(), message }
}

/// The stored tile of `page`, built from `ancestor`, the RGBA8 tile of its ancestor `levels_up`
/// LODs coarser, by bilinear magnification.
///
/// Each stored texel of the page, borders included, is centred on a point of the virtual texture
/// (`x * payload - border + i + 0.5` at the page's LOD); it takes the ancestor's texels around the
/// same point, weighted bilinearly between texel centres, as the GPU does when it samples the
/// ancestor in the page's place. The page's stored area always lies inside the ancestor's stored
/// area, borders included (edge taps clamp to the tile). Filtering is on the stored values
/// (sRGB-encoded, straight alpha), in exact integer arithmetic (the weights are multiples of
/// 2^-(levels_up+1)), rounded half up, so a constant ancestor gives the same constant.
fn magnify(ancestor: &[u8], texture: &VirtualTexture, page: PageId, levels_up: u8) -> Vec<u8> {
    let side = texture.tile_size as usize;
    let taps_x = magnify_taps(texture, page.x, levels_up);
    let taps_y = magnify_taps(texture, page.y, levels_up);
    let denominator = 1u64 << (2 * (u32::from(levels_up) + 1));
    let mut out = Vec::with_capacity(side * side * 4);
    for &(y0, y1, wy0, wy1) in &taps_y {
        for &(x0, x1, wx0, wx1) in &taps_x {
            for channel in 0..4 {
                let texel =
                    |x: usize, y: usize| u64::from(ancestor.get((y * side + x) * 4 + channel).copied().unwrap_or(0));
                let sum = wy0 * (wx0 * texel(x0, y0) + wx1 * texel(x1, y0))
                    + wy1 * (wx0 * texel(x0, y1) + wx1 * texel(x1, y1));
                out.push(((sum + denominator / 2) / denominator) as u8);
            }
        }
    }
    out
}

/// For each stored texel along one axis of the page at position `page_xy` of its LOD: the two
/// ancestor texels around its centre and their weights (summing to `2^(levels_up+1)`).
fn magnify_taps(texture: &VirtualTexture, page_xy: u16, levels_up: u8) -> Vec<(usize, usize, u64, u64)> {
    let (side, border, payload) =
        (i64::from(texture.tile_size), i64::from(texture.border), i64::from(texture.payload()));
    let scale = 1i64 << (levels_up + 1);
    let xy = i64::from(page_xy);
    let ancestor_xy = xy >> levels_up;
    let clamp = |j: i64| j.clamp(0, side - 1) as usize;
    (0..side)
        .map(|i| {
            // Centre of texel i at the page's LOD: xy * payload - border + i + 1/2. At the ancestor's
            // LOD, relative to the centre of its texel 0, scaled by `scale`:
            let position = 2 * (xy * payload - border + i) + 1 - scale * (ancestor_xy * payload - border) - scale / 2;
            let (j, fraction) = (position.div_euclid(scale), position.rem_euclid(scale));
            (clamp(j), clamp(j + 1), (scale - fraction) as u64, fraction as u64)
        })
        .collect()
}

#[cfg(test)]
mod tests {
    use super::*;

    fn texture(tile_size: u32, border: u32, pages: u16) -> VirtualTexture {
        let grid = TextureGrid::new(pages).unwrap();
        VirtualTexture { grid, width: 1, height: 1, tile_size, border }
    }

    #[test]
    fn stand_in_is_a_magenta_and_black_checkerboard() {
        let t = stand_in_tile(16);
        assert_eq!(t.len(), 16 * 16 * 4);
        let at = |x: usize, y: usize| &t[(y * 16 + x) * 4..][..4];
        assert_eq!(at(0, 0), STAND_IN_COLORS[0]);
        assert_eq!(at(1, 1), STAND_IN_COLORS[0]);
        assert_eq!(at(2, 0), STAND_IN_COLORS[1]);
        assert_eq!(at(2, 2), STAND_IN_COLORS[0]);
        assert_eq!(stand_in_tile(3).len(), 36);
    }

    #[test]
    fn taps_without_border_split_each_ancestor_texel_in_two() {
        // 4-texel tiles, no border, one level up: page x = 1 is the right half of ancestor 0.
        let taps = magnify_taps(&texture(4, 0, 2), 1, 1);
        // Centres 4.5..7.5 at LOD 0 are 2.25..3.75 at LOD 1, i.e. 1.75..3.25 past texel 0's centre.
        assert_eq!(taps, vec![(1, 2, 1, 3), (2, 3, 3, 1), (2, 3, 1, 3), (3, 3, 3, 1)]);
        let weights: Vec<u64> = taps.iter().map(|t| t.2 + t.3).collect();
        assert_eq!(weights, [4, 4, 4, 4]);
    }

    #[test]
    fn taps_stay_inside_the_ancestor_with_borders() {
        for (tile, border) in [(16u32, 2u32), (8, 1), (6, 0), (128, 4)] {
            let t = texture(tile, border, 64);
            for levels_up in 1..=6u8 {
                for xy in 0..64u16 {
                    for (j0, j1, w0, w1) in magnify_taps(&t, xy, levels_up) {
                        assert!(j0 < tile as usize && j1 < tile as usize);
                        assert_eq!(w0 + w1, 1 << (levels_up + 1));
                    }
                }
            }
        }
    }

    #[test]
    fn a_constant_ancestor_magnifies_to_the_same_constant() {
        let t = texture(8, 1, 4);
        let ancestor: Vec<u8> = [10u8, 200, 30, 128].repeat(64);
        for levels_up in 1..=2u8 {
            let out = magnify(&ancestor, &t, PageId::new(0, 0, 3, 1), levels_up);
            assert_eq!(out, ancestor);
        }
    }
}
