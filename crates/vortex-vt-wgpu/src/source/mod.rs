//! Where pages come from. The loader asks a [`PageSource`] for one stored tile at a time, on its
//! worker threads, so a source may block (read a file, wait on the network) without ever holding
//! up a frame. Vortex packs are sources ([`Pack`](vortex_pack::Pack) implements the trait, in
//! `pack`); an application streams from its own storage by implementing it; [`Delayed`] adds a
//! fixed latency to any source, to show what a slow disk or network does to a frame loop. With
//! the `http` feature, `HttpPack` reads a pack from a web server with `Range` requests; in the
//! browser (wasm32), `WebPack` reads one with `fetch`, by the same protocol code (`remote`).
//!
//! A source may also split a read in two, [`PageSource::read_stored`] (the tile's bytes as
//! stored, compressed) and [`PageSource::decode`] (those bytes to texels), so that the loader's
//! memory tier can keep recently read tiles in RAM in their stored form and serve a page the GPU
//! cache evicted without reading the source again. A source that does not is still read, one
//! [`PageSource::read_tile`] per page; the tier passes it by.

mod delayed;
#[cfg(feature = "http")]
mod http;
mod pack;
#[cfg(any(feature = "http", target_arch = "wasm32"))]
mod remote;
#[cfg(target_arch = "wasm32")]
mod web;

use std::path::Path;
use std::sync::Arc;

pub use vortex_pack::{TileId, TileKind};
use vortex_vt::page::PageId;

pub use delayed::Delayed;
#[cfg(feature = "http")]
pub use http::{HttpOptions, HttpPack, HttpStats};
#[cfg(any(feature = "http", target_arch = "wasm32"))]
pub use remote::INDEX_BLOCK;
#[cfg(target_arch = "wasm32")]
pub use web::{WebPack, WebStats};

use crate::loader::{LoaderError, RetryPolicy};
use crate::page_cache::CacheFormat;
use crate::texture::VirtualTexture;

/// One virtual texture's pages, read on the loader's worker threads. A tile is named by its
/// [`TileId`] (LOD, column, row in that LOD's page grid), the coordinates a pack uses too.
pub trait PageSource: Send + Sync {
    /// Where the texture comes from, for error messages: a pack's path, a URL.
    fn location(&self) -> &Path;

    /// The texture's shape: its page grid, image size, tile size and border.
    fn texture(&self) -> Result<VirtualTexture, LoaderError>;

    /// The stored tile `tile`, which lies in the texture's grid, in `format`: `tile_size²` RGBA8
    /// texels (sRGB-encoded colour, straight alpha, rows top down, borders included), or BC7
    /// blocks. [`SourceTile::Absent`] where the texture stores no tile (RGBA8 only): the loader
    /// then magnifies the nearest stored ancestor. An error of kind [`ReadErrorKind::Io`] is
    /// read again by the loader, after a backoff; any other gives the page the stand-in tile.
    fn read_tile(&self, tile: TileId, format: CacheFormat) -> Result<SourceTile, ReadError>;

    /// The tile as stored, not decoded, for the loader's memory tier to keep (stored bytes are a
    /// fraction of the texels); [`PageSource::decode`] makes the texels. `None`, the default,
    /// for a source with no stored form worth keeping: the tier then passes it by and every read
    /// is a [`PageSource::read_tile`]. A source that answers `Some` must implement `decode`, and
    /// `decode(read_stored)` must give what `read_tile` gives.
    fn read_stored(&self, tile: TileId) -> Result<Option<StoredRead>, ReadError> {
        let _ = tile;
        Ok(None)
    }

    /// The texels, in `format`, of `bytes`: what [`PageSource::read_stored`] gave for `tile` as
    /// [`StoredTile::Stored`] of `kind`, perhaps long ago. Runs on a loader thread with no lock
    /// held. It must not read the source: a tile served from the memory tier costs no read.
    fn decode(&self, tile: TileId, kind: TileKind, bytes: &[u8], format: CacheFormat) -> Result<Vec<u8>, ReadError> {
        let _ = (kind, bytes, format);
        let TileId { lod, x, y } = tile;
        Err(ReadError::unsupported(format!("tile (lod {lod}, x {x}, y {y}): this source decodes no stored tiles")))
    }

    /// In the browser, where nothing may block: a future that completes once
    /// [`PageSource::read_stored`] and [`PageSource::read_tile`] of `tile` answer without
    /// waiting (its fetch done, or failed). `None`, the default: the source never waits. The web
    /// loader awaits it on the page's event loop before it decodes the page.
    #[cfg(target_arch = "wasm32")]
    fn prepare(&self, tile: TileId) -> Option<LocalFuture<'_>> {
        let _ = tile;
        None
    }

    /// How the loader reads a tile of this source again after a [`ReadErrorKind::Io`] failure,
    /// given the loader's own policy (`loader`, [`Loader::set_retry`](crate::Loader::set_retry)).
    /// The default takes it. A source that retries its reads itself answers
    /// [`RetryPolicy::NONE`]: its retries and the loader's would multiply (`HttpPack`'s 6 tries
    /// a request times the loader's 3 reads were 18 requests for one page of a dead server).
    fn retry_policy(&self, loader: RetryPolicy) -> RetryPolicy {
        loader
    }

    /// Whether every tile can come as BC7 blocks as stored, so that the cache can hold BC7.
    fn holds_only_bc7(&self) -> bool {
        false
    }

    /// Whether every texel is opaque, so that a BC1 cache (which has no alpha) can hold it.
    fn opaque(&self) -> bool {
        false
    }
}

/// A future on the browser's event loop ([`PageSource::prepare`]): not `Send`, as nothing there is.
#[cfg(target_arch = "wasm32")]
pub type LocalFuture<'a> = std::pin::Pin<Box<dyn std::future::Future<Output = ()> + 'a>>;

/// What [`PageSource::read_tile`] found.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum SourceTile {
    /// The tile, in the format asked for, and the bytes read to make it (for the counters).
    Texels {
        /// The texels (or blocks) in the format asked for.
        texels: Vec<u8>,
        /// Bytes read from the source to make them.
        bytes_read: u64,
    },
    /// No tile is stored for this page: it is its nearest stored ancestor, magnified.
    Absent,
}

/// A tile as its source stores it: what the loader's memory tier keeps.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum StoredTile {
    /// No tile is stored for this page: it is its nearest stored ancestor, magnified.
    Absent,
    /// The tile's bytes as stored, which `kind` says how to decode ([`TileKind::Constant`]: the
    /// bytes are the one texel value), for [`PageSource::decode`]. Shared, so that the tier and a
    /// decoding worker hold one copy.
    Stored {
        /// How the bytes are stored.
        kind: TileKind,
        /// The stored bytes.
        bytes: Arc<[u8]>,
    },
}

/// What [`PageSource::read_stored`] read.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct StoredRead {
    /// The tile as stored.
    pub tile: StoredTile,
    /// Bytes read to get it (for the counters): a pack's payload length; none for a tile the
    /// index alone describes (absent, or one colour).
    pub bytes_read: u64,
}

/// What went wrong with a read, which says what the loader does about it.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
#[non_exhaustive]
pub enum ReadErrorKind {
    /// The read failed this time (a dropped connection, a timeout, a disk error): reading again
    /// may succeed, so the loader does, after a backoff, as [`PageSource::retry_policy`] says.
    Io,
    /// The stored bytes are wrong: a checksum fails, a payload does not decode, an index entry
    /// makes no sense. Reading again gives the same bytes: the page gets the stand-in tile.
    Corrupt,
    /// The source cannot give this tile in the form asked for: a tile kind it does not decode,
    /// a cache format its tiles cannot be made into, a tile over a limit. The stand-in tile.
    Unsupported,
    /// The source can no longer be read and waiting will not change that: a pack replaced or
    /// removed on its server, a read the application gave up on. The stand-in tile.
    Unavailable,
}

impl ReadErrorKind {
    /// The kind in a word, for messages and reports.
    pub fn name(self) -> &'static str {
        match self {
            ReadErrorKind::Io => "io",
            ReadErrorKind::Corrupt => "corrupt",
            ReadErrorKind::Unsupported => "unsupported",
            ReadErrorKind::Unavailable => "unavailable",
        }
    }
}

/// Why a tile could not be read or decoded.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{message}")]
#[non_exhaustive]
pub struct ReadError {
    /// What went wrong, which decides whether the loader reads again.
    pub kind: ReadErrorKind,
    /// What went wrong, in words: the tile's place in the source, what failed.
    pub message: String,
    /// Bytes read before the failure (counted like those of tiles that loaded).
    pub bytes_read: u64,
}

impl ReadError {
    /// An error of `kind`, nothing read.
    pub fn new(kind: ReadErrorKind, message: impl Into<String>) -> ReadError {
        ReadError { kind, message: message.into(), bytes_read: 0 }
    }

    /// A failed read that may succeed if tried again ([`ReadErrorKind::Io`]).
    pub fn io(message: impl Into<String>) -> ReadError {
        ReadError::new(ReadErrorKind::Io, message)
    }

    /// Stored bytes that are wrong ([`ReadErrorKind::Corrupt`]).
    pub fn corrupt(message: impl Into<String>) -> ReadError {
        ReadError::new(ReadErrorKind::Corrupt, message)
    }

    /// A tile the source cannot give in the form asked for ([`ReadErrorKind::Unsupported`]).
    pub fn unsupported(message: impl Into<String>) -> ReadError {
        ReadError::new(ReadErrorKind::Unsupported, message)
    }

    /// A source that can no longer be read ([`ReadErrorKind::Unavailable`]).
    pub fn unavailable(message: impl Into<String>) -> ReadError {
        ReadError::new(ReadErrorKind::Unavailable, message)
    }

    /// The same error, having read `bytes_read` bytes.
    pub fn with_bytes_read(self, bytes_read: u64) -> ReadError {
        ReadError { bytes_read, ..self }
    }

    /// The same error, its message prefixed with what was being read.
    pub(crate) fn context(self, what: String) -> ReadError {
        ReadError { message: format!("{what}: {}", self.message), ..self }
    }
}

/// The pack coordinates of a runtime page (its texture aside).
pub(crate) fn tile_id(page: PageId) -> TileId {
    TileId { lod: page.lod.into(), x: page.x.into(), y: page.y.into() }
}
