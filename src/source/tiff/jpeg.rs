//! JPEG inside TIFF (Compression 7, "new-style" JPEG of TIFF Technical Note 2), tiled or in
//! strips, as libtiff, libvips, GDAL and slide scanners write it: each tile or strip is a JPEG
//! stream, usually abbreviated (its quantisation and Huffman tables kept once in the
//! JPEGTables tag and spliced back in here), holding YCbCr (subsampled or not), RGB or grey.
//!
//! Read one row of tiles (or a group of strips) at a time, the chunks of a band decoded in
//! parallel on the rayon pool by libjpeg-turbo ([`libjpeg`]), each straight from the file with a
//! positioned read. Only the chunks under the columns asked for are decoded. While the rows of
//! one band are read, the next is decoded on the pool ([`band_ahead`]), where two bands take
//! at most a quarter of `--max-memory`; that decoding is the run's `decode` stage
//! ([`RowSource::decoding`]). Memory: one band of decoded texels (two, decoding ahead) plus a
//! compressed chunk per worker, checked against `--max-memory` before anything is allocated.
//! A damaged or missing chunk is an error naming the file and the chunk's column and row.

use std::fs::File;
use std::io::BufReader;
use std::ops::Range;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use rayon::prelude::*;
use tiff::decoder::{ChunkType, Decoder};
use tiff::tags::Tag;

use super::band_ahead::{self, BandAhead};
use super::libjpeg::{self, Colour, Extent};
use super::{Pages, open_error};
use crate::error::{Result, TilerError};
use crate::pixel::{Channels, Depth, PixelLayout};
use crate::source::stored::{self, Quality, Samples, StoredLevel, StoredLevels, StoredTiles};
use crate::source::{Decoding, ImageHeader, LossyStep, RowSource};
use crate::stages::TaskClock;

/// Chunk rows decoded together when the TIFF is in strips: enough strips to keep every core
/// busy (libtiff writes JPEG strips of 8 or 16 rows), within an eighth of `--max-memory`.
const STRIPS_PER_CORE: usize = 4;

/// Where an image's JPEG chunks are and how they are laid out: what decoding a band needs,
/// shared with the task that decodes the next band ahead.
struct Source {
    chunks: Arc<Chunks>,
    width: u32,
    height: u32,
    colour: Colour,
    /// Texels of one chunk as the TIFF lays it out (a strip is as wide as the image).
    chunk_w: u32,
    chunk_h: u32,
    across: u32,
    tiled: bool,
    /// Chunk rows held in one band.
    group: u32,
    /// The tasks' decoding time.
    clock: TaskClock,
}

pub(super) struct JpegTiff {
    source: Arc<Source>,
    /// The decoded chunks of the band, `[chunk row in band * across + column]`, each its
    /// texels inside the image only; those outside the columns read are left empty.
    band: Vec<Vec<u8>>,
    band_first: u64,
    band_rows: u64,
    /// The next band, decoding on the pool; `None` where two bands would take more than a
    /// quarter of `--max-memory`.
    ahead: Option<BandAhead>,
    columns: Option<Range<u32>>,
    next: u64,
    failed: bool,
    /// What the summary line says before the chunking (file kind, page, vendor).
    label: String,
    /// The orientation and ICC profile of the image's directory.
    embedded: crate::source::Embedded,
    /// Its page in the file, and its reduced levels'.
    pages: Pages,
}

/// Where the compressed chunks are, shared with the [`StoredTiles`] a run copies them through.
struct Chunks {
    path: PathBuf,
    file: File,
    file_len: u64,
    offsets: Vec<u64>,
    counts: Vec<u64>,
    /// The JPEGTables marker segments (no SOI/EOI), empty where each chunk is complete.
    tables: Vec<u8>,
}

impl Chunks {
    /// Chunk `index`'s complete JPEG stream (the shared tables spliced in); `name` says which
    /// chunk in an error.
    fn stream(&self, index: usize, name: &str) -> std::result::Result<Vec<u8>, String> {
        let (offset, count) = (self.offsets[index], self.counts[index]);
        if count == 0 {
            return Err(format!("{name} is missing (its byte count is 0)"));
        }
        if offset.checked_add(count).is_none_or(|end| end > self.file_len) {
            return Err(format!(
                "{name} lies past the end of the file ({count} bytes at {offset}, the file has {}): a truncated file?",
                self.file_len
            ));
        }
        let mut compressed = vec![0u8; count as usize];
        self.file.read_exact_at(&mut compressed, offset).map_err(|e| format!("{name}: cannot be read: {e}"))?;
        // A JPEG ends at its EOI: a byte after it pads the chunk to an even length (as DICOM
        // pads every fragment) and is no part of the stream.
        if compressed.ends_with(&[0xFF, 0xD9, 0x00]) {
            compressed.pop();
        }
        if self.tables.is_empty() {
            return match compressed.starts_with(&[0xFF, 0xD8]) {
                true => Ok(compressed),
                false => Err(format!("{name}: the data does not start with a JPEG SOI marker")),
            };
        }
        let mut stream = Vec::new();
        libjpeg::splice(&self.tables, &compressed, &mut stream).map_err(|m| format!("{name}: {m}"))?;
        Ok(stream)
    }
}

/// Whether the current image is JPEG-compressed (new-style, Compression 7).
pub(super) fn is_jpeg(path: &Path, decoder: &mut Decoder<BufReader<File>>) -> Result<bool> {
    Ok(super::reader_of(super::compression_code(path, decoder)?) == Some(super::Reader::Jpeg))
}

pub(super) fn open(
    path: &Path,
    decoder: &mut Decoder<BufReader<File>>,
    label: String,
    embedded: crate::source::Embedded,
    pages: Pages,
) -> Result<Box<dyn RowSource>> {
    let (width, height) = super::dimensions(path, decoder)?;
    let colour = colour(path, decoder)?;
    let tiled = decoder.get_chunk_type() == ChunkType::Tile;
    let (chunk_w, chunk_h) = if tiled {
        tile_size(path, decoder)?
    } else {
        let (_, rows) = decoder.chunk_dimensions();
        // RowsPerStrip is often 2^32-1 ("one strip"): clamp it to the image.
        (width, rows.clamp(1, height))
    };
    let (offsets, counts, tables) = chunk_tags(path, decoder, tiled)?;
    let grid = Grid { size: (width, height), chunk: (chunk_w, chunk_h), tiled, offsets, counts, tables };
    assemble(path, grid, colour, label, embedded, pages)
}

/// Where a grid of JPEG chunks lies in a file, whatever the container: a TIFF's tags or a
/// DICOM instance's encapsulated frames.
pub(crate) struct Grid {
    /// The image's texels across and down.
    pub size: (u32, u32),
    /// One chunk's texels across and down (a strip is as wide as the image).
    pub chunk: (u32, u32),
    /// Tiles (copied where they fit), not strips.
    pub tiled: bool,
    /// Each chunk's bytes in the file, row-major; a count of 0 is a missing chunk.
    pub offsets: Vec<u64>,
    pub counts: Vec<u64>,
    /// Shared table segments spliced into every chunk (no SOI/EOI), or empty.
    pub tables: Vec<u8>,
}

/// The row source of `grid`'s JPEG chunks in `path`, their samples `colour`, checked against
/// `max_memory` before anything is allocated: a TIFF's JPEG tiles or strips, and a DICOM
/// instance's JPEG baseline frames (`source::dicom`).
pub(crate) fn assemble(
    path: &Path,
    grid: Grid,
    colour: Colour,
    label: String,
    mut embedded: crate::source::Embedded,
    pages: Pages,
) -> Result<Box<dyn RowSource>> {
    let max_memory = pages.max_memory;
    let Grid { size: (width, height), chunk: (chunk_w, chunk_h), tiled, offsets, counts, tables } = grid;
    if width == 0 || height == 0 || chunk_w == 0 || chunk_h == 0 {
        let what = format!("a {width}x{height} image of {chunk_w}x{chunk_h} JPEG chunks");
        return Err(TilerError::decode(path, format!("{what}: nothing to read")));
    }
    let across = width.div_ceil(chunk_w);
    let down = height.div_ceil(chunk_h);
    let chunks = across as u64 * down as u64;
    super::enough_chunks(path, &offsets, &counts, chunks, tiled)?;
    // The chunks' JPEG coding is a lossy step (a file that states its history, a DICOM
    // instance, keeps its own).
    if embedded.lossy.is_empty() {
        let compressed = counts.iter().take(chunks as usize).fold(0u64, |sum, &c| sum.saturating_add(c));
        let samples = colour.components();
        embedded.lossy = LossyStep::of(LossyStep::JPEG, (width, height), samples, compressed);
    }
    // One band of decoded texels: a row of tiles, or a group of strips.
    let row_bytes = width as u64 * colour.components() as u64;
    let band_bytes = |group: u64| row_bytes.saturating_mul(chunk_h as u64).saturating_mul(group);
    let group = if tiled {
        1
    } else {
        let cores = std::thread::available_parallelism().map_or(1, |n| n.get()) as u64;
        let fits = (max_memory / 8) / band_bytes(1).max(1);
        (cores * STRIPS_PER_CORE as u64).min(fits).min(down as u64).max(1)
    };
    // Plus, while a band is decoded, a compressed chunk twice and a scanline per worker.
    // (A byte count past the end of the file is reported with its chunk when it is read.)
    let file = File::open(path).map_err(|e| TilerError::io(path, e))?;
    let file_len = file.metadata().map_err(|e| TilerError::io(path, e))?.len();
    let largest = counts.iter().take(chunks as usize).copied().max().unwrap_or(0).min(file_len);
    let workers = std::thread::available_parallelism().map_or(1, |n| n.get()) as u64;
    let per_worker = largest.saturating_mul(2).saturating_add(row_bytes); // read, spliced, a scanline
    let need = band_bytes(group).saturating_add(workers.saturating_mul(per_worker));
    // The next band decoded ahead where both fit a quarter of the budget: the pyramid's own
    // bands take about as much as the source's, and the rest is theirs and the tiles'.
    let ahead = need.saturating_add(band_bytes(group)) <= max_memory / 4;
    if need > max_memory {
        let what = if tiled {
            format!("a row of {chunk_w}x{chunk_h} JPEG tiles")
        } else {
            format!("a JPEG strip of {chunk_h} rows")
        };
        return Err(TilerError::unsupported(
            path,
            format!(
                "{what} of the {width}x{height} image ({} MiB decoded) would have to be held in memory, more than --max-memory ({} MiB); raise --max-memory or re-save it tiled (e.g. `vips tiffsave in.tif out.tif --tile --compression jpeg`)",
                need.div_ceil(1 << 20),
                max_memory >> 20
            ),
        ));
    }
    let chunks = Arc::new(Chunks { path: path.to_path_buf(), file, file_len, offsets, counts, tables });
    let clock = TaskClock::default();
    Ok(Box::new(JpegTiff {
        source: Arc::new(Source {
            chunks,
            width,
            height,
            colour,
            chunk_w,
            chunk_h,
            across,
            tiled,
            group: group as u32,
            clock,
        }),
        band: Vec::new(),
        band_first: 0,
        band_rows: 0,
        ahead: ahead.then(BandAhead::default),
        columns: None,
        next: 0,
        failed: false,
        label,
        embedded,
        pages,
    }))
}

/// The current directory's tile size, which JPEG tiles need in multiples of 8.
fn tile_size(path: &Path, decoder: &Decoder<BufReader<File>>) -> Result<(u32, u32)> {
    let (tw, th) = decoder.chunk_dimensions();
    if tw == 0 || th == 0 || tw % 8 != 0 || th % 8 != 0 {
        return Err(TilerError::decode(path, format!("the JPEG TIFF declares {tw}x{th} tiles (not multiples of 8)")));
    }
    Ok((tw, th))
}

/// The chunks' offsets and byte counts and the JPEGTables marker segments (no SOI/EOI; empty
/// where each chunk is complete) of the current directory.
fn chunk_tags(
    path: &Path,
    decoder: &mut Decoder<BufReader<File>>,
    tiled: bool,
) -> Result<(Vec<u64>, Vec<u64>, Vec<u8>)> {
    let tag_err = |e| open_error(path, e);
    let (offset_tag, count_tag) =
        if tiled { (Tag::TileOffsets, Tag::TileByteCounts) } else { (Tag::StripOffsets, Tag::StripByteCounts) };
    let offsets = decoder.get_tag_u64_vec(offset_tag).map_err(tag_err)?;
    let counts = decoder.get_tag_u64_vec(count_tag).map_err(tag_err)?;
    let tables = match decoder.find_tag(Tag::JPEGTables).map_err(tag_err)? {
        None => Vec::new(),
        Some(_) => {
            let raw = decoder.get_tag_u8_vec(Tag::JPEGTables).map_err(tag_err)?;
            let body = libjpeg::tables_body(&raw).ok_or_else(|| {
                TilerError::decode(path, "corrupt TIFF: JPEGTables does not start with a JPEG SOI marker")
            })?;
            body.to_vec()
        }
    };
    Ok((offsets, counts, tables))
}

/// The colour the JPEG chunks hold, from PhotometricInterpretation and SamplesPerPixel.
fn colour(path: &Path, decoder: &mut Decoder<BufReader<File>>) -> Result<Colour> {
    let tag_err = |e| open_error(path, e);
    let photometric: Option<u16> = decoder.find_tag_unsigned(Tag::PhotometricInterpretation).map_err(tag_err)?;
    let samples: u16 = decoder.find_tag_unsigned(Tag::SamplesPerPixel).map_err(tag_err)?.unwrap_or(1);
    let bits: Vec<u16> = decoder.find_tag_unsigned_vec(Tag::BitsPerSample).map_err(tag_err)?.unwrap_or_else(|| vec![1]);
    let planar: u16 = decoder.find_tag_unsigned(Tag::PlanarConfiguration).map_err(tag_err)?.unwrap_or(1);
    let refuse = |what: String| {
        Err(TilerError::unsupported(
            path,
            format!("{what} is not supported in a JPEG-compressed TIFF (8-bit grey, YCbCr and RGB are)"),
        ))
    };
    if bits.iter().any(|&b| b != 8) {
        return refuse(format!("{}-bit JPEG", bits.first().copied().unwrap_or(0)));
    }
    if planar != 1 && samples > 1 {
        return refuse("one JPEG stream per colour plane (PlanarConfiguration 2)".into());
    }
    let colour = match photometric {
        Some(0 | 1) => Colour::Grey,
        Some(2) => Colour::Rgb,
        Some(6) => Colour::YCbCr,
        Some(5) => return refuse("CMYK".into()),
        Some(other) => return refuse(format!("photometric interpretation {other}")),
        None => return Err(TilerError::decode(path, "the TIFF has no PhotometricInterpretation tag")),
    };
    if photometric == Some(0) {
        return refuse("WhiteIsZero grey".into());
    }
    if samples as usize != colour.components() {
        return refuse(format!("{samples} samples per texel ({colour:?} with extra samples)"));
    }
    Ok(colour)
}

impl Source {
    fn layout(&self) -> PixelLayout {
        let channels = if self.colour == Colour::Grey { Channels::Grey } else { Channels::Rgb };
        PixelLayout::new(channels, Depth::U8)
    }

    /// The chunk at `col`, `row` (in chunks): its texels inside the image.
    fn extent(&self, row: u32, col: u32) -> Extent {
        chunk_extent((self.chunk_w, self.chunk_h), (self.width, self.height), col, row)
    }

    /// Sizes `band`'s buffers for the band `key`: each chunk under its columns exactly to its
    /// texels inside the image (never more, whatever band the buffer held before), the others
    /// emptied. Their capacity in bytes.
    fn size_band(&self, key: &band_ahead::Key, band: &mut Vec<Vec<u8>>) -> u64 {
        let first = key.first_row;
        let chunk_rows = (self.height as u64 - first).div_ceil(self.chunk_h as u64).min(self.group as u64) as u32;
        band.resize_with((chunk_rows * self.across) as usize, Vec::new);
        for (i, texels) in band.iter_mut().enumerate() {
            let (r, c) = (i as u32 / self.across, i as u32 % self.across);
            let len = match key.columns.contains(&c) {
                true => {
                    let extent = self.extent(key.first_chunk_row + r, c);
                    extent.columns * extent.rows * self.colour.components()
                }
                false => 0,
            };
            if texels.len() != len {
                texels.clear();
                texels.reserve_exact(len);
                texels.resize(len, 0);
            }
        }
        band.iter().map(|texels| texels.capacity() as u64).sum()
    }

    /// Decodes the chunks of the band `key` under its columns into `band` (sized by
    /// [`size_band`](Self::size_band)), in parallel on the pool. A chunk that fails is
    /// reported with its own first row, not the band's.
    fn decode_band(&self, key: &band_ahead::Key, band: &mut [Vec<u8>]) -> std::result::Result<(), (u64, String)> {
        band.par_iter_mut().enumerate().try_for_each(|(i, texels)| {
            let (r, c) = (i as u32 / self.across, i as u32 % self.across);
            if !key.columns.contains(&c) {
                return Ok(());
            }
            let row = key.first_chunk_row + r;
            let decoded = self.clock.time(|| self.decode_chunk(row, c, texels));
            decoded.map_err(|m| (row as u64 * self.chunk_h as u64, m))
        })
    }

    /// The texels of the chunk at `col`, `row` (in chunks) inside the image, into `texels`.
    fn decode_chunk(&self, row: u32, col: u32, texels: &mut [u8]) -> std::result::Result<(), String> {
        let index = row as usize * self.across as usize + col as usize;
        let name = match self.tiled {
            true => tile_name(col, row, index),
            false => format!("JPEG strip {row}"),
        };
        let stream = self.chunks.stream(index, &name)?;
        libjpeg::decode(&stream, self.colour, self.extent(row, col), texels).map_err(|m| format!("{name}: {m}"))
    }
}

impl JpegTiff {
    /// The band whose first image row is `first`, under the columns read.
    fn key(&self, first: u64) -> band_ahead::Key {
        let s = &self.source;
        let columns = match &self.columns {
            Some(c) => c.start / s.chunk_w..c.end.div_ceil(s.chunk_w),
            None => 0..s.across,
        };
        band_ahead::Key { first_chunk_row: (first / s.chunk_h as u64) as u32, first_row: first, columns }
    }

    /// Makes the band holding image row `y` the one read: the band decoded ahead if it is
    /// that one, else decoded now (in parallel, this thread waiting). Then starts the next
    /// band's decoding on the pool, where it decodes ahead.
    fn load_band(&mut self, y: u64) -> std::result::Result<(), (u64, String)> {
        let source = Arc::clone(&self.source);
        let band_h = source.chunk_h as u64 * source.group as u64;
        let first = y / band_h * band_h;
        let key = self.key(first);
        let taken = match &mut self.ahead {
            Some(ahead) => ahead.take(&key),
            None => Err(Vec::new()),
        };
        // The buffers of the band read until now are reused, for this band or the next.
        let done = std::mem::take(&mut self.band);
        let (band, result, spare) = match taken {
            Ok((band, result)) => (band, result, done),
            Err(spare) => {
                let mut band = done;
                source.size_band(&key, &mut band);
                let result = source.decode_band(&key, &mut band);
                (band, result, spare)
            }
        };
        self.band = band;
        result?;
        self.band_first = first;
        self.band_rows = band_h.min(source.height as u64 - first);
        let next = first + band_h;
        if next < source.height as u64 && BandAhead::possible() {
            let next = self.key(next);
            if let Some(ahead) = &mut self.ahead {
                let mut buffers = spare;
                let bytes = source.size_band(&next, &mut buffers);
                ahead.start(next.clone(), buffers, bytes, move |band| source.decode_band(&next, band));
            }
        }
        Ok(())
    }
}

impl RowSource for JpegTiff {
    fn header(&self) -> ImageHeader {
        let s = &self.source;
        ImageHeader { width: s.width, height: s.height, layout: s.layout() }
    }

    /// The band's decoded chunks, and the next band's decoding ahead. (The compressed chunk
    /// each worker reads is freed as soon as it is decoded, and not counted.)
    fn buffer_bytes(&self) -> u64 {
        let band: u64 = self.band.iter().map(|chunk| chunk.capacity() as u64).sum();
        band + self.ahead.as_ref().map_or(0, BandAhead::bytes)
    }

    /// A band of whole chunks, two where the next is decoded ahead: each is sized to its
    /// texels inside the image, never more.
    fn most_buffer_bytes(&self) -> u64 {
        let s = &self.source;
        let chunk = s.chunk_w as u64 * s.chunk_h as u64 * s.colour.components() as u64;
        let bands = 1 + self.ahead.is_some() as u64;
        (bands * s.group as u64 * s.across as u64).saturating_mul(chunk)
    }

    fn decoding(&self) -> Decoding {
        self.source.clock.total()
    }

    fn embedded(&self) -> crate::source::Embedded {
        self.embedded.clone()
    }

    fn read_row(&mut self, out: &mut [u8]) -> Result<()> {
        let y = self.next;
        let s = Arc::clone(&self.source);
        let fail = |message: String| TilerError::DecodeRow { path: s.chunks.path.clone(), row: y, message };
        let columns = self.columns.clone().unwrap_or(0..s.width);
        let pixel = s.colour.components();
        super::check_row(y, s.height, &columns, pixel, out.len()).map_err(fail)?;
        if self.failed {
            return Err(fail("an earlier JPEG tile or strip failed to decode".into()));
        }
        let loaded = self.band_first..self.band_first + self.band_rows;
        if !loaded.contains(&y)
            && let Err((row, message)) = self.load_band(y)
        {
            self.failed = true;
            return Err(TilerError::DecodeRow { path: s.chunks.path.clone(), row, message });
        }
        // The row's part of each chunk under the columns.
        let within = y - self.band_first;
        let (chunk_row, chunk_y) = ((within / s.chunk_h as u64) as usize, (within % s.chunk_h as u64) as usize);
        let chunks = &self.band[chunk_row * s.across as usize..];
        copy_row(chunks, s.chunk_w, s.width, pixel, chunk_y, columns, out);
        self.next += 1;
        Ok(())
    }

    /// Chunks are found by row: the next read loads the band it needs.
    fn skip_rows(&mut self, rows: u32) -> Result<()> {
        self.next += rows as u64;
        Ok(())
    }

    /// Only the chunks under the columns are decoded (tiles; a strip is always whole).
    fn read_columns(&mut self, columns: Range<u32>) -> bool {
        let columns = (columns != (0..self.source.width)).then_some(columns);
        if columns != self.columns {
            // The loaded band may lack the chunks under the new columns.
            (self.columns, self.band_rows) = (columns, 0);
        }
        true
    }

    /// The tiles, to copy where the output's pages line up with them (strips never do).
    fn stored_tiles(&self) -> Option<Arc<dyn StoredTiles>> {
        let s = &self.source;
        let tiles = JpegTiles::new(&s.chunks, s.colour, (s.chunk_w, s.chunk_h), (s.width, s.height));
        s.tiled.then(|| Arc::new(tiles) as Arc<dyn StoredTiles>)
    }

    /// The tiles decoded at half size: what their texels are, as `read_row` decodes them.
    fn halved(&self) -> Option<Box<dyn RowSource>> {
        let tiles = self.stored_tiles()?;
        let path = &self.source.chunks.path;
        Some(Box::new(crate::source::halved::Halved::new(path, tiles, self.header(), self.embedded())))
    }

    /// This page and its reduced levels, where it has some, each as its JPEG tiles.
    fn stored_levels(&self) -> Result<Option<StoredLevels>> {
        let Some(full) = self.stored_tiles().filter(|_| !self.pages.levels.is_empty()) else { return Ok(None) };
        let path = &self.source.chunks.path;
        let (width, height, page) = (self.source.width, self.source.height, self.pages.index);
        let mut stored = StoredLevels {
            path: path.clone(),
            levels: vec![StoredLevel { width, height, page, tiles: full }],
            unlike: None,
        };
        for (k, &page) in self.pages.levels.iter().enumerate() {
            let k = k + 1;
            match level(path, page, self.pages.max_memory).map_err(|e| stored::in_level(e, k, page))? {
                Ok(level) => stored.levels.push(level),
                Err(why) => {
                    stored.unlike = Some(format!("level {k} (page {page}) {why}"));
                    break;
                }
            }
        }
        Ok(Some(stored))
    }

    fn describe(&self) -> String {
        let s = &self.source;
        let colour = match s.colour {
            Colour::Grey => "grey",
            Colour::YCbCr => "YCbCr",
            Colour::Rgb => "RGB",
        };
        let tables = if s.chunks.tables.is_empty() { "" } else { ", shared tables" };
        let ahead = if self.ahead.is_some() { ", the next decoded ahead" } else { "" };
        let chunks = if s.tiled {
            format!("streamed by tile row ({}x{} tiles, decoded in parallel{ahead})", s.chunk_w, s.chunk_h)
        } else {
            format!("streamed by strip ({} rows, {} strips decoded at once{ahead})", s.chunk_h, s.group)
        };
        format!("{}, jpeg ({colour}{tables}, libjpeg-turbo), {chunks}", self.label)
    }
}

/// Page `page` of `path`, a reduced level, as its JPEG tiles; `Err(why)` where it is not
/// JPEG tiles (strips, another compression).
fn level(path: &Path, page: usize, max_memory: u64) -> Result<std::result::Result<StoredLevel, String>> {
    let mut decoder = super::open_decoder(path, max_memory)?;
    decoder.seek_to_image(page).map_err(|e| open_error(path, e))?;
    if !is_jpeg(path, &mut decoder)? {
        return Ok(Err("is not JPEG-compressed".into()));
    }
    if decoder.get_chunk_type() != ChunkType::Tile {
        return Ok(Err("is stored in strips, not tiles".into()));
    }
    let (width, height) = super::dimensions(path, &mut decoder)?;
    let colour = colour(path, &mut decoder)?;
    let (tw, th) = tile_size(path, &decoder)?;
    let (offsets, counts, tables) = chunk_tags(path, &mut decoder, true)?;
    let tiles = u64::from(width.div_ceil(tw)) * u64::from(height.div_ceil(th));
    super::enough_chunks(path, &offsets, &counts, tiles, true)?;
    let file = File::open(path).map_err(|e| TilerError::io(path, e))?;
    let file_len = file.metadata().map_err(|e| TilerError::io(path, e))?.len();
    let chunks = Arc::new(Chunks { path: path.to_path_buf(), file, file_len, offsets, counts, tables });
    let tiles = Arc::new(JpegTiles::new(&chunks, colour, (tw, th), (width, height)));
    Ok(Ok(StoredLevel { width, height, page, tiles }))
}

/// How a tile is named in errors.
fn tile_name(col: u32, row: u32, index: usize) -> String {
    format!("JPEG tile at column {col}, row {row} (tile {index})")
}

/// The JPEG tiles of a tiled TIFF, handed out as files.
struct JpegTiles {
    chunks: Arc<Chunks>,
    colour: Colour,
    samples: Samples,
    size: (u32, u32),
    /// The image's texels across and down.
    image: (u32, u32),
    across: u32,
    down: u32,
    quality: Option<Quality>,
}

impl JpegTiles {
    /// The `size` tiles of a `width x height` image in `chunks`, holding `colour`.
    fn new(chunks: &Arc<Chunks>, colour: Colour, size: (u32, u32), (width, height): (u32, u32)) -> JpegTiles {
        let samples = match colour {
            Colour::Grey => Samples::Grey,
            Colour::YCbCr => Samples::YCbCr,
            Colour::Rgb => Samples::Rgb,
        };
        // The tables are in JPEGTables, or in each tile: the first tile's say the quality.
        let quality = match chunks.tables.is_empty() {
            false => stored::read_header(&[&[0xFF, 0xD8], &chunks.tables[..]].concat()),
            true => chunks.stream(0, "tile 0").ok().and_then(|s| stored::read_header(&s)),
        }
        .and_then(|h| h.luma_table)
        .map(|t| stored::estimate_quality(&t));
        JpegTiles {
            chunks: Arc::clone(chunks),
            colour,
            samples,
            size,
            image: (width, height),
            across: width.div_ceil(size.0),
            down: height.div_ceil(size.1),
            quality,
        }
    }

    /// Tile (`col`, `row`)'s complete JPEG stream, and its name for messages.
    fn stream(&self, col: u32, row: u32) -> Result<(Vec<u8>, String)> {
        let index = row as usize * self.across as usize + col as usize;
        let name = tile_name(col, row, index);
        if col >= self.across || row >= self.down {
            return Err(TilerError::decode(
                &self.chunks.path,
                format!("{name}: outside the {}x{} tiles", self.across, self.down),
            ));
        }
        let stream = self.chunks.stream(index, &name).map_err(|m| TilerError::decode(&self.chunks.path, m))?;
        Ok((stream, name))
    }
}

impl StoredTiles for JpegTiles {
    fn tile_size(&self) -> (u32, u32) {
        self.size
    }

    fn quality(&self) -> Option<Quality> {
        self.quality
    }

    fn tile(&self, col: u32, row: u32) -> Result<Option<Vec<u8>>> {
        let (stream, _) = self.stream(col, row)?;
        Ok(stored::as_file(&stream, self.samples, self.size))
    }

    fn decodes(&self) -> bool {
        true
    }

    fn decode(&self, col: u32, row: u32, denominator: u32) -> Result<Option<Vec<u8>>> {
        let (stream, name) = self.stream(col, row)?;
        let extent = chunk_extent(self.size, self.image, col, row);
        let d = denominator as usize;
        let mut texels = vec![0; extent.columns.div_ceil(d) * extent.rows.div_ceil(d) * self.colour.components()];
        libjpeg::decode_scaled(&stream, self.colour, extent, denominator, &mut texels)
            .map_err(|m| TilerError::decode(&self.chunks.path, format!("{name}: {m}")))?;
        Ok(Some(texels))
    }
}

/// The chunk at `col`, `row` of a grid of `chunk`-texel chunks over an `image`: its texels
/// inside the image.
fn chunk_extent(chunk: (u32, u32), image: (u32, u32), col: u32, row: u32) -> Extent {
    let (x0, y0) = (col * chunk.0, row as u64 * chunk.1 as u64);
    Extent {
        columns: chunk.0.min(image.0 - x0) as usize,
        rows: (chunk.1 as u64).min(image.1 as u64 - y0) as usize,
        max_columns: chunk.0 as usize,
        max_rows: chunk.1 as usize,
    }
}

/// Copies texel row `chunk_y` of a band's row of decoded chunks (`chunks[col]`, each `chunk_w`
/// wide but the last, of an image `width` wide) under `columns` into `out`.
pub(super) fn copy_row(
    chunks: &[Vec<u8>],
    chunk_w: u32,
    width: u32,
    pixel: usize,
    chunk_y: usize,
    columns: Range<u32>,
    out: &mut [u8],
) {
    for col in columns.start / chunk_w..columns.end.div_ceil(chunk_w) {
        let x0 = col * chunk_w;
        let w = chunk_w.min(width - x0) as usize;
        let row = &chunks[col as usize][chunk_y * w * pixel..][..w * pixel];
        let (from, to) = (columns.start.max(x0), columns.end.min(x0 + w as u32));
        let src = &row[(from - x0) as usize * pixel..(to - x0) as usize * pixel];
        out[(from - columns.start) as usize * pixel..][..src.len()].copy_from_slice(src);
    }
}
