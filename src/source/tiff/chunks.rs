//! One strip or tile of a TIFF, read from the file and decompressed by us rather than by the
//! `tiff` crate, whose chunk reader refuses palette images and CCITT Group 3 and cannot give
//! one plane of a planar-separate image at sub-byte depths: [`super::kinds`] reads those.
//!
//! Decoded rows are as stored: samples packed MSB-first at 1, 2 or 4 bits (each row starting
//! on a byte), 8-bit samples as they are, 16-bit samples in native byte order; the horizontal
//! predictor is undone. Compressions: none, LZW ([`super::lzw`]), Deflate (flate2), PackBits,
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

/// Where every chunk lies and how to turn its bytes into rows.
pub(super) struct Chunks {
    pub offsets: Vec<u64>,
    pub counts: Vec<u64>,
    pub codec: Codec,
    pub predictor: bool,
    pub big_endian: bool,
    /// Bits per sample: 1, 2, 4, 8 or 16.
    pub bits: u16,
    /// FillOrder 2: the bits of each byte are stored least significant first.
    pub reverse_bits: bool,
    pub file_len: u64,
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
    /// Decodes chunk `index` into `out`, exactly `shape.rows` rows of `shape.row_bytes` bytes.
    pub fn decode(&self, file: &File, index: usize, shape: Shape, out: &mut [u8]) -> Result<(), String> {
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
            // No codec here expands less than 1:16 (G4 of noise is the worst), so a byte count
            // far above that is a corrupt table, refused before allocating for it.
            let bound = (out.len() as u64).saturating_mul(16).saturating_add(1 << 16);
            if count > bound {
                return Err(format!("it claims {count} compressed bytes for {} decoded ones", out.len()));
            }
            let mut raw = vec![0u8; count as usize];
            file.read_exact_at(&mut raw, offset).map_err(|e| format!("cannot read it: {e}"))?;
            if self.reverse_bits {
                raw.iter_mut().for_each(|b| *b = b.reverse_bits());
            }
            self.decompress(&raw, shape, out).map_err(|e| format!("corrupt or undecodable TIFF data: {e}"))?;
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

    /// 16-bit samples into native order, and the horizontal predictor (only allowed at 8 and
    /// 16 bits) undone, row by row.
    fn undo_predictor(&self, out: &mut [u8], row_bytes: usize, samples: usize) {
        for row in out.chunks_exact_mut(row_bytes) {
            match self.bits {
                16 => super::lzw::undo_predictor_16(row, samples, self.big_endian, self.predictor),
                8 if self.predictor => {
                    for i in samples..row.len() {
                        row[i] = row[i].wrapping_add(row[i - samples]);
                    }
                }
                _ => {}
            }
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
