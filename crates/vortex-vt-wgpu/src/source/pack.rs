//! Vortex packs as page sources: a stored tile (PNG, JPEG, zstd, raw or constant) decoded to
//! RGBA8 by `vortex_pack::decode_rgba8`, which checks its CRC-32C; for a BC7 cache, the tile's
//! BC7 payload as stored (or blocks of a constant tile's one colour); an absent tile reported as
//! such, for the loader to magnify its ancestor.

use std::path::Path;

use vortex_pack::{Pack, PackError, Tile, TileKind};
use vortex_vt::page::TextureGrid;

use super::{PageSource, ReadError, SourceTile};
use crate::bc7;
use crate::loader::LoaderError;
use crate::page_cache::CacheFormat;
use crate::texture::VirtualTexture;

impl PageSource for Pack {
    fn location(&self) -> &Path {
        self.path()
    }

    fn texture(&self) -> Result<VirtualTexture, LoaderError> {
        VirtualTexture::from_pack(self)
    }

    fn read_tile(&self, lod: u8, x: u16, y: u16, format: CacheFormat) -> Result<SourceTile, ReadError> {
        let (lod, x, y) = (u32::from(lod), u32::from(x), u32::from(y));
        let tile_size = self.description().tile_size;
        match format {
            CacheFormat::Rgba8 => texels(self, lod, x, y, tile_size),
            CacheFormat::Bc7 => blocks(self, lod, x, y, tile_size),
            // The loader transcodes RGBA8 to BC1; it never asks a source for BC1.
            CacheFormat::Bc1 => Err(ReadError::new("a pack gives RGBA8 texels or stored BC7 blocks, not BC1")),
        }
    }

    /// One or three channels: no alpha stored.
    fn opaque(&self) -> bool {
        matches!(self.description().channels, 1 | 3)
    }

    fn holds_only_bc7(&self) -> bool {
        self.description().tile_size.is_multiple_of(4)
            && (0..self.header().index_count)
                .all(|i| matches!(TileKind::from_u8(self.entry(i).kind), Some(TileKind::Bc7 | TileKind::Constant)))
    }
}

/// The tile's RGBA8 texels, or `Absent`.
fn texels(pack: &Pack, lod: u32, x: u32, y: u32, tile_size: u32) -> Result<SourceTile, ReadError> {
    let bytes_read = match pack.tile(lod, x, y).map_err(read_error)? {
        Tile::Absent => return Ok(SourceTile::Absent),
        Tile::Constant(_) => 0,
        Tile::Data(_, payload) => payload.len() as u64,
    };
    let failed = |e| ReadError { bytes_read, ..read_error(e) };
    let texels = vortex_pack::decode_rgba8(pack, lod, x, y).map_err(failed)?.unwrap_or_default();
    let expected = (tile_size as usize).pow(2) * 4;
    if texels.len() != expected {
        let message = format!("decodes to {} bytes, not {expected} of RGBA8", texels.len());
        return Err(ReadError { message, bytes_read });
    }
    Ok(SourceTile::Texels { texels, bytes_read })
}

/// The tile's BC7 blocks: its BC7 payload as stored (checksum checked), or blocks of its one
/// colour.
fn blocks(pack: &Pack, lod: u32, x: u32, y: u32, tile_size: u32) -> Result<SourceTile, ReadError> {
    let wanted = CacheFormat::Bc7.tile_bytes(tile_size);
    let (blocks, bytes_read) = match pack.tile_checked(lod, x, y).map_err(read_error)? {
        Tile::Data(TileKind::Bc7, payload) => (payload.to_vec(), payload.len() as u64),
        Tile::Constant(_) => {
            let texels = vortex_pack::decode_rgba8(pack, lod, x, y).map_err(read_error)?.unwrap_or_default();
            let colour = texels.first_chunk::<4>().copied().unwrap_or_default();
            (bc7::solid_block(colour).repeat(wanted / bc7::BLOCK_BYTES), 0)
        }
        Tile::Data(kind, _) => {
            return Err(ReadError::new(format!("a BC7 cache takes BC7 and one-colour tiles, not {}", kind.name())));
        }
        Tile::Absent => return Err(ReadError::new("an absent tile cannot be made into BC7 blocks")),
    };
    if blocks.len() != wanted {
        let message = format!("holds {} bytes of BC7 blocks, not {wanted}", blocks.len());
        return Err(ReadError { message, bytes_read });
    }
    Ok(SourceTile::Texels { texels: blocks, bytes_read })
}

/// A pack error as a read error: the pack error already names the path and tile, which the
/// loader's error names too, so keep only what it adds.
fn read_error(e: PackError) -> ReadError {
    ReadError::new(match e {
        PackError::Tile { offset, message, .. } => format!("at byte {offset}: {message}"),
        PackError::OutOfRange { message, .. } => message,
        other => other.to_string(),
    })
}

/// Reading a texture's shape from its pack.
impl VirtualTexture {
    /// The texture stored in `pack`. Its level table must be a page grid ([`TextureGrid::from_levels`]:
    /// `w x h` tiles at LOD 0, each level the previous one halved and rounded up, down to one
    /// page; levels past that one page are ignored) within the feedback word's limits, and its
    /// LOD-0 grid must cover the image (`width x height` from the header, which UV 0..1 spans).
    /// The tiler's older square power-of-two packs qualify: their image sits at the top-left
    /// of the grid, and the pages wholly outside it are never asked for.
    pub fn from_pack(pack: &Pack) -> Result<VirtualTexture, LoaderError> {
        let path = || pack.path().to_path_buf();
        let d = pack.description();
        let levels = pack.levels();
        if levels.is_empty() {
            return Err(LoaderError::Layout {
                path: path(),
                field: "level_count",
                message: "the pack has no levels".into(),
            });
        }
        let grid = TextureGrid::from_levels(levels.iter().map(|l| [l.tiles_w, l.tiles_h]))
            .map_err(|source| LoaderError::Grid { path: path(), source })?;
        let payload = d.tile_size - 2 * d.border;
        for (axis, (field, value)) in [("width", d.width), ("height", d.height)].into_iter().enumerate() {
            let pages = grid.pages()[axis];
            let covered = u64::from(pages) * u64::from(payload);
            if u64::from(value) > covered {
                return Err(LoaderError::Layout {
                    path: path(),
                    field,
                    message: format!("{field} {value} exceeds the {covered} texels of {pages} pages of {payload}"),
                });
            }
        }
        Ok(VirtualTexture { grid, width: d.width, height: d.height, tile_size: d.tile_size, border: d.border })
    }
}
