//! A slide's associated images (label, macro photograph, thumbnail: `source::associated`) in
//! a generic pyramid: after the levels in the chain, each one IFD of one strip, Deflate with
//! the horizontal predictor (lossless: a label's barcode is read by machines), flagged
//! `NewSubfileType` 1 so that a reader looking for the image takes the full resolution, and
//! named by its `ImageDescription` as Aperio and Philips name theirs (`label`, `macro`,
//! `thumbnail`), which is how our own reader and OpenSlide's vendors find them. Untiled, so
//! OpenSlide's generic-tiff reader, which takes every tiled IFD for a level, passes them by.

use std::io::Write;

use super::ifd::{Ifd, Value, tag};
use crate::pixel::Channels;
use crate::source::associated::{Kind, Pixels};

/// One associated image written into the file.
#[derive(Clone, Debug, PartialEq, Eq)]
#[non_exhaustive]
pub struct AssociatedSummary {
    /// `label`, `overview` or `thumbnail`.
    pub kind: &'static str,
    /// Texels across.
    pub width: u32,
    /// Texels down.
    pub height: u32,
    /// Where the source stores it (`page 3`).
    pub origin: String,
    /// Its directory in the file, counted from 0 as `--page` and libvips' `page=` count.
    pub page: usize,
    /// Bytes of its strip.
    pub bytes: u64,
}

/// The word its `ImageDescription` holds.
pub(super) fn word(kind: Kind) -> &'static str {
    match kind {
        Kind::Label => "label",
        Kind::Overview => "macro",
        Kind::Thumbnail => "thumbnail",
    }
}

/// An upper bound of the strip's bytes for a `width x height` image of at most three 8-bit
/// samples: zlib's stored blocks (5 bytes every 65,535) and its header and trailer.
pub(super) fn most_bytes(width: u32, height: u32) -> u64 {
    let raw = u64::from(width) * u64::from(height) * 3;
    raw + 5 * (raw / 65_535 + 1) + 16
}

/// An associated image as the file holds it: its strip at `offset`, `len` bytes long.
#[derive(Clone, Debug)]
pub(super) struct Placed {
    pub kind: Kind,
    pub width: u32,
    pub height: u32,
    pub channels: Channels,
    pub offset: u64,
    pub len: u64,
}

/// The strip: `pixels`' rows horizontally differenced in place (`Predictor` 2), then one zlib
/// stream.
pub(super) fn strip(pixels: &mut Pixels) -> std::io::Result<Vec<u8>> {
    let channels = pixels.channels.count();
    vortex_pack::format::delta_encode_rows(&mut pixels.samples, pixels.width as usize, channels, 1);
    let mut z = flate2::write::ZlibEncoder::new(Vec::new(), flate2::Compression::new(6));
    z.write_all(&pixels.samples)?;
    z.finish()
}

/// Its IFD, signed by `signature` (the `Software` value the levels' IFDs have).
pub(super) fn ifd(image: &Placed, signature: Value) -> Ifd {
    let spp = image.channels.count() as u16;
    let mut ifd = Ifd::default();
    ifd.set(tag::NEW_SUBFILE_TYPE, Value::Long(vec![1]));
    ifd.set(tag::IMAGE_WIDTH, Value::Long(vec![image.width]));
    ifd.set(tag::IMAGE_LENGTH, Value::Long(vec![image.height]));
    ifd.set(tag::BITS_PER_SAMPLE, Value::Short(vec![8; spp as usize]));
    ifd.set(tag::COMPRESSION, Value::Short(vec![8]));
    let photometric = if image.channels == Channels::Grey { 1 } else { 2 };
    ifd.set(tag::PHOTOMETRIC, Value::Short(vec![photometric]));
    ifd.set(tag::IMAGE_DESCRIPTION, Value::Ascii(word(image.kind).into()));
    ifd.set(tag::STRIP_OFFSETS, Value::Offsets(vec![image.offset]));
    ifd.set(tag::SAMPLES_PER_PIXEL, Value::Short(vec![spp]));
    ifd.set(tag::ROWS_PER_STRIP, Value::Long(vec![image.height]));
    ifd.set(tag::STRIP_BYTE_COUNTS, Value::Offsets(vec![image.len]));
    ifd.set(tag::PLANAR_CONFIGURATION, Value::Short(vec![1]));
    ifd.set(tag::SOFTWARE, signature);
    ifd.set(tag::PREDICTOR, Value::Short(vec![2]));
    ifd.set(tag::SAMPLE_FORMAT, Value::Short(vec![1; spp as usize]));
    ifd
}
