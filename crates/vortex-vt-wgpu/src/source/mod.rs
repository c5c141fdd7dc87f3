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

pub use delayed::Delayed;
#[cfg(feature = "http")]
pub use http::{HttpOptions, HttpPack, HttpStats};
#[cfg(any(feature = "http", target_arch = "wasm32"))]
pub use remote::INDEX_BLOCK;
#[cfg(target_arch = "wasm32")]
pub use web::{WebPack, WebStats};

use crate::loader::LoaderError;
use crate::page_cache::CacheFormat;
use crate::texture::VirtualTexture;

/// One virtual texture's pages, read on the loader's worker threads.
pub trait PageSource: Send + Sync {
    /// Where the texture comes from, for error messages: a pack's path, a URL.
    fn location(&self) -> &Path;

    /// The texture's shape: its page grid, image size, tile size and border.
    fn texture(&self) -> Result<VirtualTexture, LoaderError>;

    /// The stored tile of page (`lod`, `x`, `y`), which lies in the texture's grid, in `format`:
    /// `tile_size²` RGBA8 texels (sRGB-encoded colour, straight alpha, rows top down, borders
    /// included), or BC7 blocks. [`SourceTile::Absent`] where the texture stores no tile (RGBA8
    /// only): the loader then magnifies the nearest stored ancestor.
    fn read_tile(&self, lod: u8, x: u16, y: u16, format: CacheFormat) -> Result<SourceTile, ReadError>;

    /// The tile of page (`lod`, `x`, `y`) as stored, not decoded, for the loader's memory tier to
    /// keep (stored bytes are a fraction of the texels); [`PageSource::decode`] makes the texels.
    /// `None`, the default, for a source with no stored form worth keeping: the tier then passes
    /// it by and every read is a [`PageSource::read_tile`]. A source that answers `Some` must
    /// implement `decode`, and `decode(read_stored)` must give what `read_tile` gives.
    fn read_stored(&self, lod: u8, x: u16, y: u16) -> Result<Option<StoredRead>, ReadError> {
        let _ = (lod, x, y);
        Ok(None)
    }

    /// The texels, in `format`, of `bytes`: what [`PageSource::read_stored`] gave for page
    /// (`lod`, `x`, `y`) as [`StoredTile::Stored`], perhaps long ago. Runs on a loader thread
    /// with no lock held. It must not read the source: a tile served from the memory tier costs
    /// no read.
    fn decode(
        &self,
        lod: u8,
        x: u16,
        y: u16,
        kind: u8,
        bytes: &[u8],
        format: CacheFormat,
    ) -> Result<Vec<u8>, ReadError> {
        let _ = (kind, bytes, format);
        Err(ReadError::new(format!("tile (lod {lod}, x {x}, y {y}): this source decodes no stored tiles")))
    }

    /// In the browser, where nothing may block: a future that completes once
    /// [`PageSource::read_stored`] and [`PageSource::read_tile`] of page (`lod`, `x`, `y`) answer
    /// without waiting (its fetch done, or failed). `None`, the default: the source never waits.
    /// The web loader awaits it on the page's event loop before it decodes the page.
    #[cfg(target_arch = "wasm32")]
    fn prepare(&self, lod: u8, x: u16, y: u16) -> Option<LocalFuture<'_>> {
        let _ = (lod, x, y);
        None
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
    Texels { texels: Vec<u8>, bytes_read: u64 },
    /// No tile is stored for this page: it is its nearest stored ancestor, magnified.
    Absent,
}

/// A tile as its source stores it: what the loader's memory tier keeps.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum StoredTile {
    /// No tile is stored for this page: it is its nearest stored ancestor, magnified.
    Absent,
    /// The tile's bytes as stored; `kind` says what they are, in the source's own terms (for a
    /// pack, its `TileKind` as a byte), for [`PageSource::decode`]. Shared, so that the tier and
    /// a decoding worker hold one copy.
    Stored { kind: u8, bytes: Arc<[u8]> },
}

/// What [`PageSource::read_stored`] read.
#[derive(Clone, Debug, PartialEq, Eq)]
pub struct StoredRead {
    pub tile: StoredTile,
    /// Bytes read to get it (for the counters): a pack's payload length; none for a tile the
    /// index alone describes (absent, or one colour).
    pub bytes_read: u64,
}

/// Why a tile could not be read or decoded.
#[derive(Clone, Debug, PartialEq, Eq, thiserror::Error)]
#[error("{message}")]
pub struct ReadError {
    pub message: String,
    /// Bytes read before the failure (counted like those of tiles that loaded).
    pub bytes_read: u64,
}

impl ReadError {
    pub fn new(message: impl Into<String>) -> ReadError {
        ReadError { message: message.into(), bytes_read: 0 }
    }
}
