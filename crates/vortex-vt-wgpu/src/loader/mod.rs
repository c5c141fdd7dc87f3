//! The tile loader: reads the pages the residency asks for from their [`PageSource`](crate::source::PageSource)s (Vortex
//! tile packs, or the application's own storage) and turns them into premultiplied RGBA8 texels
//! (or BC7 blocks) ready for `queue.write_texture` into a slot of the page cache. Decoding runs on the loader's own pool of worker threads (plain std threads named
//! `vortex-loader-N`); the caller's thread only queues pages and collects texels, blocking
//! ([`Loader::load`]) or not ([`Loader::request`] and [`Loader::poll`]). Pure CPU: nothing here
//! touches wgpu.
//!
//! Four parts, one file each, because each changes for its own reasons: `pool` (the worker
//! threads, the queue, request and poll, the blocking load, the counters), `decode` (one page
//! from its source: a stored tile, or an absent one from its ancestor), `magnify` (the exact
//! integer magnification of that ancestor) and `premultiply` (colour weighted by alpha, so that
//! the GPU's filter never bleeds the colour of transparent texels). This file holds what callers
//! see of all of them: the errors, a loaded page, the counters and the stand-in tile.
//!
//! Every page gets texels, so a slot is never left holding stale or garbage data:
//!
//! - a stored tile is read and decoded by its source (for a pack, `vortex_pack::Tile::decode_rgba8`,
//!   which checks its CRC-32C);
//! - an `absent` tile ("the runtime falls back to the parent tile", pack format) is built from its
//!   nearest stored ancestor by bilinear magnification (`magnify`); that is not an error;
//! - a read that fails with an I/O error ([`ReadErrorKind::Io`]) is tried again, after a
//!   backoff, as the [`RetryPolicy`] says: what fails for a moment does not show;
//! - a tile that cannot be read or decoded (corrupt, unsupported, or I/O errors past the
//!   retries), or a page outside its texture, gets the [stand-in tile](stand_in_tile) (a magenta
//!   and black checkerboard) and a [`LoadError`] that names the pack, the tile and the error's
//!   kind.
//!
//! A page's texels depend only on the pack and the page, never on the thread that decoded it or
//! on other pages, so they are the same whatever the thread count. The memory tier (`tier`, off
//! unless [`Loader::set_memory_tier`] gives it a budget) keeps tiles' stored bytes between pages:
//! it changes what is read, never what is decoded. Without it the counters too are the same
//! whatever the thread count; with it, which of two pages that share an absent ancestor reads it
//! and which finds it in RAM depends on their order.

mod decode;
mod magnify;
mod pool;
mod premultiply;
mod tier;
mod transcode;

use std::path::PathBuf;
use std::time::Duration;

use vortex_vt::page::{GridError, MAX_TEXTURES, PageId};
use vortex_vt::residency::Slot;

pub use pool::Loader;
pub use tier::{DEFAULT_MEMORY_TIER_BYTES, TIER_ENTRY_OVERHEAD, TierUsage};

use crate::source::ReadErrorKind;

/// How a loader reads a tile again when its read failed with [`ReadErrorKind::Io`] (a dropped
/// connection, a timeout: what may pass), on the worker that read it; set with
/// [`Loader::set_retry`]. Natively only: in the browser a loader never waits, and its source
/// retried the fetch already. Any other kind of failure is final at once: the page gets the
/// stand-in tile and its error.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub struct RetryPolicy {
    /// Reads of one tile in all, the first included (1: no retry). Default 3.
    pub attempts: u32,
    /// The wait before the first retry, doubled before each next one. Default 100 ms: with 3
    /// attempts a tile is given up on after 0.3 s of waiting, which a passing hiccup outlasts
    /// while a source that is down costs a worker little. A source that retries on its own
    /// says how the loader should through
    /// [`PageSource::retry_policy`](crate::source::PageSource::retry_policy) (`HttpPack`, which
    /// retries each request, asks for [`RetryPolicy::NONE`]).
    pub backoff: Duration,
}

impl RetryPolicy {
    /// One read, never another: for a source that retried already before it failed.
    pub const NONE: RetryPolicy = RetryPolicy { attempts: 1, backoff: Duration::ZERO };
}

impl Default for RetryPolicy {
    fn default() -> Self {
        RetryPolicy { attempts: 3, backoff: Duration::from_millis(100) }
    }
}

/// Why a [`VirtualTexture`](crate::VirtualTexture) or a [`Loader`] cannot be made.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum LoaderError {
    /// The pack's layout is not a virtual texture's (an image its LOD-0 grid covers).
    #[error("{}: {field}: {message}", path.display())]
    Layout {
        /// The source's location.
        path: PathBuf,
        /// The field that does not fit.
        field: &'static str,
        /// Why.
        message: String,
    },

    /// The pack's level table is not a page grid the runtime can address: the levels do not
    /// halve (rounded up) down to one page, or the grid is over the feedback word's limits.
    #[error("{}: level table: {source}", path.display())]
    Grid {
        /// The source's location.
        path: PathBuf,
        /// What is wrong with the grid.
        #[source]
        source: GridError,
    },

    /// No source given.
    #[error("a loader needs at least one pack")]
    NoTextures,

    /// More sources than a feedback word can name.
    #[error("{count} packs: a scene has at most {MAX_TEXTURES} virtual textures")]
    TooManyTextures {
        /// Sources given.
        count: usize,
    },

    /// Two packs whose tiles cannot share one physical page cache.
    #[error(
        "{}: {field} {first_value}, but {}: {field} {other_value}; the textures of one page cache need the same tile size and border",
        first.display(),
        other.display()
    )]
    Mismatch {
        /// `tile_size` or `border`.
        field: &'static str,
        /// The first source's location.
        first: PathBuf,
        /// Its value.
        first_value: u32,
        /// The other source's location.
        other: PathBuf,
        /// Its value.
        other_value: u32,
    },

    /// A worker thread could not be started.
    #[error("cannot start loader thread {index}: {source}")]
    Spawn {
        /// The worker's number.
        index: usize,
        /// What the system said.
        #[source]
        source: std::io::Error,
    },
}

/// Why a page came back with stand-in texels.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[non_exhaustive]
pub enum LoadError {
    /// The page's texture id is not an index of the loader's packs.
    #[error("page {page:?}: no texture {}; the loader has {textures}", page.texture)]
    UnknownTexture {
        /// The page.
        page: PageId,
        /// Textures the loader has.
        textures: usize,
    },

    /// The page lies outside its texture's page grid.
    #[error(
        "{}: no page (lod {lod}, x {x}, y {y}): the texture has {}x{} pages at LOD 0 and {lod_count} LODs",
        path.display(), pages[0], pages[1]
    )]
    OutOfGrid {
        /// The source's location.
        path: PathBuf,
        /// The page's LOD.
        lod: u8,
        /// Its column.
        x: u16,
        /// Its row.
        y: u16,
        /// The texture's pages across and down at LOD 0.
        pages: [u16; 2],
        /// Its LODs.
        lod_count: u8,
    },

    /// A stored tile could not be read, failed its checksum or did not decode. For an absent page
    /// this names the ancestor that failed (the message says which page it was read for).
    #[error("{}: tile (lod {lod}, x {x}, y {y}): {message}", path.display())]
    Tile {
        /// The source's location.
        path: PathBuf,
        /// The tile that failed: the page's own, or the ancestor an absent page is made from.
        lod: u32,
        /// Its column.
        x: u32,
        /// Its row.
        y: u32,
        /// What went wrong: [`ReadErrorKind::Io`] once the loader's retries are spent.
        kind: ReadErrorKind,
        /// What went wrong, in words.
        message: String,
    },

    /// The tile and every coarser tile covering it are absent: nothing to build it from.
    #[error("{}: tile (lod {lod}, x {x}, y {y}) is absent and so is every coarser tile covering it", path.display())]
    NoAncestor {
        /// The source's location.
        path: PathBuf,
        /// The page's LOD.
        lod: u8,
        /// Its column.
        x: u16,
        /// Its row.
        y: u16,
    },

    /// A worker stopped without answering (it cannot happen unless a worker thread died).
    #[error("page {page:?}: the loader's worker stopped before loading it")]
    Lost {
        /// The page.
        page: PageId,
    },
}

/// The texels of one requested page.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct LoadedPage {
    /// The page.
    pub page: PageId,
    /// The slot it was requested for, passed through.
    pub slot: Slot,
    /// `tile_size²` RGBA8 texels (sRGB-encoded premultiplied colour: each colour is
    /// `srgb(linear(c) * alpha)`), rows top down, borders included: one slot of the page cache;
    /// or BC7 blocks as stored (straight alpha). The [stand-in](stand_in_tile) when `error` is set.
    pub texels: Vec<u8>,
    /// Payload bytes read from the pack for this page: its tile's, or for an absent tile its
    /// ancestor's; counted even when they failed to decode. Constant tiles have none, and
    /// neither have tiles the memory tier held.
    pub bytes_read: u64,
    /// Tiles read for this page (its own, or its ancestors' while they are absent) that the
    /// memory tier held: decoded from RAM, nothing read.
    pub tier_hits: u32,
    /// Tiles read for this page from its source, the tier not holding them (or off).
    pub tier_misses: u32,
    /// Why the texels are the stand-in tile, if they are.
    pub error: Option<LoadError>,
}

impl LoadedPage {
    /// Whether it loaded (its texels are its own, not the stand-in).
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
    /// Tiles the memory tier held (the sum of [`LoadedPage::tier_hits`]).
    pub tier_hits: u64,
    /// Tiles read from the sources (the sum of [`LoadedPage::tier_misses`]).
    pub tier_misses: u64,
    /// Reads tried again after an I/O error ([`RetryPolicy`]).
    pub read_retries: u64,
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

#[cfg(test)]
mod tests {
    use super::*;

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
}
