#![doc = include_str!("../README.md")]
#![warn(missing_docs)]

mod decode;
mod encode;
mod ffi;

pub use decode::{Decoded, Header, Samples, decode, probe};
pub use encode::{Effort, Image, Pixels, Quality, distance_for_quality, encode, most_encoded_bytes, recompress_jpeg};

/// Whether `bytes` start as a JPEG XL file does: a bare codestream (`FF 0A`) or the ISO BMFF
/// container's signature box.
pub fn is_jxl(bytes: &[u8]) -> bool {
    const CONTAINER: [u8; 12] = [0, 0, 0, 0x0C, b'J', b'X', b'L', b' ', 0x0D, 0x0A, 0x87, 0x0A];
    bytes.starts_with(&[0xFF, 0x0A]) || bytes.starts_with(&CONTAINER)
}

/// What went wrong. `Input` is the caller's mistake (fix the call); `Encoder` and
/// `JpegRecompression` are libjxl refusing what it was given; `Corrupt`, `Truncated` and
/// `TooLarge` describe a file being decoded; `OutOfMemory` is libjxl failing to allocate.
#[derive(Debug, thiserror::Error)]
#[non_exhaustive]
pub enum Error {
    /// The image or settings handed to the encoder are inconsistent (sizes, sample counts,
    /// channel counts, a distance or effort out of range).
    #[error("{0}")]
    Input(String),
    /// libjxl refused a step of encoding: `step` is the C function, `reason` its error code.
    #[error("libjxl: {step} failed: {reason}")]
    Encoder {
        /// The libjxl function that failed.
        step: &'static str,
        /// libjxl's `JxlEncoderError`, in words.
        reason: &'static str,
    },
    /// libjxl cannot recompress this JPEG losslessly (progressive with unusual scans, CMYK,
    /// arithmetic coding, ...): it stays a JPEG, or is decoded and encoded again.
    #[error("libjxl cannot recompress this JPEG losslessly ({step}: {reason})")]
    JpegRecompression {
        /// The libjxl function that failed.
        step: &'static str,
        /// libjxl's `JxlEncoderError`, in words.
        reason: &'static str,
    },
    /// The bytes are not a valid JPEG XL file (or use what this decoder does not: animation,
    /// float samples).
    #[error("not a JPEG XL image this decoder reads: {0}")]
    Corrupt(String),
    /// The file ends before its image does.
    #[error("the JPEG XL file ends before its image does")]
    Truncated,
    /// The image is larger than the caller allows; refused from its header, before its texels
    /// are allocated.
    #[error("the JPEG XL image is {width}x{height}, larger than the {max_width}x{max_height} allowed here")]
    TooLarge {
        /// The image's size.
        width: u32,
        /// The image's size.
        height: u32,
        /// The most allowed.
        max_width: u32,
        /// The most allowed.
        max_height: u32,
    },
    /// libjxl could not allocate its encoder or decoder.
    #[error("libjxl could not allocate its {0}")]
    OutOfMemory(&'static str),
}

#[cfg(test)]
mod tests {
    use super::*;

    #[test]
    fn recognises_both_signatures() {
        assert!(is_jxl(&[0xFF, 0x0A, 0x00]));
        assert!(is_jxl(&[0, 0, 0, 0x0C, b'J', b'X', b'L', b' ', 0x0D, 0x0A, 0x87, 0x0A, 0]));
        assert!(!is_jxl(&[0xFF, 0xD8, 0xFF]));
        assert!(!is_jxl(&[0xFF]));
    }
}
