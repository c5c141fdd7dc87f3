//! [`TiffWriter`]: a pyramidal TIFF written front to back in one pass, tiles in any order.
//! (A COG is laid out otherwise, IFDs first: its tiles are staged and the file written at
//! [`TiffWriter::finish`]; see `cog.rs`.)
//!
//! ```text
//! 0   header: "II", 42 and the first IFD's offset (classic), or "II", 43, 8, 0 and a
//!     64-bit offset (BigTIFF); patched at the end
//! 16  "vortex-tiler\0" (the Software tag's value: the file's signature), padded to 32
//! 32  tile data, each tile's bytes as they arrived
//! ..  a generic pyramid's associated images, one strip each (`associated.rs`)
//! ..  the IFDs, level 0 first, then the associated images', each with its value area (tile
//!     offsets and byte counts, the OME-XML), each at a multiple of 8; an OME-TIFF of
//!     planes: plane 0's levels, then plane 1's, and so on, each plane's level 0 a main IFD
//!     (chained) and its reduced levels its SubIFDs
//! ```
//!
//! An OME-TIFF's planes come one after another (a pass of the pipeline each): their tiles
//! are appended as they come, plane after plane, and only the index grows with the planes
//! (16 bytes a tile, as for levels).

use std::fs::File;
use std::io::{BufWriter, Seek, SeekFrom, Write};
use std::path::{Path, PathBuf};

use super::associated::{self, AssociatedSummary, Placed};
use super::cog::{self, Staging};
use super::ifd::{Ifd, Value, tag};
use super::{Compression, Flavour, SIGNATURE, SIGNATURE_AT, Spec, ome};
use crate::codec::RowFilter;
use crate::error::{Result, ShowPath, TilerError};
use crate::pixel::Depth;
use crate::source::GeoValue;
use crate::source::associated::{Kind, Pixels};

/// Where tile data starts: after the header and the signature.
const DATA_AT: u64 = 32;

/// What a finished TIFF holds.
#[derive(Clone, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub struct TiffSummary {
    /// Generic pyramidal TIFF or OME-TIFF.
    pub flavour: Flavour,
    /// Whether the file is BigTIFF (64-bit offsets).
    pub bigtiff: bool,
    /// Pyramid levels, the full resolution included.
    pub levels: u32,
    /// Planes, each a pyramid of `levels`: an OME-TIFF's channels one grey plane each, else 1
    /// (the pixels' samples interleaved).
    pub planes: u32,
    /// Tiles stored, every level of every plane.
    pub tiles: u64,
    /// Bytes of tile data, as stored (compressed).
    pub tile_bytes: u64,
    /// Bytes of the whole file.
    pub file_bytes: u64,
    /// The `Compression` written (`none`, `deflate`, `zstd`, `jpeg`).
    pub compression: &'static str,
    /// Whether the levels are the slide's own, every tile copied as stored (`--levels
    /// stored`), not our power-of-two pyramid.
    pub levels_copied: bool,
    /// Why the slide's own levels were not copied, where the file would have copied them.
    pub levels_declined: Option<String>,
    /// The source's associated images the file holds after its levels.
    pub associated: Vec<AssociatedSummary>,
    /// The source's associated images it leaves out (`--no-associated`, or a flavour other
    /// than the generic one).
    pub associated_left_out: usize,
}

/// A TIFF being written: the file, and where each tile went.
pub struct TiffWriter {
    path: PathBuf,
    file: BufWriter<File>,
    /// A COG's tiles until [`TiffWriter::finish`] writes the file whole; `None` for the other
    /// flavours, whose tiles go straight into `file`.
    staging: Option<Staging>,
    spec: Spec,
    big: bool,
    /// Bytes written so far (the next tile's offset).
    len: u64,
    /// Each level's first entry in `tiles`, plane by plane (plane `p`'s level `k` at
    /// `p * levels + k`).
    bases: Vec<usize>,
    /// Offset and length of every tile, plane by plane, level by level, row by row; offset 0:
    /// not yet written.
    /// A COG's offsets are in its staging file (each past its leader, so never 0).
    tiles: Vec<(u64, u64)>,
    tile_bytes: u64,
    /// JPEG tiles: each IFD's shared tables (its `JPEGTables`), those of its first tile; a
    /// later tile with the same tables is stored without them (abbreviated), one with others
    /// whole. Indexed as `bases`.
    tables: Vec<Option<Vec<u8>>>,
    /// The associated images written after the tiles (a generic pyramid's).
    associated: Vec<Placed>,
}

fn write_err(path: &Path) -> impl Fn(std::io::Error) -> TilerError + '_ {
    move |e| TilerError::write(path, e)
}

impl TiffWriter {
    /// Starts the TIFF `spec` describes in `file` (opened for writing, empty), whose name is
    /// `path` (for messages). The caller has checked the tile index's memory
    /// ([`Spec::index_bytes`]) against its budget.
    pub fn create(path: &Path, file: File, spec: Spec) -> Result<TiffWriter> {
        spec.check()?;
        let all = spec.total_tiles();
        let total = usize::try_from(all)
            .map_err(|_| TilerError::Limit(format!("{all} tiles: more than this machine indexes")))?;
        let mut tiles = Vec::new();
        tiles.try_reserve_exact(total).map_err(|_| {
            TilerError::Limit(format!("the index of {total} TIFF tiles ({} bytes) does not fit in memory", total * 16))
        })?;
        tiles.resize(total, (0, 0));
        let mut bases = Vec::with_capacity((spec.level_count() * spec.planes()) as usize);
        let mut at = 0usize;
        for _ in 0..spec.planes() {
            for k in 0..spec.level_count() {
                bases.push(at);
                at += spec.level(k).tiles() as usize;
            }
        }
        let big = spec.needs_bigtiff();
        let mut file = BufWriter::with_capacity(1 << 20, file);
        let (staging, len) = if spec.flavour == Flavour::Cog {
            // The file is written whole at the end; the tiles wait beside it.
            (Some(Staging::create(path).map_err(write_err(path))?), 0)
        } else {
            let mut head = header(big, 0);
            head.resize(SIGNATURE_AT as usize, 0);
            head.extend(SIGNATURE.as_bytes());
            head.resize(DATA_AT as usize, 0);
            file.write_all(&head).map_err(write_err(path))?;
            (None, DATA_AT)
        };
        let path = path.to_path_buf();
        let tables = vec![None; bases.len()];
        Ok(TiffWriter {
            path,
            file,
            staging,
            spec,
            big,
            len,
            bases,
            tiles,
            tile_bytes: 0,
            tables,
            associated: Vec::new(),
        })
    }

    /// Appends tile `(x, y)` of `level` of plane `plane` (0, or an OME-TIFF's channel
    /// `plane`): `bytes` as the file stores them (compressed; a JPEG whose tables are its
    /// level's shared ones is stored without them).
    pub fn add_plane_tile(&mut self, plane: u32, level: u32, x: u32, y: u32, bytes: &[u8]) -> Result<()> {
        let err = |message: String| TilerError::Encode { lod: level, x, y, message };
        if plane >= self.spec.planes() {
            return Err(err(format!("plane {plane}: the TIFF has {} plane(s)", self.spec.planes())));
        }
        if level >= self.spec.level_count() {
            return Err(err(format!("the TIFF has {} levels", self.spec.level_count())));
        }
        let (c, r) = self.spec.level(level).grid();
        if x >= c || y >= r {
            return Err(err(format!("level {level} of the TIFF is {c}x{r} tiles")));
        }
        if bytes.is_empty() {
            return Err(err("an empty tile".into()));
        }
        let at = self.base(plane, level) + y as usize * c as usize + x as usize;
        if self.tiles[at].0 != 0 {
            return Err(err("internal error: the tile came twice".into()));
        }
        let abbreviated = match self.spec.compression {
            Compression::Jpeg { .. } => self.abbreviate((plane * self.spec.level_count() + level) as usize, bytes),
            _ => None,
        };
        let bytes = abbreviated.as_deref().unwrap_or(bytes);
        let offset = match &mut self.staging {
            Some(staging) => {
                if u32::try_from(bytes.len()).is_err() {
                    return Err(err(format!("{} bytes: a COG tile's length is a 32-bit leader", bytes.len())));
                }
                staging.append(bytes).map_err(write_err(&self.path))?
            }
            None => {
                let end = self.len + bytes.len() as u64;
                if !self.big && end > u32::MAX as u64 {
                    return Err(TilerError::Limit(format!(
                        "{}: the tiles passed 4 GiB, more than a classic TIFF's bound said; write BigTIFF",
                        self.path.shown()
                    )));
                }
                self.file.write_all(bytes).map_err(write_err(&self.path))?;
                std::mem::replace(&mut self.len, end)
            }
        };
        self.tiles[at] = (offset, bytes.len() as u64);
        self.tile_bytes += bytes.len() as u64;
        Ok(())
    }

    /// Appends an associated image of the source (a generic pyramid's: after its tiles, before
    /// the IFDs), its rows differenced and deflated in place; its strip's length.
    pub fn add_associated(&mut self, kind: Kind, mut pixels: Pixels) -> Result<u64> {
        if self.spec.flavour == Flavour::Cog {
            return Err(TilerError::Internal(format!("an associated image in a {} file", self.spec.flavour.name())));
        }
        let strip = associated::strip(&mut pixels).map_err(write_err(&self.path))?;
        let end = self.len + strip.len() as u64;
        if !self.big && end > u32::MAX as u64 {
            return Err(TilerError::Limit(format!(
                "{}: the {} passed 4 GiB, more than a classic TIFF's bound said; write BigTIFF",
                self.path.shown(),
                kind.name()
            )));
        }
        self.file.write_all(&strip).map_err(write_err(&self.path))?;
        let (width, height, channels) = (pixels.width, pixels.height, pixels.channels);
        let len = strip.len() as u64;
        self.associated.push(Placed { kind, width, height, channels, offset: self.len, len });
        self.len = end;
        Ok(len)
    }

    /// Writes the IFDs after the tiles, points the header at the first, and syncs the file;
    /// a COG's file is written whole here ([`TiffWriter::finish_cog`]). Fails, naming it, if a
    /// tile is missing.
    pub fn finish(mut self) -> Result<TiffSummary> {
        if let Some(missing) = self.tiles.iter().position(|t| t.0 == 0) {
            let at = self.bases.iter().rposition(|&b| b <= missing).unwrap_or(0);
            let levels = self.spec.level_count() as usize;
            let (plane, level) = (at / levels, at % levels);
            let (c, _) = self.spec.level(level as u32).grid();
            let i = missing - self.bases[at];
            let plane = if self.spec.planar { format!("plane {plane}, ") } else { String::new() };
            return Err(TilerError::Internal(format!(
                "{}: tile ({plane}level {level}, x {}, y {}) was never written",
                self.path.shown(),
                i % c as usize,
                i / c as usize
            )));
        }
        if self.staging.is_some() {
            return self.finish_cog();
        }
        let levels = self.spec.level_count() as usize;
        let planes = self.spec.planes();
        // Plane by plane, level 0 first: plane `p`'s level `k` is IFD `p * levels + k`.
        let mut ifds: Vec<Ifd> = (0..planes)
            .flat_map(|p| (0..levels).map(move |k| (p, k as u32)))
            .map(|(p, k)| self.level_ifd(p, k))
            .collect();
        let planes = planes as usize;
        ifds.extend(self.associated.iter().map(|image| associated::ifd(image, self.signature())));
        self.tiles = Vec::new();
        let sub_ifds = self.spec.flavour == Flavour::Ome && levels > 1;
        if sub_ifds {
            for main in ifds.iter_mut().take(planes * levels).step_by(levels) {
                main.set(tag::SUB_IFDS, Value::Ifds(vec![0; levels - 1]));
            }
        }
        // Lay the IFDs out, level 0 first, each at a multiple of 8.
        let mut offsets = Vec::with_capacity(ifds.len());
        let mut at = self.len.next_multiple_of(8);
        for ifd in &ifds {
            offsets.push(at);
            at = (at + ifd.encoded_len(self.big)).next_multiple_of(8);
        }
        if !self.big && at > u32::MAX as u64 {
            return Err(TilerError::Limit(format!(
                "{}: the file passed 4 GiB, more than a classic TIFF's bound said; write BigTIFF",
                self.path.shown()
            )));
        }
        if sub_ifds {
            for (p, main) in ifds.iter_mut().take(planes * levels).step_by(levels).enumerate() {
                if let Some(Value::Ifds(v)) = main.get_mut(tag::SUB_IFDS) {
                    v.copy_from_slice(&offsets[p * levels + 1..][..levels - 1]);
                }
            }
        }
        for (k, ifd) in ifds.iter().enumerate() {
            // The generic pyramid chains every level, then its associated images; OME's
            // reduced levels hang off their plane's level 0, and the planes' level 0s are
            // chained, then the associated images.
            let next = match self.spec.flavour {
                // (A COG is finished by `finish_cog`, chained likewise.)
                Flavour::Generic | Flavour::Cog => offsets.get(k + 1).copied().unwrap_or(0),
                Flavour::Ome if k >= planes * levels => offsets.get(k + 1).copied().unwrap_or(0),
                Flavour::Ome if k % levels == 0 => offsets.get(k + levels).copied().unwrap_or(0),
                Flavour::Ome => 0,
            };
            let pad = (offsets[k] - self.len) as usize;
            let bytes = ifd.encode(offsets[k], next, self.big);
            self.file.write_all(&vec![0; pad]).map_err(write_err(&self.path))?;
            self.file.write_all(&bytes).map_err(write_err(&self.path))?;
            self.len = offsets[k] + bytes.len() as u64;
        }
        let TiffWriter { path, file, spec, big, len, tile_bytes, .. } = self;
        let mut file = file.into_inner().map_err(|e| TilerError::write(&path, e.into_error()))?;
        let first = offsets[0];
        let patched = if big {
            file.seek(SeekFrom::Start(8)).and_then(|_| file.write_all(&first.to_le_bytes()))
        } else {
            file.seek(SeekFrom::Start(4)).and_then(|_| file.write_all(&(first as u32).to_le_bytes()))
        };
        patched.and_then(|()| file.sync_all()).map_err(write_err(&path))?;
        Ok(summary(&spec, big, tile_bytes, len))
    }

    /// A COG's file, written whole now that every tile's length is known (`cog.rs`): the
    /// header, GDAL's ghost area, the IFDs (level 0 first, chained), then the staged tiles
    /// copied in the file's order, the coarsest level first, each level's row by row, each
    /// tile framed by its leader and trailer.
    fn finish_cog(mut self) -> Result<TiffSummary> {
        let big = self.big;
        let levels = self.spec.level_count() as usize;
        let mut ifds: Vec<Ifd> = (0..levels).map(|k| self.level_ifd(0, k as u32)).collect();
        // The IFDs' lengths do not depend on the offsets they hold: lay them out, then the data.
        let mut at = cog::first_ifd_at(big);
        let mut offsets = Vec::with_capacity(levels);
        for ifd in &ifds {
            offsets.push(at);
            at += ifd.encoded_len(big);
        }
        let data_at = at;
        for k in (0..levels).rev() {
            let tiles = self.level_tiles(0, k as u32);
            let Some(Value::Offsets(v)) = ifds[k].get_mut(tag::TILE_OFFSETS) else {
                return Err(TilerError::Internal("a COG level without its tile offsets".into()));
            };
            for (offset, &(_, len)) in v.iter_mut().zip(tiles) {
                *offset = at + 4;
                at += len + cog::FRAMING;
            }
        }
        if !big && at > u32::MAX as u64 {
            return Err(TilerError::Limit(format!(
                "{}: the file passed 4 GiB, more than a classic TIFF's bound said; write BigTIFF",
                self.path.shown()
            )));
        }
        let path = self.path.clone();
        let mut head = header(big, offsets[0]);
        head.extend(cog::ghost_area());
        head.resize(offsets[0] as usize, 0);
        self.file.write_all(&head).map_err(write_err(&path))?;
        for (k, ifd) in ifds.iter().enumerate() {
            let next = offsets.get(k + 1).copied().unwrap_or(0);
            self.file.write_all(&ifd.encode(offsets[k], next, big)).map_err(write_err(&path))?;
        }
        drop(ifds);
        let staging = self.staging.take().ok_or_else(|| TilerError::Internal("a COG without its tiles".into()))?;
        let TiffWriter { file, spec, tile_bytes, tiles, bases, .. } = self;
        let mut file = file.into_inner().map_err(|e| TilerError::write(&path, e.into_error()))?;
        // The tiles in the file's order: the coarsest level first, each level's row by row.
        let ranges = (0..levels).rev().flat_map(|k| {
            let end = bases.get(k + 1).copied().unwrap_or(tiles.len());
            tiles[bases[k]..end].iter().copied()
        });
        let copied = cog::assemble(staging, &mut file, ranges).map_err(write_err(&path))?;
        if data_at + copied != at {
            return Err(TilerError::Internal(format!(
                "{}: {copied} bytes of tiles copied where {} were laid out",
                path.shown(),
                at - data_at
            )));
        }
        file.sync_all().map_err(write_err(&path))?;
        Ok(summary(&spec, big, tile_bytes, at))
    }

    /// Where plane `p`'s level `k` starts in the index.
    /// JPEG `tile` of IFD `ifd` without its tables where they are the IFD's shared ones (the
    /// first tile's become them); `None`: stored whole (no tables, or others).
    fn abbreviate(&mut self, ifd: usize, tile: &[u8]) -> Option<Vec<u8>> {
        let (tables, rest) = crate::source::stored::split_tables(tile).filter(|(t, _)| !t.is_empty())?;
        let shared = self.tables[ifd].get_or_insert_with(|| tables.clone());
        (*shared == tables).then_some(rest)
    }

    fn base(&self, p: u32, k: u32) -> usize {
        self.bases[(p * self.spec.level_count() + k) as usize]
    }

    /// The `Software` tag's value, the signature: in a COG, whose header is followed by GDAL's
    /// ghost area, the text itself, which the IFD's value area holds near its start (the tags
    /// before it have small values); elsewhere the copy after the header.
    fn signature(&self) -> Value {
        match self.spec.flavour {
            Flavour::Cog => Value::Ascii(SIGNATURE.into()),
            _ => Value::AsciiAt { offset: SIGNATURE_AT, count: SIGNATURE.len() as u64 + 1 },
        }
    }

    /// Plane `p`'s level `k`'s tiles in the index, row by row.
    fn level_tiles(&self, p: u32, k: u32) -> &[(u64, u64)] {
        let (c, r) = self.spec.level(k).grid();
        &self.tiles[self.base(p, k)..][..c as usize * r as usize]
    }

    /// Plane `p`'s level `k`'s IFD, its tiles' offsets and byte counts from the index.
    fn level_ifd(&self, p: u32, k: u32) -> Ifd {
        let s = &self.spec;
        let level = s.level(k);
        let (w, h) = (level.width, level.height);
        let spp = s.stored.channels.count();
        let mut ifd = Ifd::default();
        ifd.set(tag::NEW_SUBFILE_TYPE, Value::Long(vec![u32::from(k > 0)]));
        ifd.set(tag::IMAGE_WIDTH, Value::Long(vec![w]));
        ifd.set(tag::IMAGE_LENGTH, Value::Long(vec![h]));
        ifd.set(tag::BITS_PER_SAMPLE, Value::Short(vec![s.stored.depth.bytes() as u16 * 8; spp]));
        ifd.set(tag::COMPRESSION, Value::Short(vec![s.compression.code()]));
        ifd.set(tag::PHOTOMETRIC, Value::Short(vec![s.photometric()]));
        if (p, k) == (0, 0) && s.flavour == Flavour::Ome {
            ifd.set(tag::IMAGE_DESCRIPTION, Value::Ascii(ome::xml(s, &self.associated)));
        }
        ifd.set(tag::SAMPLES_PER_PIXEL, Value::Short(vec![spp as u16]));
        if let Some(size) = s.pixel_size {
            // Pixels a centimetre at this level: 2^k times fewer in our pyramid; a copied
            // level's pixels as much larger as it is narrower than the full resolution.
            let scale = match s.copied.is_empty() {
                true => (1u64 << k) as f64,
                false => f64::from(s.level(0).width) / f64::from(w),
            };
            let per_cm = rational(10_000.0 / (size.0 * scale));
            ifd.set(tag::X_RESOLUTION, Value::Rational(vec![per_cm]));
            ifd.set(tag::Y_RESOLUTION, Value::Rational(vec![per_cm]));
            ifd.set(tag::RESOLUTION_UNIT, Value::Short(vec![3]));
        }
        ifd.set(tag::PLANAR_CONFIGURATION, Value::Short(vec![1]));
        ifd.set(tag::SOFTWARE, self.signature());
        match s.predictor() {
            RowFilter::None => {}
            RowFilter::Delta => ifd.set(tag::PREDICTOR, Value::Short(vec![2])),
            RowFilter::FloatingPoint => ifd.set(tag::PREDICTOR, Value::Short(vec![3])),
        }
        if let Some(tables) = &self.tables[(p * s.level_count() + k) as usize] {
            ifd.set(tag::JPEG_TABLES, Value::Undefined([&[0xFF, 0xD8], &tables[..], &[0xFF, 0xD9]].concat()));
        }
        ifd.set(tag::TILE_WIDTH, Value::Long(vec![level.tile.0]));
        ifd.set(tag::TILE_LENGTH, Value::Long(vec![level.tile.1]));
        let tiles = self.level_tiles(p, k);
        ifd.set(tag::TILE_OFFSETS, Value::Offsets(tiles.iter().map(|t| t.0).collect()));
        ifd.set(tag::TILE_BYTE_COUNTS, Value::Offsets(tiles.iter().map(|t| t.1).collect()));
        // A GeoTIFF source's tags, as they were: level 0 is the source's grid. As GDAL writes
        // its overviews, the reduced levels repeat only the no-data value (GDAL derives their
        // transform from their size).
        for (t, value) in &s.geo {
            if k == 0 || *t == crate::source::tiff::geo::tag::GDAL_NODATA {
                let value = match value {
                    GeoValue::Shorts(v) => Value::Short(v.clone()),
                    GeoValue::Doubles(v) => Value::Double(v.clone()),
                    GeoValue::Ascii(v) => Value::Ascii(v.clone()),
                };
                ifd.set(*t, value);
            }
        }
        if let Some(icc) = &s.icc {
            ifd.set(tag::ICC_PROFILE, Value::Undefined(icc.clone()));
        }
        if s.stored.channels.has_alpha() {
            // Unassociated alpha: the samples are not premultiplied.
            ifd.set(tag::EXTRA_SAMPLES, Value::Short(vec![2]));
        }
        let format = if matches!(s.stored.depth, Depth::F32 | Depth::F16) { 3 } else { 1 };
        ifd.set(tag::SAMPLE_FORMAT, Value::Short(vec![format; spp]));
        if let Compression::Jpeg { subsampling } = s.compression
            && s.photometric() == 6
        {
            let factor = u16::from(subsampling.factor());
            ifd.set(tag::YCBCR_SUBSAMPLING, Value::Short(vec![factor, factor]));
            let white = [(0, 1), (255, 1), (128, 1), (255, 1), (128, 1), (255, 1)];
            ifd.set(tag::REFERENCE_BLACK_WHITE, Value::Rational(white.to_vec()));
        }
        ifd
    }
}

/// The header: "II", 42 and the first IFD's offset (classic), or "II", 43, 8, 0 and a 64-bit
/// offset (BigTIFF).
fn header(big: bool, first_ifd: u64) -> Vec<u8> {
    let mut head = Vec::with_capacity(16);
    head.extend(b"II");
    if big {
        head.extend(43u16.to_le_bytes());
        head.extend(8u16.to_le_bytes());
        head.extend(0u16.to_le_bytes());
        head.extend(first_ifd.to_le_bytes());
    } else {
        head.extend(42u16.to_le_bytes());
        head.extend((first_ifd as u32).to_le_bytes());
    }
    head
}

/// What a finished file of `spec` holds.
fn summary(spec: &Spec, big: bool, tile_bytes: u64, file_bytes: u64) -> TiffSummary {
    TiffSummary {
        flavour: spec.flavour,
        bigtiff: big,
        levels: spec.level_count(),
        planes: spec.planes(),
        tiles: spec.total_tiles(),
        tile_bytes,
        file_bytes,
        compression: spec.compression.name(),
        levels_copied: !spec.copied.is_empty(),
        levels_declined: None,
        associated: Vec::new(),
        associated_left_out: spec.associated_left_out,
    }
}

/// `value` as a TIFF rational, to 6 significant figures or as near as 32 bits allow.
fn rational(value: f64) -> (u32, u32) {
    for den in [1_000_000u32, 1000, 1] {
        let num = (value * den as f64).round();
        if num >= 1.0 && num <= u32::MAX as f64 {
            return (num as u32, den);
        }
    }
    if value < 1.0 { (1, u32::MAX) } else { (u32::MAX, 1) }
}
