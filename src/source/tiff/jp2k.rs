//! JPEG 2000 inside TIFF, as Aperio writes its SVS slides: each tile a raw J2K codestream,
//! Compression 33003 (the components are Y, Cb, Cr, turned into RGB here as OpenSlide does) or
//! 33005 (R, G, B). Decoded by OpenJPEG (the `jpeg2k` crate over `openjpeg-sys`), one row of
//! tiles at a time, the tiles of a row in parallel on the rayon pool, each read straight from
//! the file. Memory: one row of decoded tiles plus, per worker, a compressed tile and
//! OpenJPEG's 32-bit samples of one tile, checked against `--max-memory` before anything is
//! allocated. A damaged tile, or one whose bytes lie past the end of the file, is an error
//! naming the file and the tile's column and row.

use std::fs::File;
use std::io::BufReader;
use std::os::unix::fs::FileExt;
use std::path::{Path, PathBuf};
use std::sync::Arc;

use tiff::decoder::{ChunkType, Decoder};
use tiff::tags::Tag;

use super::{Pages, open_error};
use crate::error::{Result, TilerError};
use crate::pixel::{Channels, Depth, PixelLayout};
use crate::source::stored::codestream::Codestream;
use crate::source::stored::{self, Coding, Quality, StoredLevel, StoredLevels, StoredTiles};
use crate::source::tile_rows::TileRows;
use crate::source::{Embedded, ImageHeader, LossyStep, RowSource};

/// Whether the image is JPEG 2000 in Aperio's two forms.
pub(super) fn is_jp2k(path: &Path, decoder: &mut Decoder<BufReader<File>>) -> Result<bool> {
    Ok(super::reader_of(super::compression_code(path, decoder)?) == Some(super::Reader::Jpeg2000))
}

pub(super) struct Jp2kTiff {
    path: PathBuf,
    width: u32,
    height: u32,
    /// The components are Y, Cb, Cr (33003), not R, G, B (33005).
    ycbcr: bool,
    chunk_w: u32,
    chunk_h: u32,
    across: u32,
    chunks: Arc<Codestreams>,
    /// The decoded row of tiles (RGB) and where the reader is.
    rows: TileRows,
    label: String,
    embedded: Embedded,
    /// The page read and its reduced levels, for an output that copies them.
    pages: Pages,
}

/// Where a grid's codestreams lie in a file, and the reading of one: the reader decodes them,
/// an output that copies them takes them as they are ([`Jp2kTiles`]).
pub(in crate::source) struct Codestreams {
    path: PathBuf,
    file: File,
    file_len: u64,
    /// Each chunk's bytes in the file, row-major.
    offsets: Vec<u64>,
    counts: Vec<u64>,
    /// The most bytes a chunk may claim: twice its texels' and 64 KiB of headers.
    bound: u64,
    /// Its texels across and down, and what it is (`tile`, `frame`), for messages.
    chunk: (u32, u32),
    what: &'static str,
}

impl Codestreams {
    /// The chunks of `path` at `offsets` and `counts`, each `w x h` texels of `texel_bytes`
    /// bytes once decoded; `what` names one in messages.
    pub(in crate::source) fn new(
        path: &Path,
        (offsets, counts): (Vec<u64>, Vec<u64>),
        (w, h): (u32, u32),
        texel_bytes: u64,
        what: &'static str,
    ) -> Result<Codestreams> {
        let file = File::open(path).map_err(|e| TilerError::io(path, e))?;
        let file_len = file.metadata().map_err(|e| TilerError::io(path, e))?.len();
        let bound = (u64::from(w) * u64::from(h) * texel_bytes).saturating_mul(2) + (1 << 16);
        Ok(Codestreams { path: path.to_path_buf(), file, file_len, offsets, counts, bound, chunk: (w, h), what })
    }

    /// Chunk `index`'s bytes as stored, or what is wrong with where the file puts them.
    pub(in crate::source) fn read(&self, index: usize) -> std::result::Result<Vec<u8>, String> {
        let (offset, count) = match (self.offsets.get(index), self.counts.get(index)) {
            (Some(&o), Some(&c)) if c > 0 => (o, c),
            _ => return Err("the file gives it no data (offset or byte count missing or 0)".into()),
        };
        if offset.checked_add(count).is_none_or(|end| end > self.file_len) {
            return Err(format!(
                "its {count} bytes at offset {offset} run past the end of the file: a truncated file?"
            ));
        }
        if count > self.bound {
            return Err(format!(
                "it claims {count} compressed bytes for a {}x{} {}",
                self.chunk.0, self.chunk.1, self.what
            ));
        }
        let mut raw = vec![0u8; count as usize];
        self.file.read_exact_at(&mut raw, offset).map_err(|e| format!("cannot read it: {e}"))?;
        Ok(raw)
    }
}

pub(super) fn open(
    path: &Path,
    decoder: &mut Decoder<BufReader<File>>,
    label: String,
    embedded: Embedded,
    pages: Pages,
) -> Result<Box<dyn RowSource>> {
    let tag_err = |e| open_error(path, e);
    let (width, height) = super::dimensions(path, decoder)?;
    let ycbcr = decoder.find_tag_unsigned::<u16>(Tag::Compression).map_err(tag_err)? == Some(33003);
    let samples: u16 = decoder.find_tag_unsigned(Tag::SamplesPerPixel).map_err(tag_err)?.unwrap_or(1);
    let bits: Vec<u16> = decoder.find_tag_unsigned_vec(Tag::BitsPerSample).map_err(tag_err)?.unwrap_or(vec![1]);
    if samples != 3 || bits.iter().any(|&b| b != 8) {
        let message = format!(
            "JPEG 2000 TIFF with {samples} samples of {bits:?} bits is not supported (8-bit RGB and YCbCr are)"
        );
        return Err(TilerError::unsupported(path, message));
    }
    let (chunk_w, chunk_h, tiled) = match decoder.get_chunk_type() {
        ChunkType::Tile => {
            let (w, h) = decoder.chunk_dimensions();
            (w, h, true)
        }
        ChunkType::Strip => (width, decoder.chunk_dimensions().1.clamp(1, height), false),
    };
    if chunk_w == 0 || chunk_h == 0 {
        return Err(TilerError::decode(path, format!("the TIFF declares {chunk_w}x{chunk_h} tiles")));
    }
    let (offsets_tag, counts_tag) =
        if tiled { (Tag::TileOffsets, Tag::TileByteCounts) } else { (Tag::StripOffsets, Tag::StripByteCounts) };
    let offsets = decoder.get_tag_u64_vec(offsets_tag).map_err(tag_err)?;
    let counts = decoder.get_tag_u64_vec(counts_tag).map_err(tag_err)?;
    let grid = Grid { size: (width, height), chunk: (chunk_w, chunk_h), offsets, counts };
    // Strips are never copied as a level's tiles.
    let pages = if tiled { pages } else { Pages { levels: Vec::new(), ..pages } };
    assemble(path, grid, ycbcr, label, embedded, pages)
}

/// Where a grid of JPEG 2000 codestreams lies in a file: a TIFF's tiles or strips, or a
/// DICOM instance's JPEG 2000 frames (`source::dicom`).
pub(crate) struct Grid {
    /// The image's texels across and down.
    pub size: (u32, u32),
    /// One chunk's texels across and down.
    pub chunk: (u32, u32),
    /// Each chunk's bytes in the file, row-major.
    pub offsets: Vec<u64>,
    pub counts: Vec<u64>,
}

/// The row source of `grid`'s codestreams in `path`; `ycbcr`: their three components are Y,
/// Cb, Cr without the codestream's own colour transform (turned into RGB here), not R, G, B.
/// `pages`: the page read, its reduced levels, and `--max-memory`.
pub(crate) fn assemble(
    path: &Path,
    grid: Grid,
    ycbcr: bool,
    label: String,
    mut embedded: Embedded,
    pages: Pages,
) -> Result<Box<dyn RowSource>> {
    let max_memory = pages.max_memory;
    let Grid { size: (width, height), chunk: (chunk_w, chunk_h), offsets, counts } = grid;
    if width == 0 || height == 0 || chunk_w == 0 || chunk_h == 0 {
        return Err(TilerError::decode(
            path,
            format!("a {width}x{height} image of {chunk_w}x{chunk_h} JPEG 2000 tiles"),
        ));
    }
    let across = width.div_ceil(chunk_w);
    // A row of tiles of RGB texels, and per worker a compressed tile (at most twice its
    // texels, checked per tile) and OpenJPEG's i32 per sample.
    let tile = chunk_w as u64 * chunk_h as u64 * 3;
    // (The cores, not the rayon pool's size: asking the pool would start it before the CLI
    // sizes it.)
    let cores = std::thread::available_parallelism().map_or(1, |n| n.get());
    let workers = cores.min(across as usize) as u64;
    let need = (tile * across as u64).saturating_add(tile.saturating_mul(6).saturating_mul(workers));
    if need > max_memory {
        return Err(TilerError::unsupported(
            path,
            format!(
                "the JPEG 2000 image is stored in {chunk_w}x{chunk_h} tiles: a row of them and the tiles being decoded ({} MiB) would have to be held in memory, more than --max-memory ({} MiB); raise --max-memory",
                need.div_ceil(1 << 20),
                max_memory >> 20
            ),
        ));
    }
    let chunks = Codestreams::new(path, (offsets, counts), (chunk_w, chunk_h), 3, "tile")?;
    // The first tile's coding style says whether the wavelet was the irreversible one (a
    // lossy step; a file that states its history, a DICOM instance, keeps its own).
    if embedded.lossy.is_empty() && irreversible(&main_header(&chunks)) {
        let tiles = (across as usize).saturating_mul(height.div_ceil(chunk_h) as usize);
        let compressed = chunks.counts.iter().take(tiles).fold(0u64, |sum, &c| sum.saturating_add(c));
        embedded.lossy = LossyStep::of(LossyStep::JPEG_2000, (width, height), 3, compressed);
    }
    Ok(Box::new(Jp2kTiff {
        path: path.to_path_buf(),
        width,
        height,
        ycbcr,
        chunk_w,
        chunk_h,
        across,
        chunks: Arc::new(chunks),
        rows: TileRows::new((width, height), (chunk_w, chunk_h), 3, "tile"),
        label,
        embedded,
        pages,
    }))
}

/// The first bytes (4 KiB at most) of the first tile's codestream; empty where there are
/// none to read (a damaged tile is reported when it is decoded).
fn main_header(chunks: &Codestreams) -> Vec<u8> {
    let (Some(&offset), Some(&count)) = (chunks.offsets.first(), chunks.counts.first()) else { return Vec::new() };
    let mut head = vec![0u8; count.min(4096).min(chunks.file_len.saturating_sub(offset)) as usize];
    match chunks.file.read_exact_at(&mut head, offset) {
        Ok(()) => head,
        Err(_) => Vec::new(),
    }
}

/// Whether a codestream's main header says it was coded with the irreversible (9-7) wavelet;
/// false where it is the reversible (5-3) one or the header is unreadable.
fn irreversible(head: &[u8]) -> bool {
    Codestream::read(head).ok().and_then(|c| c.coding).is_some_and(|c| !c.reversible)
}

impl Jp2kTiff {
    /// Tile `index` into `texels`: its `w` x `h` texels inside the image, as RGB.
    fn decode_tile(&self, index: usize, w: u32, h: u32, texels: &mut Vec<u8>) -> std::result::Result<(), String> {
        let raw = self.chunks.read(index)?;
        let siz = self.check_size(&raw)?;
        let origin = (u64::from(siz.origin.0), u64::from(siz.origin.1));
        let image = decode_codestream(&raw)?;
        let comps = image.components();
        if comps.len() < 3 {
            return Err(format!("the JPEG 2000 tile has {} components, 3 expected", comps.len()));
        }
        // Where texel (x, y) of the tile finds each component's sample: subsampled components
        // (dx, dy > 1, e.g. 4:2:0 chroma) are upsampled by nearest neighbour, the sample whose
        // footprint covers the texel, as OpenSlide and opj_decompress do (with an odd origin the
        // first texel takes the first sample).
        let mut planes = Vec::with_capacity(3);
        for (i, c) in comps[..3].iter().enumerate() {
            let (dx, dy) = siz.components.get(i).map_or((1, 1), |c| (u64::from(c.dx), u64::from(c.dy)));
            let first = |origin: u64, d: u64| origin.div_ceil(d);
            let (fx, fy) = (first(origin.0, dx), first(origin.1, dy));
            // The component's sample under the tile's last texel must be there.
            let covers = |origin: u64, n: u32, d: u64, f: u64, have: u32| {
                ((origin + n as u64 - 1) / d).saturating_sub(f) < have as u64
            };
            let shaped = covers(origin.0, w, dx, fx, c.width()) && covers(origin.1, h, dy, fy, c.height());
            if !shaped || c.precision() != 8 || c.is_signed() || c.data().len() < (c.width() * c.height()) as usize {
                return Err(format!(
                    "JPEG 2000 component {i} is {}x{} of {}{} bits, subsampled {dx}x{dy}; unsigned 8-bit covering {w}x{h} texels expected",
                    c.width(),
                    c.height(),
                    if c.is_signed() { "signed " } else { "" },
                    c.precision()
                ));
            }
            let columns: Vec<usize> =
                (0..w as u64).map(|x| ((origin.0 + x) / dx).saturating_sub(fx) as usize).collect();
            planes.push((c.data(), c.width() as usize, dy, fy, columns));
        }
        let sample = |plane: usize, r: u32, x: usize| {
            let (data, stride, dy, fy, columns) = &planes[plane];
            let row = ((origin.1 + r as u64) / dy).saturating_sub(*fy) as usize;
            data[row * stride + columns[x]].clamp(0, 255)
        };
        texels.clear();
        texels.reserve(w as usize * h as usize * 3);
        for r in 0..h {
            for x in 0..w as usize {
                let (a, b, c) = (sample(0, r, x), sample(1, r, x), sample(2, r, x));
                let rgb = if self.ycbcr { ycbcr_to_rgb(a, b, c) } else { [a as u8, b as u8, c as u8] };
                texels.extend_from_slice(&rgb);
            }
        }
        Ok(())
    }
}

/// A JPEG 2000 codestream decoded by OpenJPEG, or what failed in words (the binding's "Null
/// pointer from openjpeg-sys" means OpenJPEG returned no image).
fn decode_codestream(raw: &[u8]) -> std::result::Result<jpeg2k::Image, String> {
    // OpenJPEG reports damage through its result; a panic in the binding must not take the
    // whole run down either.
    std::panic::catch_unwind(|| jpeg2k::Image::from_bytes(raw))
        .map_err(|_| "the JPEG 2000 decoder failed".to_string())?
        .map_err(|e| match e {
            jpeg2k::error::Error::NullPointerError(_) | jpeg2k::error::Error::CodecError(_) => {
                "OpenJPEG could not decode it (damaged or unsupported JPEG 2000 data)".to_string()
            }
            e => format!("corrupt JPEG 2000 data: {e}"),
        })
}

impl Jp2kTiff {
    /// Refuses a codestream whose SIZ marker declares more texels or components than a tile
    /// holds, before OpenJPEG allocates for them; returns what its main header says.
    fn check_size(&self, raw: &[u8]) -> std::result::Result<Codestream, String> {
        let c = Codestream::read(raw)?;
        let components = c.components.len();
        if c.width > self.chunk_w || c.height > self.chunk_h || !(1..=4).contains(&components) {
            let (w, h, tw, th) = (c.width, c.height, self.chunk_w, self.chunk_h);
            return Err(format!(
                "the codestream declares {w}x{h} texels of {components} components in a {tw}x{th} tile"
            ));
        }
        Ok(c)
    }
}

/// JFIF YCbCr to RGB in libjpeg's fixed point (16 fractional bits, each term rounded), the
/// conversion OpenSlide applies to Aperio's YCbCr JPEG 2000 tiles.
fn ycbcr_to_rgb(y: i32, cb: i32, cr: i32) -> [u8; 3] {
    const HALF: i32 = 1 << 15;
    let fix = |v: f64| (v * 65536.0 + 0.5) as i32;
    let (cb, cr) = (cb - 128, cr - 128);
    let r = y + ((fix(1.402) * cr + HALF) >> 16);
    let g = y + ((-fix(0.34414) * cb - fix(0.71414) * cr + HALF) >> 16);
    let b = y + ((fix(1.772) * cb + HALF) >> 16);
    [r.clamp(0, 255) as u8, g.clamp(0, 255) as u8, b.clamp(0, 255) as u8]
}

/// Page `page` of `path`, a reduced level, as its JPEG 2000 tiles; `Err(why)` where it is not
/// tiles of the same coding as the page read (`ycbcr`).
fn level(path: &Path, page: usize, ycbcr: bool, max_memory: u64) -> Result<std::result::Result<StoredLevel, String>> {
    let mut decoder = super::open_decoder(path, max_memory)?;
    decoder.seek_to_image(page).map_err(|e| open_error(path, e))?;
    match decoder.find_tag_unsigned::<u16>(Tag::Compression).map_err(|e| open_error(path, e))? {
        Some(33003) if ycbcr => {}
        Some(33005) if !ycbcr => {}
        _ => return Ok(Err(format!("is not JPEG 2000 of {} components", if ycbcr { "YCbCr" } else { "RGB" }))),
    }
    if decoder.get_chunk_type() != ChunkType::Tile {
        return Ok(Err("is stored in strips, not tiles".into()));
    }
    let (width, height) = super::dimensions(path, &mut decoder)?;
    let (tw, th) = decoder.chunk_dimensions();
    if tw == 0 || th == 0 {
        return Err(TilerError::decode(path, format!("page {page} declares {tw}x{th} tiles")));
    }
    let offsets = decoder.get_tag_u64_vec(Tag::TileOffsets).map_err(|e| open_error(path, e))?;
    let counts = decoder.get_tag_u64_vec(Tag::TileByteCounts).map_err(|e| open_error(path, e))?;
    let (across, down) = (width.div_ceil(tw), height.div_ceil(th));
    super::enough_chunks(path, &offsets, &counts, u64::from(across) * u64::from(down), true)?;
    let chunks = Arc::new(Codestreams::new(path, (offsets, counts), (tw, th), 3, "tile")?);
    Ok(Ok(StoredLevel { width, height, page, tiles: Arc::new(Jp2kTiles { chunks, ycbcr, across, down }) }))
}

/// The JPEG 2000 tiles of a tiled TIFF page, handed out as stored.
struct Jp2kTiles {
    chunks: Arc<Codestreams>,
    ycbcr: bool,
    across: u32,
    down: u32,
}

impl StoredTiles for Jp2kTiles {
    fn tile_size(&self) -> (u32, u32) {
        self.chunks.chunk
    }

    fn quality(&self) -> Option<Quality> {
        None
    }

    fn coding(&self) -> Coding {
        Coding::Jpeg2000 { ycbcr: self.ycbcr }
    }

    fn tile(&self, col: u32, row: u32) -> Result<Option<Vec<u8>>> {
        let index = row as usize * self.across as usize + col as usize;
        let name = format!("JPEG 2000 tile at column {col}, row {row} (tile {index})");
        if col >= self.across || row >= self.down {
            let message = format!("{name}: outside the {}x{} tiles", self.across, self.down);
            return Err(TilerError::decode(&self.chunks.path, message));
        }
        let raw = self.chunks.read(index).map_err(|m| TilerError::decode(&self.chunks.path, format!("{name}: {m}")))?;
        Ok(Some(raw))
    }
}

impl RowSource for Jp2kTiff {
    rows_of_tile_rows!(decode_tile);

    fn header(&self) -> ImageHeader {
        ImageHeader { width: self.width, height: self.height, layout: PixelLayout::new(Channels::Rgb, Depth::U8) }
    }

    fn embedded(&self) -> Embedded {
        self.embedded.clone()
    }

    /// This page and its reduced levels, where it has some, each as its JPEG 2000 tiles, for a
    /// DICOM series to copy (strips, or a level coded otherwise, end them: `unlike`).
    fn stored_levels(&self) -> Result<Option<StoredLevels>> {
        if self.pages.levels.is_empty() {
            return Ok(None);
        }
        let path = &self.path;
        let full = Jp2kTiles {
            chunks: Arc::clone(&self.chunks),
            ycbcr: self.ycbcr,
            across: self.across,
            down: self.height.div_ceil(self.chunk_h),
        };
        let (width, height, page) = (self.width, self.height, self.pages.index);
        let mut stored = StoredLevels {
            path: path.clone(),
            levels: vec![StoredLevel { width, height, page, tiles: Arc::new(full) }],
            unlike: None,
        };
        for (k, &page) in self.pages.levels.iter().enumerate() {
            let k = k + 1;
            match level(path, page, self.ycbcr, self.pages.max_memory).map_err(|e| stored::in_level(e, k, page))? {
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
        let colour = if self.ycbcr { "YCbCr" } else { "RGB" };
        format!(
            "{}, jpeg 2000 ({colour}, OpenJPEG), streamed by tile row ({}x{} tiles, decoded in parallel)",
            self.label, self.chunk_w, self.chunk_h
        )
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    /// A codestream OpenJPEG cannot decode is said so, not as a null pointer of the binding.
    #[test]
    fn an_undecodable_codestream_says_what_failed() {
        // SOC, then a SIZ of a 16x16 image of 3 components, then nothing a decoder can use.
        let mut raw = vec![0xFF, 0x4F, 0xFF, 0x51, 0, 47, 0, 0, 0, 0, 0, 16, 0, 0, 0, 16];
        raw.extend([0; 16]);
        raw.extend([0, 0, 0, 16, 0, 0, 0, 16, 0, 0, 0, 0, 0, 0, 0, 0, 0, 3]);
        raw.extend([7, 1, 1, 7, 1, 1, 7, 1, 1]);
        raw.extend([0xAB; 64]);
        let e = decode_codestream(&raw).expect_err("not decodable");
        assert!(!e.contains("Null pointer"), "{e}");
        assert!(e.contains("OpenJPEG could not decode it") || e.starts_with("corrupt JPEG 2000 data"), "{e}");
    }
}
