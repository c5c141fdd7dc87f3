//! Vortex packs as page sources. A stored tile is read as it is stored (its payload, checksum
//! checked, or its one colour) and decoded on its own: to RGBA8 by `Tile::decode_rgba8`, or
//! for a BC7 cache taken as stored BC7 blocks (or blocks of a constant tile's one colour). The
//! loader's memory tier keeps the stored bytes between the two; an absent tile is reported as
//! such, for the loader to magnify its ancestor.

use std::path::Path;
use std::sync::Arc;

use vortex_pack::{Description, Pack, PackError, PackLayout, Tile, TileId, TileKind};
use vortex_vt::page::TextureGrid;

use super::{PageSource, ReadError, ReadErrorKind, SourceTile, StoredRead, StoredTile};
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

    /// The tile decoded where it lies in the pack, with no copy of its stored bytes (what the
    /// loader reads when the memory tier is off).
    fn read_tile(&self, id: TileId, format: CacheFormat) -> Result<SourceTile, ReadError> {
        let (tile, bytes_read) = checked(self, id)?;
        match tile {
            Tile::Absent if format == CacheFormat::Rgba8 => Ok(SourceTile::Absent),
            Tile::Absent => Err(absent_as(format)),
            tile => decode_tile(self.layout(), tile, format)
                .map(|texels| SourceTile::Texels { texels, bytes_read })
                .map_err(|e| e.with_bytes_read(bytes_read)),
        }
    }

    /// The tile's stored bytes, copied out of the pack so that the memory tier may keep them.
    fn read_stored(&self, id: TileId) -> Result<Option<StoredRead>, ReadError> {
        let (tile, bytes_read) = checked(self, id)?;
        let tile = match tile {
            Tile::Absent => StoredTile::Absent,
            Tile::Constant(value) => StoredTile::Stored { kind: TileKind::Constant, bytes: Arc::from(value) },
            Tile::Data(kind, payload) => StoredTile::Stored { kind, bytes: Arc::from(payload) },
        };
        Ok(Some(StoredRead { tile, bytes_read }))
    }

    fn decode(&self, _: TileId, kind: TileKind, bytes: &[u8], format: CacheFormat) -> Result<Vec<u8>, ReadError> {
        decode_stored(self.layout(), kind, bytes, format)
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

/// The tile as stored, in the pack (its payload, checksum checked, or its one colour, or
/// `Absent`), and the bytes read for it. A payload that fails its checksum still counts as read.
fn checked(pack: &Pack, id: TileId) -> Result<(Tile<'_>, u64), ReadError> {
    let payload_len = |tile: &Tile| if let Tile::Data(_, payload) = tile { payload.len() as u64 } else { 0 };
    let tile = pack.tile_checked(id).map_err(|e| {
        let bytes_read = pack.tile(id).map_or(0, |tile| payload_len(&tile));
        read_error(e).with_bytes_read(bytes_read)
    })?;
    let bytes_read = payload_len(&tile);
    Ok((tile, bytes_read))
}

/// A stored tile's RGBA8 texels (any kind), or its BC7 blocks (a BC7 or one-colour tile: the
/// loader asks for BC7 only when every tile is one of those); never BC1, which the loader
/// transcodes.
pub(super) fn decode_tile(head: &PackLayout, tile: Tile<'_>, format: CacheFormat) -> Result<Vec<u8>, ReadError> {
    let (d, limit) = (&head.header().description, head.limits().max_decoded_bytes);
    match format {
        CacheFormat::Rgba8 => texels(tile, d, limit),
        CacheFormat::Bc7 => blocks(tile, d, limit),
        CacheFormat::Bc1 => Err(ReadError::unsupported("a pack gives RGBA8 texels or stored BC7 blocks, not BC1")),
    }
}

/// What [`PageSource::decode`] does for a pack: the stored tile of `kind` decoded as
/// [`decode_tile`] does.
pub(super) fn decode_stored(
    head: &PackLayout,
    kind: TileKind,
    bytes: &[u8],
    format: CacheFormat,
) -> Result<Vec<u8>, ReadError> {
    let tile = match kind {
        TileKind::Absent => return Err(absent_as(format)),
        TileKind::Constant => Tile::Constant(bytes),
        kind => Tile::Data(kind, bytes),
    };
    decode_tile(head, tile, format)
}

/// Why an absent tile is no answer in `format`: only an RGBA8 page can be magnified from its
/// ancestor.
pub(super) fn absent_as(format: CacheFormat) -> ReadError {
    ReadError::unsupported(format!("an absent tile cannot be made into {}", format.name()))
}

/// The tile's RGBA8 texels.
fn texels(tile: Tile<'_>, d: &Description, limit: u64) -> Result<Vec<u8>, ReadError> {
    let texels = tile.decode_rgba8(d, limit).map_err(read_error)?.unwrap_or_default();
    let expected = (d.tile_size as usize).pow(2) * 4;
    if texels.len() != expected {
        return Err(ReadError::corrupt(format!("decodes to {} bytes, not {expected} of RGBA8", texels.len())));
    }
    Ok(texels)
}

/// The tile's BC7 blocks: its BC7 payload as stored, or blocks of its one colour.
fn blocks(tile: Tile<'_>, d: &Description, limit: u64) -> Result<Vec<u8>, ReadError> {
    let wanted = CacheFormat::Bc7.tile_bytes(d.tile_size);
    let blocks = match tile {
        Tile::Data(TileKind::Bc7, payload) => payload.to_vec(),
        Tile::Constant(_) => {
            let texels = tile.decode_rgba8(d, limit).map_err(read_error)?.unwrap_or_default();
            let colour = texels.first_chunk::<4>().copied().unwrap_or_default();
            bc7::solid_block(colour).repeat(wanted / bc7::BLOCK_BYTES)
        }
        Tile::Data(kind, _) => {
            return Err(ReadError::unsupported(format!(
                "a BC7 cache takes BC7 and one-colour tiles, not {}",
                kind.name()
            )));
        }
        Tile::Absent => return Err(absent_as(CacheFormat::Bc7)),
    };
    if blocks.len() != wanted {
        return Err(ReadError::corrupt(format!("holds {} bytes of BC7 blocks, not {wanted}", blocks.len())));
    }
    Ok(blocks)
}

/// A pack error as a read error: the pack error already names the path and tile, which the
/// loader's error names too, so keep only what it adds. Its kind: an I/O error may pass; bytes
/// that fail a check or do not decode are corrupt; what this reader refuses (a newer format, a
/// limit, a tile outside the pack) is unsupported.
pub(super) fn read_error(e: PackError) -> ReadError {
    let kind = match &e {
        PackError::Io { .. } => ReadErrorKind::Io,
        PackError::Corrupt { .. } | PackError::Tile { .. } | PackError::Payload { .. } => ReadErrorKind::Corrupt,
        _ => ReadErrorKind::Unsupported,
    };
    ReadError::new(
        kind,
        match e {
            PackError::Tile { offset, message, .. } => format!("at byte {offset}: {message}"),
            PackError::OutOfRange { message, .. } => message,
            PackError::Payload { kind, message } => format!("{kind} payload: {message}"),
            other => other.to_string(),
        },
    )
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
        VirtualTexture::from_layout(pack.layout())
    }

    /// As [`VirtualTexture::from_pack`], from a pack's checked header and level table (a pack
    /// read in pieces, over HTTP say).
    pub fn from_layout(head: &PackLayout) -> Result<VirtualTexture, LoaderError> {
        let path = || head.path().to_path_buf();
        let d = &head.header().description;
        let levels = head.levels();
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
