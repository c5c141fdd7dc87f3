//! One page from its pack, on a loader worker: a stored tile (PNG, JPEG, zstd, raw or constant)
//! decoded to RGBA8 by `vortex_pack::decode_rgba8`, which checks its CRC-32C; an absent tile built
//! from its nearest stored ancestor (`magnify`); or, for a BC7 cache, the tile's BC7 blocks as
//! stored. Every failure is a [`LoadError`] naming the pack and the tile.
//!
//! Apart from the pool so that what a page's texels are depends on the pack and the page alone:
//! these are plain functions of their arguments, with no thread, queue or shared counter in
//! sight (what they read and decode is tallied in a [`Tally`] the caller adds up).

use std::path::Path;
use std::sync::Arc;

use vortex_pack::{Pack, PackError, Tile, TileKind};
use vortex_vt::page::PageId;

use super::LoadError;
use super::magnify::magnify;
use crate::bc7;
use crate::page_cache::CacheFormat;
use crate::texture::VirtualTexture;

/// How a page's texels were made.
pub(super) enum Made {
    Stored,
    FromAncestor,
}

/// What loading one page read and decoded, whether or not it succeeded.
#[derive(Debug, Default)]
pub(super) struct Tally {
    /// Payload bytes read: the page's tile's, or an absent page's ancestor's.
    pub(super) bytes_read: u64,
    /// Stored tiles decoded to texels or taken as BC7 blocks (0 or 1).
    pub(super) tiles_decoded: u64,
}

/// The page's texels from its tile, or from its nearest stored ancestor if the tile is absent;
/// with `bc7`, its BC7 blocks instead ([`blocks`]). `packs` and `textures` are indexed by
/// texture id.
pub(super) fn texels(
    packs: &[Arc<Pack>],
    textures: &[VirtualTexture],
    page: PageId,
    bc7: bool,
    tally: &mut Tally,
) -> Result<(Vec<u8>, Made), LoadError> {
    let index = page.texture as usize;
    let (Some(pack), Some(texture)) = (packs.get(index), textures.get(index)) else {
        return Err(LoadError::UnknownTexture { page, textures: packs.len() });
    };
    let grid = texture.grid;
    if !grid.contains(page) {
        return Err(LoadError::OutOfGrid {
            path: pack.path().to_path_buf(),
            lod: page.lod,
            x: page.x,
            y: page.y,
            pages: grid.pages(),
            lod_count: grid.lod_count(),
        });
    }
    if bc7 {
        return blocks(pack, texture, page, tally).map(|b| (b, Made::Stored));
    }
    for tile in page.ancestors_and_self(&grid) {
        let levels_up = tile.lod - page.lod;
        let (lod, x, y) = (u32::from(tile.lod), u32::from(tile.x), u32::from(tile.y));
        let failed = |e: PackError| tile_error(pack.path(), page, tile, e);
        match pack.tile(lod, x, y).map_err(failed)? {
            Tile::Absent => continue,
            Tile::Constant(_) => {}
            Tile::Data(_, payload) => tally.bytes_read += payload.len() as u64,
        }
        let Some(texels) = vortex_pack::decode_rgba8(pack, lod, x, y).map_err(failed)? else {
            continue;
        };
        let expected = (texture.tile_size as usize).pow(2) * 4;
        if texels.len() != expected {
            let message = format!("decodes to {} bytes, not {expected} of RGBA8", texels.len());
            return Err(tile_error_message(pack.path(), page, tile, message));
        }
        tally.tiles_decoded += 1;
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
fn blocks(pack: &Pack, texture: &VirtualTexture, page: PageId, tally: &mut Tally) -> Result<Vec<u8>, LoadError> {
    let (lod, x, y) = (u32::from(page.lod), u32::from(page.x), u32::from(page.y));
    let failed = |e: PackError| tile_error(pack.path(), page, page, e);
    let wanted = CacheFormat::Bc7.tile_bytes(texture.tile_size);
    let blocks = match pack.tile_checked(lod, x, y).map_err(failed)? {
        Tile::Data(TileKind::Bc7, payload) => {
            tally.bytes_read += payload.len() as u64;
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
    tally.tiles_decoded += 1;
    Ok(blocks)
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
