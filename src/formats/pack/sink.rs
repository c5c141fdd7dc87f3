//! A sink that writes one pack file instead of a directory of tiles: `split --pack`.
//!
//! Tiles arrive from the encoder threads in any order; the pack writer appends each payload
//! as it comes (one pass, no intermediate files) and keeps only the index in memory.
//! One-colour tiles are stored as their colour, with no payload.

use std::path::Path;
use std::sync::Mutex;

use vortex_pack::{Description, NewTile, PackWriter, TileId, TileKind, WriteOptions, WriteSummary};

use crate::codec::{Codec, RowFilter};
use crate::error::{Result, TilerError};
use crate::layout::Layout;
use crate::pixel::PixelLayout;
use crate::sink::TileSink;

/// A pack being written as a run's sink: tiles appended as they come, the index and header
/// at [`PackSink::finish`], under a temporary name until then.
pub struct PackSink {
    writer: Mutex<PackWriter>,
    kind: TileKind,
}

/// The pack's description of a tiler layout and stored texel format.
pub(crate) fn pack_description(layout: &Layout, stored: PixelLayout) -> Description {
    Description {
        width: layout.width,
        height: layout.height,
        tile_size: layout.tile_size,
        border: layout.border,
        level_count: layout.lod_count,
        channels: stored.channels.count() as u8,
        sample_bytes: stored.depth.bytes() as u8,
        sample_format: stored.depth.pack_sample_format(),
    }
}

/// The pack's kind of the tiles `codec` makes; Deflate and LZW tiles and the floating-point
/// predictor are a TIFF's, which no pack holds.
pub fn tile_kind(codec: Codec) -> Result<TileKind> {
    Ok(match codec {
        Codec::Jpeg { .. } => TileKind::Jpeg,
        Codec::Png { .. } => TileKind::Png,
        Codec::Raw => TileKind::Raw,
        Codec::Zstd { filter: RowFilter::None, .. } => TileKind::Zstd,
        Codec::Zstd { filter: RowFilter::Delta, .. } => TileKind::ZstdDelta,
        Codec::Bc1 => TileKind::Bc1,
        Codec::Bc7 { .. } => TileKind::Bc7,
        Codec::Jxl { .. } => TileKind::Jxl,
        Codec::Deflate { .. } | Codec::Lzw { .. } | Codec::Zstd { filter: RowFilter::FloatingPoint, .. } => {
            return Err(TilerError::Options(format!(
                "--codec {} compresses the tiles of a TIFF; a pack takes png, raw, zstd or zstd-delta",
                codec.name()
            )));
        }
    })
}

impl PackSink {
    /// Starts `dest`; `metadata` is the run's `info.json`.
    pub fn create(
        dest: &Path,
        layout: &Layout,
        stored: PixelLayout,
        codec: Codec,
        metadata: &[u8],
        options: WriteOptions,
    ) -> Result<PackSink> {
        let d = pack_description(layout, stored);
        let writer = PackWriter::create(dest, d, layout.pack_levels(), metadata, options)?;
        Ok(PackSink { writer: Mutex::new(writer), kind: tile_kind(codec)? })
    }

    /// Writes the index and header and renames the pack into place.
    pub fn finish(self) -> Result<WriteSummary> {
        let writer = self.writer.into_inner().map_err(|_| TilerError::panicked("a tile writer"))?;
        Ok(writer.finish()?)
    }

    /// [`finish`](Self::finish) with other metadata than given at the start.
    pub(crate) fn finish_with_metadata(self, metadata: Vec<u8>) -> Result<WriteSummary> {
        let mut writer = self.writer.into_inner().map_err(|_| TilerError::panicked("a tile writer"))?;
        writer.set_metadata(metadata)?;
        Ok(writer.finish()?)
    }

    fn add(&self, lod: u32, x: u32, y: u32, tile: NewTile) -> Result<()> {
        let mut w = self.writer.lock().map_err(|_| TilerError::panicked("a tile writer"))?;
        Ok(w.add(TileId { lod, x, y }, tile)?)
    }
}

impl TileSink for PackSink {
    fn write_tile(&self, lod: u32, x: u32, y: u32, bytes: &[u8]) -> Result<()> {
        self.add(lod, x, y, NewTile::Data(self.kind, bytes))
    }

    fn takes_constants(&self) -> bool {
        true
    }

    fn write_constant(&self, lod: u32, x: u32, y: u32, texel: &[u8]) -> Result<()> {
        self.add(lod, x, y, NewTile::Constant(texel))
    }

    fn ordered(&self) -> bool {
        true
    }

    /// Payload bytes stored: identical tiles count once.
    fn bytes_written(&self) -> u64 {
        self.writer.lock().map_or(0, |w| w.payload_bytes())
    }
}
