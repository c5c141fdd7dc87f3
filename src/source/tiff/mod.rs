//! TIFF and BigTIFF through the `tiff` crate, read one strip (or one row of tiles) at a time:
//! only the current strip or tile row is held, never the whole image.
//!
//! Accepted: grey, grey+alpha, RGB and RGBA with 8-, 16- or 32-bit unsigned, 16- or 32-bit
//! float or 16-bit signed samples ([`samples`]) stored contiguously (PlanarConfiguration 1),
//! uncompressed or compressed with LZW, Deflate or PackBits, with or without the horizontal
//! (or, for floats, floating-point) predictor; JPEG-compressed images go to [`jpeg`]
//! (libjpeg-turbo), or to [`ndpi`] where one strip is cut by restart markers; planar-separate, 1/2/4-bit, palette, CMYK and CCITT fax images to
//! [`kinds`]; Aperio's JPEG 2000 (33003/33005) to [`jp2k`] (OpenJPEG). Everything else
//! (uncompressed YCbCr, Lab, other sample formats, old-style JPEG, ...) is refused with a
//! message naming what the file is. Compressed strips are decoded a few ahead, several at once
//! ([`strips_ahead`]). Which image of a multi-image file is read: [`pyramid`].
//!
//! As libvips reads them: extra samples past grey, grey+alpha, RGB or RGBA (ExtraSamples
//! unspecified, or any after the alpha) are dropped, and associated (premultiplied) alpha is
//! turned into straight alpha ([`unpremultiply`] says how it rounds).

mod band_ahead;
mod chunks;
mod fax;
pub mod geo;
// Their tile grids serve DICOM's frames too (`source::dicom`).
pub(super) mod jp2k;
pub(super) mod jpeg;
mod kinds;
pub(super) mod libjpeg;
mod lzw;
mod ndpi;
mod ndpi_dir;
mod pitch;
mod pyramid;
// Its reading of SampleFormat and BitsPerSample serves the channel source too.
pub(super) mod samples;
// Its OME-XML scanning serves the channel source too (`source::channels`).
pub(super) mod slide;
mod strips_ahead;

use std::fs::File;
use std::io::BufReader;
use std::panic::{AssertUnwindSafe, catch_unwind};
use std::path::{Path, PathBuf};
use std::sync::Arc;

use tiff::decoder::{ChunkType, Decoder, Limits};
use tiff::tags::{CompressionMethod, PhotometricInterpretation, PlanarConfiguration, Predictor, Tag};
use tiff::{ColorType, TiffError};

use self::lzw::{OwnStrips, StripReader};
use self::strips_ahead::{StripDecoder, StripsAhead};
use super::{ImageHeader, RowSource};
use crate::error::{Result, TilerError};
use crate::pixel::{Channels, Depth, PixelLayout};

pub struct TiffSource {
    path: PathBuf,
    decoder: Decoder<BufReader<File>>,
    width: u32,
    height: u32,
    layout: PixelLayout,
    chunking: Chunking,
    compression: CompressionMethod,
    /// The file kind, page and vendor, for the summary line ([`pyramid`]).
    label: String,
    /// The directory read (workers decoding ahead open the file again and go there).
    page: usize,
    /// Samples per pixel as the decoder delivers them (the crate already drops extra samples of
    /// RGB/RGBA images; grey images keep theirs and are compacted here).
    file_samples: usize,
    /// The alpha is associated (premultiplied, ExtraSamples 1): rows are un-premultiplied.
    associated: bool,
    /// The current strip or tile row, as whole image rows of `file_samples` native-endian samples.
    band: Vec<u8>,
    /// First image row held in `band`, and how many rows it holds.
    band_first: u64,
    band_rows: u64,
    /// One decoded tile (tiled images only).
    tile: Vec<u8>,
    next: u64,
    /// Set once a strip failed: the decoder's state is not trusted after that.
    failed: bool,
    /// Uncompressed 8-bit strips, whose rows (or parts of them) are read straight from the file.
    direct: Option<DirectStrips>,
    /// The columns each row is read from, when fewer than all were asked for and the file
    /// can give them for less: `direct` strips, or tiles (only those under the columns are
    /// decoded).
    columns: Option<std::ops::Range<u32>>,
    /// Decoders for the workers of `ahead`, one per worker, where compressed strips are
    /// decoded ahead (0: on this thread).
    ahead_workers: usize,
    ahead: Option<StripsAhead>,
    /// The most [`buffer_bytes`](RowSource::buffer_bytes) can say, from the sizes chosen at open.
    most_buffer_bytes: u64,
    /// LZW or Deflate strips the workers decode with our own decoder rather than the crate's.
    own: Option<Arc<OwnStrips>>,
    max_memory: u64,
    /// Orientation (274) and ICC profile (34675), which `source::open_with` applies.
    embedded: super::Embedded,
}

/// The file offset of every strip or tile of an uncompressed 8-bit TIFF without predictor whose
/// samples are the texels as they are: a stripe or a shard narrower than the image reads
/// only its columns of each row (a 4096-texel shard of a 16384-texel image reads a quarter
/// of the bytes); a tiled one reads [`rows`](Self::rows) rows of each tile at a time, not
/// whole tiles (a row of 256-texel tiles of a 16384-texel image is 12 MiB decoded: issue 28).
struct DirectStrips {
    file: File,
    offsets: Vec<u64>,
    /// Bytes of one stored texel: SamplesPerPixel, extra samples included.
    pixel: usize,
    /// A row as stored, where its texels carry extra samples to drop; of tiles, the rows of one
    /// tile being read.
    row: Vec<u8>,
    /// Rows of each tile read at once (tiles only): as few as keep each read at least
    /// [`DIRECT_TILE_READ`] bytes.
    rows: u32,
}

/// Bytes read at once from one tile, where a tiled TIFF's rows are read straight from the file:
/// large enough that the reads' count adds little to the kernel's copy (a few per tile, 16384
/// reads for a 16384² image of 256-texel tiles), small enough that the rows held across the
/// image's width are a small part of a whole row of tiles (an eighth, for 256-texel tiles).
const DIRECT_TILE_READ: u64 = 32 << 10;

/// What a TIFF's texels hold, as stored and as delivered.
struct Samples {
    layout: PixelLayout,
    /// Samples per texel the decoder delivers.
    delivered: usize,
    /// Samples per texel in the file (SamplesPerPixel).
    stored: usize,
    /// The alpha is associated (premultiplied).
    associated: bool,
    /// What the samples are; `layout` has their size as stored.
    kind: samples::Stored,
}

#[derive(Clone, Copy)]
enum Chunking {
    /// Strips of `rows` rows (the last may be shorter).
    Strips { rows: u32 },
    /// Tiles of `width` x `height` (edge tiles are padded in the file).
    Tiles { width: u32, height: u32, across: u32 },
}

impl Chunking {
    /// Rows covered by one strip or one row of tiles.
    fn rows(self) -> u32 {
        match self {
            Chunking::Strips { rows } => rows,
            Chunking::Tiles { height, .. } => height,
        }
    }
}

/// Refuses fewer offsets or byte counts than the grid's `chunks`.
pub(super) fn enough_chunks(path: &Path, offsets: &[u64], counts: &[u64], chunks: u64, tiled: bool) -> Result<()> {
    if (offsets.len() as u64) < chunks || (counts.len() as u64) < chunks {
        let message = format!(
            "corrupt file: {} offsets and {} byte counts for {chunks} {}",
            offsets.len(),
            counts.len(),
            if tiled { "tiles" } else { "strips" }
        );
        return Err(TilerError::decode(path, message));
    }
    Ok(())
}

/// The page read and the pages of its reduced levels (`pyramid::Chosen`), read as stored
/// levels when a run asks for them (`RowSource::stored_levels`), and the memory the reader may
/// hold.
pub(crate) struct Pages {
    pub index: usize,
    pub levels: Vec<usize>,
    pub max_memory: u64,
}

impl Pages {
    /// One image with no levels of its own to copy (a DICOM instance).
    pub(crate) fn alone(max_memory: u64) -> Pages {
        Pages { index: 0, levels: Vec::new(), max_memory }
    }
}

pub fn open(path: &Path, max_memory: u64, pick: crate::source::Pick) -> Result<Box<dyn RowSource>> {
    let bigtiff = is_bigtiff(path)?;
    ndpi_dir::check_reachable(path)?;
    let mut decoder = open_decoder(path, max_memory)?;
    let chosen = pyramid::choose(path, &mut decoder, pick, bigtiff, max_memory)?;
    let embedded = super::Embedded {
        orientation: decoder
            .find_tag_unsigned::<u16>(Tag::Orientation)
            .map_err(|e| open_error(path, e))?
            .map(super::orient::Orientation::from_tag)
            .unwrap_or_default(),
        icc: profile(path, &mut decoder)?,
        geo: geo::read(&mut decoder),
        pitch: chosen.pitch,
        // The JPEG and JPEG 2000 readers say what their coding lost.
        lossy: Vec::new(),
        channel: chosen.channel.clone(),
    };
    if jpeg::is_jpeg(path, &mut decoder)? {
        // One strip cut by restart markers (Hamamatsu NDPI) is read an interval at a time.
        if let Some(source) = ndpi::open(path, &mut decoder, &chosen.label, &embedded, max_memory, chosen.index)? {
            return Ok(source);
        }
        let pages = Pages { index: chosen.index, levels: chosen.levels, max_memory };
        return jpeg::open(path, &mut decoder, chosen.label, embedded, pages);
    }
    if jp2k::is_jp2k(path, &mut decoder)? {
        let pages = Pages { index: chosen.index, levels: chosen.levels, max_memory };
        return jp2k::open(path, &mut decoder, chosen.label, embedded, pages);
    }
    if kinds::handles(path, &mut decoder)? {
        return kinds::open(path, &mut decoder, chosen.label, embedded, max_memory);
    }
    let (width, height) = decoder.dimensions().map_err(|e| open_error(path, e))?;
    let compression = check_compression(path, &mut decoder)?;
    let Samples { layout, delivered: file_samples, stored, associated, kind } = pixel_layout(path, &mut decoder)?;

    let chunking = match decoder.get_chunk_type() {
        ChunkType::Strip => {
            let (_, rows) = decoder.chunk_dimensions();
            // RowsPerStrip is often 2^32-1 ("one strip"): clamp it to the image.
            Chunking::Strips { rows: rows.clamp(1, height) }
        }
        ChunkType::Tile => {
            let (tw, th) = decoder.chunk_dimensions();
            if tw == 0 || th == 0 {
                return Err(TilerError::decode(path, format!("the TIFF declares {tw}x{th} tiles")));
            }
            Chunking::Tiles { width: tw, height: th, across: width.div_ceil(tw) }
        }
    };

    let pixel_bytes = (file_samples * layout.depth.bytes()) as u64;
    let row_bytes = width as u64 * pixel_bytes;
    let direct = match layout.depth {
        // Tiles are read into a band of the delivered texels: only where they are the stored ones.
        Depth::U8 if matches!(chunking, Chunking::Strips { .. }) || stored == file_samples => {
            direct_strips(path, &mut decoder, compression, chunking, stored, height, width)?
        }
        _ => None,
    };
    // Memory held: one strip or tile row of whole image rows, plus one tile; where rows are read
    // straight from the file, none of a strip, a few of a tile row.
    let band_rows = chunking.rows().min(height) as u64;
    let held_rows = match &direct {
        Some(direct) => (direct.rows as u64).min(band_rows),
        None => band_rows,
    };
    let tile_bytes = match chunking {
        Chunking::Strips { .. } => 0,
        Chunking::Tiles { width: tw, .. } if direct.is_some() => held_rows * tw as u64 * pixel_bytes,
        Chunking::Tiles { width: tw, height: th, .. } => tw as u64 * th as u64 * pixel_bytes,
    };
    let need = row_bytes.saturating_mul(held_rows).saturating_add(tile_bytes);
    if need > max_memory {
        let what = match chunking {
            Chunking::Strips { .. } if band_rows == height as u64 => "the TIFF is stored as a single strip".to_string(),
            Chunking::Strips { rows } => format!("the TIFF is stored in strips of {rows} rows"),
            Chunking::Tiles { width: tw, height: th, .. } => format!("the TIFF is stored in {tw}x{th} tiles"),
        };
        return Err(TilerError::unsupported(
            path,
            format!(
                "{what}, so one {} of the {width}x{height} {layout} image ({} MiB decoded) would have to be held in memory, more than --max-memory ({} MiB); raise --max-memory or re-save it with smaller strips or tiles (e.g. `tiffcp -r 64 in.tif out.tif` or `gdal_translate -co TILED=YES in.tif out.tif`)",
                if matches!(chunking, Chunking::Tiles { .. }) { "row of tiles" } else { "strip" },
                need.div_ceil(1 << 20),
                max_memory >> 20
            ),
        ));
    }
    // Our LZW and Deflate decoders' predictor and byte order are those of 8- and 16-bit samples.
    let ours =
        matches!(compression, CompressionMethod::LZW | CompressionMethod::Deflate | CompressionMethod::OldDeflate);
    let own = match ours && stored == file_samples && layout.depth.is_narrow_int() {
        true => own_strips(path, &mut decoder, chunking, row_bytes, stored, layout.depth, compression)?.map(Arc::new),
        false => None,
    };
    let ahead_workers = match chunking {
        Chunking::Strips { .. } if compression != CompressionMethod::None && height as u64 > 2 * band_rows => {
            let workers = std::thread::available_parallelism().map_or(1, |n| n.get()).min(4);
            // What the workers and the reader hold: within an eighth of --max-memory (vips
            // writes Deflate strips of 128 rows: 6 MiB each at 16384 RGB texels).
            let fits =
                strips_ahead::bytes_at_most(&ahead_shape(own.as_deref(), height, band_rows, row_bytes), workers as u64)
                    <= max_memory / 8;
            if workers > 1 && fits { workers } else { 0 }
        }
        _ => 0,
    };
    // Strips decoded ahead come in pieces the workers allocate: no band of its own.
    let band_bytes = if ahead_workers > 0 { 0 } else { row_bytes * held_rows };
    let band = vec![
        0u8;
        usize::try_from(band_bytes)
            .map_err(|_| TilerError::unsupported(path, "a strip is too large for this machine"))?
    ];
    let tile = vec![0u8; tile_bytes as usize];
    // What `buffer_bytes` can say at most: the band and the tile as allocated here, a stored row
    // of direct strips (resized to the columns read: at most twice the widest), and the pieces
    // of the strips decoded ahead with each worker's LZW window.
    let ahead_bytes = match ahead_workers as u64 {
        0 => 0,
        workers => {
            let shape = ahead_shape(own.as_deref(), height, band_rows, row_bytes);
            let windows = own.as_deref().map_or(0, |own| own.worker_bytes_at_most(band_rows * row_bytes));
            strips_ahead::bytes_at_most(&shape, workers).saturating_add(workers.saturating_mul(windows))
        }
    };
    let direct_row = direct.as_ref().map_or(0, |d| 2 * width as u64 * d.pixel as u64);
    let most_buffer_bytes = (band_bytes + tile_bytes).saturating_add(direct_row).saturating_add(ahead_bytes);

    Ok(samples::widen(
        Box::new(TiffSource {
            path: path.to_path_buf(),
            decoder,
            width,
            height,
            layout,
            chunking,
            compression,
            label: chosen.label,
            page: chosen.index,
            file_samples,
            associated,
            band,
            band_first: 0,
            band_rows: 0,
            tile,
            next: 0,
            failed: false,
            direct,
            columns: None,
            ahead_workers,
            ahead: None,
            most_buffer_bytes,
            own,
            max_memory,
            embedded,
        }),
        kind,
    ))
}

/// The associated images of the TIFF at `path` (for `source::associated`): each one's kind
/// (`label`, `macro`, `thumbnail`), directory, width and height.
pub(crate) fn associated_pages(path: &Path, max_memory: u64) -> Result<Vec<(&'static str, usize, u32, u32)>> {
    pyramid::associated_pages(path, max_memory)
}

/// The physical size of a pixel of page `page`, as [`open`] finds it for that page (its
/// `Embedded::pitch`): for a page of more samples than a texel holds, which [`open_sample`]
/// reads a channel at a time.
pub(super) fn page_pitch(path: &Path, page: usize, max_memory: u64) -> Result<Option<crate::source::PixelPitch>> {
    let page = u32::try_from(page).map_err(|_| TilerError::Options(format!("page {page}: past any TIFF's pages")))?;
    let mut decoder = open_decoder(path, max_memory)?;
    let pick = crate::source::Pick { page: Some(page), series: None };
    Ok(pyramid::choose(path, &mut decoder, pick, is_bigtiff(path)?, max_memory)?.pitch)
}

/// Sample `k` of every texel of page `page` as a grey image: a channel of an image of more
/// samples than a texel holds (`source::channels`), read by [`kinds`], the reader of samples
/// as they are stored (together or in planes, whatever the photometric calls them).
pub(super) fn open_sample(path: &Path, page: usize, k: usize, max_memory: u64) -> Result<Box<dyn RowSource>> {
    let mut decoder = open_decoder(path, max_memory)?;
    if page > 0 {
        decoder.seek_to_image(page).map_err(|e| open_error(path, e))?;
    }
    kinds::open_sample(path, &mut decoder, k, max_memory)
}

/// How strips decoded ahead are handed over: in pieces of a few rows where our own decoders
/// stream them (LZW, Deflate), else whole (the `tiff` crate decodes a strip at once).
fn ahead_shape(own: Option<&OwnStrips>, height: u32, strip_rows: u64, row_bytes: u64) -> strips_ahead::Shape {
    let piece_rows = match own {
        Some(_) => strips_ahead::Shape::rows_per_piece(row_bytes, strip_rows),
        None => strip_rows,
    };
    strips_ahead::Shape { height: height as u64, strip_rows, piece_rows, row_bytes }
}

/// [`OwnStrips`] of an LZW or Deflate TIFF stored in strips whose samples are delivered as
/// they are stored (no extra samples dropped, no WhiteIsZero inversion).
fn own_strips(
    path: &Path,
    decoder: &mut Decoder<BufReader<File>>,
    chunking: Chunking,
    row_bytes: u64,
    samples: usize,
    depth: Depth,
    compression: CompressionMethod,
) -> Result<Option<OwnStrips>> {
    let Chunking::Strips { .. } = chunking else { return Ok(None) };
    let tag = |decoder: &mut Decoder<BufReader<File>>, t| {
        decoder.find_tag_unsigned::<u16>(t).map_err(|e| open_error(path, e))
    };
    if tag(decoder, Tag::PhotometricInterpretation)? == Some(0) {
        return Ok(None);
    }
    let predictor = match tag(decoder, Tag::Predictor)?.unwrap_or(1) {
        1 => false,
        2 => true,
        _ => return Ok(None),
    };
    let sixteen_bit = depth == Depth::U16;
    let offsets = decoder.get_tag_u64_vec(Tag::StripOffsets).map_err(|e| open_error(path, e))?;
    let counts = decoder.get_tag_u64_vec(Tag::StripByteCounts).map_err(|e| open_error(path, e))?;
    let big_endian = decoder.byte_order() == tiff::tags::ByteOrder::BigEndian;
    let row_bytes = row_bytes as usize;
    let deflate = compression != CompressionMethod::LZW;
    Ok(Some(OwnStrips { offsets, counts, row_bytes, samples, sixteen_bit, big_endian, predictor, deflate }))
}

/// The first directory's `Software` tag, where `path` is a TIFF that has one: how `split`
/// recognises a TIFF it wrote before (`output::claim`).
pub(crate) fn software(path: &Path) -> Option<String> {
    let mut decoder = open_decoder(path, 64 << 20).ok()?;
    decoder.get_tag_ascii_string(Tag::Software).ok()
}

/// A decoder of the TIFF's first image, its buffers bounded by `max_memory`.
pub(super) fn open_decoder(path: &Path, max_memory: u64) -> Result<Decoder<BufReader<File>>> {
    let file = File::open(path).map_err(|e| TilerError::io(path, e))?;
    // The first directory is read with the crate's default limits (256 MiB of tag values, ample
    // for the strip tables of any image this tool can take); the limits below apply to the rest.
    let decoder = Decoder::new(BufReader::with_capacity(1 << 16, file)).map_err(|e| match e {
        // A seek past 2^63 bytes: the header's offset of the first directory, which the crate
        // does not name.
        TiffError::IoError(io) if io.kind() == std::io::ErrorKind::InvalidInput => match first_ifd_offset(path) {
            Some(offset) => TilerError::decode(
                path,
                format!("not a readable TIFF: the header's first directory offset ({offset}) lies past any file"),
            ),
            None => open_error(path, TiffError::IoError(io)),
        },
        e => open_error(path, e),
    })?;
    let max = usize::try_from(max_memory).unwrap_or(usize::MAX);
    let mut limits = Limits::default();
    // Bounds every buffer the crate allocates itself (tag value arrays, whole-chunk results).
    limits.decoding_buffer_size = max;
    limits.ifd_value_size = max;
    // Checked against a chunk's *compressed* byte count. None of the accepted compressions buffer
    // the compressed chunk (they stream it from the file), and an uncompressed strip of a wide
    // image easily exceeds the crate's 128 MiB default, so this limit is lifted; the decoded size
    // of a strip or tile row is checked against --max-memory below instead.
    limits.intermediate_buffer_size = usize::MAX;
    Ok(decoder.with_limits(limits))
}

/// The ICC profile (tag 34675) of `decoder`'s current directory, its size checked against
/// [`MAX_PROFILE_BYTES`](super::icc::MAX_PROFILE_BYTES) before it is read.
fn profile(path: &Path, decoder: &mut Decoder<BufReader<File>>) -> Result<Option<Vec<u8>>> {
    let Some(entry) = decoder.image_ifd().find_entry(Tag::IccProfile) else { return Ok(None) };
    if entry.count() > super::icc::MAX_PROFILE_BYTES {
        return Err(super::icc::too_large(path, Some(entry.count()), "TIFF tag 34675"));
    }
    let value = decoder.get_tag(Tag::IccProfile).map_err(|e| open_error(path, e))?;
    let bytes = value.into_u8_vec().map_err(|_| {
        TilerError::decode(path, "the ICC profile (TIFF tag 34675) is not a run of bytes: a damaged tag")
    })?;
    Ok(Some(bytes))
}

/// The ImageDescription (tag 270) of `decoder`'s current directory, "" without one (or one
/// that is not ASCII text). Its size is checked before it is read: one larger than
/// `--max-memory` is an error naming the tag (the `tiff` crate would print a debug line to
/// stderr and fail without saying which tag).
pub(super) fn description(path: &Path, decoder: &mut Decoder<BufReader<File>>, max_memory: u64) -> Result<String> {
    let Some(entry) = decoder.image_ifd().find_entry(Tag::ImageDescription) else { return Ok(String::new()) };
    if entry.count() > max_memory {
        return Err(TilerError::unsupported(
            path,
            format!(
                "its ImageDescription (tag 270, an OME-XML document or a vendor's text) holds {} bytes, more than --max-memory ({}); raise --max-memory",
                entry.count(),
                crate::limits::human_bytes(max_memory)
            ),
        ));
    }
    Ok(decoder.get_tag_ascii_string(Tag::ImageDescription).unwrap_or_default())
}

/// [`DirectStrips`] of an 8-bit TIFF, if its strips hold rows as the texels they are, each of
/// `stored` samples (extra samples included, dropped as rows are read).
fn direct_strips(
    path: &Path,
    decoder: &mut Decoder<BufReader<File>>,
    compression: CompressionMethod,
    chunking: Chunking,
    stored: usize,
    height: u32,
    width: u32,
) -> Result<Option<DirectStrips>> {
    let tag = |decoder: &mut Decoder<BufReader<File>>, t| {
        decoder.find_tag_unsigned::<u16>(t).map_err(|e| open_error(path, e))
    };
    let as_is = compression == CompressionMethod::None
        && tag(decoder, Tag::Predictor)?.unwrap_or(1) == 1
        && tag(decoder, Tag::PhotometricInterpretation)? != Some(0); // WhiteIsZero is inverted
    if !as_is {
        return Ok(None);
    }
    // Per strip or tile: the bytes its rows need (an edge tile is stored whole, padded), and
    // what it is called in an error.
    let (offsets_tag, counts_tag, chunks, need, rows_at_once): (_, _, u32, Box<dyn Fn(u32) -> u64>, u32) =
        match chunking {
            Chunking::Strips { rows } => {
                let row_bytes = width as u64 * stored as u64;
                let need = move |strip: u32| rows.min(height - strip * rows) as u64 * row_bytes;
                (Tag::StripOffsets, Tag::StripByteCounts, height.div_ceil(rows), Box::new(need), 0)
            }
            Chunking::Tiles { width: tw, height: th, across } => {
                let tile_row = tw as u64 * stored as u64;
                let rows = DIRECT_TILE_READ.div_ceil(tile_row).min(th as u64) as u32;
                let tiles = across.saturating_mul(height.div_ceil(th));
                (Tag::TileOffsets, Tag::TileByteCounts, tiles, Box::new(move |_| th as u64 * tile_row), rows)
            }
        };
    let what = if rows_at_once == 0 { "strip" } else { "tile" };
    let offsets = decoder.get_tag_u64_vec(offsets_tag).map_err(|e| open_error(path, e))?;
    // A row read straight from the file must lie inside its strip or tile, not run on into
    // whatever follows a short one: an uncompressed chunk holds its rows whole, or the file is
    // corrupt.
    let counts = decoder.get_tag_u64_vec(counts_tag).map_err(|e| open_error(path, e))?;
    for chunk in 0..chunks {
        let need = need(chunk);
        let (count, offset) = (counts.get(chunk as usize), offsets.get(chunk as usize));
        if count.is_none_or(|&c| c < need) || offset.is_none() {
            let holds = count.map_or("no byte count".to_string(), |c| format!("{c} bytes"));
            let message = format!("corrupt TIFF: uncompressed {what} {chunk} holds {holds}, its rows need {need}");
            return Err(TilerError::decode(path, message));
        }
    }
    let file = File::open(path).map_err(|e| TilerError::io(path, e))?;
    Ok(Some(DirectStrips { file, offsets, pixel: stored, row: Vec::new(), rows: rows_at_once }))
}

/// Whether the file is a BigTIFF (only for the summary line; the crate reads both).
/// The first directory's offset as the header gives it (bytes 4-7 of a TIFF, 8-15 of a
/// BigTIFF, in the byte order of bytes 0-1), for an error message; `None` for a header too
/// short or not a TIFF's.
fn first_ifd_offset(path: &Path) -> Option<u64> {
    use std::io::Read;
    let mut head = [0u8; 16];
    File::open(path).ok()?.read_exact(&mut head).ok()?;
    let little = match &head[..2] {
        b"II" => true,
        b"MM" => false,
        _ => return None,
    };
    let (at, width) = if is_bigtiff(path).ok()? { (8, 8) } else { (4, 4) };
    let mut bytes = [0u8; 8];
    if little {
        bytes[..width].copy_from_slice(&head[at..at + width]);
        Some(u64::from_le_bytes(bytes))
    } else {
        bytes[8 - width..].copy_from_slice(&head[at..at + width]);
        Some(u64::from_be_bytes(bytes))
    }
}

fn is_bigtiff(path: &Path) -> Result<bool> {
    use std::io::Read;
    let mut head = [0u8; 4];
    let mut file = File::open(path).map_err(|e| TilerError::io(path, e))?;
    let n = file.read(&mut head).map_err(|e| TilerError::io(path, e))?;
    Ok(n == 4 && (head == *b"II+\0" || head == *b"MM\0+"))
}

/// The image's size, refused where it has no pixels.
pub(super) fn dimensions(path: &Path, decoder: &mut Decoder<BufReader<File>>) -> Result<(u32, u32)> {
    let (width, height) = decoder.dimensions().map_err(|e| open_error(path, e))?;
    if width == 0 || height == 0 {
        return Err(TilerError::decode(path, format!("the TIFF says {width}x{height}: the image has no pixels")));
    }
    Ok((width, height))
}

pub(super) fn open_error(path: &Path, e: TiffError) -> TilerError {
    match e {
        TiffError::UnsupportedError(u) => TilerError::unsupported(path, format!("unsupported TIFF: {u}")),
        TiffError::LimitsExceeded => {
            TilerError::unsupported(path, "the TIFF's tag data exceeds the decoder's memory limits; raise --max-memory")
        }
        TiffError::IoError(io) if io.kind() == std::io::ErrorKind::UnexpectedEof => {
            TilerError::decode(path, "truncated TIFF: the file ends inside its header or a directory")
        }
        other => TilerError::decode(path, format!("not a readable TIFF: {other}")),
    }
}

/// Which reader decodes a TIFF compression.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Reader {
    /// The `tiff` crate's chunk reader, and ours in `kinds` (planar, palette, CMYK, sub-byte).
    Chunks,
    /// libjpeg-turbo (`jpeg.rs`; `ndpi.rs` for one strip cut by restart markers).
    Jpeg,
    /// OpenJPEG (`jp2k.rs`): Aperio's two forms.
    Jpeg2000,
    /// The fax decoders of `kinds` (`fax.rs`): 1-bit images only.
    Fax,
}

/// Every TIFF compression read, by its Compression (tag 259) code, with its name and its
/// reader. The dispatch in [`open`] and every message listing what is read come from here.
pub(super) const COMPRESSIONS: [(u16, &str, Reader); 11] = [
    (1, "uncompressed", Reader::Chunks),
    (5, "LZW", Reader::Chunks),
    (8, "Deflate", Reader::Chunks),
    (32946, "Deflate (old code)", Reader::Chunks),
    (32773, "PackBits", Reader::Chunks),
    (7, "JPEG", Reader::Jpeg),
    (33003, "Aperio JPEG 2000 YCbCr", Reader::Jpeg2000),
    (33005, "Aperio JPEG 2000 RGB", Reader::Jpeg2000),
    (2, "CCITT modified Huffman", Reader::Fax),
    (3, "CCITT Group 3 fax", Reader::Fax),
    (4, "CCITT Group 4 fax", Reader::Fax),
];

/// The reader of compression `code`, `None` for one not read.
pub(super) fn reader_of(code: u16) -> Option<Reader> {
    COMPRESSIONS.iter().find(|c| c.0 == code).map(|c| c.2)
}

/// The compression of `decoder`'s current image (1, none, where the tag is absent).
pub(super) fn compression_code(path: &Path, decoder: &mut Decoder<BufReader<File>>) -> Result<u16> {
    Ok(decoder.find_tag_unsigned(Tag::Compression).map_err(|e| open_error(path, e))?.unwrap_or(1))
}

/// "uncompressed (1), LZW (5), ...": the compressions the `readers` read, from [`COMPRESSIONS`].
pub(super) fn compressions_read(readers: &[Reader]) -> String {
    let names: Vec<String> =
        COMPRESSIONS.iter().filter(|c| readers.contains(&c.2)).map(|c| format!("{} ({})", c.1, c.0)).collect();
    names.join(", ")
}

/// The compression of an image the chunk reader reads, refused (naming what is read) where it
/// is not one of its [`Reader::Chunks`] compressions.
pub(super) fn check_compression(path: &Path, decoder: &mut Decoder<BufReader<File>>) -> Result<CompressionMethod> {
    let code = compression_code(path, decoder)?;
    let method = CompressionMethod::from_u16_exhaustive(code);
    let named = COMPRESSIONS.iter().find(|c| c.0 == code);
    match named {
        Some((_, _, Reader::Chunks)) => Ok(method),
        // Read by another reader, but not for an image of this kind (a channel set's page of more
        // than four samples): that reader took the others before this was asked.
        Some((_, name, _)) => Err(TilerError::unsupported(
            path,
            format!(
                "TIFF compression {name} ({code}) is not supported for this image (its samples are read from {}); re-save it with one of those, e.g. `tiffcp -c lzw in.tif out.tif`",
                compressions_read(&[Reader::Chunks])
            ),
        )),
        None if code == 6 => Err(TilerError::unsupported(
            path,
            "TIFF compression 6 (old-style JPEG, withdrawn in 1995) is not supported (new-style JPEG, compression 7, is); re-save it with libtiff, e.g. `tiffcp -c jpeg in.tif out.tif`",
        )),
        None => {
            let name = match method {
                CompressionMethod::ZSTD => "Zstandard".to_string(),
                CompressionMethod::WebP => "WebP".to_string(),
                _ => format!("code {code}"),
            };
            let all = [Reader::Chunks, Reader::Jpeg, Reader::Jpeg2000, Reader::Fax];
            Err(TilerError::unsupported(
                path,
                format!(
                    "TIFF compression {name} is not supported (these are read: {}; the fax codes for 1-bit images); re-save it with one of those, e.g. `tiffcp -c lzw in.tif out.tif`",
                    compressions_read(&all)
                ),
            ))
        }
    }
}

/// The output layout, and the samples per texel as stored and as the decoder delivers them.
fn pixel_layout(path: &Path, decoder: &mut Decoder<BufReader<File>>) -> Result<Samples> {
    let tag_err = |e| open_error(path, e);
    let photometric_code: Option<u16> = decoder.find_tag_unsigned(Tag::PhotometricInterpretation).map_err(tag_err)?;
    let photometric = photometric_code.and_then(PhotometricInterpretation::from_u16);
    let unsupported = |what: String| {
        Err(TilerError::unsupported(
            path,
            format!(
                "{what} TIFF is not supported (grey, grey+alpha, RGB and RGBA of 8/16/32-bit unsigned, 16/32-bit float or 16-bit signed samples are); convert it first, e.g. to 8-bit RGB"
            ),
        ))
    };
    match photometric {
        Some(
            PhotometricInterpretation::WhiteIsZero
            | PhotometricInterpretation::BlackIsZero
            | PhotometricInterpretation::RGB,
        ) => {}
        Some(PhotometricInterpretation::RGBPalette) => return unsupported("a palette (indexed colour)".into()),
        Some(PhotometricInterpretation::CMYK) => return unsupported("a CMYK (separated)".into()),
        Some(PhotometricInterpretation::YCbCr) => return unsupported("a YCbCr".into()),
        Some(PhotometricInterpretation::TransparencyMask) => return unsupported("a transparency-mask".into()),
        Some(
            PhotometricInterpretation::CIELab | PhotometricInterpretation::IccLab | PhotometricInterpretation::ItuLab,
        ) => {
            return unsupported("a CIE L*a*b*".into());
        }
        Some(other) => return unsupported(format!("a {other:?}")),
        None => match photometric_code {
            Some(code) => return unsupported(format!("a photometric interpretation {code}")),
            None => return Err(TilerError::decode(path, "the TIFF has no PhotometricInterpretation tag")),
        },
    }

    let formats: Vec<u16> = decoder.find_tag_unsigned_vec(Tag::SampleFormat).map_err(tag_err)?.unwrap_or_default();
    let bits: Vec<u16> = decoder.find_tag_unsigned_vec(Tag::BitsPerSample).map_err(tag_err)?.unwrap_or_else(|| vec![1]);
    let kind = match samples::stored(&formats, &bits) {
        Ok(kind) => kind,
        Err(what) => return unsupported(what),
    };
    let depth = kind.file_depth();
    let samples: u16 = decoder.find_tag_unsigned(Tag::SamplesPerPixel).map_err(tag_err)?.unwrap_or(1);
    let planar: u16 = decoder.find_tag_unsigned(Tag::PlanarConfiguration).map_err(tag_err)?.unwrap_or(1);
    if PlanarConfiguration::from_u16(planar) != Some(PlanarConfiguration::Chunky) && samples > 1 {
        return unsupported("a planar-separate (one plane per channel, PlanarConfiguration 2)".into());
    }
    let predictor: u16 = decoder.find_tag_unsigned(Tag::Predictor).map_err(tag_err)?.unwrap_or(1);
    match Predictor::from_u16(predictor) {
        Some(Predictor::None | Predictor::Horizontal) => {}
        // The crate undoes it for floats (and refuses it on other samples).
        Some(Predictor::FloatingPoint) if depth.is_float() => {}
        _ => return unsupported(format!("a predictor-{predictor}")),
    }
    let extra: Vec<u16> = decoder.find_tag_unsigned_vec(Tag::ExtraSamples).map_err(tag_err)?.unwrap_or_default();
    let first_extra_is_alpha = matches!(extra.first(), Some(1 | 2));

    let colour = decoder.colortype().map_err(|e| open_error(path, e))?;
    let (channels, file_samples) = match colour {
        ColorType::Gray(_) => (Channels::Grey, 1),
        ColorType::Multiband { num_samples, .. } if photometric != Some(PhotometricInterpretation::RGB) => {
            if photometric == Some(PhotometricInterpretation::WhiteIsZero) {
                return unsupported("a WhiteIsZero grey with extra samples".into());
            }
            let channels = if first_extra_is_alpha { Channels::GreyAlpha } else { Channels::Grey };
            (channels, num_samples as usize)
        }
        ColorType::RGB(_) => (Channels::Rgb, 3),
        ColorType::RGBA(_) => (Channels::Rgba, 4),
        other => return unsupported(format!("a {other:?}")),
    };
    // ExtraSamples 1 is associated alpha: colours premultiplied by it, which vips undoes.
    let associated = channels.has_alpha() && extra.first() == Some(&1);
    if !depth.is_narrow_int() && (associated || photometric == Some(PhotometricInterpretation::WhiteIsZero)) {
        let what = if associated { "associated (premultiplied) alpha" } else { "WhiteIsZero" };
        return unsupported(format!("a {}-bit {} {what}", depth.bytes() * 8, depth.tile_type()));
    }
    Ok(Samples {
        layout: PixelLayout::new(channels, depth),
        delivered: file_samples,
        stored: samples as usize,
        associated,
        kind,
    })
}

impl TiffSource {
    /// Decodes the strip or tile row holding image row `y` into `band`.
    fn load_band(&mut self, y: u64) -> Result<()> {
        let rows_per = self.chunking.rows() as u64;
        let index = (y / rows_per) as u32;
        // Tiles read straight from the file: the few rows of the tile row from `y`'s on.
        let (first, end) = match &self.direct {
            Some(DirectStrips { rows: at_once @ 1.., .. }) => {
                let first = y - y % rows_per + (y % rows_per) / *at_once as u64 * *at_once as u64;
                (first, (first + *at_once as u64).min((index as u64 + 1) * rows_per))
            }
            _ => (index as u64 * rows_per, (index as u64 + 1) * rows_per),
        };
        let rows = end.min(self.height as u64) - first;
        let row_bytes = self.width as usize * self.file_samples * self.layout.depth.bytes();
        let strip_bytes = row_bytes * rows as usize;
        let result = match self.chunking {
            Chunking::Tiles { width: tw, across, .. } if self.direct.is_some() => {
                let tiles = match &self.columns {
                    Some(c) => c.start / tw..c.end.div_ceil(tw),
                    None => 0..across,
                };
                let within = first % rows_per;
                self.read_direct_tiles(index, tiles, within, rows as usize, row_bytes)
            }
            Chunking::Strips { .. } if self.ahead_workers > 0 => {
                // A piece of the strip, from `y`'s row on: its rows are the band.
                match self.take_strip_ahead(y, row_bytes) {
                    Ok((first, rows)) => {
                        (self.band_first, self.band_rows) = (first, rows);
                        return Ok(());
                    }
                    Err(m) => Err((format!("strip {index}"), m)),
                }
            }
            Chunking::Strips { .. } => {
                let (decoder, band) = (&mut self.decoder, &mut self.band[..strip_bytes]);
                guarded(|| decoder.read_chunk_bytes(index, band)).map_err(|m| (format!("strip {index}"), m))
            }
            Chunking::Tiles { width: tw, across, .. } => {
                let (decoder, band) = (&mut self.decoder, &mut self.band[..strip_bytes]);
                let pixel_bytes = self.file_samples * self.layout.depth.bytes();
                let mut result = Ok(());
                let tiles = match &self.columns {
                    Some(c) => c.start / tw..c.end.div_ceil(tw),
                    None => 0..across,
                };
                for col in tiles {
                    let chunk = index * across + col;
                    let x0 = col as usize * tw as usize;
                    let data_w = (tw as usize).min(self.width as usize - x0);
                    let tile_row = data_w * pixel_bytes;
                    let tile = &mut self.tile[..tile_row * rows as usize];
                    if let Err(m) = guarded(|| decoder.read_chunk_bytes(chunk, tile)) {
                        result = Err((format!("tile {chunk} (tile row {index}, column {col})"), m));
                        break;
                    }
                    for (dst, src) in band.chunks_exact_mut(row_bytes).zip(tile.chunks_exact(tile_row)) {
                        dst[x0 * pixel_bytes..][..tile_row].copy_from_slice(src);
                    }
                }
                result
            }
        };
        if let Err((chunk, message)) = result {
            self.failed = true;
            return Err(TilerError::DecodeRow {
                path: self.path.clone(),
                row: y,
                message: format!("{chunk} (rows {first}..{}): {message}", first + rows),
            });
        }
        self.band_first = first;
        self.band_rows = rows;
        Ok(())
    }
}

impl TiffSource {
    /// Rows `within..within + rows` of the tiles `tiles` of tile row `index`, read straight from
    /// the file into `band` (each tile's rows are one read, into `tile`).
    fn read_direct_tiles(
        &mut self,
        index: u32,
        tiles: std::ops::Range<u32>,
        within: u64,
        rows: usize,
        row_bytes: usize,
    ) -> std::result::Result<(), (String, String)> {
        let Chunking::Tiles { width: tw, across, .. } = self.chunking else { return Ok(()) };
        let Some(direct) = &self.direct else { return Ok(()) };
        let tile_row = tw as usize * direct.pixel;
        let read = &mut self.tile[..tile_row * rows];
        for col in tiles {
            let chunk = index * across + col;
            let x0 = col as usize * tw as usize;
            let data = (tw as usize).min(self.width as usize - x0) * direct.pixel;
            let at = direct.offsets[chunk as usize] + within * tile_row as u64;
            if std::os::unix::fs::FileExt::read_exact_at(&direct.file, read, at).is_err() {
                let message = "the tile is not where its offset says (a truncated file?)".to_string();
                return Err((format!("tile {chunk} (tile row {index}, column {col})"), message));
            }
            for (dst, src) in self.band.chunks_exact_mut(row_bytes).zip(read.chunks_exact(tile_row)) {
                dst[x0 * direct.pixel..][..data].copy_from_slice(&src[..data]);
            }
        }
        Ok(())
    }

    /// The piece holding image row `y` from the workers decoding ahead, into `band`: its first
    /// row and its rows. They are started at `y`'s strip if they are not at `y` (the first
    /// strip, or after a skip or a rewind), and the pieces of that strip above `y` passed over.
    fn take_strip_ahead(&mut self, y: u64, row_bytes: usize) -> std::result::Result<(u64, u64), String> {
        let strip_rows = self.chunking.rows() as u64;
        let mut ahead = match self.ahead.take() {
            Some(ahead) if ahead.next_row() == y => ahead,
            elsewhere => {
                drop(elsewhere); // stops its workers
                self.start_ahead((y / strip_rows) as u32, row_bytes)?
            }
        };
        loop {
            let piece = ahead.take(std::mem::take(&mut self.band));
            let (first, band) = piece?;
            self.band = band;
            let rows = (self.band.len() / row_bytes.max(1)) as u64;
            if y < first + rows {
                self.ahead = Some(ahead);
                return Ok((first, rows));
            }
        }
    }

    /// One worker per `ahead_workers`, each with a decoder of its own, from strip `first` on.
    fn start_ahead(&self, first: u32, row_bytes: usize) -> std::result::Result<StripsAhead, String> {
        let decoders = (0..self.ahead_workers)
            .map(|_| -> std::result::Result<Box<dyn StripDecoder>, String> {
                if let Some(strips) = &self.own {
                    let file = File::open(&self.path).map_err(|e| TilerError::io(&self.path, e).to_string())?;
                    return Ok(Box::new(StripReader::new(file, Arc::clone(strips))));
                }
                let mut decoder = open_decoder(&self.path, self.max_memory).map_err(|e| e.to_string())?;
                if self.page > 0 {
                    decoder.seek_to_image(self.page).map_err(|e| e.to_string())?;
                }
                Ok(Box::new(WholeStrips { decoder, strip: 0 }))
            })
            .collect::<std::result::Result<Vec<_>, _>>()?;
        let shape = ahead_shape(self.own.as_deref(), self.height, self.chunking.rows() as u64, row_bytes as u64);
        StripsAhead::start(decoders, first, shape).map_err(|e| format!("cannot start the strip decoders: {e}"))
    }
}

/// The `tiff` crate's decoder, for a worker: a strip can only be decoded whole.
struct WholeStrips {
    decoder: Decoder<BufReader<File>>,
    strip: u32,
}

impl StripDecoder for WholeStrips {
    fn begin(&mut self, strip: u32) -> std::result::Result<(), String> {
        self.strip = strip;
        Ok(())
    }

    fn fill(&mut self, out: &mut [u8]) -> std::result::Result<(), String> {
        let (decoder, strip) = (&mut self.decoder, self.strip);
        guarded(|| decoder.read_chunk_bytes(strip, out))
    }
}

/// Why row `y` of a `height`-row image cannot be read into `out_len` bytes of `columns` of
/// `pixel`-byte texels, if it cannot (both TIFF sources check the same).
fn check_row(
    y: u64,
    height: u32,
    columns: &std::ops::Range<u32>,
    pixel: usize,
    out_len: usize,
) -> std::result::Result<(), String> {
    if y >= height as u64 {
        return Err("read past the last row".into());
    }
    let want = columns.len() * pixel;
    if out_len != want {
        return Err(format!("row buffer has {out_len} bytes, expected {want}"));
    }
    Ok(())
}

/// Runs a chunk read, turning both its errors and any panic inside the crate (which a corrupt
/// file should not cause, but a decoder bug must not take the whole run down) into a message.
pub(super) fn guarded(read: impl FnOnce() -> tiff::TiffResult<()>) -> std::result::Result<(), String> {
    match catch_unwind(AssertUnwindSafe(read)) {
        Ok(Ok(())) => Ok(()),
        Ok(Err(TiffError::IoError(e))) if e.kind() == std::io::ErrorKind::UnexpectedEof => {
            Err(format!("the file ends early (truncated TIFF): {e}"))
        }
        Ok(Err(e)) => Err(format!("corrupt or undecodable TIFF data: {e}")),
        Err(panic) => {
            let what = panic
                .downcast_ref::<String>()
                .map(String::as_str)
                .or_else(|| panic.downcast_ref::<&str>().copied())
                .unwrap_or("unknown panic");
            Err(format!("the TIFF decoder failed: {what}"))
        }
    }
}

impl RowSource for TiffSource {
    fn header(&self) -> ImageHeader {
        ImageHeader { width: self.width, height: self.height, layout: self.layout }
    }

    fn embedded(&self) -> super::Embedded {
        self.embedded.clone()
    }

    fn read_row(&mut self, out: &mut [u8]) -> Result<()> {
        let y = self.next;
        let fail = |message: String| TilerError::DecodeRow { path: self.path.clone(), row: y, message };
        let columns = self.columns.clone().unwrap_or(0..self.width);
        let out_pixel = self.layout.bytes_per_pixel();
        check_row(y, self.height, &columns, out_pixel, out.len()).map_err(fail)?;
        if let (Some(direct), Chunking::Strips { rows }) = (&mut self.direct, self.chunking) {
            // Straight from the file, whole rows or a part: into `out` with no band and no copy,
            // or, where texels carry extra samples, through one stored row.
            let strip = (y / rows as u64) as usize;
            let within = (y % rows as u64) * self.width as u64 + columns.start as u64;
            let at = direct.offsets.get(strip).map(|o| o + within * direct.pixel as u64);
            let as_stored = direct.pixel == out_pixel;
            if !as_stored {
                direct.row.resize(columns.len() * direct.pixel, 0);
            }
            let into = if as_stored { &mut *out } else { &mut direct.row[..] };
            if at.is_none_or(|at| std::os::unix::fs::FileExt::read_exact_at(&direct.file, into, at).is_err()) {
                let message = format!("strip {strip} is not where its offset says (a truncated file?)");
                return Err(TilerError::DecodeRow { path: self.path.clone(), row: y, message });
            }
            if !as_stored {
                keep_leading(out, out_pixel, &direct.row, direct.pixel);
            }
        } else {
            self.read_band_row(y, out, columns)?;
        }
        if self.associated {
            unpremultiply(out, self.layout);
        }
        self.next += 1;
        Ok(())
    }

    /// The decoded strip, piece of a strip or row of tiles, the one tile, a stored row and the
    /// pieces the workers decoded ahead, are decoding or keep spare.
    fn buffer_bytes(&self) -> u64 {
        let row = self.direct.as_ref().map_or(0, |d| d.row.capacity());
        let ahead = self.ahead.as_ref().map_or(0, StripsAhead::held_bytes);
        (self.band.capacity() + self.tile.capacity() + row) as u64 + ahead
    }

    fn most_buffer_bytes(&self) -> u64 {
        self.most_buffer_bytes
    }

    /// Strips and tiles are found by row: the next read loads the one it needs.
    fn skip_rows(&mut self, rows: u32) -> Result<()> {
        self.next += rows as u64;
        Ok(())
    }

    /// Uncompressed 8-bit strips are read in part and only the tiles under the columns are
    /// decoded; other strips decode whole rows.
    fn read_columns(&mut self, columns: std::ops::Range<u32>) -> bool {
        let part = columns != (0..self.width);
        let can = self.direct.is_some() || matches!(self.chunking, Chunking::Tiles { .. });
        let columns = (part && can).then_some(columns);
        if columns != self.columns {
            // A loaded row of tiles may lack the tiles under the new columns.
            (self.columns, self.band_rows) = (columns, 0);
        }
        self.columns.is_some() || !part
    }

    fn describe(&self) -> String {
        let kind = &self.label;
        let compression = match self.compression {
            CompressionMethod::None => "uncompressed",
            CompressionMethod::LZW => "lzw",
            CompressionMethod::Deflate | CompressionMethod::OldDeflate => "deflate",
            CompressionMethod::PackBits => "packbits",
            _ => "compressed",
        };
        match self.chunking {
            Chunking::Strips { rows } => {
                let at_once = match self.ahead_workers {
                    0 => String::new(),
                    n => format!(", {n} decoded at once"),
                };
                format!("{kind}, {compression}, streamed by strip ({rows} rows{at_once})")
            }
            Chunking::Tiles { width, height, .. } => {
                format!("{kind}, {compression}, streamed by tile row ({width}x{height} tiles)")
            }
        }
    }
}

impl TiffSource {
    /// Row `y` (the `columns` of it) out of the strip or tile row holding it, decoded into
    /// `band` first if it is not there.
    fn read_band_row(&mut self, y: u64, out: &mut [u8], columns: std::ops::Range<u32>) -> Result<()> {
        let fail = |message: String| TilerError::DecodeRow { path: self.path.clone(), row: y, message };
        if self.failed {
            return Err(fail("an earlier strip failed to decode".into()));
        }
        if y >= self.band_first + self.band_rows {
            self.load_band(y)?;
        }
        let sample = self.layout.depth.bytes();
        let file_pixel = self.file_samples * sample;
        let row_bytes = self.width as usize * file_pixel;
        let row = &self.band[(y - self.band_first) as usize * row_bytes..][..row_bytes];
        let row = &row[columns.start as usize * file_pixel..columns.end as usize * file_pixel];
        // The crate has already converted samples to native byte order (and applied the
        // predictor and WhiteIsZero inversion); only surplus extra samples are dropped here.
        keep_leading(out, self.layout.bytes_per_pixel(), row, file_pixel);
        Ok(())
    }
}

/// Copies the first `out_pixel` bytes of each `pixel`-byte texel of `row` into `out`: extra
/// samples dropped.
fn keep_leading(out: &mut [u8], out_pixel: usize, row: &[u8], pixel: usize) {
    if pixel == out_pixel {
        out.copy_from_slice(row);
    } else {
        for (o, i) in out.chunks_exact_mut(out_pixel).zip(row.chunks_exact(pixel)) {
            o.copy_from_slice(&i[..out_pixel]);
        }
    }
}

/// Straight alpha from associated (premultiplied) alpha, as libvips's TIFF loader gives it: each
/// colour sample times `max / alpha`, in single precision, truncated and clamped to `max` (255
/// or 65535); a texel of alpha 0 has colour 0. Matches libvips 8.18 on every 8-bit pair of
/// sample and alpha.
fn unpremultiply(row: &mut [u8], layout: PixelLayout) {
    let (b, n) = (layout.depth.bytes(), layout.channels.count());
    let max = if b == 1 { 255.0f32 } else { 65535.0 };
    let get = |s: &[u8]| if b == 1 { s[0] as f32 } else { u16::from_ne_bytes([s[0], s[1]]) as f32 };
    for texel in row.chunks_exact_mut(n * b) {
        let (colour, alpha) = texel.split_at_mut((n - 1) * b);
        let alpha = get(alpha);
        let factor = if alpha == 0.0 { 0.0 } else { max / alpha };
        for sample in colour.chunks_exact_mut(b) {
            // `as` truncates toward zero, as vips's cast does.
            let v = (get(sample) * factor).min(max) as u16;
            if b == 1 {
                sample[0] = v as u8;
            } else {
                sample.copy_from_slice(&v.to_ne_bytes());
            }
        }
    }
}

#[cfg(test)]
mod tests {
    use super::*;
    use crate::source::read_all;

    /// The first page, as `source::open` reads it.
    fn open(path: &Path, max_memory: u64) -> Result<Box<dyn RowSource>> {
        super::open(path, max_memory, crate::source::Pick::default())
    }
    use tiff::encoder::{Compression, DeflateLevel, TiffEncoder, TiffKind, colortype};

    /// The `image` crate's whole-image decode, as native-endian bytes.
    fn image_crate_decode(path: &Path) -> (PixelLayout, Vec<u8>) {
        use image::DynamicImage as D;
        let layout = |c, d| PixelLayout::new(c, d);
        match image::open(path).unwrap() {
            D::ImageLuma8(i) => (layout(Channels::Grey, Depth::U8), i.into_raw()),
            D::ImageRgb8(i) => (layout(Channels::Rgb, Depth::U8), i.into_raw()),
            D::ImageRgba8(i) => (layout(Channels::Rgba, Depth::U8), i.into_raw()),
            D::ImageLuma16(i) => (layout(Channels::Grey, Depth::U16), bytemuck::cast_slice(&i.into_raw()).to_vec()),
            D::ImageRgb16(i) => (layout(Channels::Rgb, Depth::U16), bytemuck::cast_slice(&i.into_raw()).to_vec()),
            D::ImageRgba16(i) => (layout(Channels::Rgba, Depth::U16), bytemuck::cast_slice(&i.into_raw()).to_vec()),
            other => panic!("unexpected {:?}", other.color()),
        }
    }

    /// A deterministic pattern with gradients, edges and noise, `samples` values per pixel.
    fn pattern(width: u32, height: u32, samples: usize, max: u32) -> Vec<u32> {
        let mut state = 0x1234_5678u32;
        let mut v = Vec::with_capacity((width * height) as usize * samples);
        for y in 0..height {
            for x in 0..width {
                for c in 0..samples as u32 {
                    state = state.wrapping_mul(1_664_525).wrapping_add(1_013_904_223);
                    let smooth = (x * 7 + y * 3 + c * 50) % (max + 1);
                    v.push(if (x / 5 + y / 3) % 4 == 0 { state % (max + 1) } else { smooth });
                }
            }
        }
        v
    }

    fn encode<K: TiffKind, C: colortype::ColorType>(
        mut encoder: TiffEncoder<File, K>,
        width: u32,
        height: u32,
        rows_per_strip: Option<u32>,
        data: &[C::Inner],
    ) where
        [C::Inner]: tiff::encoder::TiffValue,
    {
        let mut image = encoder.new_image::<C>(width, height).unwrap();
        if let Some(rows) = rows_per_strip {
            image.rows_per_strip(rows).unwrap();
        }
        image.write_data(data).unwrap();
    }

    fn write_with<C: colortype::ColorType>(
        path: &Path,
        compression: Compression,
        big: bool,
        rows: Option<u32>,
        w: u32,
        h: u32,
        data: &[C::Inner],
    ) where
        [C::Inner]: tiff::encoder::TiffValue,
    {
        let file = File::create(path).unwrap();
        if big {
            encode::<_, C>(TiffEncoder::new_big(file).unwrap().with_compression(compression), w, h, rows, data);
        } else {
            encode::<_, C>(TiffEncoder::new(file).unwrap().with_compression(compression), w, h, rows, data);
        }
    }

    fn assert_matches_image_crate(path: &Path, expect: PixelLayout) {
        let mut source = open(path, 1 << 30).unwrap();
        assert_eq!(source.layout(), expect, "{}", path.display());
        let ours = read_all(source.as_mut()).unwrap();
        let (layout, theirs) = image_crate_decode(path);
        assert_eq!(layout, expect);
        assert!(ours == theirs, "{} differs from the image crate's decode", path.display());
    }

    #[test]
    fn strips_match_image_crate_for_every_compression_and_layout() {
        let dir = tempfile::tempdir().unwrap();
        let compressions = [
            ("none", Compression::Uncompressed),
            ("lzw", Compression::Lzw),
            ("deflate", Compression::Deflate(DeflateLevel::Fast)),
            ("packbits", Compression::Packbits),
        ];
        let (w, h) = (101, 67);
        for (name, compression) in compressions {
            for (i, rows) in [None, Some(1), Some(7), Some(1000)].into_iter().enumerate() {
                let p = |kind: &str| dir.path().join(format!("{name}-{i}-{kind}.tif"));
                let g8: Vec<u8> = pattern(w, h, 1, 255).into_iter().map(|v| v as u8).collect();
                let rgb8: Vec<u8> = pattern(w, h, 3, 255).into_iter().map(|v| v as u8).collect();
                let rgba8: Vec<u8> = pattern(w, h, 4, 255).into_iter().map(|v| v as u8).collect();
                let g16: Vec<u16> = pattern(w, h, 1, 65535).into_iter().map(|v| v as u16).collect();
                let rgb16: Vec<u16> = pattern(w, h, 3, 65535).into_iter().map(|v| v as u16).collect();
                let rgba16: Vec<u16> = pattern(w, h, 4, 65535).into_iter().map(|v| v as u16).collect();
                write_with::<colortype::Gray8>(&p("g8"), compression, false, rows, w, h, &g8);
                write_with::<colortype::RGB8>(&p("rgb8"), compression, false, rows, w, h, &rgb8);
                write_with::<colortype::RGBA8>(&p("rgba8"), compression, false, rows, w, h, &rgba8);
                write_with::<colortype::Gray16>(&p("g16"), compression, false, rows, w, h, &g16);
                write_with::<colortype::RGB16>(&p("rgb16"), compression, false, rows, w, h, &rgb16);
                write_with::<colortype::RGBA16>(&p("rgba16"), compression, false, rows, w, h, &rgba16);
                assert_matches_image_crate(&p("g8"), PixelLayout::new(Channels::Grey, Depth::U8));
                assert_matches_image_crate(&p("rgb8"), PixelLayout::new(Channels::Rgb, Depth::U8));
                assert_matches_image_crate(&p("rgba8"), PixelLayout::new(Channels::Rgba, Depth::U8));
                assert_matches_image_crate(&p("g16"), PixelLayout::new(Channels::Grey, Depth::U16));
                assert_matches_image_crate(&p("rgb16"), PixelLayout::new(Channels::Rgb, Depth::U16));
                assert_matches_image_crate(&p("rgba16"), PixelLayout::new(Channels::Rgba, Depth::U16));
                // Compressed strips, more than two: decoded on a worker per core, where there are several.
                if let Some(rows) = rows {
                    let ahead = name != "none" && h > 2 * rows;
                    let several = std::thread::available_parallelism().is_ok_and(|n| n.get() > 1);
                    let described = open(&p("rgb8"), 1 << 30).unwrap().describe();
                    assert_eq!(described.contains("decoded at once"), ahead && several, "{described}");
                }
            }
        }
    }

    #[test]
    fn sixteen_bit_round_trip_is_native_endian() {
        let dir = tempfile::tempdir().unwrap();
        let (w, h) = (64, 40);
        let values: Vec<u16> = pattern(w, h, 3, 65535).into_iter().map(|v| v as u16).collect();
        let path = dir.path().join("rgb16.tif");
        write_with::<colortype::RGB16>(&path, Compression::Lzw, false, Some(5), w, h, &values);
        let mut source = open(&path, 1 << 30).unwrap();
        let got = read_all(source.as_mut()).unwrap();
        let got: Vec<u16> = got.chunks_exact(2).map(|b| u16::from_ne_bytes([b[0], b[1]])).collect();
        assert_eq!(got, values);

        // Big-endian ("MM") file, written by hand: samples must come out native too.
        let grey: Vec<u16> = pattern(w, h, 1, 65535).into_iter().map(|v| v as u16).collect();
        let be: Vec<u8> = grey.iter().flat_map(|v| v.to_be_bytes()).collect();
        let path = dir.path().join("be16.tif");
        let strips = strips_of(&be, w as usize * 2, 16);
        write_tiff(&path, true, basic_tags(w, h, &[16], 1, Some(16)), &strips, false);
        let mut source = open(&path, 1 << 30).unwrap();
        assert_eq!(source.layout(), PixelLayout::new(Channels::Grey, Depth::U16));
        let got = read_all(source.as_mut()).unwrap();
        let got: Vec<u16> = got.chunks_exact(2).map(|b| u16::from_ne_bytes([b[0], b[1]])).collect();
        assert_eq!(got, grey);
    }

    #[test]
    fn uncompressed_strips_are_read_in_part_and_the_rest_in_whole_rows() {
        let dir = tempfile::tempdir().unwrap();
        let (w, h) = (90u32, 33u32);
        let rgb8: Vec<u8> = pattern(w, h, 3, 255).into_iter().map(|v| v as u8).collect();
        let row = |y: u32, c: &std::ops::Range<u32>| {
            rgb8[((y * w + c.start) * 3) as usize..((y * w + c.end) * 3) as usize].to_vec()
        };
        for (name, compression) in [("raw.tif", Compression::Uncompressed), ("lzw.tif", Compression::Lzw)] {
            let path = dir.path().join(name);
            write_with::<colortype::RGB8>(&path, compression, false, Some(4), w, h, &rgb8);
            let mut source = open(&path, 1 << 30).unwrap();
            let columns = 17..61;
            source.skip_rows(5).unwrap();
            let part = source.read_columns(columns.clone());
            assert_eq!(part, name == "raw.tif", "{name}");
            let got_columns = if part { columns.clone() } else { 0..w };
            let mut out = vec![0u8; got_columns.len() * 3];
            for y in 5..h {
                source.read_row(&mut out).unwrap();
                assert_eq!(out, row(y, &got_columns), "{name} row {y}");
            }
            // All the columns again: whole rows.
            let mut source = open(&path, 1 << 30).unwrap();
            assert!(source.read_columns(0..w));
            let mut out = vec![0u8; w as usize * 3];
            source.read_row(&mut out).unwrap();
            assert_eq!(out, row(0, &(0..w)));
        }
    }

    #[test]
    fn bigtiff_and_predictor() {
        let dir = tempfile::tempdir().unwrap();
        let (w, h) = (90, 33);
        let rgb16: Vec<u16> = pattern(w, h, 3, 65535).into_iter().map(|v| v as u16).collect();
        let path = dir.path().join("big.tif");
        write_with::<colortype::RGB16>(
            &path,
            Compression::Deflate(DeflateLevel::Balanced),
            true,
            Some(4),
            w,
            h,
            &rgb16,
        );
        // Through the format dispatch, as the pipeline opens it.
        let source = crate::source::open(&path, crate::limits::Budget::new(1 << 30)).unwrap();
        assert!(source.describe().starts_with("bigtiff, deflate"), "{}", source.describe());
        drop(source);
        assert_matches_image_crate(&path, PixelLayout::new(Channels::Rgb, Depth::U16));

        let path = dir.path().join("predicted.tif");
        let rgb8: Vec<u8> = pattern(w, h, 3, 255).into_iter().map(|v| v as u8).collect();
        let encoder = TiffEncoder::new(File::create(&path).unwrap())
            .unwrap()
            .with_compression(Compression::Lzw)
            .with_predictor(Predictor::Horizontal);
        encode::<_, colortype::RGB8>(encoder, w, h, Some(8), &rgb8);
        let mut source = open(&path, 1 << 30).unwrap();
        assert_eq!(read_all(source.as_mut()).unwrap(), rgb8);
    }

    /// LZW and Deflate strips larger than a piece are handed over a few rows at a time: the rows written,
    /// in order, with the workers and the reader holding at most `strips_ahead::bytes_at_most`
    /// of pieces, less than the whole strips (one taken and one per worker) they held before.
    #[test]
    fn compressed_strips_come_in_pieces_within_the_bound() {
        strips_in_pieces("deflate", Compression::Deflate(DeflateLevel::Fast));
        strips_in_pieces("lzw", Compression::Lzw);
    }

    fn strips_in_pieces(name: &str, compression: Compression) {
        let dir = tempfile::tempdir().unwrap();
        // 6 KiB rows in strips of 256 (1.5 MiB; the last one short): pieces of 42 rows.
        let (w, h, strip_rows) = (2048u32, 1100u32, 256u32);
        let rgb8: Vec<u8> = pattern(w, h, 3, 255).into_iter().map(|v| v as u8).collect();
        let path = dir.path().join("wide.tif");
        let encoder = TiffEncoder::new(File::create(&path).unwrap())
            .unwrap()
            .with_compression(compression)
            .with_predictor(Predictor::Horizontal);
        encode::<_, colortype::RGB8>(encoder, w, h, Some(strip_rows), &rgb8);
        let mut source = open(&path, 1 << 30).unwrap();
        let (row_bytes, mut most, mut got) = (w as usize * 3, 0, Vec::new());
        let mut row = vec![0u8; row_bytes];
        for _ in 0..h {
            source.read_row(&mut row).unwrap();
            most = most.max(source.buffer_bytes());
            got.extend_from_slice(&row);
        }
        assert!(got == rgb8, "{name}: the rows differ from those written");
        let workers = std::thread::available_parallelism().map_or(1, |n| n.get()).min(4) as u64;
        if workers > 1 {
            let rows = strips_ahead::Shape::rows_per_piece(row_bytes as u64, strip_rows as u64);
            assert_eq!(rows, 42);
            let shape = strips_ahead::Shape {
                height: h as u64,
                strip_rows: strip_rows as u64,
                piece_rows: rows,
                row_bytes: row_bytes as u64,
            };
            let strip = strip_rows as u64 * row_bytes as u64;
            // An LZW worker's window (the strings since the last clear code) besides.
            let windows = if name == "lzw" { workers * (512 << 10) } else { 0 };
            assert!(most <= strips_ahead::bytes_at_most(&shape, workers) + windows, "{name}: {most} bytes held");
            assert!(most < (workers + 1) * strip, "{name}: {most} bytes held: whole strips");
        }
        // A strip whose data is garbage from its middle on: an error naming the strip and a row
        // of it, not a panic or rows of garbage.
        let mut bytes = std::fs::read(&path).unwrap();
        let mut decoder = Decoder::new(File::open(&path).unwrap()).unwrap();
        let offsets = decoder.get_tag_u64_vec(Tag::StripOffsets).unwrap();
        let counts = decoder.get_tag_u64_vec(Tag::StripByteCounts).unwrap();
        let (at, len) = (offsets[2] as usize, counts[2] as usize);
        bytes[at + len / 2..at + len].fill(0xFF);
        std::fs::write(&path, &bytes).unwrap();
        let mut source = open(&path, 1 << 30).unwrap();
        match read_all(source.as_mut()).unwrap_err() {
            TilerError::DecodeRow { row, message, .. } => {
                assert!((512..768).contains(&row), "{name}: row {row}: {message}");
                assert!(message.contains("strip 2"), "{name}: {message}");
            }
            other => panic!("{name}: unexpected {other}"),
        }
    }

    // ---- A minimal TIFF writer for layouts the `tiff` encoder cannot make (tiles, grey+alpha,
    // big-endian, directory before the data, unsupported kinds).

    type Entry = (u16, u16, Vec<u32>);
    const SHORT: u16 = 3;
    const LONG: u16 = 4;

    fn basic_tags(w: u32, h: u32, bits: &[u32], photometric: u32, rows_per_strip: Option<u32>) -> Vec<Entry> {
        let mut tags = vec![
            (256, LONG, vec![w]),
            (257, LONG, vec![h]),
            (258, SHORT, bits.to_vec()),
            (259, SHORT, vec![1]),
            (262, SHORT, vec![photometric]),
            (277, SHORT, vec![bits.len() as u32]),
        ];
        if let Some(rows) = rows_per_strip {
            tags.push((278, LONG, vec![rows]));
        }
        tags
    }

    fn set_tag(tags: &mut Vec<Entry>, entry: Entry) {
        tags.retain(|t| t.0 != entry.0);
        tags.push(entry);
    }

    fn strips_of(data: &[u8], row_bytes: usize, rows: usize) -> Vec<Vec<u8>> {
        data.chunks(row_bytes * rows).map(<[u8]>::to_vec).collect()
    }

    /// Cuts `data` (rows of `w` pixels of `pixel` bytes) into `tw` x `th` tiles, zero-padded.
    fn tiles_of(data: &[u8], w: usize, h: usize, pixel: usize, tw: usize, th: usize) -> Vec<Vec<u8>> {
        let mut tiles = Vec::new();
        for ty in (0..h).step_by(th) {
            for tx in (0..w).step_by(tw) {
                let mut tile = vec![0u8; tw * th * pixel];
                for y in ty..(ty + th).min(h) {
                    let n = (tw.min(w - tx)) * pixel;
                    tile[(y - ty) * tw * pixel..][..n].copy_from_slice(&data[(y * w + tx) * pixel..][..n]);
                }
                tiles.push(tile);
            }
        }
        tiles
    }

    /// Writes a classic TIFF with its directory first (right after the header), then the
    /// out-of-line tag values, then the strips or tiles in order.
    fn write_tiff(path: &Path, big_endian: bool, mut tags: Vec<Entry>, chunks: &[Vec<u8>], tiled: bool) {
        let (offsets_tag, counts_tag) = if tiled { (324, 325) } else { (273, 279) };
        tags.push((offsets_tag, LONG, vec![0; chunks.len()]));
        tags.push((counts_tag, LONG, chunks.iter().map(|c| c.len() as u32).collect()));
        tags.sort_by_key(|t| t.0);
        let size = |t: &Entry| t.2.len() * if t.1 == SHORT { 2 } else { 4 };
        let ifd_len = 2 + 12 * tags.len() + 4;
        let extra: usize = tags.iter().map(size).filter(|&s| s > 4).sum();
        let mut at = 8 + ifd_len + extra;
        let offsets: Vec<u32> = chunks
            .iter()
            .map(|c| {
                let o = at;
                at += c.len();
                o as u32
            })
            .collect();
        tags.iter_mut().find(|t| t.0 == offsets_tag).unwrap().2 = offsets;

        let u16b = |v: u16| if big_endian { v.to_be_bytes() } else { v.to_le_bytes() };
        let u32b = |v: u32| if big_endian { v.to_be_bytes() } else { v.to_le_bytes() };
        let mut out: Vec<u8> = if big_endian { b"MM\0*".to_vec() } else { b"II*\0".to_vec() };
        out.extend(u32b(8));
        out.extend(u16b(tags.len() as u16));
        let mut extra_at = 8 + ifd_len;
        let mut extra_bytes = Vec::new();
        for (tag, ty, values) in &tags {
            out.extend(u16b(*tag));
            out.extend(u16b(*ty));
            out.extend(u32b(values.len() as u32));
            let mut bytes = Vec::new();
            for &v in values {
                if *ty == SHORT {
                    bytes.extend(u16b(v as u16));
                } else {
                    bytes.extend(u32b(v));
                }
            }
            if bytes.len() <= 4 {
                bytes.resize(4, 0);
                out.extend(bytes);
            } else {
                out.extend(u32b(extra_at as u32));
                extra_at += bytes.len();
                extra_bytes.extend(bytes);
            }
        }
        out.extend(u32b(0));
        out.extend(extra_bytes);
        for c in chunks {
            out.extend(c);
        }
        std::fs::write(path, out).unwrap();
    }

    fn tiled_tags(w: u32, h: u32, bits: &[u32], photometric: u32, tw: u32, th: u32) -> Vec<Entry> {
        let mut tags = basic_tags(w, h, bits, photometric, None);
        tags.push((322, LONG, vec![tw]));
        tags.push((323, LONG, vec![th]));
        tags
    }

    #[test]
    fn tiled_tiff_matches_source_and_image_crate() {
        let dir = tempfile::tempdir().unwrap();
        let (w, h, tw, th) = (100u32, 70u32, 32u32, 16u32);
        let rgb: Vec<u8> = pattern(w, h, 3, 255).into_iter().map(|v| v as u8).collect();
        let path = dir.path().join("tiled.tif");
        let tiles = tiles_of(&rgb, w as usize, h as usize, 3, tw as usize, th as usize);
        write_tiff(&path, false, tiled_tags(w, h, &[8, 8, 8], 2, tw, th), &tiles, true);
        let mut source = open(&path, 1 << 30).unwrap();
        assert!(source.describe().contains("tile row (32x16 tiles)"), "{}", source.describe());
        assert_eq!(read_all(source.as_mut()).unwrap(), rgb);
        assert_matches_image_crate(&path, PixelLayout::new(Channels::Rgb, Depth::U8));

        // A shard's columns, from row 20: only the tiles under them, and a change of columns
        // within a row of tiles decodes the tiles it lacks.
        let mut source = open(&path, 1 << 30).unwrap();
        source.skip_rows(20).unwrap();
        for (columns, rows) in [(40u32..70u32, 20u32..26u32), (5..99, 26..40)] {
            assert!(source.read_columns(columns.clone()));
            let mut out = vec![0u8; columns.len() * 3];
            for y in rows {
                source.read_row(&mut out).unwrap();
                let want = &rgb[((y * w + columns.start) * 3) as usize..((y * w + columns.end) * 3) as usize];
                assert_eq!(out, want, "row {y}, columns {columns:?}");
            }
        }

        // 16-bit grey, big-endian, tiles larger than the image.
        let grey: Vec<u16> = pattern(w, h, 1, 65535).into_iter().map(|v| v as u16).collect();
        let be: Vec<u8> = grey.iter().flat_map(|v| v.to_be_bytes()).collect();
        let path = dir.path().join("tiled16.tif");
        let tiles = tiles_of(&be, w as usize, h as usize, 2, 128, 128);
        write_tiff(&path, true, tiled_tags(w, h, &[16], 1, 128, 128), &tiles, true);
        let mut source = open(&path, 1 << 30).unwrap();
        let got = read_all(source.as_mut()).unwrap();
        let got: Vec<u16> = got.chunks_exact(2).map(|b| u16::from_ne_bytes([b[0], b[1]])).collect();
        assert_eq!(got, grey);
    }

    #[test]
    fn grey_alpha_and_extra_samples() {
        let dir = tempfile::tempdir().unwrap();
        let (w, h) = (37u32, 21u32);
        let ga: Vec<u8> = pattern(w, h, 2, 255).into_iter().map(|v| v as u8).collect();
        let path = dir.path().join("ga.tif");
        let mut tags = basic_tags(w, h, &[8, 8], 1, Some(4));
        tags.push((338, SHORT, vec![2]));
        write_tiff(&path, false, tags, &strips_of(&ga, w as usize * 2, 4), false);
        let mut source = open(&path, 1 << 30).unwrap();
        assert_eq!(source.layout(), PixelLayout::new(Channels::GreyAlpha, Depth::U8));
        assert_eq!(read_all(source.as_mut()).unwrap(), ga);

        // An unspecified extra sample is dropped: plain grey.
        let path = dir.path().join("g-extra.tif");
        let mut tags = basic_tags(w, h, &[8, 8], 1, Some(4));
        tags.push((338, SHORT, vec![0]));
        write_tiff(&path, false, tags, &strips_of(&ga, w as usize * 2, 4), false);
        let mut source = open(&path, 1 << 30).unwrap();
        assert_eq!(source.layout(), PixelLayout::new(Channels::Grey, Depth::U8));
        let grey: Vec<u8> = ga.iter().step_by(2).copied().collect();
        assert_eq!(read_all(source.as_mut()).unwrap(), grey);

        // WhiteIsZero grey is inverted.
        let path = dir.path().join("wiz.tif");
        write_tiff(&path, false, basic_tags(w, h, &[8], 0, None), std::slice::from_ref(&grey), false);
        let mut source = open(&path, 1 << 30).unwrap();
        let inverted: Vec<u8> = grey.iter().map(|v| 255 - v).collect();
        assert_eq!(read_all(source.as_mut()).unwrap(), inverted);
    }

    /// `data` (texels of `stored` 8-bit samples) written with `extra` as ExtraSamples, in
    /// uncompressed strips of 16 rows or in 16x16 tiles.
    fn write_extra(path: &Path, w: u32, h: u32, photometric: u32, extra: &[u32], data: &[u8], tiled: bool) {
        let stored = data.len() / (w * h) as usize;
        let bits = vec![8; stored];
        let mut tags = match tiled {
            true => tiled_tags(w, h, &bits, photometric, 16, 16),
            false => basic_tags(w, h, &bits, photometric, Some(16)),
        };
        tags.push((338, SHORT, extra.to_vec()));
        let chunks = match tiled {
            true => tiles_of(data, w as usize, h as usize, stored, 16, 16),
            false => strips_of(data, w as usize * stored, 16),
        };
        write_tiff(path, false, tags, &chunks, tiled);
    }

    #[test]
    fn extra_samples_of_any_count_are_dropped_at_the_stored_stride() {
        // Uncompressed 8-bit strips, read straight from the file, once took the texels at the
        // stride of the samples kept: scrambled rows (issue 27).
        let dir = tempfile::tempdir().unwrap();
        let (w, h) = (45u32, 40u32);
        let cases: [(u32, &[u32], Channels); 7] = [
            (2, &[0], Channels::Rgb),
            (2, &[0, 0], Channels::Rgb),
            (2, &[0, 0, 0], Channels::Rgb),
            (2, &[2, 0], Channels::Rgba),
            (2, &[2, 0, 0], Channels::Rgba),
            (1, &[0, 0], Channels::Grey),
            (1, &[2, 0], Channels::GreyAlpha),
        ];
        for (photometric, extra, channels) in cases {
            let stored = if photometric == 2 { 3 } else { 1 } + extra.len();
            let data: Vec<u8> = pattern(w, h, stored, 255).into_iter().map(|v| v as u8).collect();
            // The naive decode: each texel's first samples.
            let keep = channels.count();
            let naive: Vec<u8> = data.chunks_exact(stored).flat_map(|t| t[..keep].to_vec()).collect();
            for tiled in [false, true] {
                let what = format!("{channels:?} + {extra:?}, tiled {tiled}");
                let path = dir.path().join("extra.tif");
                write_extra(&path, w, h, photometric, extra, &data, tiled);
                let mut source = open(&path, 1 << 30).unwrap();
                assert_eq!(source.layout(), PixelLayout::new(channels, Depth::U8), "{what}");
                assert!(read_all(source.as_mut()).unwrap() == naive, "{what}");
                // A shard's columns, from row 17. RGB with extra samples past its alpha is read
                // as stored by `kinds`, which gives whole rows.
                let mut source = open(&path, 1 << 30).unwrap();
                source.skip_rows(17).unwrap();
                let part = source.read_columns(5..33);
                assert_eq!(part, photometric != 2, "{what}");
                let (x0, n) = if part { (5, 28) } else { (0, w as usize) };
                let mut out = vec![0u8; n * keep];
                for y in 17..h as usize {
                    source.read_row(&mut out).unwrap();
                    assert_eq!(out, naive[(y * w as usize + x0) * keep..][..n * keep], "{what}, row {y}");
                }
            }
        }
    }

    #[test]
    fn associated_alpha_is_unpremultiplied_as_vips_does() {
        // Every 8-bit pair: red is the column (the premultiplied sample), alpha the row.
        let dir = tempfile::tempdir().unwrap();
        let data: Vec<u8> = (0..256u32)
            .flat_map(|a| (0..256u32).flat_map(move |v| [v, v * 7 % 256, 255 - v, a]))
            .map(|s| s as u8)
            .collect();
        for tiled in [false, true] {
            let path = dir.path().join("assoc.tif");
            write_extra(&path, 256, 256, 2, &[1], &data, tiled);
            let mut source = open(&path, 1 << 30).unwrap();
            assert_eq!(source.layout(), PixelLayout::new(Channels::Rgba, Depth::U8));
            let got = read_all(source.as_mut()).unwrap();
            let at = |v: usize, a: usize| &got[(a * 256 + v) * 4..][..4];
            // colour x 255 / alpha in single precision, truncated, clamped; alpha kept.
            assert_eq!(at(100, 200)[0], 127, "127.5 truncates");
            assert_eq!(at(3, 7)[0], 109, "109.29 truncates");
            assert_eq!(at(7, 7)[0], 254, "7 x (255 / 7) in single precision is just under 255");
            assert_eq!(at(128, 255)[0], 128);
            assert_eq!(at(200, 100)[0], 255, "more than the alpha clamps");
            assert_eq!(at(5, 0), [0, 0, 0, 0], "alpha 0: colour 0");
            assert_eq!(at(77, 90)[3], 90);
            // The whole table as libvips 8.18 loads it (FNV-1a 64 of its bytes).
            let fnv = got.iter().fold(0xcbf2_9ce4_8422_2325u64, |h, &b| (h ^ b as u64).wrapping_mul(0x100_0000_01b3));
            assert_eq!(fnv, 0x549b_dea1_9d70_e7ed, "tiled {tiled}");
        }

        // 16-bit (decoded strips), against what libvips 8.18 gives for the same pairs.
        let pairs: [(u16, u16, u16); 9] = [
            (17183, 32968, 34157),
            (28243, 61666, 30014),
            (52347, 52971, 64763),
            (15500, 21643, 46934),
            (40000, 30000, 65535),
            (1234, 0, 0),
            (7, 7, 65535),
            (32767, 65535, 32767),
            (3, 5, 39321),
        ];
        let texels: Vec<u8> = pairs.iter().flat_map(|&(v, a, _)| [v, v, 0, a]).flat_map(|s| s.to_le_bytes()).collect();
        let path = dir.path().join("assoc16.tif");
        let mut tags = basic_tags(pairs.len() as u32, 1, &[16; 4], 2, None);
        tags.push((338, SHORT, vec![1]));
        write_tiff(&path, false, tags, &[texels], false);
        let mut source = open(&path, 1 << 30).unwrap();
        let got = read_all(source.as_mut()).unwrap();
        let got: Vec<u16> = got.chunks_exact(2).map(|b| u16::from_ne_bytes([b[0], b[1]])).collect();
        for (texel, &(v, a, want)) in got.chunks_exact(4).zip(&pairs) {
            assert_eq!([texel[0], texel[1], texel[2], texel[3]], [want, want, 0, a], "sample {v}, alpha {a}");
        }
    }

    #[test]
    fn a_strip_shorter_than_its_rows_is_refused() {
        // Strip 2 (rows 16-23) says it holds 100 bytes fewer than its rows: a row read straight
        // from the file would run on into strip 3.
        let dir = tempfile::tempdir().unwrap();
        let (w, h) = (50u32, 40u32);
        let rgb: Vec<u8> = pattern(w, h, 3, 255).into_iter().map(|v| v as u8).collect();
        let mut strips = strips_of(&rgb, w as usize * 3, 8);
        strips[2].truncate(1200 - 100);
        let path = dir.path().join("short.tif");
        write_tiff(&path, false, basic_tags(w, h, &[8, 8, 8], 2, Some(8)), &strips, false);
        let err = open(&path, 1 << 30).err().expect("a short strip is refused");
        let text = err.to_string();
        assert!(text.contains("short.tif") && text.contains("strip 2 holds 1100 bytes"), "{text}");
    }

    #[test]
    fn truncated_file_is_an_error_naming_the_row() {
        let dir = tempfile::tempdir().unwrap();
        let (w, h) = (50u32, 40u32);
        let rgb: Vec<u8> = pattern(w, h, 3, 255).into_iter().map(|v| v as u8).collect();
        let path = dir.path().join("cut.tif");
        write_tiff(&path, false, basic_tags(w, h, &[8, 8, 8], 2, Some(8)), &strips_of(&rgb, w as usize * 3, 8), false);
        let bytes = std::fs::read(&path).unwrap();
        // Strips are 50 x 8 x 3 = 1200 bytes: drop the last and 100 bytes of the one before,
        // which cuts its last row (31; uncompressed rows are read from the file one by one).
        std::fs::write(&path, &bytes[..bytes.len() - 1200 - 100]).unwrap();
        let mut source = open(&path, 1 << 30).unwrap();
        let err = read_all(source.as_mut()).unwrap_err();
        match &err {
            TilerError::DecodeRow { row, message, .. } => {
                assert_eq!(*row, 31, "{err}");
                assert!(message.contains("strip 3"), "{err}");
            }
            other => panic!("unexpected {other}"),
        }
        assert!(err.to_string().contains("cut.tif"), "{err}");

        // Compressed strips cut short, written by the `tiff` encoder (directory last): the
        // directory is gone, so opening fails.
        let path = dir.path().join("cut-lzw.tif");
        write_with::<colortype::RGB8>(&path, Compression::Lzw, false, Some(8), w, h, &rgb);
        let bytes = std::fs::read(&path).unwrap();
        for keep in [bytes.len() / 2, 10, 4] {
            std::fs::write(&path, &bytes[..keep]).unwrap();
            let err = open(&path, 1 << 30).err().expect("truncated file must not open");
            assert!(err.to_string().contains("cut-lzw.tif"), "{err}");
        }

        // LZW data cut inside a strip, directory first.
        let path = dir.path().join("cut-lzw2.tif");
        write_with::<colortype::RGB8>(&path, Compression::Lzw, false, Some(8), w, h, &rgb);
        let mut decoder = Decoder::new(File::open(&path).unwrap()).unwrap();
        let strips: Vec<Vec<u8>> = (0..5)
            .map(|i| {
                let offset = decoder.get_tag_u64_vec(Tag::StripOffsets).unwrap()[i] as usize;
                let count = decoder.get_tag_u64_vec(Tag::StripByteCounts).unwrap()[i] as usize;
                std::fs::read(&path).unwrap()[offset..offset + count].to_vec()
            })
            .collect();
        let mut tags = basic_tags(w, h, &[8, 8, 8], 2, Some(8));
        set_tag(&mut tags, (259, SHORT, vec![5]));
        write_tiff(&path, false, tags, &strips, false);
        let bytes = std::fs::read(&path).unwrap();
        std::fs::write(&path, &bytes[..bytes.len() - strips[4].len() / 2]).unwrap();
        let mut source = open(&path, 1 << 30).unwrap();
        let err = read_all(source.as_mut()).unwrap_err();
        assert!(matches!(err, TilerError::DecodeRow { row: 32, .. }), "{err}");
    }

    #[test]
    fn unsupported_kinds_are_refused_with_a_reason() {
        let dir = tempfile::tempdir().unwrap();
        let (w, h) = (16u32, 8u32);
        let expect_unsupported = |path: &Path, needle: &str| {
            let err = open(path, 1 << 30).err().unwrap_or_else(|| panic!("{} opened", path.display()));
            assert!(matches!(err, TilerError::Unsupported { .. }), "{err}");
            assert!(err.to_string().contains(needle), "{err} lacks {needle:?}");
        };

        // 32-bit and half floats are read (samples.rs); doubles are not.
        let path = dir.path().join("double.tif");
        write_with::<colortype::Gray64Float>(
            &path,
            Compression::Uncompressed,
            false,
            None,
            w,
            h,
            &vec![0.5f64; (w * h) as usize],
        );
        expect_unsupported(&path, "64-bit floating-point (SampleFormat 3");

        let path = dir.path().join("ycbcr.tif");
        let mut tags = basic_tags(w, h, &[8, 8, 8], 6, None);
        tags.push((530, SHORT, vec![1, 1]));
        write_tiff(&path, false, tags, &[vec![0; (w * h * 3) as usize]], false);
        expect_unsupported(&path, "YCbCr");

        // New-style JPEG (7) is read (jpeg.rs); old-style is not.
        let path = dir.path().join("old-jpeg-in-tiff.tif");
        let mut tags = basic_tags(w, h, &[8, 8, 8], 2, None);
        set_tag(&mut tags, (259, SHORT, vec![6]));
        write_tiff(&path, false, tags, &[vec![0; 10]], false);
        expect_unsupported(&path, "old-style JPEG");
    }

    #[test]
    fn strip_over_max_memory_is_refused_and_says_why() {
        let dir = tempfile::tempdir().unwrap();
        let (w, h) = (256u32, 256u32);
        let rgb = vec![100u8; (w * h * 3) as usize];
        // Uncompressed rows are read straight from the file: one strip holds no memory.
        let path = dir.path().join("one-raw-strip.tif");
        write_with::<colortype::RGB8>(&path, Compression::Uncompressed, false, Some(h), w, h, &rgb);
        let mut source = open(&path, 100_000).unwrap();
        assert_eq!(read_all(source.as_mut()).unwrap(), rgb);
        // A compressed one is decoded whole.
        let path = dir.path().join("one-strip.tif");
        write_with::<colortype::RGB8>(&path, Compression::Lzw, false, Some(h), w, h, &rgb);
        let err = open(&path, 100_000).err().unwrap();
        assert!(matches!(err, TilerError::Unsupported { .. }), "{err}");
        let text = err.to_string();
        assert!(text.contains("single strip") && text.contains("--max-memory") && text.contains("tiffcp"), "{text}");
        // The same file streams fine once a strip fits.
        assert!(open(&path, 256 * 256 * 3).is_ok());

        // Tiles: one row of 256x256 tiles of a 256-wide image.
        let path = dir.path().join("tiles.tif");
        let tiles = tiles_of(&rgb, w as usize, h as usize, 3, 256, 256);
        write_tiff(&path, false, tiled_tags(w, h, &[8, 8, 8], 2, 256, 256), &tiles, true);
        // Uncompressed, they are read straight from the file 43 rows at a time (32 KiB of each
        // tile): 64 KiB held, not the 192 KiB of the row of tiles.
        let mut source = open(&path, 100_000).unwrap();
        assert_eq!(read_all(source.as_mut()).unwrap(), rgb);
        let err = open(&path, 50_000).err().unwrap();
        assert!(err.to_string().contains("row of tiles"), "{err}");
    }

    /// A single uncompressed strip far above the `tiff` crate's 128 MiB default limits
    /// (16384 x 4096 RGB, 192 MiB). Slow and large on disk: run with `--ignored`.
    #[test]
    #[ignore]
    fn huge_single_uncompressed_strip() {
        let dir = tempfile::tempdir().unwrap();
        let (w, h) = (16384u32, 4096u32);
        let rgb: Vec<u8> = (0..w as usize * h as usize * 3).map(|i| (i % 251) as u8).collect();
        let path = dir.path().join("huge.tif");
        write_with::<colortype::RGB8>(&path, Compression::Uncompressed, false, Some(h), w, h, &rgb);
        let mut source = open(&path, 1 << 30).unwrap();
        assert_eq!(read_all(source.as_mut()).unwrap(), rgb);
    }
}
