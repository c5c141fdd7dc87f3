//! Decoding a tile to RGBA8 (feature `decode`): for viewers, tests and `verify --decode`, not
//! for a runtime's hot path (a runtime uploads raw or block-compressed payloads as they are).
//!
//! Every texel format becomes 8-bit RGBA: grey `g` is `(g, g, g, 255)`, grey-alpha `(g, a)` is
//! `(g, g, g, a)`, RGB gets an opaque alpha, and 16-bit samples become 8-bit with rounding,
//! `(v + 128) / 257`. Raw, zstd and zstd-delta payloads (and constant values) hold
//! little-endian samples; PNG's 16-bit samples are big-endian as PNG defines them. BC1 and BC7
//! blocks are decoded as Direct3D defines them (`bcdec_rs`); in a pack of RGB texels the alpha
//! they decode to is ignored (255).
//!
//! Payload bytes are untrusted: before anything is allocated the decoded size must equal the
//! tile's (`tile_size^2` texels) and stay under a byte limit, so that a payload claiming a huge
//! image (a zstd frame header, PNG's IHDR, JPEG's SOF) costs nothing.

use std::io::Cursor;

use crate::error::{PackError, Result};
use crate::format::{Description, ENTRY_LEN, TileKind, delta_decode_rows};
use crate::reader::{Pack, Tile, TileId};

impl Pack {
    /// Tile `id` as `tile_size^2` RGBA8 texels, rows top down; `None` if it is absent. Payload
    /// checksums are checked ([`Pack::tile_checked`]); a payload that does not decode to exactly
    /// one tile, or would need more than the pack's
    /// [`Limits::max_decoded_bytes`](crate::Limits::max_decoded_bytes), is a
    /// [`PackError::Tile`](crate::PackError::Tile) naming the tile and its byte.
    pub fn decode_rgba8(&self, id: TileId) -> Result<Option<Vec<u8>>> {
        let position = self.position(id)?;
        let max_bytes = self.limits().max_decoded_bytes;
        let d = self.description();
        match self.tile_checked(id)? {
            Tile::Absent => Ok(None),
            Tile::Constant(value) => {
                let entry_at = self.header().index_offset + position * ENTRY_LEN as u64;
                constant_rgba8(d, value, max_bytes).map(Some).map_err(|m| self.layout().tile_error(id, entry_at, m))
            }
            Tile::Data(kind, bytes) => {
                let offset = self.entry(position).offset_or_value;
                let mut decoder = PayloadDecoder::default();
                decoder.decode(kind, bytes, d, max_bytes).map(Some).map_err(|m| self.layout().tile_error(id, offset, m))
            }
        }
    }
}

impl Tile<'_> {
    /// The tile as `tile_size^2` RGBA8 texels of a pack described by `d`, exactly as
    /// [`Pack::decode_rgba8`] decodes it in place; `None` if it is absent. For a tile held away
    /// from its pack ([`Pack::tile_checked`]'s answer, or a copy of its bytes kept since: a cache
    /// of stored tiles). The checksum is not checked here: check it when the bytes are read.
    /// Nothing larger than `max_bytes` is allocated. An error is a
    /// [`PackError::Payload`](crate::PackError::Payload) (no file, no position: the caller knows
    /// which tile it decoded).
    pub fn decode_rgba8(self, d: &Description, max_bytes: u64) -> Result<Option<Vec<u8>>> {
        match self {
            Tile::Absent => Ok(None),
            Tile::Constant(value) => constant_rgba8(d, value, max_bytes)
                .map(Some)
                .map_err(|message| PackError::Payload { kind: TileKind::Constant.name(), message }),
            Tile::Data(kind, bytes) => PayloadDecoder::default()
                .decode(kind, bytes, d, max_bytes)
                .map(Some)
                .map_err(|message| PackError::Payload { kind: kind.name(), message }),
        }
    }

    /// The tile's payload as texels in the pack's own texel format, for converting packs: one
    /// raw tile, `tile_size^2` texels of `channels` samples, rows top down, samples
    /// little-endian. Raw, zstd, zstd-delta, BC1 and BC7 payloads decode; PNG and JPEG payloads
    /// are image files (see [`Tile::decode_rgba8`]), and absent and constant tiles have no
    /// payload: those are refused. Nothing larger than `max_bytes` is allocated.
    pub fn decode_texels(self, d: &Description, max_bytes: u64) -> Result<Vec<u8>> {
        let (kind, bytes) = match self {
            Tile::Data(kind, bytes) => (kind, bytes),
            Tile::Absent => (TileKind::Absent, &[][..]),
            Tile::Constant(value) => (TileKind::Constant, value),
        };
        let fail = |message: String| PackError::Payload { kind: kind.name(), message };
        let mut decoder = PayloadDecoder::default();
        match kind {
            TileKind::Raw => {
                let raw = raw_len(d, max_bytes).map_err(fail)?;
                if bytes.len() as u64 != raw {
                    return Err(fail(format!("a raw tile is {raw} bytes, this payload {}", bytes.len())));
                }
                Ok(bytes.to_vec())
            }
            TileKind::Zstd | TileKind::ZstdDelta => decoder.unzstd(kind, bytes, d, max_bytes).map_err(fail),
            TileKind::Bc1 | TileKind::Bc7 => {
                let rgba = decode_blocks(kind, bytes, d, max_bytes).map_err(fail)?;
                let channels = d.channels as usize;
                if channels == 4 {
                    return Ok(rgba);
                }
                let mut out = alloc(raw_len(d, max_bytes).map_err(fail)?).map_err(fail)?;
                for (o, px) in out.chunks_exact_mut(channels).zip(rgba.chunks_exact(4)) {
                    o.copy_from_slice(&px[..channels]);
                }
                Ok(out)
            }
            TileKind::Png | TileKind::Jpeg | TileKind::Jxl => {
                Err(fail(format!("{} payloads are image files, not texels (see decode_rgba8)", kind.name())))
            }
            TileKind::Absent | TileKind::Constant => Err(fail(format!("{} tiles have no payload", kind.name()))),
        }
    }
}

/// A tile whose every texel is `value` (channels x sample bytes, little-endian).
pub(crate) fn constant_rgba8(d: &Description, value: &[u8], max_bytes: u64) -> Result<Vec<u8>, String> {
    refuse_wide(d)?;
    let len = rgba_len(d, max_bytes)?;
    let texel = texels_to_rgba8(value, d.channels, d.sample_bytes, Endian::Little)?;
    let mut out = alloc(len)?;
    for px in out.chunks_exact_mut(4) {
        px.copy_from_slice(&texel);
    }
    Ok(out)
}

/// Decodes payloads, keeping what can be reused between tiles (a zstd context).
#[derive(Default)]
pub(crate) struct PayloadDecoder {
    zstd: Option<zstd::bulk::Decompressor<'static>>,
}

impl PayloadDecoder {
    /// `bytes`, a payload of `kind`, as one RGBA8 tile; the error says why not.
    pub(crate) fn decode(
        &mut self,
        kind: TileKind,
        bytes: &[u8],
        d: &Description,
        max_bytes: u64,
    ) -> Result<Vec<u8>, String> {
        refuse_wide(d)?;
        let rgba = rgba_len(d, max_bytes)?;
        let out = match kind {
            TileKind::Raw => {
                let raw = raw_len(d, max_bytes)?;
                if bytes.len() as u64 != raw {
                    return Err(format!("a raw tile is {raw} bytes, this payload {}", bytes.len()));
                }
                texels_to_rgba8(bytes, d.channels, d.sample_bytes, Endian::Little)?
            }
            TileKind::Zstd | TileKind::ZstdDelta => {
                let buf = self.unzstd(kind, bytes, d, max_bytes)?;
                texels_to_rgba8(&buf, d.channels, d.sample_bytes, Endian::Little)?
            }
            TileKind::Png => decode_png(bytes, d.tile_size, max_bytes)?,
            TileKind::Jpeg => decode_jpeg(bytes, d.tile_size, max_bytes)?,
            TileKind::Jxl => decode_jxl(bytes, d, max_bytes)?,
            TileKind::Bc1 | TileKind::Bc7 => decode_blocks(kind, bytes, d, max_bytes)?,
            TileKind::Absent | TileKind::Constant => return Err(format!("{} tiles have no payload", kind.name())),
        };
        if out.len() as u64 != rgba {
            return Err(format!("decodes to {} RGBA8 bytes, expected {rgba}", out.len()));
        }
        Ok(out)
    }
}

impl PayloadDecoder {
    /// A zstd or zstd-delta payload as one raw tile (the row filter undone).
    fn unzstd(&mut self, kind: TileKind, bytes: &[u8], d: &Description, max_bytes: u64) -> Result<Vec<u8>, String> {
        let raw = raw_len(d, max_bytes)?;
        let mut buf = alloc(raw)?;
        let decompressor = match &mut self.zstd {
            Some(d) => d,
            slot @ None => slot.insert(zstd::bulk::Decompressor::new().map_err(|e| format!("zstd: {e}"))?),
        };
        match decompressor.decompress_to_buffer(bytes, &mut buf[..]) {
            Ok(n) if n as u64 == raw => {}
            Ok(n) => return Err(format!("zstd payload decompresses to {n} bytes; a raw tile is {raw}")),
            Err(e) => return Err(format!("zstd payload does not decompress to one {raw}-byte raw tile: {e}")),
        }
        if kind == TileKind::ZstdDelta {
            let (c, sb) = (d.channels as usize, d.sample_bytes as usize);
            delta_decode_rows(&mut buf, d.tile_size as usize, c, sb);
        }
        Ok(buf)
    }
}

/// BC1 or BC7 blocks (rows of 4x4 blocks, top down) as one RGBA8 tile; alpha is 255 in a pack
/// of RGB texels.
fn decode_blocks(kind: TileKind, bytes: &[u8], d: &Description, max_bytes: u64) -> Result<Vec<u8>, String> {
    if let Some(why) = d.refuses(kind) {
        return Err(why);
    }
    let Some(expected) = d.block_tile_len(kind) else {
        return Err(format!("{} tiles are not blocks", kind.name()));
    };
    if bytes.len() as u64 != expected {
        return Err(format!("a {} tile has {expected} bytes, not {}", kind.name(), bytes.len()));
    }
    let mut out = alloc(rgba_len(d, max_bytes)?)?;
    let side = d.tile_size as usize;
    let pitch = side * 4;
    let block_len = if kind == TileKind::Bc1 { 8 } else { 16 };
    for (i, block) in bytes.chunks_exact(block_len).enumerate() {
        let (bx, by) = (i % (side / 4), i / (side / 4));
        let at = by * 4 * pitch + bx * 16;
        match kind {
            TileKind::Bc1 => bcdec_rs::bc1(block, &mut out[at..], pitch),
            _ => bcdec_rs::bc7(block, &mut out[at..], pitch),
        }
    }
    if d.channels == 3 {
        for px in out.chunks_exact_mut(4) {
            px[3] = 255;
        }
    }
    Ok(out)
}

/// Bytes of one RGBA8 tile, if within the limit.
fn rgba_len(d: &Description, max_bytes: u64) -> Result<u64, String> {
    let side = d.tile_size as u64;
    side.checked_mul(side)
        .and_then(|n| n.checked_mul(4))
        .filter(|n| *n <= max_bytes)
        .ok_or_else(|| format!("a {side}x{side} RGBA8 tile exceeds the decoding limit of {max_bytes} bytes"))
}

/// Bytes of one raw tile, if within the limit.
fn raw_len(d: &Description, max_bytes: u64) -> Result<u64, String> {
    d.raw_tile_len()
        .filter(|n| *n <= max_bytes)
        .ok_or_else(|| format!("a raw {0}x{0} tile exceeds the decoding limit of {max_bytes} bytes", d.tile_size))
}

/// A zeroed buffer of `len` bytes (already checked against a limit), failing instead of
/// aborting when memory is short.
fn alloc(len: u64) -> Result<Vec<u8>, String> {
    let len = usize::try_from(len).map_err(|_| format!("{len} bytes do not fit in memory"))?;
    let mut v = Vec::new();
    v.try_reserve_exact(len).map_err(|e| format!("cannot allocate {len} bytes: {e}"))?;
    v.resize(len, 0);
    Ok(v)
}

#[derive(Clone, Copy)]
enum Endian {
    Little,
    Big,
}

/// 32-bit and float samples have no one RGBA8 form (which range would map to 0-255?): their
/// texels are read with [`Tile::decode_texels`].
fn refuse_wide(d: &Description) -> Result<(), String> {
    if d.required_features() != 0 {
        return Err(format!("{} have no RGBA8 form; read the texels (Tile::decode_texels)", d.texel_name()));
    }
    Ok(())
}

/// Packed texels of `channels` samples of `sample_bytes` each, as RGBA8.
fn texels_to_rgba8(src: &[u8], channels: u8, sample_bytes: u8, endian: Endian) -> Result<Vec<u8>, String> {
    let (c, sb) = (channels as usize, sample_bytes as usize);
    if !(1..=4).contains(&c) || !(1..=2).contains(&sb) {
        return Err(format!("{c} channels of {sb} bytes is not a texel format"));
    }
    let texel = c * sb;
    if !src.len().is_multiple_of(texel) {
        return Err(format!("{} bytes are not whole {texel}-byte texels", src.len()));
    }
    let mut out = Vec::new();
    out.try_reserve_exact(src.len() / texel * 4).map_err(|e| format!("cannot allocate the RGBA8 tile: {e}"))?;
    for t in src.chunks_exact(texel) {
        let s = |i: usize| -> u8 {
            if sb == 1 {
                t[i]
            } else {
                let pair = [t[2 * i], t[2 * i + 1]];
                let v = match endian {
                    Endian::Little => u16::from_le_bytes(pair),
                    Endian::Big => u16::from_be_bytes(pair),
                };
                ((v as u32 + 128) / 257) as u8
            }
        };
        let px = match c {
            1 => [s(0), s(0), s(0), 255],
            2 => [s(0), s(0), s(0), s(1)],
            3 => [s(0), s(1), s(2), 255],
            _ => [s(0), s(1), s(2), s(3)],
        };
        out.extend_from_slice(&px);
    }
    Ok(out)
}

fn decode_png(bytes: &[u8], side: u32, max_bytes: u64) -> Result<Vec<u8>, String> {
    let limit = png::Limits { bytes: usize::try_from(max_bytes).unwrap_or(usize::MAX) };
    let mut decoder = png::Decoder::new_with_limits(Cursor::new(bytes), limit);
    // Palettes, transparency chunks and 1/2/4-bit samples become 8-bit grey/RGB(A).
    decoder.set_transformations(png::Transformations::EXPAND);
    let mut reader = decoder.read_info().map_err(|e| format!("png: {e}"))?;
    let (w, h) = reader.info().size();
    if (w, h) != (side, side) {
        return Err(format!("png image is {w}x{h}, the tile is {side}x{side}"));
    }
    let size = reader
        .output_buffer_size()
        .filter(|n| *n as u64 <= max_bytes)
        .ok_or_else(|| format!("png image exceeds the decoding limit of {max_bytes} bytes"))?;
    let mut buf = alloc(size as u64)?;
    let info = reader.next_frame(&mut buf).map_err(|e| format!("png: {e}"))?;
    reader.finish().map_err(|e| format!("png: {e}"))?;
    let channels = match info.color_type {
        png::ColorType::Grayscale => 1,
        png::ColorType::GrayscaleAlpha => 2,
        png::ColorType::Rgb => 3,
        png::ColorType::Rgba => 4,
        png::ColorType::Indexed => return Err("png: palette not expanded".into()),
    };
    let sample_bytes = match info.bit_depth {
        png::BitDepth::Eight => 1,
        png::BitDepth::Sixteen => 2,
        other => return Err(format!("png: {other:?} samples not expanded")),
    };
    buf.truncate(info.buffer_size());
    texels_to_rgba8(&buf, channels, sample_bytes, Endian::Big)
}

fn decode_jpeg(bytes: &[u8], side: u32, max_bytes: u64) -> Result<Vec<u8>, String> {
    use zune_jpeg::zune_core::colorspace::ColorSpace;
    use zune_jpeg::zune_core::options::DecoderOptions;
    let max_side = usize::try_from(side).unwrap_or(usize::MAX);
    let options = DecoderOptions::default()
        .set_strict_mode(true)
        .set_max_width(max_side)
        .set_max_height(max_side)
        .jpeg_set_out_colorspace(ColorSpace::RGBA);
    let mut decoder = zune_jpeg::JpegDecoder::new_with_options(Cursor::new(bytes), options);
    decoder.decode_headers().map_err(|e| format!("jpeg: {e:?}"))?;
    let (w, h) = decoder.dimensions().ok_or("jpeg: no image size")?;
    if (w as u64, h as u64) != (side as u64, side as u64) {
        return Err(format!("jpeg image is {w}x{h}, the tile is {side}x{side}"));
    }
    let size = decoder
        .output_buffer_size()
        .filter(|n| *n as u64 <= max_bytes)
        .ok_or_else(|| format!("jpeg image exceeds the decoding limit of {max_bytes} bytes"))?;
    let colorspace = decoder.output_colorspace().ok_or("jpeg: no colour space")?;
    let channels = match colorspace {
        ColorSpace::Luma => 1,
        ColorSpace::LumaA => 2,
        ColorSpace::RGB => 3,
        ColorSpace::RGBA => 4,
        other => return Err(format!("jpeg: cannot convert {other:?} to RGBA")),
    };
    let mut buf = alloc(size as u64)?;
    decoder.decode_into(&mut buf).map_err(|e| format!("jpeg: {e:?}"))?;
    texels_to_rgba8(&buf, channels, 1, Endian::Little)
}

/// A JPEG XL tile (`jxl-oxide`): its size read from its header and checked before anything
/// is rendered, the renderer's allocations held under `max_bytes`; 16-bit samples become 8-bit
/// as raw ones do, `(v + 128) / 257`.
fn decode_jxl(bytes: &[u8], d: &Description, max_bytes: u64) -> Result<Vec<u8>, String> {
    use jxl_oxide::{AllocTracker, JxlImage};
    let limit = usize::try_from(max_bytes).unwrap_or(usize::MAX);
    let image = JxlImage::builder()
        .alloc_tracker(AllocTracker::with_limit(limit))
        .read(bytes)
        .map_err(|e| format!("jxl: {e}"))?;
    let side = d.tile_size;
    let (w, h) = (image.width(), image.height());
    if (w, h) != (side, side) {
        return Err(format!("jxl image is {w}x{h}, the tile is {side}x{side}"));
    }
    if image.num_loaded_keyframes() != 1 {
        return Err(format!("jxl image has {} frames, a tile one", image.num_loaded_keyframes()));
    }
    let render = image.render_frame(0).map_err(|e| format!("jxl: {e}"))?;
    let mut stream = render.stream();
    let channels = stream.channels();
    if !(1..=4).contains(&channels) {
        return Err(format!("jxl image has {channels} channels (CMYK or extra channels), not grey or RGB"));
    }
    let samples = side as u64 * side as u64 * channels as u64;
    if samples * d.sample_bytes.max(1) as u64 > max_bytes {
        return Err(format!("jxl image exceeds the decoding limit of {max_bytes} bytes"));
    }
    let (texels, sample_bytes) = if d.sample_bytes == 2 {
        let mut buf = vec![0u16; samples as usize];
        stream.write_to_buffer(&mut buf);
        (buf.iter().flat_map(|v| v.to_le_bytes()).collect(), 2)
    } else {
        let mut buf = alloc(samples)?;
        stream.write_to_buffer(&mut buf);
        (buf, 1)
    };
    texels_to_rgba8(&texels, channels as u8, sample_bytes, Endian::Little)
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn expands_every_texel_format() {
        assert_eq!(texels_to_rgba8(&[7], 1, 1, Endian::Little).unwrap(), [7, 7, 7, 255]);
        assert_eq!(texels_to_rgba8(&[7, 9], 2, 1, Endian::Little).unwrap(), [7, 7, 7, 9]);
        assert_eq!(texels_to_rgba8(&[1, 2, 3], 3, 1, Endian::Little).unwrap(), [1, 2, 3, 255]);
        assert_eq!(texels_to_rgba8(&[1, 2, 3, 4], 4, 1, Endian::Little).unwrap(), [1, 2, 3, 4]);
        // 16 bits: (v + 128) / 257, little- or big-endian.
        let le = [0xff, 0xff, 0x00, 0x00, 0x80, 0x00, 0x81, 0x00];
        assert_eq!(texels_to_rgba8(&le, 4, 2, Endian::Little).unwrap(), [255, 0, 0, 1]);
        let be = [0xff, 0xff, 0x00, 0x00, 0x00, 0x80, 0x00, 0x81];
        assert_eq!(texels_to_rgba8(&be, 4, 2, Endian::Big).unwrap(), [255, 0, 0, 1]);
        for v in [0u16, 1, 128, 129, 257, 385, 386, 65535] {
            let exact = (v as f64 / 257.0).round() as u8;
            assert_eq!(texels_to_rgba8(&v.to_le_bytes(), 1, 2, Endian::Little).unwrap()[0], exact, "{v}");
        }
        assert!(texels_to_rgba8(&[1, 2, 3], 2, 1, Endian::Little).is_err());
        assert!(texels_to_rgba8(&[1], 5, 1, Endian::Little).is_err());
    }
}
