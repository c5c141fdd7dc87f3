//! One page from its source, on a loader worker: its stored tile, premultiplied; an absent tile
//! built from its nearest stored ancestor (`magnify`); or, for a BC7 cache, the tile's BC7
//! blocks as stored. Tiles are read through the memory tier (`tier`), which may hold their
//! stored bytes. Every failure is a [`LoadError`] naming the source and the tile.
//!
//! Apart from the pool so that what a page's texels are depends on the source and the page
//! alone: these are plain functions of their arguments, with no thread, queue or shared counter
//! in sight (what they read and decode is tallied in a [`Tally`] the caller adds up).

use std::sync::Arc;

use vortex_vt::page::PageId;

use super::magnify::magnify;
use super::premultiply::premultiply;
use super::tier::{self, Tier};
use super::{LoadError, RetryPolicy};
use crate::page_cache::CacheFormat;
use crate::source::{PageSource, ReadError, ReadErrorKind};
use crate::texture::VirtualTexture;

/// How a page's texels were made.
pub(super) enum Made {
    Stored,
    FromAncestor,
}

/// What loading one page read and decoded, whether or not it succeeded.
#[derive(Debug, Default)]
pub(super) struct Tally {
    /// Bytes read: the page's tile's, or an absent page's ancestor's.
    pub(super) bytes_read: u64,
    /// Stored tiles decoded to texels or taken as BC7 blocks (0 or 1).
    pub(super) tiles_decoded: u64,
    /// Tiles (the page's, or its ancestors' while they are absent) the memory tier held, and
    /// those read from the source instead.
    pub(super) tier_hits: u32,
    pub(super) tier_misses: u32,
    /// Reads tried again after an I/O error.
    pub(super) read_retries: u32,
}

/// The page's texels from its tile, or from its nearest stored ancestor if the tile is absent,
/// premultiplied if they are `colour` (data is taken as stored); for a BC7 cache, its BC7 blocks
/// instead. `sources` and `textures` are indexed by texture id. Every tile is read through the
/// memory `tier`, and read again as `retry` says when its read fails with an I/O error.
#[allow(clippy::too_many_arguments)] // the page's whole context, each of which it needs
pub(super) fn texels(
    sources: &[Arc<dyn PageSource>],
    textures: &[VirtualTexture],
    tier: &Tier,
    retry: RetryPolicy,
    page: PageId,
    format: CacheFormat,
    colour: bool,
    tally: &mut Tally,
) -> Result<(Vec<u8>, Made), LoadError> {
    let index = page.texture as usize;
    let (Some(source), Some(texture)) = (sources.get(index), textures.get(index)) else {
        return Err(LoadError::UnknownTexture { page, textures: sources.len() });
    };
    let grid = texture.grid;
    if !grid.contains(page) {
        return Err(LoadError::OutOfGrid {
            path: source.location().to_path_buf(),
            lod: page.lod,
            x: page.x,
            y: page.y,
            pages: grid.pages(),
            lod_count: grid.lod_count(),
        });
    }
    let wanted = format.tile_bytes(texture.tile_size);
    for tile in page.ancestors_and_self(&grid) {
        let failed = |e: ReadError| tile_error(source.as_ref(), page, tile, e.kind, e.message);
        let Some(mut texels) = tier::read(tier, source.as_ref(), tile, format, retry, tally).map_err(failed)? else {
            if format == CacheFormat::Rgba8 {
                continue;
            }
            let message = "an absent tile cannot be made into BC7 blocks".to_string();
            return Err(tile_error(source.as_ref(), page, tile, ReadErrorKind::Unsupported, message));
        };
        if texels.len() != wanted {
            let message =
                format!("the source gave {} bytes, not the {wanted} of a {} tile", texels.len(), format.name());
            return Err(tile_error(source.as_ref(), page, tile, ReadErrorKind::Corrupt, message));
        }
        tally.tiles_decoded += 1;
        if format == CacheFormat::Bc7 {
            return Ok((texels, Made::Stored));
        }
        if colour {
            premultiply(&mut texels);
        }
        let levels_up = tile.lod - page.lod;
        return Ok(if levels_up == 0 {
            (texels, Made::Stored)
        } else {
            (magnify(&texels, texture, page, levels_up), Made::FromAncestor)
        });
    }
    Err(LoadError::NoAncestor { path: source.location().to_path_buf(), lod: page.lod, x: page.x, y: page.y })
}

/// `message`, read for `page` from its tile or ancestor `tile`, as a [`LoadError::Tile`] naming
/// `tile`.
fn tile_error(
    source: &dyn PageSource,
    page: PageId,
    tile: PageId,
    kind: ReadErrorKind,
    mut message: String,
) -> LoadError {
    if tile != page {
        message.push_str(&format!(
            " (the nearest stored ancestor of absent tile lod {}, x {}, y {})",
            page.lod, page.x, page.y
        ));
    }
    LoadError::Tile {
        path: source.location().to_path_buf(),
        lod: tile.lod.into(),
        x: tile.x.into(),
        y: tile.y.into(),
        kind,
        message,
    }
}
