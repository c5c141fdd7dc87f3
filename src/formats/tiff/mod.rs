//! Pyramidal TIFF out: one file holding every level of the pyramid as tiled images, in the
//! two layouts the readers of slides and microscopy open (docs/tiff.md).
//!
//! * [`Flavour::Generic`], what `vips tiffsave --tile --pyramid` writes: every level a tiled
//!   IFD of its own in one chain, the reduced ones marked `NewSubfileType` 1 (OpenSlide's
//!   generic-tiff reader, libvips `page=N`).
//! * [`Flavour::Ome`], an OME-TIFF: the full resolution in the first IFD with the OME-XML in
//!   its `ImageDescription`, each reduced level one of its SubIFDs (tag 330), as bioformats,
//!   QuPath and tifffile read a pyramid.
//! * [`Flavour::Cog`], a Cloud Optimized GeoTIFF as GDAL's COG driver lays it out: the
//!   generic pyramid's IFDs first, behind GDAL's ghost area, then the tile data, the coarsest
//!   level first (`cog.rs`: the tiles staged beside the file and copied into place at the end).
//!
//! The file is written in one pass (`TiffWriter`): the header and a signature first, then
//! each tile's bytes appended as it arrives, with only its offset and length kept (16 bytes a
//! tile); at the end the IFDs, their arrays and the OME-XML, and the header's first-IFD offset
//! patched. Classic TIFF or BigTIFF is decided before the first byte from an upper bound of
//! the file's size (`Spec::needs_bigtiff`), or always with [`BigTiff::Always`].
//! `TiffSink` is the writer as a pipeline sink. Tiles come compressed from the encoder
//! threads (`Spec::codec`: JPEG, or Deflate, LZW and zstd with the horizontal predictor, which
//! is the pack's row-delta filter, for integer samples and the floating-point one for floats) and in the producer's order (the sink is `ordered`), so the
//! file's bytes are the same on every run, whatever the thread count; the file is written
//! under a temporary name and renamed into place when complete.
//!
//! A JPEG-tiled source's stored tiles are copied into level 0 where they are what the tags
//! say (`TiffSink`'s `takes_stored_jpeg`). A GeoTIFF source's georeferencing tags are written
//! again into a COG's or a generic pyramid's full resolution (`Spec::geo`). A slide's
//! associated images (label, macro, thumbnail) follow a generic pyramid's levels, each one
//! strip of its own (`associated.rs`). An OME-TIFF holds channels as grey planes
//! (`Spec::planar`), one pass of the pipeline each: plane `c`'s tiles come after plane
//! `c - 1`'s, and its IFDs are the `c`th main IFD with its SubIFDs. JPEG tiles share their
//! tables: each IFD's `JPEGTables` are its first tile's, and every tile with the same tables
//! is stored without them (`TiffWriter::abbreviate`), as libvips and scanners write them.

mod associated;
mod cog;
mod copy;
mod ifd;
mod ome;
mod sink;
#[cfg(test)]
mod tests;
mod writer;

pub use associated::AssociatedSummary;
pub(crate) use copy::{Coding, coding_name, compression, copyable, fits};
pub(crate) use sink::TiffSink;
pub use writer::TiffSummary;
pub(crate) use writer::TiffWriter;

use crate::codec::{Codec, RowFilter, Subsampling};
use crate::error::{Result, TilerError};
use crate::layout::{Layout, Level};
use crate::pixel::{Channels, Depth, PixelLayout};
use crate::source::GeoValue;
use crate::source::associated::Associated;

/// Where the writer puts its signature, after the header: the `Software` tag's value, which
/// names the file as ours so that a later run may replace it (`output::claim`).
pub(crate) const SIGNATURE_AT: u64 = 16;
/// The signature's text (NUL-terminated in the file, as TIFF's ASCII values are).
pub(crate) const SIGNATURE: &str = "vortex-tiler";

/// The default tile side, libvips' and most scanners'.
pub(crate) const DEFAULT_TILE_SIZE: u32 = 256;

/// Which pyramidal TIFF layout to write.
#[derive(Clone, Copy, Debug, PartialEq, Eq, Hash)]
pub enum Flavour {
    /// Every level a tiled IFD in one chain (`vips tiffsave --tile --pyramid`).
    Generic,
    /// OME-TIFF: reduced levels as SubIFDs of the full resolution, OME-XML in its description.
    Ome,
    /// Cloud Optimized GeoTIFF: the generic pyramid's IFDs first, then the tile data coarse to
    /// fine, as GDAL's COG driver writes it (its validator passes).
    Cog,
}

impl Flavour {
    /// The flavour's name in messages and `--json`.
    pub fn name(self) -> &'static str {
        match self {
            Flavour::Generic => "tiff",
            Flavour::Ome => "ome-tiff",
            Flavour::Cog => "cog",
        }
    }

    /// The flavour a file name says: `.ome.tif` and `.ome.tiff` OME-TIFF, `.cog.tif` and
    /// `.cog.tiff` a COG, `.tif` and `.tiff` the generic pyramid (case-insensitive); other
    /// names none.
    pub(crate) fn of_name(name: &str) -> Option<Flavour> {
        let name = name.to_ascii_lowercase();
        if name.ends_with(".ome.tif") || name.ends_with(".ome.tiff") {
            Some(Flavour::Ome)
        } else if name.ends_with(".cog.tif") || name.ends_with(".cog.tiff") {
            Some(Flavour::Cog)
        } else if name.ends_with(".tif") || name.ends_with(".tiff") {
            Some(Flavour::Generic)
        } else {
            None
        }
    }
}

/// How each tile's bytes are compressed (the TIFF `Compression` tag).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub enum Compression {
    /// Uncompressed samples (1).
    None,
    /// zlib streams ("Adobe Deflate", 8), integer samples horizontally differenced first.
    Deflate {
        /// The zlib level, 0 (stored) to 9 (smallest); a planned output always takes 6.
        level: u32,
    },
    /// LZW (5), integer samples horizontally differenced first.
    Lzw,
    /// zstd frames (50000, libtiff's code), integer samples horizontally differenced first.
    Zstd {
        /// The zstd level, 1 to 22 (`--zstd-level`).
        level: i32,
    },
    /// One whole JPEG stream a tile (7), YCbCr at the encoder's subsampling, or grey.
    Jpeg {
        /// Chroma subsampling of RGB tiles.
        subsampling: Subsampling,
    },
    /// One JPEG XL file a tile (50002, as libvips and tifffile write it): grey or RGB, alpha
    /// as an extra sample, 8 or 16 bits; lossy at the run's quality, or lossless.
    Jxl,
}

impl Compression {
    /// The `Compression` tag's value.
    pub fn code(self) -> u16 {
        match self {
            Compression::None => 1,
            Compression::Deflate { .. } => 8,
            Compression::Lzw => 5,
            Compression::Zstd { .. } => 50000,
            Compression::Jpeg { .. } => 7,
            Compression::Jxl => 50002,
        }
    }

    /// Its name in messages and `--json`.
    pub fn name(self) -> &'static str {
        match self {
            Compression::None => "none",
            Compression::Deflate { .. } => "deflate",
            Compression::Lzw => "lzw",
            Compression::Zstd { .. } => "zstd",
            Compression::Jpeg { .. } => "jpeg",
            Compression::Jxl => "jxl",
        }
    }
}

/// Classic TIFF (offsets of 32 bits, files under 4 GiB) or BigTIFF (64 bits).
#[derive(Clone, Copy, Debug, Default, PartialEq, Eq)]
pub enum BigTiff {
    /// BigTIFF only where the file could pass 4 GiB (`Spec::needs_bigtiff`).
    #[default]
    Auto,
    /// Always BigTIFF.
    Always,
}

/// An OME channel's name and colour, where the source says them (OME's `Channel` `Name` and
/// `Color`); nothing is invented for what it does not say.
#[derive(Clone, Debug, Default, PartialEq, Eq)]
pub(crate) struct OmeChannel {
    pub name: Option<String>,
    /// RGBA, red in the high byte (OME's `Color`, written as the signed 32-bit integer it is).
    pub colour: Option<u32>,
}

/// The physical side of a level-0 pixel, in micrometres (OME's `PhysicalSizeX`/`Y`, and the
/// TIFF resolution tags).
#[derive(Clone, Copy, Debug, PartialEq)]
pub(crate) struct Micrometres(pub f64);

/// Everything the file says, fixed before its first byte.
#[derive(Clone, Debug, PartialEq)]
pub(crate) struct Spec {
    pub flavour: Flavour,
    /// The pyramid's page grid, border 0: the full-resolution size, the tile side (a multiple
    /// of 16, the TIFF rule; edge tiles are whole tiles) and the levels (`lod_count`, the full
    /// resolution included). Level `k` is `layout.level_extent(k)` in `layout.grid(k)` tiles.
    pub layout: Layout,
    /// The samples of each pixel as stored.
    pub stored: PixelLayout,
    pub compression: Compression,
    pub bigtiff: BigTiff,
    /// The image's name (OME's `Image Name`).
    pub name: String,
    /// The physical size of a full-resolution pixel, where known.
    pub pixel_size: Option<Micrometres>,
    /// A GeoTIFF source's georeferencing tags, ascending, written as they are into the full
    /// resolution's IFD (none in the reduced levels, as GDAL writes its overviews); empty for
    /// none.
    pub geo: Vec<(u16, GeoValue)>,
    /// The ICC profile the samples are in (`--keep-icc`), in every level's IFD; `None`: sRGB,
    /// which TIFF readers assume.
    pub icc: Option<Vec<u8>>,
    /// The slide's own levels where they are copied as stored (`--levels stored`): each its
    /// size and tiles, any downsample between them; empty: `layout`'s levels.
    pub copied: Vec<Level>,
    /// The source's associated images (label, macro, thumbnail), each written after the
    /// levels as an IFD of its own (the generic flavour only; empty for the others).
    pub associated: Vec<Associated>,
    /// The most bytes one associated image may take decoded (half of `--max-memory`).
    pub associated_bytes: u64,
    /// The associated images the source has that the file leaves out (`--no-associated`,
    /// or a flavour that holds none).
    pub associated_left_out: usize,
    /// An OME-TIFF's channels as OME names them. With `planar`, one grey plane each: plane `c`
    /// is a main IFD of its own (the `c`th of the chain, its reduced levels its SubIFDs), as
    /// bioformats and raw2ometiff write more channels than a pixel holds. Without, at most one
    /// entry: the one channel of `stored`'s interleaved samples; empty: nothing said of it.
    pub channels: Vec<OmeChannel>,
    /// Whether each of `channels` is a grey plane of its own (OME-TIFF only).
    pub planar: bool,
}

impl Spec {
    /// Levels, the full resolution included.
    pub fn level_count(&self) -> u32 {
        Level::count(&self.copied, &self.layout)
    }

    /// Level `k`'s image and tiles.
    pub fn level(&self, k: u32) -> Level {
        Level::of(&self.copied, &self.layout, k)
    }

    /// Planes: a grey one per channel where `planar`, else the one of interleaved samples.
    pub fn planes(&self) -> u32 {
        match self.planar {
            true => self.channels.len() as u32,
            false => 1,
        }
    }

    /// Tiles of one plane, every level.
    pub fn plane_tiles(&self) -> u64 {
        (0..self.level_count()).map(|k| self.level(k).tiles()).sum()
    }

    /// Tiles, every level of every plane.
    pub fn total_tiles(&self) -> u64 {
        self.plane_tiles().saturating_mul(u64::from(self.planes()))
    }

    /// The longest side of any level's tiles.
    fn tile_side(&self) -> u32 {
        (0..self.level_count()).map(|k| self.level(k).tile).map(|(w, h)| w.max(h)).max().unwrap_or(0)
    }

    /// Refuses what no TIFF (or no reader of these flavours) holds, before anything is
    /// written; the messages say what to change.
    pub fn check(&self) -> Result<()> {
        let l = &self.layout;
        let t = l.tile_size;
        if t == 0 || !t.is_multiple_of(16) {
            return Err(TilerError::Options(format!(
                "--tile-size {t}: TIFF tiles are a multiple of 16 pixels a side (e.g. 256 or 512)"
            )));
        }
        if let Some((k, c)) = self.copied.iter().enumerate().find(|(_, c)| {
            let (w, h) = c.tile;
            w == 0 || h == 0 || !w.is_multiple_of(16) || !h.is_multiple_of(16) || c.width == 0 || c.height == 0
        }) {
            return Err(TilerError::Options(format!(
                "level {k} of the slide is {}x{} in {}x{} tiles: a TIFF's tiles are a multiple of 16 pixels a side",
                c.width, c.height, c.tile.0, c.tile.1
            )));
        }
        if l.border != 0 {
            return Err(TilerError::Options(format!("--border {}: TIFF tiles have no border", l.border)));
        }
        if l.width == 0 || l.height == 0 {
            return Err(TilerError::Geometry(format!("a {}x{} image has no pixels", l.width, l.height)));
        }
        let levels = self.level_count();
        if levels == 0 || levels > 32 {
            return Err(TilerError::Geometry(format!("a TIFF pyramid of {levels} levels")));
        }
        let s = self.stored;
        match self.compression {
            Compression::Jpeg { .. } if s.depth != Depth::U8 || s.channels.has_alpha() => {
                return Err(TilerError::Options(format!(
                    "JPEG in TIFF holds 8-bit grey or RGB, not {s}: use --codec deflate or zstd"
                )));
            }
            Compression::Jxl if !s.depth.is_narrow_int() => {
                return Err(TilerError::Options(format!(
                    "JPEG XL in TIFF holds 8 or 16-bit samples, not {s}: use --codec deflate or zstd"
                )));
            }
            Compression::Deflate { level } if level > 9 => {
                return Err(TilerError::Options(format!("Deflate level {level} is outside 0..=9")));
            }
            _ => {}
        }
        if matches!(s.depth, Depth::F16) {
            return Err(TilerError::Options(
                "half-float samples: TIFF readers of these pyramids take 8, 16 or 32-bit samples".into(),
            ));
        }
        if self.flavour == Flavour::Cog && self.most_tile_bytes() > u32::MAX as u64 {
            return Err(TilerError::Options(format!(
                "--tile-size {t}: a COG tile's length is a 32-bit leader, and these tiles could pass 4 GiB"
            )));
        }
        if self.planar {
            let planes = self.channels.len();
            if self.flavour != Flavour::Ome {
                return Err(TilerError::Options(format!(
                    "{planes} channels as planes: only an OME-TIFF (-o FILE.ome.tif) holds them; a {} holds one to four samples a pixel: pick them with --channels",
                    self.flavour.name()
                )));
            }
            if planes == 0 || planes > crate::source::channels::MAX_CHANNELS {
                return Err(TilerError::Options(format!(
                    "an OME-TIFF of {planes} planes: 1 to {} are written",
                    crate::source::channels::MAX_CHANNELS
                )));
            }
            if self.stored.channels != Channels::Grey || !self.copied.is_empty() {
                return Err(TilerError::Internal(format!(
                    "an OME-TIFF's planes are grey pyramids of ours, not {} samples or copied levels",
                    self.stored
                )));
            }
        } else if self.channels.len() > 1 {
            return Err(TilerError::Internal("interleaved samples are one OME channel".into()));
        }
        if let Some(c) = self.channels.iter().find(|c| c.name.as_ref().is_some_and(|n| n.contains('\0'))) {
            return Err(TilerError::Options(format!(
                "the channel name {:?} holds a NUL character",
                c.name.as_deref().unwrap_or_default()
            )));
        }
        if self.name.contains('\0') {
            return Err(TilerError::Options("the image's name holds a NUL character".into()));
        }
        if !self.associated.is_empty() && self.flavour == Flavour::Cog {
            return Err(TilerError::Internal(format!("associated images in a {} file", self.flavour.name())));
        }
        if let Some(image) = self.associated.iter().find(|a| a.width == 0 || a.height == 0) {
            return Err(TilerError::Options(format!(
                "the {} ({}) is {}x{}: it has no pixels; --no-associated leaves the associated images out",
                image.kind.name(),
                image.origin(),
                image.width,
                image.height
            )));
        }
        Ok(())
    }

    /// Bytes of one tile's samples, uncompressed (our pyramid's tiles are all one size).
    pub fn raw_tile_bytes(&self) -> u64 {
        (self.layout.tile_size as u64).pow(2) * self.stored.bytes_per_pixel() as u64
    }

    /// The most bytes one stored tile may take, as the codec states it
    /// ([`Codec::most_encoded_bytes`]): the raw samples for none, the compressors' bounds
    /// (zstd's `ZSTD_compressBound`; zlib's stored blocks, generously), and for JPEG
    /// libjpeg-turbo's `tj3JPEGBufSize` at any quality.
    pub fn most_tile_bytes(&self) -> u64 {
        let codec = match self.compression {
            Compression::Jpeg { subsampling } => Codec::Jpeg { quality: 100, subsampling },
            Compression::Jxl => Codec::Jxl { quality: None, effort: crate::codec::JxlEffort::clamped(1) },
            _ => self.codec().unwrap_or(Codec::Raw),
        };
        codec.most_encoded_bytes(self.tile_side(), self.stored)
    }

    /// Memory the writer's tile index holds at its peak: an offset and a length a tile (16
    /// bytes) while the tiles come, and at the end the IFDs' offset and byte-count arrays
    /// beside it (16 more), until the index is dropped.
    pub fn index_bytes(&self) -> u64 {
        self.total_tiles().saturating_mul(32)
    }

    /// An upper bound of the file's size: header, tiles at their largest (a COG's with their
    /// leader and trailer), IFDs, their arrays, the georeferencing, the ICC profiles, the
    /// OME-XML and a COG's ghost area.
    pub fn most_file_bytes(&self) -> u64 {
        let framing = if self.flavour == Flavour::Cog { cog::FRAMING } else { 0 };
        let total = self.total_tiles();
        let tiles = total.saturating_mul(self.most_tile_bytes() + framing);
        let geo: u64 = (self.geo.iter())
            .map(|(_, v)| match v {
                GeoValue::Shorts(v) => 2 * v.len() as u64,
                GeoValue::Doubles(v) => 8 * v.len() as u64,
                GeoValue::Ascii(v) => v.len() as u64 + 1,
            } + 24)
            .sum();
        let icc = self.icc.as_ref().map_or(0, |p| p.len() as u64 + 2);
        let ifds =
            u64::from(self.level_count()) * u64::from(self.planes()) * (4096 + icc) + total.saturating_mul(16) + geo;
        let xml = ome::xml(self, &[]).len() as u64;
        // Each associated image's strip, and its IFD and OME-XML `Image` in 4 KiB.
        let associated: u64 = (self.associated.iter())
            .map(|a| associated::most_bytes(a.width, a.height).saturating_add(4096))
            .fold(0, u64::saturating_add);
        tiles.saturating_add(ifds).saturating_add(xml).saturating_add(associated).saturating_add(1024)
    }

    /// Whether the file is written as BigTIFF: always asked, or its size could pass what
    /// 32-bit offsets reach.
    pub fn needs_bigtiff(&self) -> bool {
        self.bigtiff == BigTiff::Always || self.most_file_bytes() > u32::MAX as u64
    }

    /// How rows are filtered before Deflate, LZW or zstd: integer samples horizontally
    /// differenced (`Predictor` 2), float ones by the floating-point predictor (3).
    pub fn predictor(&self) -> RowFilter {
        if !matches!(self.compression, Compression::Deflate { .. } | Compression::Lzw | Compression::Zstd { .. }) {
            return RowFilter::None;
        }
        match self.stored.depth {
            Depth::U8 | Depth::U16 | Depth::U32 => RowFilter::Delta,
            Depth::F16 | Depth::F32 => RowFilter::FloatingPoint,
        }
    }

    /// The codec whose tiles the file stores as they come from the encoders: raw samples, or
    /// Deflate, LZW and zstd of them filtered as [`Spec::predictor`] says. `None` for JPEG and
    /// JPEG XL, whose quality is the run's setting, not the file's.
    pub fn codec(&self) -> Option<Codec> {
        let filter = self.predictor();
        match self.compression {
            Compression::None => Some(Codec::Raw),
            Compression::Deflate { level } => Some(Codec::Deflate { level, filter }),
            Compression::Lzw => Some(Codec::Lzw { filter }),
            Compression::Zstd { level } => Some(Codec::Zstd { level, filter }),
            Compression::Jpeg { .. } | Compression::Jxl => None,
        }
    }

    /// The `Photometric` tag: grey is black-is-zero; RGB tiles in JPEG are YCbCr (what
    /// the encoder writes) unless coded as RGB, RGB otherwise.
    pub(crate) fn photometric(&self) -> u16 {
        match (self.stored.channels, self.compression) {
            (Channels::Grey | Channels::GreyAlpha, _) => 1,
            (_, Compression::Jpeg { subsampling }) if subsampling != Subsampling::Rgb => 6,
            _ => 2,
        }
    }
}
