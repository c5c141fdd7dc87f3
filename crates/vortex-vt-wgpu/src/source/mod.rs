//! Where pages come from. The loader asks a [`PageSource`] for one stored tile at a time, on its
//! worker threads, so a source may block (read a file, wait on the network) without ever holding
//! up a frame. Vortex packs are sources ([`Pack`](vortex_pack::Pack) implements the trait, in
//! `pack`); an application streams from its own storage by implementing it; [`Delayed`] adds a
//! fixed latency to any source, to show what a slow disk or network does to a frame loop.

mod delayed;
mod pack;

use std::path::Path;

pub use delayed::Delayed;

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

    /// Whether every tile can come as BC7 blocks as stored, so that the cache can hold BC7.
    fn holds_only_bc7(&self) -> bool {
        false
    }

    /// Whether every texel is opaque, so that a BC1 cache (which has no alpha) can hold it.
    fn opaque(&self) -> bool {
        false
    }
}

/// What [`PageSource::read_tile`] found.
#[derive(Clone, Debug, PartialEq, Eq)]
pub enum SourceTile {
    /// The tile, in the format asked for, and the bytes read to make it (for the counters).
    Texels { texels: Vec<u8>, bytes_read: u64 },
    /// No tile is stored for this page: it is its nearest stored ancestor, magnified.
    Absent,
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
