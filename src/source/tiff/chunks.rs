//! One strip or tile of a TIFF, read from the file and decompressed by us rather than by the
//! `tiff` crate, whose chunk reader refuses palette images and CCITT Group 3 and cannot give
//! one plane of a planar-separate image at sub-byte depths: [`super::kinds`] reads those.
//!
//! Decoded rows are as stored: samples packed MSB-first at 1, 2 or 4 bits (each row starting
//! on a byte), 8-bit samples as they are, 16- and 32-bit samples in native byte order; the
//! horizontal predictor (2) and the floating-point one (3, TIFF Technical Note 3) are undone. Compressions: none, LZW ([`super::lzw`]), Deflate (flate2), PackBits,
//! CCITT Group 3 (one- and two-dimensional), Group 4 and modified Huffman fax ([`super::fax`]).

use std::fs::File;
use std::io::Read;
use std::os::unix::fs::FileExt;

/// How a chunk's bytes are compressed.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Codec {
    None,
    Lzw,
    Deflate,
    PackBits,
    /// CCITT T.4 one-dimensional (Compression 3, T4Options without bit 0).
    Fax3,
    /// CCITT T.6 (Compression 4).
    Fax4,
    /// CCITT T.4 two-dimensional (Compression 3, T4Options bit 0).
    Fax3TwoD,
    /// CCITT modified Huffman without EOLs (Compression 2).
    FaxMh,
}

impl Codec {
    pub fn name(self) -> &'static str {
        match self {
            Codec::None => "uncompressed",
            Codec::Lzw => "lzw",
            Codec::Deflate => "deflate",
            Codec::PackBits => "packbits",
            Codec::Fax3 => "ccitt g3",
            Codec::Fax4 => "ccitt g4",
            Codec::Fax3TwoD => "ccitt g3 2-d",
            Codec::FaxMh => "ccitt modified huffman",
        }
    }
}

/// The differencing a chunk's rows were stored with (TIFF tag 317).
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(super) enum Predictor {
    None,
    /// 2: each sample less the same sample of the texel to its left, as integers of its size.
    Horizontal,
    /// 3: a row's floats split into planes of their bytes (most significant first), each byte
    /// less the byte one texel to its left (TIFF Technical Note 3; 16- and 32-bit floats).
    Float,
}

/// Where every chunk lies and how to turn its bytes into rows.
pub(super) struct Chunks {
    pub offsets: Vec<u64>,
    pub counts: Vec<u64>,
    pub codec: Codec,
    pub predictor: Predictor,
    pub big_endian: bool,
    /// Bits per sample: 1, 2, 4, 8, 16 or 32.
    pub bits: u16,
    /// FillOrder 2: the bits of each byte are stored least significant first.
    pub reverse_bits: bool,
    pub file_len: u64,
    /// The compressed bytes of the chunk being decoded, kept for the next (its capacity is
    /// at most [`compressed_at_most`](Self::compressed_at_most)).
    pub raw: Vec<u8>,
}

/// The rows a chunk decodes to: `width` texels (a tile's full width, edge tiles included) of
/// `samples` samples each, `rows` of them.
#[derive(Clone, Copy)]
pub(super) struct Shape {
    pub width: u32,
    pub rows: u32,
    pub samples: usize,
}

impl Shape {
    pub fn row_bytes(self, bits: u16) -> usize {
        (self.width as usize * self.samples * bits as usize).div_ceil(8)
    }
}

impl Chunks {
    /// The most compressed bytes [`decode`](Self::decode) holds at once for the chunks
    /// `indices`, each decoding to `decoded` bytes: the largest byte count among them, none
    /// over the bound a count is refused beyond; 0 uncompressed (read straight into the rows).
    pub fn compressed_at_most(&self, indices: impl Iterator<Item = usize>, decoded: u64) -> u64 {
        if self.codec == Codec::None {
            return 0;
        }
        let bound = compressed_bound(decoded);
        indices.filter_map(|i| self.counts.get(i)).map(|&c| c.min(bound)).max().unwrap_or(0)
    }

    /// Decodes chunk `index` into `out`, exactly `shape.rows` rows of `shape.row_bytes` bytes.
    pub fn decode(&mut self, file: &File, index: usize, shape: Shape, out: &mut [u8]) -> Result<(), String> {
        let (offset, count) = match (self.offsets.get(index), self.counts.get(index)) {
            (Some(&o), Some(&c)) => (o, c),
            _ => return Err("the TIFF gives it no offset or byte count".into()),
        };
        if offset.checked_add(count).is_none_or(|end| end > self.file_len) {
            return Err(format!(
                "its {count} bytes at offset {offset} run past the end of the file ({} bytes): a truncated TIFF?",
                self.file_len
            ));
        }
        let row_bytes = shape.row_bytes(self.bits);
        debug_assert_eq!(out.len(), row_bytes * shape.rows as usize);
        if self.codec == Codec::None {
            // Straight into the rows: the byte count must cover them.
            if count < out.len() as u64 {
                return Err(format!("uncompressed, it holds {count} bytes where its rows need {}", out.len()));
            }
            file.read_exact_at(out, offset).map_err(|e| format!("cannot read it: {e}"))?;
            if self.reverse_bits {
                out.iter_mut().for_each(|b| *b = b.reverse_bits());
            }
        } else {
            if count > compressed_bound(out.len() as u64) {
                return Err(format!("it claims {count} compressed bytes for {} decoded ones", out.len()));
            }
            let mut raw = std::mem::take(&mut self.raw);
            raw.clear();
            raw.resize(count as usize, 0);
            let read = file.read_exact_at(&mut raw, offset).map_err(|e| format!("cannot read it: {e}"));
            if self.reverse_bits {
                raw.iter_mut().for_each(|b| *b = b.reverse_bits());
            }
            let decoded = read.and_then(|()| {
                self.decompress(&raw, shape, out).map_err(|e| format!("corrupt or undecodable TIFF data: {e}"))
            });
            self.raw = raw;
            decoded?;
        }
        self.undo_predictor(out, row_bytes, shape.samples);
        Ok(())
    }

    fn decompress(&self, raw: &[u8], shape: Shape, out: &mut [u8]) -> Result<(), String> {
        match self.codec {
            Codec::None => unreachable!("read straight into the rows"),
            Codec::Lzw => super::lzw::decode(raw, out).map_err(|e| e.to_string()),
            Codec::Deflate => flate2::read::ZlibDecoder::new(raw).read_exact(out).map_err(|e| format!("deflate: {e}")),
            Codec::PackBits => unpack_bits(raw, out),
            // A decoder bug on a hostile file must not take the whole run down.
            Codec::Fax3 | Codec::Fax4 => std::panic::catch_unwind(std::panic::AssertUnwindSafe(|| {
                super::fax::decode(raw, self.codec == Codec::Fax4, shape.width, out)
            }))
            .unwrap_or_else(|_| Err("the fax decoder failed on this data".into())),
            Codec::Fax3TwoD => super::fax::decode_lines(raw, super::fax::Lines::TwoDimensional, shape.width, out),
            Codec::FaxMh => super::fax::decode_lines(raw, super::fax::Lines::ModifiedHuffman, shape.width, out),
        }
    }

    /// 16- and 32-bit samples into native order, and the predictor (the horizontal one at 8,
    /// 16 and 32 bits, the floating-point one at 16 and 32) undone, row by row.
    fn undo_predictor(&self, out: &mut [u8], row_bytes: usize, samples: usize) {
        let horizontal = self.predictor == Predictor::Horizontal;
        let mut bytes = Vec::new();
        for row in out.chunks_exact_mut(row_bytes) {
            match (self.bits, self.predictor) {
                (16 | 32, Predictor::Float) => undo_float_predictor(row, samples, self.bits as usize / 8, &mut bytes),
                (16, _) => super::lzw::undo_predictor_16(row, samples, self.big_endian, horizontal),
                (32, _) => undo_predictor_32(row, samples, self.big_endian, horizontal),
                (8, Predictor::Horizontal) => {
                    for i in samples..row.len() {
                        row[i] = row[i].wrapping_add(row[i - samples]);
                    }
                }
                _ => {}
            }
        }
    }
}

/// The most compressed bytes a chunk of `decoded` bytes may claim: no codec here expands less
/// than 1:16 (G4 of noise is the worst), so a byte count far above that is a corrupt table,
/// refused before allocating for it.
fn compressed_bound(decoded: u64) -> u64 {
    decoded.saturating_mul(16).saturating_add(1 << 16)
}

/// A row of 32-bit samples into native order, each texel's added to the one to its left where
/// they were stored as differences (`predictor`).
fn undo_predictor_32(row: &mut [u8], samples: usize, big_endian: bool, predictor: bool) {
    let stride = 4 * samples;
    for i in (0..row.len() - row.len() % 4).step_by(4) {
        let b = [row[i], row[i + 1], row[i + 2], row[i + 3]];
        let mut v = if big_endian { u32::from_be_bytes(b) } else { u32::from_le_bytes(b) };
        if predictor && i >= stride {
            let left = &row[i - stride..i - stride + 4];
            v = v.wrapping_add(u32::from_ne_bytes([left[0], left[1], left[2], left[3]]));
        }
        row[i..i + 4].copy_from_slice(&v.to_ne_bytes());
    }
}

/// The floating-point predictor undone on a row of `size`-byte floats, `samples` per texel:
/// each byte plus the one `samples` to its left, then the byte planes (most significant
/// first, whatever the file's byte order) gathered back into native-order floats. `bytes` is
/// scratch of one row.
fn undo_float_predictor(row: &mut [u8], samples: usize, size: usize, bytes: &mut Vec<u8>) {
    for i in samples..row.len() {
        row[i] = row[i].wrapping_add(row[i - samples]);
    }
    bytes.clear();
    bytes.extend_from_slice(row);
    let count = row.len() / size;
    for (k, float) in row.chunks_exact_mut(size).enumerate() {
        for (byte, out) in float.iter_mut().enumerate() {
            // Plane 0 holds the most significant bytes.
            let plane = if cfg!(target_endian = "big") { byte } else { size - 1 - byte };
            *out = bytes[plane * count + k];
        }
    }
}

/// PackBits (Apple's run-length code, TIFF compression 32773) into `out`, which it must fill:
/// a header byte n in 0..=127 copies n+1 literal bytes, 129..=255 repeats the next byte 257-n
/// times, 128 is a no-op. Output past `out` (a run overshooting the row end) is dropped, as
/// libtiff drops it.
fn unpack_bits(raw: &[u8], out: &mut [u8]) -> Result<(), String> {
    let (mut i, mut o) = (0usize, 0usize);
    while o < out.len() {
        let Some(&n) = raw.get(i) else {
            return Err(format!("packbits data ends after {o} of {} bytes", out.len()));
        };
        i += 1;
        match n {
            0..=127 => {
                let len = n as usize + 1;
                let Some(lit) = raw.get(i..i + len) else {
                    return Err(format!("packbits literal run cut short after {o} of {} bytes", out.len()));
                };
                let take = len.min(out.len() - o);
                out[o..o + take].copy_from_slice(&lit[..take]);
                (i, o) = (i + len, o + take);
            }
            128 => {}
            _ => {
                let Some(&v) = raw.get(i) else {
                    return Err(format!("packbits repeat cut short after {o} of {} bytes", out.len()));
                };
                let take = (257 - n as usize).min(out.len() - o);
                out[o..o + take].fill(v);
                (i, o) = (i + 1, o + take);
            }
        }
    }
    Ok(())
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn packbits_matches_the_specification_example() {
        // TIFF 6.0, section 9: the packed form of a 24-byte sequence.
        let packed = [0xFE, 0xAA, 0x02, 0x80, 0x00, 0x2A, 0xFD, 0xAA, 0x03, 0x80, 0x00, 0x2A, 0x22, 0xF7, 0xAA];
        let unpacked = [
            0xAA, 0xAA, 0xAA, 0x80, 0x00, 0x2A, 0xAA, 0xAA, 0xAA, 0xAA, 0x80, 0x00, 0x2A, 0x22, 0xAA, 0xAA, 0xAA, 0xAA,
            0xAA, 0xAA, 0xAA, 0xAA, 0xAA, 0xAA,
        ];
        let mut out = [0u8; 24];
        unpack_bits(&packed, &mut out).unwrap();
        assert_eq!(out, unpacked);
        // Cut short: an error, not a short row.
        let err = unpack_bits(&packed[..10], &mut out).unwrap_err();
        assert!(err.contains("after 10 of 24"), "{err}");
    }
}
