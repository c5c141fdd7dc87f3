//! The rest of TIFF that scanners, slide vendors and document systems write: planar-separate
//! images (one plane per sample, PlanarConfiguration 2), 1/2/4-bit grey, palette (indexed
//! colour), CMYK, and CCITT fax; and every sample of a texel as stored, one at a time, for the
//! channels of an image of more samples than a texel holds ([`open_sample`]). Chunks are read
//! and decompressed by [`chunks`], one strip or one row of tiles at a time (of every plane
//! read), never a whole plane; each row is then turned into texels:
//!
//! - grey and RGB samples of 8, 16 or 32 bits (unsigned, float, or signed 16-bit) are carried
//!   as stored, byte for byte ([`samples`] widens half floats and signed ones to `f32`), and
//!   only the planes of the samples kept are read.
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
//! [`samples`]: super::samples

use std::fs::File;
use std::io::BufReader;
use std::path::{Path, PathBuf};

use tiff::decoder::{ChunkType, Decoder};
use tiff::tags::Tag;

use super::chunks::{Chunks, Codec, Predictor, Shape};
use super::samples::{self, Stored};
use super::{Chunking, open_error};
use crate::error::{Result, TilerError};
use crate::limits::human_bytes;
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
    // RGB with extra samples past its alpha: the crate drops them before undoing the predictor,
    // at the stride of the samples kept (tests/it/tiff_corpus.rs found it), so every sample is
    // read here as stored.
    let samples = tag(decoder, Tag::SamplesPerPixel)?.unwrap_or(1);
    let extra: Vec<u16> =
        decoder.find_tag_unsigned_vec(Tag::ExtraSamples).map_err(|e| open_error(path, e))?.unwrap_or_default();
    // Four RGB samples with no ExtraSamples tag at all (as the `image` and `tiff` crates write
    // RGBA) are RGBA, as libtiff takes them; an explicit 0 (unspecified) is not an alpha.
    let alpha = matches!(extra.first(), Some(1 | 2)) || (extra.is_empty() && samples == 4);
    let rgb_dropping = photometric == Some(2) && samples > 3 + alpha as u16;
    // LZW tiles: the crate wants an end code that libtiff and tifffile do not (a tile's rows
    // complete, libtiff stops); our decoder stops there too.
    let lzw_tiles = compression == 5 && decoder.get_chunk_type() == ChunkType::Tile;
    Ok(planar
        || matches!(photometric, Some(3 | 5))
        || matches!(bits, 1 | 2 | 4)
        || super::reader_of(compression) == Some(super::Reader::Fax)
        || rgb_dropping
        || lzw_tiles)
}

/// How a row of stored samples becomes texels.
enum Kind {
    /// Samples `first..first + keep` of each texel as they are stored (8, 16 or 32 bits):
    /// grey (+alpha) or RGB(A) texels, or one channel.
    AsStored { first: usize, keep: usize },
    /// Sub-byte or WhiteIsZero grey (+alpha): the first `keep` samples of each texel, scaled
    /// up to 8 bits from fewer, the grey one inverted for WhiteIsZero.
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
    /// One band (a strip or a row of tiles) per plane read: one plane, or when planar those
    /// `planes` names.
    bands: Vec<Vec<u8>>,
    planes: Vec<usize>,
    /// Strips or tiles in one plane.
    per_plane: usize,
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
    /// What the buffers above hold at most, the compressed bytes of a chunk included.
    most_buffer_bytes: u64,
}

/// What every kind shares: the samples as stored and how they are coded.
struct Form {
    width: u32,
    /// SamplesPerPixel.
    stored: usize,
    planar: bool,
    photometric: u16,
    bits: u16,
    /// What 8-, 16- and 32-bit samples are (`samples::stored`); `None` at fewer bits.
    sample: Option<Stored>,
    codec: Codec,
    predictor: Predictor,
    extra: Vec<u16>,
}

fn form(path: &Path, decoder: &mut Decoder<BufReader<File>>) -> Result<Form> {
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
    let formats: Vec<u16> = decoder.find_tag_unsigned_vec(Tag::SampleFormat).map_err(tag_err)?.unwrap_or_default();
    let sample = match bits {
        1 | 2 | 4 if bits_all.iter().all(|&b| b == bits) => {
            if formats.iter().any(|&f| f != 1) {
                return unsupported(format!(
                    "a {bits}-bit image with SampleFormat {formats:?} (not unsigned integers):"
                ));
            }
            None
        }
        _ => match samples::stored(&formats, &bits_all) {
            Ok(kind) => Some(kind),
            Err(what) => return unsupported(what),
        },
    };
    let codec = codec(path, decoder, bits, stored)?;
    let float = matches!(sample, Some(Stored::Half | Stored::AsIs(Depth::F32)));
    let predictor = match u16_tag(decoder, Tag::Predictor)?.unwrap_or(1) {
        1 => Predictor::None,
        2 if bits >= 8 => Predictor::Horizontal,
        3 if float => Predictor::Float,
        p => return unsupported(format!("a {bits}-bit image with predictor {p}:")),
    };
    let extra: Vec<u16> = decoder.find_tag_unsigned_vec(Tag::ExtraSamples).map_err(tag_err)?.unwrap_or_default();
    Ok(Form { width, stored, planar, photometric, bits, sample, codec, predictor, extra })
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
    let u16_tag = |decoder: &mut Decoder<BufReader<File>>, t| -> Result<Option<u16>> {
        decoder.find_tag_unsigned::<u16>(t).map_err(|e| open_error(path, e))
    };
    let f = form(path, decoder)?;
    let (stored, bits, width) = (f.stored, f.bits, f.width);
    let alpha = matches!(f.extra.first(), Some(1 | 2));
    // Palette, CMYK, sub-byte and WhiteIsZero samples are unsigned integers of 16 bits or fewer.
    let narrow = |what: &str| match f.sample {
        None | Some(Stored::AsIs(Depth::U8 | Depth::U16)) => Ok(()),
        Some(_) => Err(TilerError::unsupported(
            path,
            format!("a {what} of {bits}-bit samples that are not unsigned integers: TIFF is not supported"),
        )),
    };
    let (kind, layout, what) = match (f.photometric, f.sample) {
        // Samples carried as stored: 8-, 16- and 32-bit grey and RGB, with alpha.
        (1 | 2, Some(sample)) if f.photometric == 1 || stored >= 3 => {
            let (grey, colours) = if f.photometric == 1 { (true, 1) } else { (false, 3) };
            let with_alpha = alpha && stored > colours;
            let channels = match (grey, with_alpha) {
                (true, false) => Channels::Grey,
                (true, true) => Channels::GreyAlpha,
                (false, false) => Channels::Rgb,
                (false, true) => Channels::Rgba,
            };
            let depth = sample.file_depth();
            let what = format!("{bits}-bit {}", if grey { "grey" } else { "RGB" });
            (Kind::AsStored { first: 0, keep: channels.count() }, PixelLayout::new(channels, depth), what)
        }
        (0 | 1, _) => {
            narrow("WhiteIsZero or sub-byte grey")?;
            let channels = if alpha && stored >= 2 { Channels::GreyAlpha } else { Channels::Grey };
            let invert = f.photometric == 0;
            let what = format!("{bits}-bit grey{}", if invert { " (WhiteIsZero)" } else { "" });
            let depth = if bits == 16 { Depth::U16 } else { Depth::U8 };
            (Kind::Direct { keep: channels.count(), invert }, PixelLayout::new(channels, depth), what)
        }
        (3, _) if stored == 1 && bits <= 8 => {
            narrow("palette")?;
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
        (5, _) if stored >= 4 && matches!(bits, 8 | 16) => {
            narrow("CMYK")?;
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
            let depth = if bits == 16 { Depth::U16 } else { Depth::U8 };
            let what = format!("{bits}-bit CMYK, {}", cmyk.note);
            let row = vec![0u8; width as usize * 4 * depth.bytes()];
            (Kind::Cmyk { cmyk, row }, PixelLayout::new(Channels::Rgb, depth), what)
        }
        (3, _) => return unsupported(format!("a {bits}-bit palette with {stored} samples per texel")),
        (5, _) => return unsupported(format!("a {bits}-bit CMYK (8- and 16-bit CMYK are read)")),
        (p, _) => return unsupported(format!("a {bits}-bit photometric-{p} image with {stored} samples per texel:")),
    };
    let associated = alpha && f.extra.first() == Some(&1);
    if associated && !layout.depth.is_narrow_int() {
        return unsupported(format!("a {bits}-bit {} with associated (premultiplied) alpha", layout.depth.tile_type()));
    }
    let widen = f.sample.filter(|_| matches!(kind, Kind::AsStored { .. }));
    let parts = Parts { kind, layout, what, form: f, label, embedded, associated };
    let source = finish(path, decoder, parts, max_memory)?;
    Ok(match widen {
        Some(sample) => samples::widen(source, sample),
        None => source,
    })
}

/// Sample `k` of every texel of the TIFF page in `decoder` as a grey image, whatever the
/// photometric says the samples are: a channel of an image of more samples than a texel
/// holds (`source::channels`). Samples of 8, 16 or 32 bits, carried as stored (half floats
/// and signed 16-bit ones widened to `f32`, as for texels).
pub(super) fn open_sample(
    path: &Path,
    decoder: &mut Decoder<BufReader<File>>,
    k: usize,
    max_memory: u64,
) -> Result<Box<dyn RowSource>> {
    let f = form(path, decoder)?;
    let Some(sample) = f.sample else {
        return Err(TilerError::unsupported(
            path,
            format!(
                "channels of {}-bit samples: channels of 8/16/32-bit unsigned, 16/32-bit float or 16-bit signed samples are read",
                f.bits
            ),
        ));
    };
    if k >= f.stored {
        return Err(TilerError::Options(format!("channel {k}: the TIFF has {} samples per texel", f.stored)));
    }
    if f.photometric == 6 {
        // Subsampled chroma is stored in blocks, not texel by texel.
        return Err(TilerError::unsupported(
            path,
            "channels of a YCbCr TIFF (PhotometricInterpretation 6): TIFF is not supported",
        ));
    }
    let layout = PixelLayout::new(Channels::Grey, sample.file_depth());
    let what = format!("{}-bit sample {k} of {}", f.bits, f.stored);
    let kind = Kind::AsStored { first: k, keep: 1 };
    let parts = Parts {
        kind,
        layout,
        what,
        form: f,
        label: "TIFF channel".into(),
        embedded: Embedded::default(),
        associated: false,
    };
    Ok(samples::widen(finish(path, decoder, parts, max_memory)?, sample))
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
                "TIFF compression {other} is not supported for planar, palette, CMYK or sub-byte images, nor for channels of more than four samples per texel (none, LZW, Deflate, PackBits, CCITT G3/G4 are); re-save it with `tiffcp -c lzw in.tif out.tif`"
            ),
        )),
    }
}

/// What [`open`] found, for [`finish`] to lay the chunks out.
struct Parts {
    kind: Kind,
    layout: PixelLayout,
    what: String,
    form: Form,
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
    let f = &p.form;
    let (width, height) = decoder.dimensions().map_err(tag_err)?;
    let chunking = match decoder.get_chunk_type() {
        ChunkType::Strip => Chunking::Strips { rows: decoder.chunk_dimensions().1.clamp(1, height) },
        ChunkType::Tile => {
            let (tw, th) = decoder.chunk_dimensions();
            if tw == 0 || th == 0 || !(tw as u64 * f.bits as u64).is_multiple_of(8) {
                return Err(TilerError::decode(
                    path,
                    format!("corrupt TIFF: {tw}x{th} tiles of {}-bit samples", f.bits),
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
        codec: f.codec,
        predictor: f.predictor,
        big_endian: decoder.byte_order() == tiff::tags::ByteOrder::BigEndian,
        bits: f.bits,
        reverse_bits: decoder.find_tag_unsigned::<u16>(Tag::FillOrder).map_err(tag_err)? == Some(2),
        file_len,
        raw: Vec::new(),
    };
    let chunk_samples = if f.planar { 1 } else { f.stored };
    // The planes read: of samples carried as stored, only theirs; else every one.
    let planes: Vec<usize> = match (&p.kind, f.planar) {
        (_, false) => vec![0],
        (Kind::AsStored { first, keep }, true) => (*first..first + keep).collect(),
        (_, true) => (0..f.stored).collect(),
    };
    let plane_row = Shape { width, rows: 1, samples: chunk_samples }.row_bytes(f.bits) as u64;
    let band_rows = chunking.rows().min(height) as u64;
    let (chunk_shape, per_plane) = match chunking {
        Chunking::Strips { rows } => (Shape { width, rows, samples: chunk_samples }, height.div_ceil(rows) as usize),
        Chunking::Tiles { width: tw, height: th, across } => {
            (Shape { width: tw, rows: th, samples: chunk_samples }, across as usize * height.div_ceil(th) as usize)
        }
    };
    let tile_bytes = match chunking {
        Chunking::Strips { .. } => 0,
        Chunking::Tiles { .. } => chunk_shape.row_bytes(f.bits) as u64 * chunk_shape.rows as u64,
    };
    // The unpacked row of sub-byte, WhiteIsZero, palette and CMYK texels, and CMYK's row.
    let unpacked = match &p.kind {
        Kind::AsStored { .. } => 0,
        _ => width as u64 * f.stored as u64 * 2,
    };
    let cmyk_row = match &p.kind {
        Kind::Cmyk { row, .. } => row.len() as u64,
        _ => 0,
    };
    let chunk_bytes = chunk_shape.row_bytes(f.bits) as u64 * chunk_shape.rows as u64;
    let read = planes.iter().flat_map(|&plane| plane * per_plane..(plane + 1) * per_plane);
    let compressed = chunks.compressed_at_most(read, chunk_bytes);
    // Held: one band per plane read, one tile, the compressed bytes of one chunk, the rows.
    let most = (plane_row * band_rows)
        .saturating_mul(planes.len() as u64)
        .saturating_add(tile_bytes)
        .saturating_add(compressed)
        .saturating_add(unpacked + cmyk_row);
    if most > max_memory {
        let unit = match chunking {
            Chunking::Strips { rows } => format!("strips of {rows} rows"),
            Chunking::Tiles { width: tw, height: th, .. } => format!("{tw}x{th} tiles"),
        };
        return Err(TilerError::unsupported(
            path,
            format!(
                "the {width}x{height} TIFF is stored in {unit}, so one band of them ({}, every plane read) would have to be held in memory, more than --max-memory ({}); raise --max-memory or re-save it with smaller strips (e.g. `tiffcp -r 64 in.tif out.tif`)",
                human_bytes(most),
                human_bytes(max_memory)
            ),
        ));
    }
    let band_len = usize::try_from(plane_row * band_rows)
        .map_err(|_| TilerError::unsupported(path, "a strip is too large for this machine"))?;
    let what = format!("{}{}", if f.planar { "planar-separate " } else { "" }, p.what);
    Ok(Box::new(KindsSource {
        path: path.to_path_buf(),
        file,
        chunks,
        width,
        height,
        layout: p.layout,
        kind: p.kind,
        chunking,
        stored: f.stored,
        chunk_samples,
        bands: vec![vec![0u8; band_len]; planes.len()],
        planes,
        per_plane,
        band_first: 0,
        band_rows: 0,
        tile: vec![0u8; tile_bytes as usize],
        samples: vec![0u16; (unpacked / 2) as usize],
        associated: p.associated,
        next: 0,
        label: p.label,
        what,
        embedded: p.embedded,
        most_buffer_bytes: most,
    }))
}

impl KindsSource {
    /// Decodes, for every plane read, the strip or row of tiles holding row `y`.
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
        let (planar, per_plane) = (self.chunk_samples == 1 && self.stored > 1, self.per_plane);
        for (&plane, dest) in self.planes.iter().zip(self.bands.iter_mut()) {
            let of_plane = |what: String| if planar { format!("{what} of plane {plane}") } else { what };
            let dest = &mut dest[..plane_row * rows as usize];
            match self.chunking {
                Chunking::Strips { .. } => {
                    let index = plane * per_plane + band;
                    let shape = Shape { width: self.width, rows, samples: self.chunk_samples };
                    self.chunks
                        .decode(&self.file, index, shape, dest)
                        .map_err(|m| fail(of_plane(format!("strip {index}")), m))?;
                }
                Chunking::Tiles { width: tw, height: th, across } => {
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

    /// Samples `first..first + keep` of each texel of row `y` of the loaded band into `out`,
    /// byte for byte (samples of 8 bits or more, already in native order).
    fn copy_as_stored(&self, y: u64, first: usize, keep: usize, out: &mut [u8]) {
        let b = self.chunks.bits as usize / 8;
        let plane_row = Shape { width: self.width, rows: 1, samples: self.chunk_samples }.row_bytes(self.chunks.bits);
        let at = (y - self.band_first) as usize * plane_row;
        if self.chunk_samples > 1 {
            // Texels of `stored` samples together: the kept ones are side by side.
            let texel = self.chunk_samples * b;
            let row = &self.bands[0][at..at + plane_row];
            for (o, t) in out.chunks_exact_mut(keep * b).zip(row.chunks_exact(texel)) {
                o.copy_from_slice(&t[first * b..(first + keep) * b]);
            }
        } else {
            // One sample per texel, or one plane per kept sample.
            for (c, band) in self.bands.iter().enumerate() {
                let plane = &band[at..at + plane_row];
                for (o, s) in out.chunks_exact_mut(keep * b).zip(plane.chunks_exact(b)) {
                    o[c * b..(c + 1) * b].copy_from_slice(s);
                }
            }
        }
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
        if let Kind::AsStored { first, keep } = self.kind {
            self.copy_as_stored(y, first, keep, out);
            if self.associated {
                super::unpremultiply(out, self.layout);
            }
            self.next += 1;
            return Ok(());
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
            Kind::AsStored { .. } => {}
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

    /// The bands, the tile, the compressed bytes of the last chunk and the unpacked row.
    fn buffer_bytes(&self) -> u64 {
        let bands: usize = self.bands.iter().map(Vec::capacity).sum();
        let cmyk = match &self.kind {
            Kind::Cmyk { row, .. } => row.capacity(),
            _ => 0,
        };
        (bands + self.tile.capacity() + self.chunks.raw.capacity() + 2 * self.samples.capacity() + cmyk) as u64
    }

    fn most_buffer_bytes(&self) -> u64 {
        self.most_buffer_bytes
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
