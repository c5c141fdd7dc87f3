//! A sink that writes one pack file instead of a directory of tiles: `split --pack`.
//!
//! Tiles arrive from the encoder threads in any order; the pack writer appends each payload
//! as it comes (one pass, no intermediate files) and keeps only the index in memory.
//! One-colour tiles are stored as their colour, with no payload. The pack goes to a local file
//! or to any [`PackOutput`] (a pack at `s3://` is streamed: `crate::store::stream`).

use std::collections::HashSet;
use std::path::Path;
use std::sync::Mutex;

use vortex_pack::{Description, NewTile, PackOutput, PackWriter, TileId, TileKind, WriteOptions, WriteSummary};

use crate::codec::{Codec, RowFilter};
use crate::error::{Result, TilerError};
use crate::layout::Layout;
use crate::pixel::PixelLayout;
use crate::resume::{Interrupted, Journal, Record};
use crate::sink::TileSink;

/// The writer of a pack to a local file or to another output.
type Writer = PackWriter<Box<dyn PackOutput + Send>>;

/// A pack being written as a run's sink: tiles appended as they come, the index and header
/// at [`PackSink::finish`], under a temporary name (or not visible) until then.
pub struct PackSink {
    writer: Mutex<Writer>,
    kind: TileKind,
    /// A resumable run's journal and the tiles kept from the run it resumes.
    resume: Option<(Journal, HashSet<TileId>)>,
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

/// A bound on the bytes of a pack of `layout`'s tiles of `stored` texels with `metadata_len`
/// bytes of metadata, for an output that must plan its size (a streamed upload's part size):
/// every tile a payload of twice its raw size (an encoder that expands noise expands it by far
/// less), the index and metadata, and room for the alignments.
pub(crate) fn size_bound(layout: &Layout, stored: PixelLayout, metadata_len: usize) -> u64 {
    let d = pack_description(layout, stored);
    let tiles = layout.total_tiles();
    let raw = d.raw_tile_len().unwrap_or(u64::MAX);
    let payloads = tiles.saturating_mul(raw.saturating_mul(2).saturating_add(8));
    payloads
        .saturating_add(tiles.saturating_mul(vortex_pack::format::ENTRY_LEN as u64))
        .saturating_add(metadata_len as u64 + (1 << 20))
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
        Ok(PackSink { writer: Mutex::new(writer.boxed()), kind: tile_kind(codec)?, resume: None })
    }

    /// [`create`](Self::create) writing to `out`, which must be empty (an upload streamed as
    /// the pack is made).
    pub(crate) fn create_to(
        out: Box<dyn PackOutput + Send>,
        layout: &Layout,
        stored: PixelLayout,
        codec: Codec,
        metadata: &[u8],
        options: WriteOptions,
    ) -> Result<PackSink> {
        let d = pack_description(layout, stored);
        let writer = PackWriter::with_output(out, d, layout.pack_levels(), metadata, options)?;
        Ok(PackSink { writer: Mutex::new(writer), kind: tile_kind(codec)?, resume: None })
    }

    /// [`create`](Self::create) for a resumable run (`--resume`): every tile added is recorded
    /// in `journal`; the tiles an interrupted run's journal records (`previous`, its staged
    /// file taken over by [`Journal::start`]) are kept, in the order it added them, up to the
    /// first whose payload is not the one recorded, and its file cut there
    /// ([`PackWriter::resume`]), so that the tiles added next land where an uninterrupted run
    /// puts them; the file stays when the sink is dropped unfinished.
    #[expect(clippy::too_many_arguments, reason = "create's, and the journal's")]
    pub(crate) fn create_resuming(
        dest: &Path,
        layout: &Layout,
        stored: PixelLayout,
        codec: Codec,
        metadata: &[u8],
        options: WriteOptions,
        journal: Journal,
        previous: Option<Interrupted>,
    ) -> Result<PackSink> {
        let d = pack_description(layout, stored);
        let kind = tile_kind(codec)?;
        let (mut writer, kept) = match previous {
            None => (PackWriter::create(dest, d, layout.pack_levels(), metadata, options)?, HashSet::new()),
            Some(previous) => {
                let entries: Vec<(TileId, vortex_pack::Entry)> = (previous.records.iter())
                    .map_while(|r| match r {
                        Record::Entry { id, entry } => Some((*id, *entry)),
                        Record::File { .. } => None,
                    })
                    .collect();
                let levels = layout.pack_levels();
                let (writer, held) =
                    PackWriter::resume(dest, d, levels, metadata, options, &previous.staging, &entries)?;
                let records: Vec<Record> =
                    entries[..held].iter().map(|&(id, entry)| Record::Entry { id, entry }).collect();
                journal.keep(&records)?;
                (writer, entries[..held].iter().map(|(id, _)| *id).collect())
            }
        };
        writer.keep_on_drop();
        Ok(PackSink { writer: Mutex::new(writer.boxed()), kind, resume: Some((journal, kept)) })
    }

    /// Writes the index and header and renames the pack into place.
    pub fn finish(self) -> Result<WriteSummary> {
        let writer = self.writer.into_inner().map_err(|_| TilerError::panicked("a tile writer"))?;
        let summary = writer.finish()?;
        if let Some((journal, _)) = self.resume {
            journal.finish()?;
        }
        Ok(summary)
    }

    /// [`finish`](Self::finish) with other metadata than given at the start.
    pub(crate) fn finish_with_metadata(self, metadata: Vec<u8>) -> Result<WriteSummary> {
        let mut writer = self.writer.into_inner().map_err(|_| TilerError::panicked("a tile writer"))?;
        writer.set_metadata(metadata)?;
        Ok(writer.finish()?)
    }

    fn add(&self, lod: u32, x: u32, y: u32, tile: NewTile) -> Result<()> {
        let id = TileId { lod, x, y };
        let mut w = self.writer.lock().map_err(|_| TilerError::panicked("a tile writer"))?;
        let Some((journal, kept)) = &self.resume else { return Ok(w.add(id, tile)?) };
        if kept.contains(&id) {
            return Ok(());
        }
        w.add(id, tile)?;
        // Recorded under the writer's lock: the journal's order is the order of the adds.
        let entry = w.entry(id).ok_or_else(|| TilerError::Internal(format!("tile {id:?} added, not entered")))?;
        journal.record(Record::Entry { id, entry })
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

    fn kept(&self, lod: u32, x: u32, y: u32) -> bool {
        self.resume.as_ref().is_some_and(|(_, kept)| kept.contains(&TileId { lod, x, y }))
    }

    /// Payload bytes stored: identical tiles count once.
    fn bytes_written(&self) -> u64 {
        self.writer.lock().map_or(0, |w| w.payload_bytes())
    }
}
