//! The rest of TIFF that scanners, slide vendors and document systems write: planar-separate
//! images (one plane per sample, PlanarConfiguration 2), 1/2/4-bit grey, palette (indexed
//! colour), CMYK, and CCITT fax. Chunks are read and decompressed by [`chunks`], one strip or
//! one row of tiles at a time (of every plane), never a whole plane; each row is then turned
//! into texels:
//!
//! - grey of 1, 2 or 4 bits becomes 8-bit grey scaled to the full range (x 255, 85, 17), as
//!   libvips loads it; WhiteIsZero is inverted.
//! - palette indices (1, 2, 4 or 8 bits) become RGB through the ColorMap: 8-bit when the map
//!   holds no more than 8 bits (every entry below 256, as some old writers store it and libtiff
//!   takes it, or every entry a multiple of 257, the exact 16-bit form of an 8-bit value), else
//!   16-bit with the map's values as they are, so no colour is rounded away.
//! - CMYK (InkSet 1, 8- or 16-bit) goes to sRGB through the embedded ICC profile, or without one the
//!   default CMYK profile, as CMYK JPEG does ([`crate::source::icc::Cmyk`]).
//!
//! [`chunks`]: super::chunks

use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};

use tiff::decoder::{ChunkType, Decoder};
use tiff::tags::Tag;

use super::chunks::{Chunks, Codec, Shape};
use super::{Chunking, open_error};
use crate::error::{Result, TilerError};
use crate::pixel::{Channels, Depth, PixelLayout};
use crate::source::icc::Cmyk;
use crate::source::{Embedded, ImageHeader, RowSource};

/// Whether the image in `decoder` is one of the kinds read here rather than by the `tiff`
/// crate's chunk reader: planar-separate, fewer than 8 bits, palette, CMYK or fax.
pub(super) fn handles(path: &Path, decoder: &mut Decoder<BufReader<File>>) -> Result<bool> {
    let tag = |decoder: &mut Decoder<BufReader<File>>, t| -> Result<Option<u16>> {
        decoder.find_tag_unsigned::<u16>(t).map_err(|e| open_error(path, e))
    };
    let planar =
        tag(decoder, Tag::PlanarConfiguration)?.unwrap_or(1) == 2 && tag(decoder, Tag::SamplesPerPixel)? > Some(1);
    let photometric = tag(decoder, Tag::PhotometricInterpretation)?;
    let compression = tag(decoder, Tag::Compression)?.unwrap_or(1);
    let bits: Option<Vec<u16>> = decoder.find_tag_unsigned_vec(Tag::BitsPerSample).map_err(|e| open_error(path, e))?;
    let bits = bits.and_then(|b| b.first().copied()).unwrap_or(1);
    Ok(planar
        || matches!(photometric, Some(3 | 5))
        || matches!(bits, 1 | 2 | 4)
        || super::reader_of(compression) == Some(super::Reader::Fax))
}

/// How a row of stored samples becomes texels.
enum Kind {
    /// Grey (+alpha) or RGB(A): the first `keep` samples of each texel, scaled up to 8 bits
    /// from fewer, the grey one inverted for WhiteIsZero.
    Direct { keep: usize, invert: bool },
    /// Indices into a ColorMap of `3 * n` entries (reds, greens, blues); `shift` is 8 for a
    /// 16-bit map taken to 8 bits, 0 otherwise.
    Palette { map: Vec<u16>, shift: u32 },
    /// 8-bit CMYK to RGB; the row of CMYK texels is gathered first.
    Cmyk { cmyk: Cmyk, row: Vec<u8> },
}

pub struct KindsSource {
    path: PathBuf,
    file: File,
    chunks: Chunks,
    width: u32,
    height: u32,
    layout: PixelLayout,
    kind: Kind,
    chunking: Chunking,
    /// Samples per texel in the file, and per texel within one chunk (1 when planar).
    stored: usize,
    chunk_samples: usize,
    /// One band (a strip or a row of tiles) per plane: one plane, or `stored` when planar.
    bands: Vec<Vec<u8>>,
    band_first: u64,
    band_rows: u64,
    tile: Vec<u8>,
    /// The current row's samples, unpacked and interleaved (texel by texel).
    samples: Vec<u16>,
    associated: bool,
    next: u64,
    label: String,
    what: String,
    embedded: Embedded,
}

pub(super) fn open(
    path: &Path,
    decoder: &mut Decoder<BufReader<File>>,
    label: String,
    mut embedded: Embedded,
    max_memory: u64,
) -> Result<Box<dyn RowSource>> {
    let tag_err = |e| open_error(path, e);
    let unsupported = |what: String| Err(TilerError::unsupported(path, format!("{what} TIFF is not supported")));
    let (width, _) = super::dimensions(path, decoder)?;
    let u16_tag = |decoder: &mut Decoder<BufReader<File>>, t| -> Result<Option<u16>> {
        decoder.find_tag_unsigned::<u16>(t).map_err(|e| open_error(path, e))
    };
    let stored = u16_tag(decoder, Tag::SamplesPerPixel)?.unwrap_or(1) as usize;
    let planar = u16_tag(decoder, Tag::PlanarConfiguration)?.unwrap_or(1) == 2 && stored > 1;
    let photometric = u16_tag(decoder, Tag::PhotometricInterpretation)?
        .ok_or_else(|| TilerError::decode(path, "the TIFF has no PhotometricInterpretation tag"))?;
    let bits_all: Vec<u16> = decoder.find_tag_unsigned_vec(Tag::BitsPerSample).map_err(tag_err)?.unwrap_or(vec![1]);
    let bits = bits_all.first().copied().unwrap_or(1);
    if bits_all.iter().any(|&b| b != bits) || !matches!(bits, 1 | 2 | 4 | 8 | 16) {
        return unsupported(format!("a {bits_all:?}-bits-per-sample"));
    }
    let formats: Vec<u16> = decoder.find_tag_unsigned_vec(Tag::SampleFormat).map_err(tag_err)?.unwrap_or_default();
    if formats.iter().any(|&f| f != 1) {
        return unsupported(format!(
            "a planar, palette, CMYK or sub-byte image with SampleFormat {formats:?} (not unsigned integers):"
        ));
    }
    let codec = codec(path, decoder, bits, stored)?;
    let predictor = match u16_tag(decoder, Tag::Predictor)?.unwrap_or(1) {
        1 => false,
        2 if bits >= 8 => true,
        p => return unsupported(format!("a {bits}-bit image with predictor {p}:")),
    };
    let extra: Vec<u16> = decoder.find_tag_unsigned_vec(Tag::ExtraSamples).map_err(tag_err)?.unwrap_or_default();
    let alpha = matches!(extra.first(), Some(1 | 2));
    let depth = if bits == 16 { Depth::U16 } else { Depth::U8 };

    let (kind, layout, what) = match photometric {
        0 | 1 => {
            let channels = if alpha && stored >= 2 { Channels::GreyAlpha } else { Channels::Grey };
            let invert = photometric == 0;
            let what = format!("{bits}-bit grey{}", if invert { " (WhiteIsZero)" } else { "" });
            (Kind::Direct { keep: channels.count(), invert }, PixelLayout::new(channels, depth), what)
        }
        2 if stored >= 3 && bits >= 8 => {
            let channels = if alpha && stored >= 4 { Channels::Rgba } else { Channels::Rgb };
            let kind = Kind::Direct { keep: channels.count(), invert: false };
            (kind, PixelLayout::new(channels, depth), format!("{bits}-bit RGB"))
        }
        3 if stored == 1 && bits <= 8 => {
            let map: Vec<u16> = decoder.find_tag_unsigned_vec(Tag::ColorMap).map_err(tag_err)?.unwrap_or_default();
            let entries = 1usize << bits;
            if map.len() != 3 * entries {
                let message = format!(
                    "corrupt TIFF: a {bits}-bit palette needs a ColorMap of {} values, it has {}",
                    3 * entries,
                    map.len()
                );
                return Err(TilerError::decode(path, message));
            }
            let (shift, depth, note) = if map.iter().all(|&v| v < 256) {
                (0, Depth::U8, "8-bit map")
            } else if map.iter().all(|&v| v % 257 == 0) {
                (8, Depth::U8, "16-bit map of 8-bit values")
            } else {
                (0, Depth::U16, "16-bit map, kept at 16 bits")
            };
            let what = format!("{bits}-bit palette to RGB ({note})");
            (Kind::Palette { map, shift }, PixelLayout::new(Channels::Rgb, depth), what)
        }
        5 if stored >= 4 && matches!(bits, 8 | 16) => {
            let ink_set = u16_tag(decoder, Tag::Unknown(332))?.unwrap_or(1);
            if alpha {
                return unsupported("a CMYK with alpha".into());
            }
            if ink_set != 1 {
                return unsupported(format!("a multi-ink (InkSet {ink_set}, not CMYK)"));
            }
            let cmyk = Cmyk::new(path, embedded.icc.as_deref(), false, bits == 16)?;
            // The profile is used up turning CMYK into sRGB.
            embedded.icc = None;
            let what = format!("{bits}-bit CMYK, {}", cmyk.note);
            let row = vec![0u8; width as usize * 4 * depth.bytes()];
            (Kind::Cmyk { cmyk, row }, PixelLayout::new(Channels::Rgb, depth), what)
        }
        3 => return unsupported(format!("a {bits}-bit palette with {stored} samples per texel")),
        5 => return unsupported(format!("a {bits}-bit CMYK (8- and 16-bit CMYK are read)")),
        p => return unsupported(format!("a {bits}-bit photometric-{p} image with {stored} samples per texel:")),
    };
    let associated = alpha && extra.first() == Some(&1);
    let parts = Parts { kind, layout, what, codec, predictor, planar, stored, bits, label, embedded, associated };
    finish(path, decoder, parts, max_memory)
}

/// The codec of a file of `bits`-bit, `stored`-sample texels.
fn codec(path: &Path, decoder: &mut Decoder<BufReader<File>>, bits: u16, stored: usize) -> Result<Codec> {
    let code: u16 = decoder.find_tag_unsigned(Tag::Compression).map_err(|e| open_error(path, e))?.unwrap_or(1);
    let fax_only = |codec| match bits == 1 && stored == 1 {
        true => Ok(codec),
        false => Err(TilerError::decode(
            path,
            format!(
                "corrupt TIFF: CCITT fax compression on {stored} samples of {bits} bits (it codes 1-bit images only)"
            ),
        )),
    };
    match code {
        1 => Ok(Codec::None),
        5 => Ok(Codec::Lzw),
        8 | 32946 => Ok(Codec::Deflate),
        32773 => Ok(Codec::PackBits),
        3 => {
            let options: u32 =
                decoder.find_tag_unsigned(Tag::Unknown(292)).map_err(|e| open_error(path, e))?.unwrap_or(0);
            if options & 2 != 0 {
                return Err(TilerError::unsupported(
                    path,
                    "Group 3 fax with uncompressed mode (T4Options bit 1) is not supported (Group 3 without it and Group 4 are); re-save it with `tiffcp -c g4 in.tif out.tif`",
                ));
            }
            fax_only(if options & 1 != 0 { Codec::Fax3TwoD } else { Codec::Fax3 })
        }
        4 => fax_only(Codec::Fax4),
        2 => fax_only(Codec::FaxMh),
        other => Err(TilerError::unsupported(
            path,
            format!(
                "TIFF compression {other} is not supported for planar, palette, CMYK or sub-byte images ({} are); re-save it with `tiffcp -c lzw in.tif out.tif`",
                super::compressions_read(&[super::Reader::Chunks, super::Reader::Fax])
            ),
        )),
    }
}

/// What [`open`] found, for [`finish`] to lay the chunks out.
struct Parts {
    kind: Kind,
    layout: PixelLayout,
    what: String,
    codec: Codec,
    predictor: bool,
    planar: bool,
    stored: usize,
    bits: u16,
    label: String,
    embedded: Embedded,
    associated: bool,
}

fn finish(
    path: &Path,
    decoder: &mut Decoder<BufReader<File>>,
    p: Parts,
    max_memory: u64,
) -> Result<Box<dyn RowSource>> {
    let tag_err = |e| open_error(path, e);
    let (width, height) = decoder.dimensions().map_err(tag_err)?;
    let chunking = match decoder.get_chunk_type() {
        ChunkType::Strip => Chunking::Strips { rows: decoder.chunk_dimensions().1.clamp(1, height) },
        ChunkType::Tile => {
            let (tw, th) = decoder.chunk_dimensions();
            if tw == 0 || th == 0 || !(tw as u64 * p.bits as u64).is_multiple_of(8) {
                return Err(TilerError::decode(
                    path,
                    format!("corrupt TIFF: {tw}x{th} tiles of {}-bit samples", p.bits),
                ));
            }
            Chunking::Tiles { width: tw, height: th, across: width.div_ceil(tw) }
        }
    };
    let (offsets_tag, counts_tag) = match chunking {
        Chunking::Strips { .. } => (Tag::StripOffsets, Tag::StripByteCounts),
        Chunking::Tiles { .. } => (Tag::TileOffsets, Tag::TileByteCounts),
    };
    let file = File::open(path).map_err(|e| TilerError::io(path, e))?;
    let file_len = file.metadata().map_err(|e| TilerError::io(path, e))?.len();
    let chunks = Chunks {
        offsets: decoder.get_tag_u64_vec(offsets_tag).map_err(tag_err)?,
        counts: decoder.get_tag_u64_vec(counts_tag).map_err(tag_err)?,
        codec: p.codec,
        predictor: p.predictor,
        big_endian: decoder.byte_order() == tiff::tags::ByteOrder::BigEndian,
        bits: p.bits,
        reverse_bits: decoder.find_tag_unsigned::<u16>(Tag::FillOrder).map_err(tag_err)? == Some(2),
        file_len,
    };
    let chunk_samples = if p.planar { 1 } else { p.stored };
    let planes = if p.planar { p.stored } else { 1 };
    let plane_row = Shape { width, rows: 1, samples: chunk_samples }.row_bytes(p.bits) as u64;
    let band_rows = chunking.rows().min(height) as u64;
    let tile_bytes = match chunking {
        Chunking::Strips { .. } => 0,
        Chunking::Tiles { width: tw, height: th, .. } => {
            Shape { width: tw, rows: 1, samples: chunk_samples }.row_bytes(p.bits) as u64 * th as u64
        }
    };
    // Held: one band per plane, one tile, the unpacked row.
    let need = (plane_row * band_rows)
        .saturating_mul(planes as u64)
        .saturating_add(tile_bytes)
        .saturating_add(width as u64 * p.stored as u64 * 2);
    if need > max_memory {
        let unit = match chunking {
            Chunking::Strips { rows } => format!("strips of {rows} rows"),
            Chunking::Tiles { width: tw, height: th, .. } => format!("{tw}x{th} tiles"),
        };
        return Err(TilerError::unsupported(
            path,
            format!(
                "the {width}x{height} TIFF is stored in {unit}, so one band of them ({} MiB, every plane) would have to be held in memory, more than --max-memory ({} MiB); raise --max-memory or re-save it with smaller strips (e.g. `tiffcp -r 64 in.tif out.tif`)",
                need.div_ceil(1 << 20),
                max_memory >> 20
            ),
        ));
    }
    let band_len = usize::try_from(plane_row * band_rows)
        .map_err(|_| TilerError::unsupported(path, "a strip is too large for this machine"))?;
    Ok(Box::new(KindsSource {
        path: path.to_path_buf(),
        file,
        chunks,
        width,
        height,
        layout: p.layout,
        kind: p.kind,
        chunking,
        stored: p.stored,
        chunk_samples,
        bands: vec![vec![0u8; band_len]; planes],
        band_first: 0,
        band_rows: 0,
        tile: vec![0u8; tile_bytes as usize],
        samples: vec![0u16; width as usize * p.stored],
        associated: p.associated,
        next: 0,
        label: p.label,
        what: format!("{}{}", if p.planar { "planar-separate " } else { "" }, p.what),
        embedded: p.embedded,
    }))
}

impl KindsSource {
    /// Decodes, for every plane, the strip or row of tiles holding row `y`.
    fn load_band(&mut self, y: u64) -> Result<()> {
        let rows_per = self.chunking.rows() as u64;
        let band = (y / rows_per) as usize;
        let first = band as u64 * rows_per;
        let rows = rows_per.min(self.height as u64 - first) as u32;
        let bits = self.chunks.bits;
        let plane_row = Shape { width: self.width, rows: 1, samples: self.chunk_samples }.row_bytes(bits);
        let fail = |what: String, message: String| TilerError::DecodeRow {
            path: self.path.clone(),
            row: y,
            message: format!("{what} (rows {first}..{}): {message}", first + rows as u64),
        };
        let planes = self.bands.len();
        for (plane, dest) in self.bands.iter_mut().enumerate() {
            let of_plane = |what: String| if planes > 1 { format!("{what} of plane {plane}") } else { what };
            let dest = &mut dest[..plane_row * rows as usize];
            match self.chunking {
                Chunking::Strips { .. } => {
                    let index = plane * self.height.div_ceil(rows_per as u32) as usize + band;
                    let shape = Shape { width: self.width, rows, samples: self.chunk_samples };
                    self.chunks
                        .decode(&self.file, index, shape, dest)
                        .map_err(|m| fail(of_plane(format!("strip {index}")), m))?;
                }
                Chunking::Tiles { width: tw, height: th, across } => {
                    let per_plane = across as usize * self.height.div_ceil(th) as usize;
                    let shape = Shape { width: tw, rows: th, samples: self.chunk_samples };
                    let tile_row = shape.row_bytes(bits);
                    for col in 0..across as usize {
                        let index = plane * per_plane + band * across as usize + col;
                        self.chunks
                            .decode(&self.file, index, shape, &mut self.tile)
                            .map_err(|m| fail(of_plane(format!("tile {index} (tile row {band}, column {col})")), m))?;
                        let x0 = col * tile_row;
                        let n = tile_row.min(plane_row - x0);
                        for (d, s) in dest.chunks_exact_mut(plane_row).zip(self.tile.chunks_exact(tile_row)) {
                            d[x0..x0 + n].copy_from_slice(&s[..n]);
                        }
                    }
                }
            }
        }
        (self.band_first, self.band_rows) = (first, rows as u64);
        Ok(())
    }

    /// Row `y` of the loaded band into `samples`, texel by texel.
    fn unpack_row(&mut self, y: u64) {
        let bits = self.chunks.bits as usize;
        let plane_row = Shape { width: self.width, rows: 1, samples: self.chunk_samples }.row_bytes(bits as u16);
        let at = (y - self.band_first) as usize * plane_row;
        let stride = self.bands.len(); // planes: each sample `stride` apart in `samples`
        for (plane, band) in self.bands.iter().enumerate() {
            let row = &band[at..at + plane_row];
            let out = self.samples[plane..].iter_mut().step_by(stride);
            match bits {
                8 => out.zip(row).for_each(|(o, &v)| *o = v as u16),
                16 => out.zip(row.chunks_exact(2)).for_each(|(o, v)| *o = u16::from_ne_bytes([v[0], v[1]])),
                _ => {
                    let mask = (1u16 << bits) - 1;
                    for (i, o) in out.enumerate() {
                        let bit = i * bits;
                        *o = (row[bit / 8] as u16 >> (8 - bits - bit % 8)) & mask;
                    }
                }
            }
        }
    }
}

impl RowSource for KindsSource {
    fn header(&self) -> ImageHeader {
        ImageHeader { width: self.width, height: self.height, layout: self.layout }
    }

    fn embedded(&self) -> Embedded {
        self.embedded.clone()
    }

    fn read_row(&mut self, out: &mut [u8]) -> Result<()> {
        let y = self.next;
        let fail = |message: String| TilerError::DecodeRow { path: self.path.clone(), row: y, message };
        super::check_row(y, self.height, &(0..self.width), self.layout.bytes_per_pixel(), out.len()).map_err(fail)?;
        if y < self.band_first || y >= self.band_first + self.band_rows {
            self.load_band(y)?;
        }
        self.unpack_row(y);
        let bits = self.chunks.bits;
        let max = (1u32 << bits) - 1;
        let stored = self.stored;
        match &mut self.kind {
            Kind::Direct { keep, invert } => {
                let (keep, invert) = (*keep, *invert);
                let put = |i: usize, c: usize, out: &mut [u8]| {
                    let mut v = self.samples[i * stored + c] as u32;
                    if invert && c == 0 {
                        v = max - v;
                    }
                    match bits {
                        16 => out[(i * keep + c) * 2..][..2].copy_from_slice(&(v as u16).to_ne_bytes()),
                        _ => out[i * keep + c] = (v * 255 / max) as u8,
                    }
                };
                for i in 0..self.width as usize {
                    for c in 0..keep {
                        put(i, c, out);
                    }
                }
            }
            Kind::Palette { map, shift } => {
                let n = map.len() / 3;
                let sixteen = self.layout.depth == Depth::U16;
                for (i, &index) in self.samples.iter().enumerate() {
                    for c in 0..3 {
                        let v = map[c * n + index as usize] >> *shift;
                        match sixteen {
                            true => out[(i * 3 + c) * 2..][..2].copy_from_slice(&v.to_ne_bytes()),
                            false => out[i * 3 + c] = v as u8,
                        }
                    }
                }
            }
            Kind::Cmyk { cmyk, row } => {
                let sample = self.layout.depth.bytes();
                for (texel, s) in row.chunks_exact_mut(4 * sample).zip(self.samples.chunks_exact(stored)) {
                    for (c, bytes) in texel.chunks_exact_mut(sample).enumerate() {
                        match sample {
                            2 => bytes.copy_from_slice(&s[c].to_ne_bytes()),
                            _ => bytes[0] = s[c] as u8,
                        }
                    }
                }
                cmyk.convert(row, out);
            }
        }
        if self.associated {
            super::unpremultiply(out, self.layout);
        }
        self.next += 1;
        Ok(())
    }

    /// Strips and tiles are found by row: the next read loads the band it needs.
    fn skip_rows(&mut self, rows: u32) -> Result<()> {
        self.next += rows as u64;
        Ok(())
    }

    fn rewind(&mut self) -> Result<()> {
        self.next = 0;
        Ok(())
    }

    fn describe(&self) -> String {
        let by = match self.chunking {
            Chunking::Strips { rows } => format!("streamed by strip ({rows} rows)"),
            Chunking::Tiles { width, height, .. } => format!("streamed by tile row ({width}x{height} tiles)"),
        };
        format!("{}, {}, {}, {by}", self.label, self.chunks.codec.name(), self.what)
    }
}
