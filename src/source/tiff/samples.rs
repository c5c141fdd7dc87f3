//! What a TIFF's samples are (SampleFormat 339 and BitsPerSample 258), and the conversion of
//! those the pipeline does not carry as they are stored.
//!
//! Carried as stored: unsigned integers of 8, 16 and 32 bits (SampleFormat 1) and 32-bit IEEE
//! floats (SampleFormat 3). Widened to `f32` as rows are read, exactly (every value of both is
//! an `f32`):
//! - 16-bit IEEE floats (half): `--tile-type half` stores them back as half, bit for bit;
//! - 16-bit signed integers (SampleFormat 2): read as floats rather than offset into `u16`,
//!   because an offset changes the values every reader sees (a DEM's -12 m would read 32756),
//!   and floats keep them, sign and all, through every output that holds floats (raw and zstd
//!   packs, OME-Zarr) and give means that are not rounded to whole numbers.
//!
//! Everything else (8- and 32-bit signed, 64-bit, 24-bit, void or mixed formats) is refused
//! with a message naming the field.

use super::super::{Embedded, ImageHeader, RowSource};
use crate::error::Result;
use crate::pixel::{Depth, PixelLayout};

/// How the decoder's samples (native byte order) become the pipeline's.
#[derive(Clone, Copy, Debug, PartialEq, Eq)]
pub(in crate::source) enum Stored {
    /// Carried as they are, at this depth.
    AsIs(Depth),
    /// 16-bit floats, widened to `f32`.
    Half,
    /// 16-bit signed integers, widened to `f32`.
    Int16,
}

impl Stored {
    /// The depth of the decoder's samples: their size, for every byte count of the file.
    pub fn file_depth(self) -> Depth {
        match self {
            Stored::AsIs(d) => d,
            Stored::Half => Depth::F16,
            Stored::Int16 => Depth::U16,
        }
    }
}

/// What the samples are, from the SampleFormat (one value per sample, 1 where absent) and
/// BitsPerSample values; `Err` says what the file is, for the caller's "... TIFF is not
/// supported" message.
pub(in crate::source) fn stored(formats: &[u16], bits: &[u16]) -> std::result::Result<Stored, String> {
    let format = formats.first().copied().unwrap_or(1);
    if formats.iter().any(|&f| f != format) {
        return Err(format!("a mixed-format (SampleFormat {formats:?})"));
    }
    let b = bits.first().copied().unwrap_or(1);
    if bits.iter().any(|&x| x != b) {
        return Err(format!("a mixed-depth ({bits:?} bits per sample)"));
    }
    match (format, b) {
        (1, 8) => Ok(Stored::AsIs(Depth::U8)),
        (1, 16) => Ok(Stored::AsIs(Depth::U16)),
        (1, 32) => Ok(Stored::AsIs(Depth::U32)),
        (3, 32) => Ok(Stored::AsIs(Depth::F32)),
        (3, 16) => Ok(Stored::Half),
        (2, 16) => Ok(Stored::Int16),
        (1, b) => Err(format!("a {b}-bit")),
        (2, b) => Err(format!("a {b}-bit signed-integer (SampleFormat 2; 16-bit is)")),
        (3, b) => Err(format!("a {b}-bit floating-point (SampleFormat 3; 16- and 32-bit are)")),
        (4, _) => Err("an untyped (void, SampleFormat 4) sample".into()),
        (f, _) => Err(format!("a SampleFormat {f}")),
    }
}

/// `inner` (whose samples are `stored`), its rows widened to `f32` where they are half floats
/// or signed integers; as it is otherwise.
pub(super) fn widen(inner: Box<dyn RowSource>, stored: Stored) -> Box<dyn RowSource> {
    match stored {
        Stored::AsIs(_) => inner,
        _ => Box::new(Widened { inner, stored, row: Vec::new() }),
    }
}

/// A source of 16-bit samples read as `f32`.
struct Widened {
    inner: Box<dyn RowSource>,
    stored: Stored,
    /// One row (or part of one) as the file holds it.
    row: Vec<u8>,
}

impl RowSource for Widened {
    fn header(&self) -> ImageHeader {
        let h = self.inner.header();
        ImageHeader { layout: PixelLayout::new(h.layout.channels, Depth::F32), ..h }
    }

    fn read_row(&mut self, out: &mut [u8]) -> Result<()> {
        // Two file bytes per four `f32` bytes, whatever columns are read.
        self.row.resize(out.len() / 2, 0);
        self.inner.read_row(&mut self.row)?;
        for (o, s) in out.chunks_exact_mut(4).zip(self.row.chunks_exact(2)) {
            let bits = u16::from_ne_bytes([s[0], s[1]]);
            let v = match self.stored {
                Stored::Int16 => bits as i16 as f32,
                _ => half::f16::from_bits(bits).to_f32(),
            };
            o.copy_from_slice(&v.to_ne_bytes());
        }
        Ok(())
    }

    fn describe(&self) -> String {
        let what = if self.stored == Stored::Int16 { "16-bit signed integers" } else { "half floats" };
        format!("{}; {what} read as 32-bit floats (exactly)", self.inner.describe())
    }

    forward_row_order_to_inner!();

    fn embedded(&self) -> Embedded {
        self.inner.embedded()
    }
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn sample_formats_name_what_is_refused() {
        assert_eq!(stored(&[], &[8, 8, 8]), Ok(Stored::AsIs(Depth::U8)));
        assert_eq!(stored(&[1], &[32]), Ok(Stored::AsIs(Depth::U32)));
        assert_eq!(stored(&[3, 3, 3], &[32, 32, 32]), Ok(Stored::AsIs(Depth::F32)));
        assert_eq!(stored(&[3], &[16]), Ok(Stored::Half));
        assert_eq!(stored(&[2], &[16]), Ok(Stored::Int16));
        assert!(stored(&[3], &[64]).unwrap_err().contains("64-bit floating-point"));
        assert!(stored(&[2], &[32]).unwrap_err().contains("SampleFormat 2"));
        assert!(stored(&[4], &[8]).unwrap_err().contains("void"));
        assert!(stored(&[1, 3], &[32, 32]).unwrap_err().contains("mixed-format"));
    }
}
